"""The route table a network keeps for sparse traces: its size, its files, its build.

Between fixes 10 s or more apart a matcher's route searches are long, and answering them
from one table of every edge's routes within :data:`ROUTE_TABLE_BOUND_M` (FMM's UBODT idea on
the edge-based router, :class:`~roadnets.routes.RouteTable`) is faster than searching. The
table is built where its estimated size fits a memory budget (:data:`DEFAULT_BUDGET_MB`;
:func:`estimate_bytes` searches a sample of the edges first); where the whole bound does not
fit, with the longest of :data:`TABLE_BOUNDS_M` that does (:func:`fitted_bound`): a dense city
keeps the routes its 15 s traces need instead of none. It is kept in the network's cache
entry, in the folder :data:`ROUTES_FOLDER`: one ``.npy`` file per array, memory-mapped
(copy-on-write, never written) on reading, so the processes of one machine share one copy
through the page cache, and ``meta.json`` with the bound, the U-turn cost, the budget it was
fitted to and a checksum of every file.
Written into a temporary sibling folder and renamed into place, like the entry itself; a
folder that does not match its checksums is removed and built again.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import shutil
import tempfile
import threading
import weakref
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from roadnets.cache import file_checksum, put_in_place
from roadnets.pages import advise_huge_pages

if TYPE_CHECKING:
    from roadnets.arrays import NetworkArrays
    from roadnets.network import RoadNetwork
    from roadnets.routes import RouteTable
    from roadnets.turns import TurnGraph

__all__ = [
    "DEFAULT_BUDGET_MB",
    "ROUTES_FOLDER",
    "ROUTE_TABLE_BOUND_M",
    "TABLE_BOUNDS_M",
    "THREAD_NAME",
    "TableKeeper",
    "build_table",
    "estimate_bytes",
    "fitted_bound",
    "read_table",
    "table_bytes",
    "write_table",
]

#: Route lengths (plus U-turn costs) a table may hold from every edge, longest first: the
#: longest whose table fits the budget is built. The matcher's searches after a 30 s step
#: reach about 1,500 m (``route_factor`` x the step + ``route_slack_m``), after a 15 s step in
#: a city 600-800 m; the pairs whose searches fit in the table's bound are answered from it,
#: the others searched. Baltimore's 874 MB at 2,000 m are estimated 266 MB at 1,000 m and
#: 222 MB at 900 m (built: 228 MB); below 500 m a table would serve few sparse traces.
TABLE_BOUNDS_M = (2000.0, 1750.0, 1500.0, 1250.0, 1100.0, 1000.0, 900.0, 800.0, 700.0, 600.0, 500.0)
#: The longest of :data:`TABLE_BOUNDS_M`: what a table holds where it fits the budget.
ROUTE_TABLE_BOUND_M = TABLE_BOUNDS_M[0]

#: Largest table built without being asked (MB): Andorra's 5,625 edges need 51 MB at
#: 2,000 m, Liechtenstein's 117 MB, the 200,000-edge grid city of bench_match.py about 17 GB
#: (estimated in 0.6 s; then none is built and searches answer). Building one takes about
#: twice its size for a moment (peak RSS +107 MB for Andorra's, +257 MB for Liechtenstein's).
DEFAULT_BUDGET_MB = 256.0

#: Name of the background thread that reads or builds a table.
THREAD_NAME = "route-table"

#: The table's folder inside a network's cache entry.
ROUTES_FOLDER = "routes"

#: Bumped whenever the stored arrays change meaning; other folders are then rebuilt (3 kept
#: each record's columns side by side, one packed row: the kernels then read strided views,
#: whose compiled variants differ from those of a table's own arrays; 4 is columns again).
_FORMAT = 4

#: The arrays of a stored table's look-up index, :func:`~roadnets.record_index.record_index`.
_INDEX_ARRAYS = ("index_ptr", "index_slots")

#: Arrays of a stored table: its records, then its look-up index.
_ARRAYS = ("ptr", "state", "distance_m", "time_s", "uturns", "pred", *_INDEX_ARRAYS)

#: Bytes of one record: state (int32), length and time (float64), U-turns (int16),
#: predecessor (int32) and its two index slots (uint16).
_RECORD_BYTES = 4 + 8 + 8 + 2 + 4 + 2 * 2

#: The note when the network holds a table of its caller's (:meth:`precompute_routes`).
_GIVEN = "given (precompute_routes)"

_log = logging.getLogger("roadnets")


def estimate_bytes(
    arrays: NetworkArrays,
    turns: TurnGraph,
    bound_m: float,
    *,
    uturn_cost_m: float,
    sample: int = 256,
) -> int:
    """
    Size of a table of every edge's routes within ``bound_m``, from a sample of its searches.

    Searches ``sample`` edges spread evenly over the network (all of them when there are
    fewer) and scales their records up to every edge.
    """
    from roadnets.routes import route_table

    n = arrays.n_edges
    sources = np.unique(np.linspace(0, n - 1, min(sample, n)).astype(np.int64))
    part = route_table(arrays, turns, sources, bound_m, uturn_cost_m=uturn_cost_m)
    per_source = len(part.state) / max(len(sources), 1)
    return int(per_source * n * _RECORD_BYTES + 8 * (n + 1))


def fitted_bound(
    arrays: NetworkArrays,
    turns: TurnGraph,
    budget_bytes: float,
    *,
    uturn_cost_m: float,
    longer_than_m: float = 0.0,
) -> tuple[float, int]:
    """
    The longest bound of :data:`TABLE_BOUNDS_M` whose table fits ``budget_bytes``, and its size.

    Estimated (:func:`estimate_bytes`) from the longest bound down, stopping at the first that
    fits; bounds not longer than ``longer_than_m`` are not tried. Where none fits, the bound is
    NaN and the size the last one estimated (the shortest tried; 0 when none was).
    """
    size = 0
    for bound in TABLE_BOUNDS_M:
        if bound <= longer_than_m:
            break
        size = estimate_bytes(arrays, turns, bound, uturn_cost_m=uturn_cost_m)
        if size <= budget_bytes:
            return bound, size
    return float("nan"), size


def build_table(
    arrays: NetworkArrays, turns: TurnGraph, bound_m: float, *, uturn_cost_m: float
) -> RouteTable:
    """Every edge's routes within ``bound_m``, with the look-up index built."""
    from roadnets.routes import route_table

    sources = np.arange(arrays.n_edges, dtype=np.int64)
    table = route_table(arrays, turns, sources, bound_m, uturn_cost_m=uturn_cost_m)
    table.index()
    return table


