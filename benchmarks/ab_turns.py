"""Versions of the matcher timed in turns: source trees, or settings of one tree.

    .venv/bin/python benchmarks/ab_turns.py --variant base=/tmp/old-tree --variant new=. \
        [--variant novec=.:NUMBA_LOOP_VECTORIZE=0,NUMBA_CACHE_DIR=/tmp/nc-novec] \
        [--variant tail=.:AB_TURNS_CUT=mapmatch.hmm.assemble._assemble_kernel:free] \
        [--set krems_at_2013:15s_10m:positions ...] [--set sim:15:25:20] \
        [--rounds 100] [--passes 3] [--evict-mb 0] [--sets-dir .bench/peers/sets]

A change that saves a few per cent of a trace is smaller than the shared machine's swings
between minutes (a sixth, more in a slow spell), so it is measured in turns: one process per
variant (``NAME=TREE``, the tree's ``mapmatch`` and ``roadnets`` first on the path, and
``:KEY=VALUE,...`` added to its environment), every process loaded and warm, then round after
round each process in turn runs ``--passes`` passes over every set (match + GeoJSON text, as a
user of the library gets them; the fastest pass counts, CPU time a trace), the order reversed
every other round, so that every variant meets the same spells. Reported per set: each
variant's median over the rounds, and against the first variant the median of the rounds'
paired ratios with their quartiles (below 1: faster), and whether its documents are the
first variant's (their stats' timings left out: a change meant to be faster only should
print ``equal``). The baseline's tree once more under another name shows the sitting's noise
(its ratio should come out within a per cent of 1). ``--evict-mb 64`` reads that much other
memory before every pass, so that each pass starts cold, as in the peer comparison, where
the other peers' passes run between two of ours.

A variant may also stand for a bound rather than a version: with the setting
``AB_TURNS_CUT=KERNEL:free`` (``KERNEL`` a compiled kernel's ``module.name``) each match stops
right after that kernel returns, so the variant times everything before it: what the rest
would cost if it took no time at all; with ``AB_TURNS_CUT=KERNEL:kernels`` the compiled
kernels that ran after it in a pass before run again on that pass's arguments, one right
after another with no Python between them: what the rest would cost if its Python did. Two
such variants with the same tree price a stage of the match, its kernels and its Python
apart, under the same turns; their documents column says ``cut``.

A set is a trace file of the peer comparison, ``EXTRACT:SET:INPUT``: ``krems_at_2013:15s_10m:
positions`` is ``krems_at_2013/15s_10m/positions.csv`` in ``--sets-dir`` (a folder a
``compare_peers.py`` run wrote, ``.bench/peers/sets`` unless said: every run simulates the
same traces), matched on ``krems_at_2013.osm.gz`` from ``../shared/data/osm`` with ``sigma_m``
the set's noise; or
``sim:INTERVAL:FIXES:TRACES[:EXTRACT]``: simulated trips (heading and speed given, 2 %
outliers of 40 m) on the extract (the embedded network without one), simulated once here and
written to a file every variant reads. A tree needs its kernels compiled (its first start
takes about a minute, once); a variant with settings that change the compiled code wants a
``NUMBA_CACHE_DIR`` of its own.

The processes start in the order the variants are listed, and on this shared machine the
earlier ones ran slower: four processes of one tree, 1-5 % between the first started and the
last, in whichever order they were listed (stop 64). So a version gets two processes, listed
first and last around the other's two (``--variant base=OLD --variant new=. --variant
new2=. --variant base2=OLD``), and variants that run the same tree with the same settings
are pooled in a second table: per round the mean of their processes, against the first
variant's version's, so that the start order cancels.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import functools
import hashlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from kernel_time import ROOT, SHARED

if TYPE_CHECKING:
    from collections.abc import Callable

SETS = ROOT / ".bench" / "peers" / "sets"
#: What a worker prints when its sets are loaded and matched once.
READY = "ready"


@dataclass(frozen=True, slots=True)
class TraceSet:
    """A trace file, the extract it is matched on (``None``: the embedded network), its sigma."""

    label: str
    csv: str
    extract: str | None
    sigma_m: float | None


@dataclass(frozen=True, slots=True)
class Variant:
    """A version of the matcher: a source tree and what its process's environment adds."""

    name: str
    tree: Path
    env: dict[str, str]


