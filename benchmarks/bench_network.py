"""Road-network benchmark: cold and cached load, peak memory, candidate-query throughput.

    .venv/bin/python benchmarks/bench_network.py [--extract PATH ...] [--repeats 3]

For each extract (default: the embedded network and every extract in ../shared/data/osm/),
in a fresh process each: cold load (parse + compile + write the cache into an empty cache
folder, and bulk-load the R-tree), cached load (memory-mapped arrays + R-tree; median of
repeats) and their ratio, the process's peak RSS growth during the cold load, the cache size,
and the candidate query: 100,000 random points in the network's bounding box, every directed
edge within 50 m, one vectorised call (median of repeats).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data" / "osm"

_CHILD = r"""
import json, resource, statistics, sys, tempfile, time
from pathlib import Path
import numpy as np
import roadnets

path, repeats = Path(sys.argv[1]), int(sys.argv[2])
with tempfile.TemporaryDirectory() as cache:
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    started = time.perf_counter()
    cold = roadnets.load(path, cache_dir=cache)
    cold.rtree
    cold_s = time.perf_counter() - started
    peak_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss0
    cached = []
    for _ in range(repeats):
        started = time.perf_counter()
        net = roadnets.load(path, cache_dir=cache)
        net.rtree
        cached.append(time.perf_counter() - started)
    assert net.from_cache
    a = net.arrays
    rng = np.random.default_rng(0)
    x = rng.uniform(a.geom_x.min(), a.geom_x.max(), 100_000)
    y = rng.uniform(a.geom_y.min(), a.geom_y.max(), 100_000)
    net.nearby_edges(x[:1000], y[:1000], 50.0)
    query = []
    for _ in range(repeats):
        started = time.perf_counter()
        hits = net.nearby_edges(x, y, 50.0)
        query.append(time.perf_counter() - started)
    size = sum(f.stat().st_size for f in Path(cache).rglob("*") if f.is_file())
info = net.info()
print(json.dumps({
    "network": info.network_id, "nodes": info.nodes, "edges": info.edges,
    "road_km": round(info.road_km, 1), "cold_s": cold_s,
    "cached_s": statistics.median(cached), "peak_mb": peak_kb / 1024,
    "cache_mb": size / 2**20, "query_pts_s": 100_000 / statistics.median(query),
    "hits_per_pt": len(hits) / 100_000,
}))
"""


def bench(path: Path, repeats: int) -> dict[str, float]:
    """Measure one extract in a fresh Python process."""
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, str(path), str(repeats)],
        check=True,
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    result: dict[str, float] = json.loads(out.stdout.strip().splitlines()[-1])
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--extract", action="append", type=Path, default=None)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    sys.path.insert(0, str(ROOT))
    import roadnets

    extracts = args.extract or [roadnets.default_network_path(), *sorted(SHARED.glob("*.osm*"))]
    print(f"{datetime.date.today()}, {os.cpu_count()} cores, median of {args.repeats}\n")
    print(
        "| network | nodes | directed edges | road km | cold load s | cached load s | cold/cached "
        "| cold load peak RSS MB | cache MB | query points/s (50 m) | edges/point |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for path in extracts:
        r = bench(path, args.repeats)
        print(
            f"| {r['network']} | {r['nodes']:,} | {r['edges']:,} | {r['road_km']:,} "
            f"| {r['cold_s']:.3f} | {r['cached_s']:.4f} | {r['cold_s'] / r['cached_s']:.0f}x "
            f"| {r['peak_mb']:.0f} | {r['cache_mb']:.1f} | {r['query_pts_s']:,.0f} "
            f"| {r['hits_per_pt']:.1f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