def write_table(
    entry: Path, table: RouteTable, budget_mb: float = float("inf"), *, replace: bool = False
) -> None:
    """
    Store a table of every edge's routes (one bound) in a cache entry, atomically.

    ``budget_mb`` is the budget its bound was fitted to (:func:`fitted_bound`; infinite: none),
    so that a larger budget later builds one with a longer bound; ``replace`` puts it in the
    place of the stored one (which processes that mapped it go on reading), else a stored one
    is kept.

    Raises
    ------
    OSError
        The entry folder cannot be written.
    """
    tmp = Path(tempfile.mkdtemp(prefix=f".{ROUTES_FOLDER}-", dir=entry))
    try:
        sums = {}
        for name in _ARRAYS:
            np.save(tmp / f"{name}.npy", _array(table, name), allow_pickle=False)
            sums[name] = file_checksum(tmp / f"{name}.npy")
        meta = {
            "format": _FORMAT,
            "bound_m": _bound(table),
            "uturn_cost_m": table.uturn_cost_m,
            "budget_mb": budget_mb if np.isfinite(budget_mb) else None,
            "edges": len(table.sources),
            "checksums": sums,
        }
        (tmp / "meta.json").write_text(json.dumps(meta), encoding="utf-8")
        if replace:
            _retire(entry / ROUTES_FOLDER)
        put_in_place(tmp, entry / ROUTES_FOLDER)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _retire(folder: Path) -> None:
    """Move a stored table's folder out of its place and remove it (gone already: nothing)."""
    old = Path(tempfile.mkdtemp(prefix=f".{ROUTES_FOLDER}-old-", dir=folder.parent))
    with contextlib.suppress(OSError):  # another process moved it first
        folder.rename(old / ROUTES_FOLDER)
    shutil.rmtree(old, ignore_errors=True)