def parse_variant(text: str) -> Variant:
    """``NAME=TREE[:KEY=VALUE,...]``."""
    name, sep, rest = text.partition("=")
    tree, _, settings = rest.partition(":")
    if not sep or not name or not tree:
        msg = f"bad --variant {text!r}; write NAME=TREE or NAME=TREE:KEY=VALUE,..."
        raise SystemExit(msg)
    env = {}
    for item in filter(None, settings.split(",")):
        key, eq, value = item.partition("=")
        if not eq or not key:
            msg = f"bad setting {item!r} in --variant {text!r}; write KEY=VALUE"
            raise SystemExit(msg)
        env[key] = value
    path = Path(tree).resolve()
    if not (path / "mapmatch" / "__init__.py").is_file():
        msg = f"--variant {name}: {path} holds no mapmatch package"
        raise SystemExit(msg)
    return Variant(name, path, env)


def _extract_file(stem: str) -> str:
    found = sorted(SHARED.glob(stem + ".osm*"))
    if not found:
        msg = f"no extract {stem}.osm* in {SHARED}"
        raise SystemExit(msg)
    return str(found[0])


def parse_set(text: str, scratch: Path, sets_dir: Path = SETS) -> TraceSet:
    """A peer set (``EXTRACT:SET:INPUT``) or simulated traces (``sim:INTERVAL:FIXES:TRACES``)."""
    parts = text.split(":")
    bad = f"bad --set {text!r}; write EXTRACT:SET:INPUT or sim:INTERVAL:FIXES:TRACES[:EXTRACT]"
    if parts[0] == "sim" and len(parts) in (4, 5):
        try:
            interval, fixes, count = float(parts[1]), int(parts[2]), int(parts[3])
        except ValueError as exc:
            raise SystemExit(bad) from exc
        extract = _extract_file(parts[4]) if len(parts) == 5 else None
        path = scratch / f"sim-{len(list(scratch.iterdir()))}.csv"
        _write_simulated(path, extract, interval, fixes, count)
        return TraceSet(text, str(path), extract, None)
    if len(parts) == 3:
        stem, label, kind = parts
        path = (sets_dir / stem / label / f"{kind}.csv").resolve()  # the workers run elsewhere
        if not path.is_file():
            msg = f"no trace file {path} (benchmarks/compare_peers.py writes the peer sets)"
            raise SystemExit(msg)
        try:  # INTERVALs_NOISEm, as compare_peers.py names its sets
            noise = float(label.split("_")[1].removesuffix("m"))
        except (IndexError, ValueError) as exc:
            msg = f"--set {text!r}: a peer set is named INTERVALs_NOISEm, e.g. 15s_10m"
            raise SystemExit(msg) from exc
        return TraceSet(text, str(path), _extract_file(stem), noise)
    raise SystemExit(bad)


def _write_simulated(
    path: Path, extract: str | None, interval_s: float, fixes: int, count: int
) -> None:
    """Simulated traces (``bench_fixed_cost.traces_of``) as a trace file."""
    sys.path[:0] = [p for p in (str(ROOT), str(ROOT / "benchmarks")) if p not in sys.path]
    from bench_fixed_cost import traces_of

    import roadnets

    net = roadnets.load(extract) if extract else roadnets.load()
    rows = []
    for trace in traces_of(net, interval_s, fixes, count):
        named = {
            "time": trace.time_s,
            "lon": trace.lon,
            "lat": trace.lat,
            "heading": trace.heading_deg,
            "speed": trace.speed_mps,
        }
        columns = {name: values for name, values in named.items() if values is not None}
        rows += [
            {"trace_id": trace.trace_id} | {k: repr(float(v[i])) for k, v in columns.items()}
            for i in range(len(trace.lon))
        ]
    with path.open("w", newline="") as f:
        out = csv.DictWriter(f, fieldnames=list(rows[0]))
        out.writeheader()
        out.writerows(rows)


