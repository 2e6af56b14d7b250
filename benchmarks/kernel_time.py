"""Where a trace's time goes: each compiled kernel in the flow of matches, against warm.

    .venv/bin/python benchmarks/kernel_time.py [--extract PATH] [--interval 15]
        [--fixes 25] [--traces 20] [--csv TRACES.csv --sigma 10] [--passes 15] [--warm 5]

The traces are matched one after the other (match + GeoJSON text, as a user of the library
gets them), ``--passes`` times; every kernel the Python code calls is timed where it is
called, and the rest of the pass is the Python between them. The pass with the least time
counts. Each call of that pass is then made twice more on its own: right after the same
kernel ran on another trace's arguments (its code warm, this trace's data not), and again
with the same arguments, the fastest of ``--warm`` calls in a row (code, data and the branch
history all warm: a floor no real trace sees). In the flow a kernel starts cold (the match's
other kernels, the interpreter and the trace's data have run since its last call); the
columns say by how much, and whether its code or what it reads is the cost. Last, the whole
pass's calls are made again in their order, one right after another with no Python between
them (the fastest of ``--passes`` replays; the crossings into the kernels included, the
Python that built their arguments not): what the matches would take if the Python between
the kernels cost nothing. The final table splits that Python by the two calls it runs between
(the start of a match and the end of its document count as calls): which stretch of it costs
most. Times are wall-clock microseconds a trace on one thread (the machine may be shared: run
it twice).

The traces: ``--traces`` simulated trips on the extract, ``--fixes`` fixes each at
``--interval`` (heading and speed given, 2 % outliers of 40 m), or every trace of ``--csv``
matched with ``--sigma`` (the peer sets: ``.bench/peers/sets/krems_at_2013/15s_10m/
positions.csv --sigma 10``).
"""

from __future__ import annotations

import argparse
import collections
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data" / "osm"


def add_trace_arguments(parser: argparse.ArgumentParser) -> None:
    """The options that choose the network and the traces (see :func:`network_and_traces`)."""
    parser.add_argument("--extract", default=str(SHARED / "krems_at_2013.osm.gz"))
    parser.add_argument("--interval", type=float, default=15.0, help="seconds between fixes")
    parser.add_argument("--fixes", type=int, default=25, help="fixes a simulated trace")
    parser.add_argument("--traces", type=int, default=20, help="simulated traces")
    parser.add_argument("--csv", help="a trace file to match instead of simulated traces")
    parser.add_argument("--sigma", type=float, default=10.0, help="sigma_m with --csv")


def network_and_traces(args: argparse.Namespace) -> tuple[Any, list[Any], Any]:
    """The network (its route table read), the traces and the configuration to match them with."""
    sys.path[:0] = [str(ROOT), str(ROOT / "benchmarks")]
    from bench_fixed_cost import traces_of

    import mapmatch
    import roadnets

    net = roadnets.load(args.extract)
    net.sparse_route_table()
    if args.csv:
        return net, list(mapmatch.read_traces(args.csv)), mapmatch.MatchConfig(sigma_m=args.sigma)
    return net, traces_of(net, args.interval, args.fixes, args.traces), mapmatch.MatchConfig()


def our_kernels() -> Iterator[tuple[Any, str, Any]]:
    """``(module, name, dispatcher)`` of every numba kernel a loaded module of ours binds."""
    from numba.core.registry import CPUDispatcher

    ours = [m for name, m in list(sys.modules.items()) if name.startswith(("mapmatch", "roadnets"))]
    for module in ours:
        for name, value in list(vars(module).items()):
            if isinstance(value, CPUDispatcher):
                yield module, name, value


class _Timed:
    """A kernel's stand-in: adds each call's time, count and arguments to the pass's records."""

    def __init__(self, kernel: Any, label: str, records: _PassRecords) -> None:
        self.kernel, self.label, self.records = kernel, label, records

    def __call__(self, *args: Any) -> Any:
        records = self.records
        start = time.perf_counter()
        records.python_until(self.label, start)
        try:
            return self.kernel(*args)
        finally:
            end = time.perf_counter()
            records.spent[self.label] += end - start
            records.calls[self.label] += 1
            records.kept.append((self.label, args))
            records.last = (self.label, end)


#: Where a trace's Python starts and ends, in :attr:`_PassRecords.between`.
MATCH_CALLED, DOCUMENT_WRITTEN = "(match called)", "(document written)"


class _PassRecords:
    """
    What one pass's kernel calls took: seconds and calls by kernel, and each call's arguments.

    ``between`` holds the seconds of Python from the end of one kernel call (or the start of a
    trace's match, :data:`MATCH_CALLED`) to the start of the next (or the document's end,
    :data:`DOCUMENT_WRITTEN`), by that pair of labels: which stretch of Python costs most.
    """

    def __init__(self) -> None:
        self.spent: collections.defaultdict[str, float] = collections.defaultdict(float)
        self.calls: collections.Counter[str] = collections.Counter()
        self.kept: list[tuple[str, tuple[Any, ...]]] = []
        self.between: collections.defaultdict[tuple[str, str], float] = collections.defaultdict(
            float
        )
        self.last: tuple[str, float] = (MATCH_CALLED, 0.0)

    def python_until(self, label: str, now: float) -> None:
        """Add the Python since the last kernel call (or the trace's start) to ``between``."""
        previous, since = self.last
        self.between[previous, label] += now - since


