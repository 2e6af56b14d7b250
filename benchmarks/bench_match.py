"""Matching benchmark: points/s, peak memory and accuracy, and how cost grows.

    .venv/bin/python benchmarks/bench_match.py [--extract PATH ...] [--traces 20] [--repeats 3]
        [--skip-grid] [--grid-size 230]

1. For each extract (default: the embedded network and every extract in ../shared/data/osm/):
   simulated traces at 1 s / 5 m, 5 s / 8 m and 30 s / 20 m (2 % outliers of 40 m), one
   process, network loaded and compiled kernels warm, matching only (candidates + routing +
   Viterbi + result); points/s is the median of repeats. Accuracy beside it (route mismatch,
   fixes on the right edge, matched-length error against the truth).
2. City scale: a generated grid city (--grid-size^2 junctions 100 m apart, two-way streets,
   every fifth street one-way, avenues at 50 km/h) written as an OSM XML file and loaded
   through the normal path: load time, compiled size on disk, RSS, and the same table.
3. One 20,000-point trace (a 5.5-hour shift at 1 Hz) on the grid city: time and peak memory
   of matching its first 2,500 / 5,000 / 10,000 / 20,000 points (linear time, bounded memory).
"""

from __future__ import annotations

import argparse
import datetime
import logging
import os
import resource
import shutil
import sys
import time
import tracemalloc
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import mapmatch  # noqa: E402
import roadnets  # noqa: E402
from mapmatch.evaluation.benchmark import bench_network, markdown_table  # noqa: E402
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trip  # noqa: E402

SHARED = ROOT.parent / "shared" / "data" / "osm"
SETS = [(1.0, 5.0), (5.0, 8.0), (30.0, 20.0)]


def grid_city(path: Path, size: int) -> Path:
    """Write a grid city of size x size junctions as OSM XML (once)."""
    if path.exists():
        return path
    lon0, lat0 = 10.0, 50.0
    dlat = 100.0 / 111_132.0
    dlon = 100.0 / (111_320.0 * 0.6427876)  # cos(50 deg)
    lines = ['<?xml version="1.0" encoding="UTF-8"?>', '<osm version="0.6">']
    for i in range(size):
        for j in range(size):
            lines.append(
                f'<node id="{i * size + j + 1}" lat="{lat0 + i * dlat:.7f}" '
                f'lon="{lon0 + j * dlon:.7f}"/>'
            )
    way = 1
    for row in range(size):
        for vertical in (False, True):
            refs = [(j * size + row + 1) if vertical else (row * size + j + 1) for j in range(size)]
            tags = {"highway": "residential", "maxspeed": "30"}
            if row % 10 == 0:
                tags = {"highway": "secondary", "maxspeed": "50"}
            elif row % 5 == 0:
                tags["oneway"] = "yes" if row % 10 == 5 else "-1"
            nds = "".join(f'<nd ref="{r}"/>' for r in refs)
            tag_xml = "".join(f'<tag k="{k}" v="{v}"/>' for k, v in tags.items())
            lines.append(f'<way id="{way}">{nds}{tag_xml}</way>')
            way += 1
    lines.append("</osm>")
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


def rss_mb() -> float:
    """Current resident set size of this process, MB."""
    with open("/proc/self/statm", encoding="ascii") as handle:
        pages = int(handle.read().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def long_trace(net: roadnets.RoadNetwork) -> None:
    cfg = SimulationConfig(
        interval_s=1.0,
        noise_m=5.0,
        outlier_rate=0.02,
        route_length_m=200_000.0,
        route="random_walk",
        stop_probability=0.05,
    )
    trip = simulate_trip(net, cfg, seed=1, trace_id="shift")
    full = trip.trace
    print(f"\nOne long trace: {len(full):,} points, {trip.length_m / 1000:.1f} km\n")
    print("| points | seconds | points/s | ms per 1,000 points | peak MB (tracemalloc) |")
    print("|---:|---:|---:|---:|---:|")
    mapmatch.match(full.slice(0, 500), net)
    for n in (2_500, 5_000, 10_000, 20_000):
        part = full.slice(0, min(n, len(full)))
        started = time.perf_counter()
        mapmatch.match(part, net)
        seconds = time.perf_counter() - started
        tracemalloc.start()
        mapmatch.match(part, net)
        peak = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.stop()
        print(
            f"| {len(part):,} | {seconds:.2f} | {len(part) / seconds:,.0f} "
            f"| {1000 * seconds / len(part) * 1000:.1f} | {peak:.0f} |",
            flush=True,
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--extract", action="append", type=Path, default=None)
    parser.add_argument("--traces", type=int, default=20)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--skip-grid", action="store_true")
    parser.add_argument("--grid-only", action="store_true", help="only the city-scale part")
    parser.add_argument("--grid-size", type=int, default=230)
    args = parser.parse_args()
    logging.getLogger("mapmatch").setLevel(logging.ERROR)  # verdicts are not this table's topic
    extracts = args.extract or [roadnets.default_network_path(), *sorted(SHARED.glob("*.osm*"))]
    print(
        f"{datetime.date.today()}, {os.cpu_count()} cores; median of {args.repeats} repeats, "
        f"{args.traces} traces per set, 2 % outliers of 40 m\n"
    )
    if not args.grid_only:
        rows = []
        for path in extracts:
            net = roadnets.load(path)
            rows += bench_network(net, SETS, traces=args.traces, repeats=args.repeats)
        print(markdown_table(rows), flush=True)
    if args.skip_grid:
        return
    bench_dir = ROOT / ".bench"
    bench_dir.mkdir(exist_ok=True)
    source = grid_city(bench_dir / f"grid_city_{args.grid_size}.osm", args.grid_size)
    cache = bench_dir / "grid-cache"
    shutil.rmtree(cache, ignore_errors=True)  # the first load below must compile and write
    before = rss_mb()
    started = time.perf_counter()
    net = roadnets.load(source, cache_dir=cache, use_cache=False)
    net.rtree  # noqa: B018
    cold = time.perf_counter() - started
    started = time.perf_counter()
    net = roadnets.load(source, cache_dir=cache)
    net.rtree  # noqa: B018
    first = time.perf_counter() - started
    started = time.perf_counter()
    net = roadnets.load(source, cache_dir=cache)
    net.rtree  # noqa: B018
    cached = time.perf_counter() - started
    size = sum(f.stat().st_size for f in cache.rglob("*") if f.is_file()) / 2**20
    peak_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    info = net.info()
    print(
        f"\nGrid city: {info.nodes:,} nodes, {info.edges:,} directed edges, "
        f"{info.road_km:,.0f} km of road; OSM XML {source.stat().st_size / 2**20:.0f} MB; "
        f"compile {cold:.1f} s, compile + write cache {first:.1f} s, cached load {cached:.2f} s; "
        f"cache on disk {size:.0f} MB; RSS {rss_mb():.0f} MB (+{rss_mb() - before:.0f} MB for "
        f"the networks); peak RSS {peak_rss:.0f} MB; "
        "no precomputed path table (bounded Dijkstra per trace)\n"
    )
    print(markdown_table(bench_network(net, SETS, traces=args.traces, repeats=args.repeats)))
    long_trace(net)


if __name__ == "__main__":
    main()