# --------------------------------------------------------------------------- the worker

#: The setting (an environment variable of a variant) that makes it a bound: see the module.
CUT_SETTING = "AB_TURNS_CUT"
CUT_MODES = ("free", "kernels")


class _CutReached(BaseException):
    """Raised right after the cut kernel returns: it passes every ``except Exception``."""


class StageCut:
    """
    Matches ended right after one kernel (:data:`CUT_SETTING`), and what came after it.

    :meth:`learn` runs a trace's match in full once and keeps the kernel calls made after the
    cut's first call (and the cut's own later calls), with their arguments; :meth:`run` then
    matches the trace up to that call and, in ``kernels`` mode, makes the kept calls again.
    """

    def __init__(self, spec: str) -> None:
        name, _, mode = spec.rpartition(":")
        if mode not in CUT_MODES or "." not in name:
            msg = f"bad {CUT_SETTING}={spec!r}; write MODULE.KERNEL:free or MODULE.KERNEL:kernels"
            raise SystemExit(msg)
        self.name, self.mode = name, mode
        self.after: dict[object, list[tuple[Any, tuple[Any, ...], dict[str, Any]]]] = {}
        self.recording: list[tuple[Any, tuple[Any, ...], dict[str, Any]]] | None = None
        self.learning = True
        self._bound: list[tuple[Any, str, Any]] = []

    def install(self) -> None:
        """
        Stand in for every binding of our kernels (all compiled: a warm-up ran), and the cut's.

        The cut is a kernel (every module's binding of it) or any other function or class a
        loaded module binds under that name (that binding alone: the Python it runs is
        before the cut).
        """
        from kernel_time import our_kernels

        self._bound = list(our_kernels())
        labels = {f"{k.py_func.__module__}.{k.py_func.__name__}" for _, _, k in self._bound}
        module_name, _, attr = self.name.rpartition(".")
        module = sys.modules.get(module_name)
        other = None if self.name in labels or module is None else getattr(module, attr, None)
        if self.name not in labels and not callable(other):
            msg = f"{CUT_SETTING}: nothing loaded is named {self.name} (kernels: {sorted(labels)})"
            raise SystemExit(msg)
        for bound_in, bound_as, kernel in self._bound:
            label = f"{kernel.py_func.__module__}.{kernel.py_func.__name__}"
            setattr(bound_in, bound_as, _CutStandIn(kernel, self, cut=label == self.name))
        if other is not None:
            self._bound.append((module, attr, other))
            setattr(module, attr, _CutStandIn(other, self, cut=True))

    def learn(self, key: object, match: Callable[[], object]) -> None:
        """Match once in full, keeping the kernel calls after the cut's (``key``: the trace)."""
        self.recording = None
        match()
        self.after[key] = self.recording or []
        self.recording = None

    def stop_learning(self) -> None:
        """Only the cut kernel's stand-in stays: the kernels before it run as they are."""
        self.learning = False
        for module, attr, kernel in self._bound:
            if not getattr(module, attr).cut:
                setattr(module, attr, kernel)

    def uninstall(self) -> None:
        """Every binding its own callable again (a test's process matches on)."""
        for module, attr, value in self._bound:
            setattr(module, attr, value)
        self._bound = []

    def run(self, key: object, match: Callable[[], object]) -> None:
        """Match up to the cut, then (``kernels``) the kept calls after it."""
        try:
            match()
        except _CutReached:
            if self.mode == "kernels":
                for kernel, args, kwargs in self.after.get(key, ()):
                    kernel(*args, **kwargs)


class _CutStandIn:
    """A kernel's stand-in while a :class:`StageCut` learns or cuts."""

    def __init__(self, kernel: Any, cut_of: StageCut, *, cut: bool) -> None:
        self.kernel, self.cut_of, self.cut = kernel, cut_of, cut

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        out = self.kernel(*args, **kwargs)  # kernels take no keywords; other cuts may
        stage = self.cut_of
        if stage.recording is not None:
            stage.recording.append((self.kernel, args, kwargs))
        elif self.cut:
            if not stage.learning:
                raise _CutReached
            stage.recording = []
        return out