def _again(kernel: Callable[..., Any], args: tuple[Any, ...], times: int) -> float:
    """The fastest of ``times`` calls in a row with the same arguments, seconds."""
    best = float("inf")
    for _ in range(times):
        start = time.perf_counter()
        kernel(*args)
        best = min(best, time.perf_counter() - start)
    return best


def _after_another(
    kernel: Callable[..., Any], args: tuple[Any, ...], other: tuple[Any, ...]
) -> float:
    """Seconds of one call right after the kernel ran on ``other`` (its code warm)."""
    kernel(*other)
    start = time.perf_counter()
    kernel(*args)
    return time.perf_counter() - start


def _replay(
    kernels: dict[str, Callable[..., Any]], kept: list[tuple[str, tuple[Any, ...]]]
) -> float:
    """Seconds to make a pass's kernel calls again in their order, one right after another."""
    calls = [(kernels[label], kernel_args) for label, kernel_args in kept]
    start = time.perf_counter()
    for kernel, kernel_args in calls:
        kernel(*kernel_args)
    return time.perf_counter() - start


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_trace_arguments(parser)
    parser.add_argument("--passes", type=int, default=15, help="passes over the traces")
    parser.add_argument("--warm", type=int, default=5, help="calls in a row for the warm time")
    args = parser.parse_args(argv)
    net, traces, config = network_and_traces(args)

    import mapmatch
    from mapmatch.export import geojson_bytes

    records = _PassRecords()

    def one_pass() -> float:
        start = time.perf_counter()
        for trace in traces:
            records.last = (MATCH_CALLED, time.perf_counter())
            geojson_bytes(mapmatch.match(trace, net, config))
            records.python_until(DOCUMENT_WRITTEN, time.perf_counter())
        return time.perf_counter() - start

    one_pass()  # compiles or loads every kernel the traces need
    stand_ins: dict[int, _Timed] = {}
    bound = list(our_kernels())
    for module, name, kernel in bound:
        label = f"{kernel.py_func.__module__}.{kernel.py_func.__name__}"
        stand_in = stand_ins.setdefault(id(kernel), _Timed(kernel, label, records))
        setattr(module, name, stand_in)
    best: tuple[float, _PassRecords] | None = None
    try:
        for _ in range(max(1, args.passes)):
            records = _PassRecords()  # one_pass reads the name when it runs: this pass's
            for stand_in in stand_ins.values():
                stand_in.records = records
            total = one_pass()
            if best is None or total < best[0]:
                best = (total, records)
    finally:  # the modules get their kernels back (a test's process matches on)
        for module, name, kernel in bound:
            setattr(module, name, kernel)
    assert best is not None
    total, fastest = best
    in_flow, calls, kept = fastest.spent, fastest.calls, fastest.kept
    kernels = {s.label: s.kernel for s in stand_ins.values()}
    by_kernel: dict[str, list[tuple[Any, ...]]] = collections.defaultdict(list)
    for label, kernel_args in kept:
        by_kernel[label].append(kernel_args)
    code_warm: collections.defaultdict[str, float] = collections.defaultdict(float)
    warm: collections.defaultdict[str, float] = collections.defaultdict(float)
    for label, calls_args in by_kernel.items():
        kernel = kernels[label]
        for i, kernel_args in enumerate(calls_args):
            other = calls_args[(i + len(calls_args) // 2) % len(calls_args)]
            code_warm[label] += _after_another(kernel, kernel_args, other)
            warm[label] += _again(kernel, kernel_args, max(1, args.warm))

    replayed = min(_replay(kernels, kept) for _ in range(max(1, args.passes)))

    n = len(traces)
    points = sum(len(t.lon) for t in traces)
    us = 1e6 / n
    in_kernels = sum(in_flow.values())
    print(
        f"{n} traces, {points / n:.1f} fixes a trace: {total * us:.0f} us a trace "
        f"(match + GeoJSON), {in_kernels * us:.0f} in kernels called from Python, "
        f"{(total - in_kernels) * us:.0f} in the Python between them; the kernels "
        f"{sum(code_warm.values()) * us:.0f} with their code warm, "
        f"{sum(warm.values()) * us:.0f} all warm, {replayed * us:.0f} replayed in the pass's "
        "order with no Python between them"
    )
    print()
    print("| kernel | calls a trace | in the flow us | code warm us | all warm us |")
    print("|---|--:|--:|--:|--:|")
    for label, seconds in sorted(in_flow.items(), key=lambda item: -item[1]):
        print(
            f"| {label} | {calls[label] / n:.1f} | {seconds * us:.1f} | "
            f"{code_warm[label] * us:.1f} | {warm[label] * us:.1f} |"
        )
    print()
    print("The Python between the kernels, by the calls it runs between, in the flow:")
    print()
    print("| after | before | us a trace |")
    print("|---|---|--:|")
    for (after, before), seconds in sorted(fastest.between.items(), key=lambda item: -item[1]):
        print(f"| {after} | {before} | {seconds * us:.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
