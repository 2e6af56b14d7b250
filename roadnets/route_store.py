"""The route table a network keeps for sparse traces: its size, its files, its build.

Between fixes 10 s or more apart a matcher's route searches are long, and answering them
from one table of every edge's routes within :data:`ROUTE_TABLE_BOUND_M` (FMM's UBODT idea on
the edge-based router, :class:`~roadnets.routes.RouteTable`) is faster than searching. The
table is built where its estimated size fits a memory budget (:data:`DEFAULT_BUDGET_MB`;
:func:`estimate_bytes` searches a sample of the edges first) and kept in the network's cache
entry, in the folder :data:`ROUTES_FOLDER`: one ``.npy`` file per array, memory-mapped
(copy-on-write, never written) on reading, so the processes of one machine share one copy
through the page cache, and ``meta.json`` with the bound, the U-turn cost and a checksum of
every file.
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

if TYPE_CHECKING:
    from roadnets.arrays import NetworkArrays
    from roadnets.network import RoadNetwork
    from roadnets.routes import RouteTable
    from roadnets.turns import TurnGraph

__all__ = [
    "DEFAULT_BUDGET_MB",
    "ROUTES_FOLDER",
    "ROUTE_TABLE_BOUND_M",
    "THREAD_NAME",
    "TableKeeper",
    "build_table",
    "estimate_bytes",
    "read_table",
    "table_bytes",
    "write_table",
]

#: Route length (plus U-turn costs) the table holds from every edge: the matcher's searches
#: after a 30 s step reach about 1,500 m (``route_factor`` x the step + ``route_slack_m``).
ROUTE_TABLE_BOUND_M = 2000.0

#: Largest table built without being asked (MB): Andorra's 5,625 edges need 51 MB at
#: 2,000 m, Liechtenstein's 117 MB, the 200,000-edge grid city of bench_match.py about 17 GB
#: (estimated in 0.6 s; then none is built and searches answer). Building one takes about
#: twice its size for a moment (peak RSS +107 MB for Andorra's, +257 MB for Liechtenstein's).
DEFAULT_BUDGET_MB = 256.0

#: Name of the background thread that reads or builds a table.
THREAD_NAME = "route-table"

#: The table's folder inside a network's cache entry.
ROUTES_FOLDER = "routes"

#: Bumped whenever the stored arrays change meaning; other folders are then rebuilt.
_FORMAT = 2

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


def build_table(
    arrays: NetworkArrays, turns: TurnGraph, bound_m: float, *, uturn_cost_m: float
) -> RouteTable:
    """Every edge's routes within ``bound_m``, with the look-up index built."""
    from roadnets.routes import route_table

    sources = np.arange(arrays.n_edges, dtype=np.int64)
    table = route_table(arrays, turns, sources, bound_m, uturn_cost_m=uturn_cost_m)
    table.index()
    return table


def write_table(entry: Path, table: RouteTable) -> None:
    """
    Store a table of every edge's routes (one bound) in a cache entry, atomically.

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
            "bound_m": float(table.bounds_m.min(initial=np.inf)),
            "uturn_cost_m": table.uturn_cost_m,
            "edges": len(table.sources),
            "checksums": sums,
        }
        (tmp / "meta.json").write_text(json.dumps(meta), encoding="utf-8")
        put_in_place(tmp, entry / ROUTES_FOLDER)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def read_table(
    entry: Path, turns: TurnGraph, *, bound_m: float, uturn_cost_m: float
) -> RouteTable | None:
    """
    The stored table of a cache entry (memory-mapped), or ``None``.

    ``None`` when there is none, or it was built with another bound or U-turn cost, or for
    another network; a folder that is corrupt is removed (and so built again).
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
            or meta["bound_m"] != bound_m
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
            loaded[name] = np.asarray(np.load(path, mmap_mode="c", allow_pickle=False))
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
    bound, cost = ROUTE_TABLE_BOUND_M, DEFAULT_UTURN_COST_M
    found = None
    if entry is not None:
        found = read_table(entry, net.turns, bound_m=bound, uturn_cost_m=cost)
    if found is not None:
        return _attach(net, keeper, found, stored=True, how="read from the cache entry")
    budget = net.route_table_budget_mb
    if budget <= 0:
        return "none: route_table_budget_mb is 0"
    size = estimate_bytes(net.arrays, net.turns, bound, uturn_cost_m=cost)
    if size > budget * 1e6:
        return f"none: about {size / 1e6:,.1f} MB, over the {budget:g} MB budget"
    table = build_table(net.arrays, net.turns, bound, uturn_cost_m=cost)
    if entry is None:
        return _attach(net, keeper, table, stored=False, how="built (no cache entry to keep it)")
    try:
        write_table(entry, table)
    except OSError as exc:
        how = f"built, not stored ({exc})"
        return _attach(net, keeper, table, stored=False, how=how)
    stored = read_table(entry, net.turns, bound_m=bound, uturn_cost_m=cost)
    if stored is None:  # removed in between: keep the one in memory
        return _attach(net, keeper, table, stored=False, how="built, not stored")
    return _attach(net, keeper, stored, stored=True, how="built and stored in the cache entry")


def _attach(
    net: RoadNetwork, keeper: TableKeeper, table: RouteTable, *, stored: bool, how: str
) -> str:
    if net.precomputed_routes is not None:  # one given meanwhile wins
        return _GIVEN
    net.precomputed_routes = table
    keeper.stored = stored
    return f"{how}: {table_bytes(table) / 1e6:,.0f} MB, routes within {ROUTE_TABLE_BOUND_M:,.0f} m"


def table_bytes(table: RouteTable) -> int:
    """Bytes of a table's arrays (with its look-up index)."""
    return sum(_array(table, name).nbytes for name in _ARRAYS)