def read_table(
    entry: Path, turns: TurnGraph, *, bounds_m: tuple[float, ...], uturn_cost_m: float
) -> RouteTable | None:
    """
    The stored table of a cache entry (memory-mapped), or ``None``.

    ``None`` when there is none, or it was built with a bound not in ``bounds_m`` or another
    U-turn cost, or for another network; a folder that is corrupt is removed (and so built
    again).
    """
    from roadnets.routes import RouteTable

    folder = entry / ROUTES_FOLDER
    meta_path = folder / "meta.json"
    if not meta_path.exists():
        return None
    try:
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
        if (
            meta.get("format") != _FORMAT
            or meta["bound_m"] not in bounds_m
            or meta["uturn_cost_m"] != uturn_cost_m
        ):
            return None
        n = int(meta["edges"])
        loaded: dict[str, np.ndarray[Any, Any]] = {}
        for name in _ARRAYS:
            path = folder / f"{name}.npy"
            if file_checksum(path) != meta["checksums"][name]:
                msg = f"checksum of {path.name} differs"
                raise ValueError(msg)
            # copy-on-write: shared pages, never written, and writeable like a table built
            # here, so the compiled matcher sees one array type for both
            mapped = np.load(path, mmap_mode="c", allow_pickle=False)
            advise_huge_pages(mapped)  # before its pages are read: 2 MB ones where possible
            loaded[name] = np.asarray(mapped)
        if n != turns.n_edges or len(loaded["ptr"]) != n + 1:
            msg = f"it holds {n:,} edges, the network {turns.n_edges:,}"
            raise ValueError(msg)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        _log.warning("stored route table %s is corrupt (%s); building it again", folder, exc)
        with contextlib.suppress(OSError):
            shutil.rmtree(folder)
        return None
    table = RouteTable(
        sources=np.arange(n, dtype=np.int64),
        bounds_m=np.full(n, float(meta["bound_m"])),
        complete=True,
        uturn_cost_m=float(meta["uturn_cost_m"]),
        weighted=False,
        ptr=loaded["ptr"],
        state=loaded["state"],
        distance_m=loaded["distance_m"],
        time_s=loaded["time_s"],
        uturns=loaded["uturns"],
        pred=loaded["pred"],
        turns=turns,
    )
    table._index.extend(loaded[name] for name in _INDEX_ARRAYS)  # stored with it
    return table


