"""Fixed cost of one match, cost per point, and garbage-collection pauses (issue 15).

    .venv/bin/python benchmarks/bench_fixed_cost.py [--extract PATH] [--repeats 7]
        [--sizes 2,30,300] [--intervals 1,15] [--traces 20] [--gc] [--gc-traces 10000]
        [--grid-size 230] [--no-freeze]

1. Per trace, network loaded and kernels warm, one thread: traces of 2, 30 and 300 fixes
   (slices of simulated trips at each sampling interval, heading and speed given, 2 %
   outliers of 40 m), matched one after the other; the median over ``--repeats`` passes of
   the mean time per trace, wall clock and process CPU time (the machine may be shared: the
   load average is printed), match only and match + GeoJSON text
   (``mapmatch.export.geojson_bytes``). The cost per point is the slope between the 30- and
   300-fix traces of each interval.
2. ``--gc``: a process that has loaded a grid city (``bench_match.grid_city``: 230 x 230
   junctions, about 200k directed edges) matches ``--gc-traces`` traces; every collection is
   timed through ``gc.callbacks``. Reported: collections per generation, the longest pause,
   and how many took over 10 ms. ``roadnets.freeze_after_load()`` is called after loading
   (``--no-freeze`` leaves it out, to compare).
"""

from __future__ import annotations

import argparse
import gc
import logging
import os
import statistics
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import mapmatch  # noqa: E402
import roadnets  # noqa: E402
from mapmatch.evaluation.simulate import (  # noqa: E402
    SimulationConfig,
    simulate_trips,
    strip_to_class,
)
from mapmatch.export import geojson_bytes  # noqa: E402

SHARED = ROOT.parent / "shared" / "data" / "osm"


def traces_of(
    net: roadnets.RoadNetwork, interval_s: float, size: int, count: int
) -> list[mapmatch.Trace]:
    """``count`` traces of ``size`` fixes at ``interval_s`` (slices of simulated trips)."""
    length = max(3000.0, 15.0 * interval_s * size)
    cfg = SimulationConfig(
        interval_s=interval_s,
        noise_m=5.0 if interval_s < 5 else 10.0,
        outlier_rate=0.02,
        route_length_m=length,
    )
    out = []
    for trip in simulate_trips(net, cfg, count=count, seed=300 + size):
        trace = strip_to_class(trip.trace, "heading_speed")
        out.append(trace.slice(0, min(size, len(trace))))
    return out


def time_traces(
    net: roadnets.RoadNetwork, traces: list[mapmatch.Trace], repeats: int, *, output: bool
) -> tuple[float, float]:
    """Median over repeats of the mean wall and CPU seconds per trace."""
    config = mapmatch.MatchConfig()

    def one(trace: mapmatch.Trace) -> None:
        result = mapmatch.match(trace, net, config)
        if output:
            geojson_bytes(result)

    for trace in traces:  # warm: kernels, caches
        one(trace)
    walls, cpus = [], []
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        for trace in traces:
            one(trace)
        walls.append((time.perf_counter() - wall) / len(traces))
        cpus.append((time.process_time() - cpu) / len(traces))
    return statistics.median(walls), statistics.median(cpus)