def worker(
    sets: list[dict[str, Any]], passes: int, evict_mb: int = 0, evict_pages: bool = False
) -> None:
    """
    Load the sets, say where ``mapmatch`` came from, then time a round on each ``go``.

    ``evict_mb``: before each pass, that many MB of other memory are read (untimed), so the
    pass starts with the caches holding none of the match's code or data, as a pass of the
    peer comparison does after the other peers' passes. ``evict_pages``: one value of each
    of its 4 KB pages instead, in a random order, the memory on 4 KB pages, so that the
    address translations (TLB, page-walk caches) are cold too, as after a peer's look-ups in
    a table of gigabytes.
    """
    import numpy as np

    import mapmatch
    import roadnets
    from mapmatch.export import geojson_bytes

    jobs = []
    digests = []
    for s in sets:
        net = roadnets.load(s["extract"]) if s["extract"] else roadnets.load()
        net.sparse_route_table()
        traces = list(mapmatch.read_traces(s["csv"]))
        config = mapmatch.MatchConfig(sigma_m=s["sigma_m"]) if s["sigma_m"] else None
        digest = hashlib.sha256()
        for trace in traces:  # warm, and the documents' digest
            digest.update(_without_timings(geojson_bytes(mapmatch.match(trace, net, config))))
        digests.append(digest.hexdigest()[:16])
        jobs.append((net, traces, config))
    spec = os.environ.get(CUT_SETTING)
    stage = None if spec is None else StageCut(spec)
    if stage is not None:
        stage.install()
        for s, (net, traces, config) in enumerate(jobs):
            for t, trace in enumerate(traces):
                stage.learn((s, t), functools.partial(_document, trace, net, config))
        stage.stop_learning()
        digests = ["cut"] * len(jobs)
    print(json.dumps({READY: str(Path(mapmatch.__file__).parent), "digests": digests}), flush=True)
    other = _small_paged(evict_mb) if evict_pages else np.ones(evict_mb * 2**20 // 8)
    pages = np.random.default_rng(0).permutation(np.arange(0, len(other), 4096 // 8))

    def evict() -> None:
        if evict_pages:
            other[pages].sum()
        else:
            other.sum()

    for _ in sys.stdin:
        times = []
        for s, (net, traces, config) in enumerate(jobs):
            best = float("inf")
            for _ in range(passes):
                evict()
                start = time.process_time()
                if stage is None:
                    for trace in traces:
                        geojson_bytes(mapmatch.match(trace, net, config))
                else:
                    for t, trace in enumerate(traces):
                        stage.run((s, t), functools.partial(_document, trace, net, config))
                best = min(best, time.process_time() - start)
            times.append(best / len(traces) * 1e6)
        print(json.dumps(times), flush=True)


def _small_paged(mb: int) -> Any:
    """
    ``mb`` MB of ones on 4 KB pages, as a C++ peer's tables are (numpy asks for 2 MB pages above
    4 MB, and 1 GB read a value a page on 2 MB pages needs only 512 address translations).
    """
    import mmap

    import numpy as np

    size = max(mb * 2**20, mmap.PAGESIZE)
    memory = mmap.mmap(-1, size)
    with contextlib.suppress(AttributeError, OSError):  # no such advice here: pages as they come
        memory.madvise(mmap.MADV_NOHUGEPAGE)
    values = np.frombuffer(memory, dtype=np.float64)
    values[:] = 1.0
    return values


def _document(trace: Any, net: Any, config: Any) -> bytes:
    """A trace's match and GeoJSON text, as the passes make them."""
    import mapmatch
    from mapmatch.export import geojson_bytes

    return geojson_bytes(mapmatch.match(trace, net, config))


def _without_timings(document: bytes) -> bytes:
    """A GeoJSON document without its stats' timings (which differ every run), re-written."""
    try:
        doc = json.loads(document)
    except ValueError:
        return document  # not JSON: it differs from the baseline's as it is
    if isinstance(doc, dict) and isinstance(doc.get("stats"), dict):
        doc["stats"].pop("timings_s", None)
    return json.dumps(doc, separators=(",", ":")).encode()


# --------------------------------------------------------------------------- the turns


class Worker:
    """A variant's process, loaded and warm: asked for a round, it answers its times."""

    def __init__(
        self,
        variant: Variant,
        sets: list[TraceSet],
        passes: int,
        evict_mb: int = 0,
        evict_pages: bool = False,
    ) -> None:
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(
            [str(variant.tree), *filter(None, [env.get("PYTHONPATH")])]
        )
        env.update(variant.env)
        spec = json.dumps(
            [{"csv": s.csv, "extract": s.extract, "sigma_m": s.sigma_m} for s in sets]
        )
        self.process = subprocess.Popen(
            [
                sys.executable,
                __file__,
                "--worker",
                spec,
                "--passes",
                str(passes),
                "--evict-mb",
                str(evict_mb),
                *(["--evict-pages"] if evict_pages else []),
            ],
            cwd=tempfile.gettempdir(),  # not a tree: only PYTHONPATH says which mapmatch
            env=env,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        self.name = variant.name
        line = self._line()
        if not line:
            self.close()
            msg = f"variant {variant.name}: its worker stopped before it was ready"
            raise SystemExit(msg)
        said = json.loads(line)
        if Path(said[READY]) != variant.tree / "mapmatch":
            self.close()
            msg = f"variant {variant.name} imported mapmatch from {said[READY]}, not its tree"
            raise SystemExit(msg)
        #: Per set, 16 hex digits of the SHA-256 of its documents, their timings left out.
        self.digests: list[str] = said["digests"]

    def _line(self) -> str:
        assert self.process.stdout is not None
        return self.process.stdout.readline()

    def round(self) -> list[float]:
        """One round: us a trace per set."""
        assert self.process.stdin is not None
        self.process.stdin.write("go\n")
        self.process.stdin.flush()
        line = self._line()
        if not line:
            msg = f"variant {self.name}: its worker stopped in the middle of the turns"
            raise SystemExit(msg)
        times: list[float] = json.loads(line)
        return times

    def close(self) -> None:
        assert self.process.stdin is not None
        assert self.process.stdout is not None
        self.process.stdin.close()  # the worker's loop ends
        self.process.wait()
        self.process.stdout.close()


def run_turns(
    variants: list[Variant],
    sets: list[TraceSet],
    rounds: int,
    passes: int,
    evict_mb: int = 0,
    evict_pages: bool = False,
) -> tuple[dict[str, list[list[float]]], dict[str, list[str]]]:
    """Each variant's us a trace per round and set, and its documents' digests per set."""
    workers: dict[str, Worker] = {}
    try:
        for v in variants:
            workers[v.name] = Worker(v, sets, passes, evict_mb, evict_pages)
        times: dict[str, list[list[float]]] = {v.name: [] for v in variants}
        for r in range(rounds):
            for v in variants if r % 2 == 0 else variants[::-1]:
                times[v.name].append(workers[v.name].round())
    finally:
        for w in workers.values():
            w.close()
    return times, {name: w.digests for name, w in workers.items()}


def report(
    variants: list[Variant],
    sets: list[TraceSet],
    times: dict[str, list[list[float]]],
    digests: dict[str, list[str]],
) -> str:
    """The table: per set and variant, the median us a trace, the paired ratio, the output."""
    base = variants[0].name
    lines = [
        "| set | variant | us a trace (median) | / " + base + " (paired, quartiles) | documents |",
        "|---|---|--:|---|---|",
    ]
    for i, s in enumerate(sets):
        ours = [round_[i] for round_ in times[base]]
        for v in variants:
            mine = [round_[i] for round_ in times[v.name]]
            if v.name == base:
                ratio, same = "", f"`{digests[base][i]}`"
            else:
                paired = sorted(b / a for a, b in zip(ours, mine, strict=True))
                q1, q3 = paired[len(paired) // 4], paired[(3 * len(paired)) // 4]
                ratio = f"{statistics.median(paired):.3f} ({q1:.3f}-{q3:.3f})"
                same = "equal" if digests[v.name][i] == digests[base][i] else "differ"
                same = "cut" if digests[v.name][i] == "cut" else same
            median = statistics.median(mine)
            lines.append(f"| {s.label} | {v.name} | {median:.1f} | {ratio} | {same} |")
    return "\n".join(lines)


def pooled_report(
    variants: list[Variant], sets: list[TraceSet], times: dict[str, list[list[float]]]
) -> str:
    """
    Per set and version (a tree and its settings), its processes pooled: the table, or "".

    Each round's time of a version is the mean of its processes'; the ratio is the median of
    the rounds' ratios to the first variant's version, with its quartiles. Empty where no
    version has more than one process.
    """
    versions: dict[tuple[Path, tuple[tuple[str, str], ...]], list[str]] = {}
    for v in variants:
        versions.setdefault((v.tree, tuple(sorted(v.env.items()))), []).append(v.name)
    if all(len(names) == 1 for names in versions.values()):
        return ""
    groups = list(versions.values())
    lines = [
        "| set | version (processes) | us a trace (median) | / first (paired, quartiles) |",
        "|---|---|--:|---|",
    ]
    for i, s in enumerate(sets):
        pooled = [
            [statistics.fmean(times[n][r][i] for n in names) for r in range(len(times[names[0]]))]
            for names in groups
        ]
        for names, mine in zip(groups, pooled, strict=True):
            ratio = ""
            if names is not groups[0]:
                paired = sorted(b / a for a, b in zip(pooled[0], mine, strict=True))
                q1, q3 = paired[len(paired) // 4], paired[(3 * len(paired)) // 4]
                ratio = f"{statistics.median(paired):.3f} ({q1:.3f}-{q3:.3f})"
            label = " + ".join(names)
            lines.append(f"| {s.label} | {label} | {statistics.median(mine):.1f} | {ratio} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--variant", action="append", default=[], help="NAME=TREE[:KEY=VALUE,...]")
    p.add_argument("--set", action="append", default=[], help="EXTRACT:SET:INPUT or sim:...")
    p.add_argument("--rounds", type=int, default=100, help="rounds of turns (default 100)")
    p.add_argument("--passes", type=int, default=3, help="passes a round, the fastest kept")
    p.add_argument(
        "--evict-mb", type=int, default=0, help="MB of other memory read before each pass"
    )
    p.add_argument(
        "--evict-pages",
        action="store_true",
        help="read one value of each 4 KB page of that memory (on 4 KB pages), in a random order",
    )
    p.add_argument("--sets-dir", type=Path, default=SETS, help="where the peer sets are")
    p.add_argument("--worker", help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.worker is not None:
        worker(json.loads(a.worker), a.passes, a.evict_mb, a.evict_pages)
        return 0
    if len(a.variant) < 2:
        p.error("give at least two --variant")
    if a.rounds < 1 or a.passes < 1 or a.evict_mb < 0:
        p.error("--rounds and --passes must be at least 1, --evict-mb at least 0")
    variants = [parse_variant(v) for v in a.variant]
    if len({v.name for v in variants}) < len(variants):
        p.error("every --variant needs a name of its own")
    with tempfile.TemporaryDirectory(prefix="ab-turns-") as scratch:
        sets = [parse_set(s, Path(scratch), a.sets_dir) for s in a.set or ["sim:15:25:20"]]
        load = os.getloadavg()[0]
        began = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
        times, digests = run_turns(variants, sets, a.rounds, a.passes, a.evict_mb, a.evict_pages)
    how = " (a value a page, in a random order)" if a.evict_pages else ""
    evicted = f", {a.evict_mb} MB read{how} before each" if a.evict_mb else ""
    print(
        f"{began}, {a.rounds} rounds of {a.passes} passes{evicted}, load average {load:.2f} at the "
        f"start and {os.getloadavg()[0]:.2f} at the end; CPU us a trace, match + GeoJSON\n"
    )
    print(report(variants, sets, times, digests))
    pooled = pooled_report(variants, sets, times)
    if pooled:
        print("\nEach version's processes pooled (the start order cancels where they flank):\n")
        print(pooled)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