def _stored_budget_mb(entry: Path) -> float:
    """
    The budget the stored table's bound was fitted to (infinite: its bound is the longest).

    Read from its ``meta.json``; tables stored before budgets were kept hold the longest bound.
    """
    try:
        meta = json.loads((entry / ROUTES_FOLDER / "meta.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return float("inf")
    budget = meta.get("budget_mb")
    return float("inf") if budget is None else float(budget)


def _record_budget(entry: Path, budget_mb: float) -> None:
    """
    Note in the stored table's ``meta.json`` that ``budget_mb`` fits no longer bound either.

    So that later processes with that budget read the table without estimating again; the
    file is replaced atomically, and a failure to write it only costs them the estimate.
    """
    meta_path = entry / ROUTES_FOLDER / "meta.json"
    tmp = None
    try:
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
        meta["budget_mb"] = budget_mb
        fd, tmp = tempfile.mkstemp(prefix=".meta-", suffix=".json", dir=meta_path.parent)
        with os.fdopen(fd, "w", encoding="utf-8") as out:
            out.write(json.dumps(meta))
        os.replace(tmp, meta_path)
        tmp = None
    except (OSError, ValueError) as exc:
        _log.debug("budget of the stored route table %s not recorded: %s", meta_path, exc)
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)


def _array(table: RouteTable, name: str) -> np.ndarray[Any, Any]:
    if name in _INDEX_ARRAYS:
        return table.index()[_INDEX_ARRAYS.index(name)]
    found: np.ndarray[Any, Any] = getattr(table, name)
    return found


class TableKeeper:
    """
    A network's sparse-trace table: looked for once, read or built in the background.

    :meth:`request` starts the work in a daemon thread and returns at once (the matcher
    calls it on its first sparse trace, and searches until the table is there); :meth:`ensure`
    does it in the calling thread or waits for it. :attr:`note` says what became of it.
    """

    def __init__(self) -> None:
        self._reset()
        _KEEPERS.add(self)

    def _reset(self) -> None:
        self._lock = threading.Lock()
        self._job: threading.Thread | None = None
        self.note = "not looked for yet"
        #: Whether the network's table is the one memory-mapped from its cache entry.
        self.stored = False

    @property
    def started(self) -> bool:
        """Whether the table was looked for (or is being) in this process."""
        return self._job is not None

    def request(self, net: RoadNetwork) -> None:
        """Look for the table (and build it when it fits the budget) in the background."""
        with self._lock:
            if self._job is not None:
                return
            self._job = threading.Thread(
                target=self._provide, args=(net,), name=THREAD_NAME, daemon=True
            )
            self.note = "being read or built"
            self._job.start()

    def ensure(self, net: RoadNetwork) -> RouteTable | None:
        """The table after looking for it (or building it) here, or waiting for the job."""
        self.request(net)
        assert self._job is not None
        self._job.join()
        return net.precomputed_routes

    def _provide(self, net: RoadNetwork) -> None:
        try:
            self.note = _provide(net, self)
        except Exception as exc:  # a background thread must not die unheard
            self.note = f"failed: {exc}"
            _log.warning("route table for %s not built: %s", net.network_id, exc)


#: Every keeper of this process: a forked child starts each afresh (the parent's thread and
#: lock are not there), checked once at the fork rather than on every match.
_KEEPERS: weakref.WeakSet[TableKeeper] = weakref.WeakSet()


def _forked() -> None:
    for keeper in list(_KEEPERS):
        keeper._reset()


os.register_at_fork(after_in_child=_forked)


def _provide(net: RoadNetwork, keeper: TableKeeper) -> str:
    """Attach the network's table (stored, else built within budget); say what happened."""
    from roadnets.turns import DEFAULT_UTURN_COST_M

    if net.precomputed_routes is not None:
        return _GIVEN
    entry = Path(net.cache_entry) if net.cache_entry is not None else None
    cost = DEFAULT_UTURN_COST_M
    budget = net.route_table_budget_mb
    found = None
    if entry is not None:
        found = read_table(entry, net.turns, bounds_m=TABLE_BOUNDS_M, uturn_cost_m=cost)
    longer_than = 0.0
    if found is not None and entry is not None:
        reach = _bound(found)
        if reach >= ROUTE_TABLE_BOUND_M or not budget > _stored_budget_mb(entry):
            return _attach(net, keeper, found, stored=True, how="read from the cache entry")
        longer_than = reach  # fitted to a smaller budget than today's: a longer bound may fit
    if budget <= 0:
        return "none: route_table_budget_mb is 0"
    bound, size = fitted_bound(
        net.arrays, net.turns, budget * 1e6, uturn_cost_m=cost, longer_than_m=longer_than
    )
    if found is not None and entry is not None and np.isnan(bound):
        # the stored one is still the longest that fits: say so for the budget, once
        _record_budget(entry, budget)
        return _attach(net, keeper, found, stored=True, how="read from the cache entry")
    if np.isnan(bound):
        return (
            f"none: about {size / 1e6:,.1f} MB even for routes within {TABLE_BOUNDS_M[-1]:,.0f} m, "
            f"over the {budget:g} MB budget"
        )
    table = build_table(net.arrays, net.turns, bound, uturn_cost_m=cost)
    if entry is None:
        return _attach(net, keeper, table, stored=False, how="built (no cache entry to keep it)")
    try:
        fitted_to = budget if bound < ROUTE_TABLE_BOUND_M else float("inf")
        # one stored that could not serve (shorter, or of an older format) gives way
        stale = found is not None or (entry / ROUTES_FOLDER / "meta.json").exists()
        write_table(entry, table, fitted_to, replace=stale)
    except OSError as exc:
        how = f"built, not stored ({exc})"
        return _attach(net, keeper, table, stored=False, how=how)
    stored = read_table(entry, net.turns, bounds_m=(bound,), uturn_cost_m=cost)
    if stored is None:  # removed in between: keep the one in memory
        return _attach(net, keeper, table, stored=False, how="built, not stored")
    return _attach(net, keeper, stored, stored=True, how="built and stored in the cache entry")


def _bound(table: RouteTable) -> float:
    """The bound every source of a table was searched with (the table's reach)."""
    return float(table.bounds_m.min(initial=np.inf))


def _attach(
    net: RoadNetwork, keeper: TableKeeper, table: RouteTable, *, stored: bool, how: str
) -> str:
    if net.precomputed_routes is not None:  # one given meanwhile wins
        return _GIVEN
    net.precomputed_routes = table
    keeper.stored = stored
    reach = _bound(table)
    return f"{how}: {table_bytes(table) / 1e6:,.0f} MB, routes within {reach:,.0f} m"


def table_bytes(table: RouteTable) -> int:
    """Bytes of a table's arrays (with its look-up index)."""
    return sum(_array(table, name).nbytes for name in _ARRAYS)