def fixed_cost(args: argparse.Namespace) -> None:
    path = args.extract or (SHARED / "andorra_2020.osm.pbf")
    if not Path(path).exists():
        path = roadnets.default_network_path()
    net = roadnets.load(path)
    roadnets.warm_kernels()
    # the sparse-trace route table, as `mapmatch network build` leaves it: else the first
    # sparse trace reads or builds it in a background thread, inside the timed passes
    net.sparse_route_table()
    sizes = [int(s) for s in args.sizes.split(",")]
    intervals = [float(s) for s in args.intervals.split(",")]
    load = os.getloadavg()
    print(
        f"{Path(path).name}: {net.arrays.n_edges:,} edges; {os.cpu_count()} cores, load average "
        f"{load[0]:.1f} / {load[1]:.1f}; median of {args.repeats} passes over {args.traces} "
        "traces, one thread\n"
    )
    print(
        "| interval | fixes | match ms (wall) | match ms (CPU) | + GeoJSON ms (wall) "
        "| + GeoJSON ms (CPU) | points/s match | points/s + GeoJSON |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    slopes: dict[float, dict[int, tuple[float, float, float]]] = {}
    for interval in intervals:
        for size in sizes:
            traces = traces_of(net, interval, size, args.traces)
            fixes = statistics.mean(len(t) for t in traces)
            wall, cpu = time_traces(net, traces, args.repeats, output=False)
            wall_out, cpu_out = time_traces(net, traces, args.repeats, output=True)
            slopes.setdefault(interval, {})[size] = (fixes, wall, wall_out)
            print(
                f"| {interval:g} s | {fixes:.0f} | {1e3 * wall:.3f} | {1e3 * cpu:.3f} "
                f"| {1e3 * wall_out:.3f} | {1e3 * cpu_out:.3f} | {fixes / wall:,.0f} "
                f"| {fixes / wall_out:,.0f} |",
                flush=True,
            )
    print()
    for interval, by_size in slopes.items():
        if 30 in by_size and 300 in by_size:
            n30, w30, o30 = by_size[30]
            n300, w300, o300 = by_size[300]
            per = (w300 - w30) / (n300 - n30)
            per_out = (o300 - o30) / (n300 - n30)
            print(
                f"{interval:g} s: {1e6 * per:.1f} us per point matching, {1e6 * per_out:.1f} us "
                "with the GeoJSON (slope between the 30- and 300-fix traces)"
            )


def gc_check(args: argparse.Namespace) -> None:
    from bench_match import grid_city  # benchmarks/ on the path

    bench = ROOT / ".bench"
    bench.mkdir(exist_ok=True)
    source = grid_city(bench / f"grid_city_{args.grid_size}.osm", args.grid_size)
    started = time.perf_counter()
    net = roadnets.load(source, cache_dir=bench / "grid-cache")
    roadnets.warm_kernels()
    cfg = SimulationConfig(interval_s=5.0, noise_m=8.0, outlier_rate=0.02, route_length_m=1500.0)
    pool = [t.trace for t in simulate_trips(net, cfg, count=200, seed=5)]
    for trace in pool[:20]:
        mapmatch.match(trace, net)  # kernels, the R-tree and the turn graph built
    frozen = roadnets.freeze_after_load() if args.freeze else 0
    print(
        f"\nGC check: grid city {net.arrays.n_edges:,} edges loaded and warm in "
        f"{time.perf_counter() - started:.1f} s; {len(gc.get_objects()):,} objects tracked, "
        f"{frozen:,} frozen; matching {args.gc_traces:,} traces of "
        f"{statistics.mean(len(t) for t in pool):.0f} fixes (5 s)"
    )
    pauses: list[tuple[int, float]] = []
    clock: dict[str, Any] = {}

    def callback(phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            clock["t"] = time.perf_counter()
        else:
            pauses.append((int(info["generation"]), time.perf_counter() - clock["t"]))

    gc.callbacks.append(callback)
    try:
        started = time.perf_counter()
        points = 0
        for i in range(args.gc_traces):
            trace = pool[i % len(pool)]
            mapmatch.match(trace, net)
            points += len(trace)
        seconds = time.perf_counter() - started
    finally:
        gc.callbacks.remove(callback)
    by_gen = {g: [p for gen, p in pauses if gen == g] for g in (0, 1, 2)}
    longest = max((p for _, p in pauses), default=0.0)
    over = sum(p > 0.010 for _, p in pauses)
    print(
        f"{args.gc_traces:,} traces, {points:,} points in {seconds:.1f} s "
        f"({points / seconds:,.0f} points/s); collections per generation: "
        + ", ".join(
            f"gen {g}: {len(v)} (longest {1e3 * max(v, default=0):.2f} ms)"
            for g, v in by_gen.items()
        )
        + f"; longest pause {1e3 * longest:.2f} ms; {over} over 10 ms"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--extract", type=Path, default=None)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--traces", type=int, default=20)
    parser.add_argument("--sizes", default="2,30,300")
    parser.add_argument("--intervals", default="1,15")
    parser.add_argument("--gc", action="store_true", help="also run the GC-pause check")
    parser.add_argument("--gc-only", action="store_true", help="only the GC-pause check")
    parser.add_argument("--gc-traces", type=int, default=10_000)
    parser.add_argument("--grid-size", type=int, default=230)
    parser.add_argument("--no-freeze", dest="freeze", action="store_false")
    args = parser.parse_args()
    logging.getLogger("mapmatch").setLevel(logging.ERROR)
    if not args.gc_only:
        fixed_cost(args)
    if args.gc or args.gc_only:
        gc_check(args)


if __name__ == "__main__":
    main()
