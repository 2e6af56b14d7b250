"""Road-network benchmark: loads, memory, queries, GC pauses, pickles, imports and kernels.

    .venv/bin/python benchmarks/bench_network.py [--extract PATH ...] [--grid 230]
                                                 [--repeats 5] [--cold-kernels]

Table 1, for each extract (default: the embedded network and every extract in
../shared/data/osm/; ``--grid N`` adds an N x N grid city, 230 gives 200,146 directed edges),
in a fresh process each (libraries imported and kernels warmed first, with
``roadnets.warm_kernels()``): cold load (parse + compile + write the cache into an empty cache
folder, and bulk-load the R-tree), cached load (memory-mapped arrays + R-tree; median of
repeats) and their ratio, the process's peak RSS growth during the cold load, the cache size,
and the candidate query: 100,000 random points in the network's bounding box, every directed
edge within 50 m, one vectorised call (median of repeats).

Table 2, same processes: what a long-running process pays for keeping the network. The
process imports mapmatch (as the service and the batch do), loads the network from the cache
and uses it (R-tree, routes, names); then: tracked objects the cached load added
(``len(gc.get_objects())`` growth), the pause of a full ``gc.collect()`` (median of repeats),
the same after ``roadnets.freeze_after_load()``, the pickle of the network (bytes) and the
time to unpickle it (re-opening its cache entry).

Then: ``python -X importtime -c "import roadnets"`` (cumulative microseconds of the
``roadnets`` line, median of repeats, fresh processes), ``import roadnets`` + cached load of
the default network in one fresh process, and ``roadnets.warm_kernels()`` in a fresh process
with numba's cache warm; with ``--cold-kernels`` also into an empty ``NUMBA_CACHE_DIR`` (a
fresh install: about 12 s on 2 cores).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data" / "osm"
sys.path.insert(0, str(ROOT))

_CHILD = r"""
import gc, json, pickle, resource, statistics, sys, tempfile, time
from pathlib import Path
import numpy as np
try:
    import mapmatch  # noqa: F401 - the imports a service or a batch worker holds
except Exception:  # a half-restructured mapmatch must not stop the network figures
    pass
import roadnets

path, repeats = Path(sys.argv[1]), int(sys.argv[2])


def full_gc_ms():
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        gc.collect()
        times.append(1000 * (time.perf_counter() - started))
    return statistics.median(times)


roadnets.warm_kernels()  # libosmium, pyproj, libspatialindex and the routers: loaded once
with tempfile.TemporaryDirectory() as cache:
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    started = time.perf_counter()
    cold = roadnets.load(path, cache_dir=cache)
    cold.rtree
    cold_s = time.perf_counter() - started
    peak_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss0
    del cold
    cached = []
    for _ in range(repeats):
        started = time.perf_counter()
        net = roadnets.load(path, cache_dir=cache)
        net.rtree
        cached.append(time.perf_counter() - started)
    del net
    gc.collect()
    objects0 = len(gc.get_objects())
    net = roadnets.load(path, cache_dir=cache)
    gc.collect()
    objects_added = len(gc.get_objects()) - objects0
    assert net.from_cache
    a = net.arrays
    rng = np.random.default_rng(0)
    x = rng.uniform(a.geom_x.min(), a.geom_x.max(), 100_000)
    y = rng.uniform(a.geom_y.min(), a.geom_y.max(), 100_000)
    net.nearby_edges(x[:1000], y[:1000], 50.0)
    n = min(a.n_edges, 500)
    net.edge_routes(np.arange(n), (np.arange(n) * 7) % a.n_edges, 1000.0)
    net.way_names.names_of(a.edge_way_id[:1000])
    query = []
    for _ in range(repeats):
        started = time.perf_counter()
        hits = net.nearby_edges(x, y, 50.0)
        query.append(time.perf_counter() - started)
    gc_ms = full_gc_ms()
    tracked = len(gc.get_objects())
    frozen = roadnets.freeze_after_load()
    gc_frozen_ms = full_gc_ms()
    gc.unfreeze()
    blob = pickle.dumps(net)
    started = time.perf_counter()
    again = pickle.loads(blob)
    unpickle_ms = 1000 * (time.perf_counter() - started)
    size = sum(f.stat().st_size for f in Path(cache).rglob("*") if f.is_file())
info = net.info()
print(json.dumps({
    "network": info.network_id, "nodes": info.nodes, "edges": info.edges,
    "road_km": round(info.road_km, 1), "cold_s": cold_s,
    "cached_s": statistics.median(cached), "peak_mb": peak_kb / 1024,
    "cache_mb": size / 2**20, "query_pts_s": 100_000 / statistics.median(query),
    "hits_per_pt": len(hits) / 100_000, "objects_added": objects_added,
    "tracked": tracked, "frozen": frozen, "gc_ms": gc_ms, "gc_frozen_ms": gc_frozen_ms,
    "pickle_bytes": len(blob), "unpickle_ms": unpickle_ms,
}))
"""


def _run(args: list[str], env: dict[str, str] | None = None) -> str:
    out = subprocess.run(
        [sys.executable, *args], check=True, capture_output=True, text=True, cwd=ROOT, env=env
    )
    return out.stdout + out.stderr


def bench(path: Path, repeats: int) -> dict[str, float]:
    """Measure one extract in a fresh Python process."""
    result: dict[str, float] = json.loads(
        _run(["-c", _CHILD, str(path), str(repeats)]).strip().splitlines()[-1]
    )
    return result


def import_figures(repeats: int) -> dict[str, float]:
    """Import time of roadnets, and import + cached load of the default network (fresh)."""
    cumulative = []
    for _ in range(repeats):
        text = _run(["-X", "importtime", "-c", "import roadnets"])
        line = next(row for row in text.splitlines() if row.rstrip().endswith("| roadnets"))
        cumulative.append(int(line.split("|")[1]))
    code = (
        "import time; t = time.perf_counter(); import roadnets; t1 = time.perf_counter(); "
        "net = roadnets.load(); t2 = time.perf_counter(); "
        "print(t1 - t, t2 - t1, net.from_cache)"
    )
    _run(["-c", code])  # fill the cache
    runs = [_run(["-c", code]).split() for _ in range(repeats)]
    return {
        "import_ms": statistics.median(cumulative) / 1000,
        "import_wall_ms": 1000 * statistics.median(float(r[0]) for r in runs),
        "load_ms": 1000 * statistics.median(float(r[1]) for r in runs),
    }


def kernel_figures(*, cold: bool) -> dict[str, object]:
    """``roadnets.warm_kernels()`` in fresh processes: numba's cache warm, and empty."""
    code = "import roadnets, json; w = roadnets.warm_kernels(); print(w.seconds, w.compiled)"
    out: dict[str, object] = {}
    warm = _run(["-c", code]).split()
    out["warm_s"], out["warm_compiled"] = float(warm[0]), int(warm[1])
    if cold:
        with tempfile.TemporaryDirectory() as empty:
            env = {**os.environ, "NUMBA_CACHE_DIR": empty}
            first = _run(["-c", code], env=env).split()
        out["cold_s"], out["cold_compiled"] = float(first[0]), int(first[1])
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--extract", action="append", type=Path, default=None)
    parser.add_argument("--grid", type=int, default=0, help="add a GRID x GRID grid city")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--cold-kernels", action="store_true", help="time a fresh compile too")
    args = parser.parse_args()
    import roadnets

    extracts = args.extract or [roadnets.default_network_path(), *sorted(SHARED.glob("*.osm*"))]
    workdir = Path(tempfile.mkdtemp(prefix="bench-network-"))
    if args.grid:
        from benchmarks.bench_match import grid_city

        extracts.append(grid_city(workdir / f"grid{args.grid}_city.osm", args.grid))
    print(f"{datetime.date.today()}, {os.cpu_count()} cores, median of {args.repeats}\n")
    print(
        "| network | nodes | directed edges | road km | cold load s | cached load s | cold/cached "
        "| cold load peak RSS MB | cache MB | query points/s (50 m) | edges/point |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    rows = []
    for path in extracts:
        r = bench(path, args.repeats)
        rows.append(r)
        print(
            f"| {r['network']} | {r['nodes']:,} | {r['edges']:,} | {r['road_km']:,} "
            f"| {r['cold_s']:.3f} | {r['cached_s']:.4f} | {r['cold_s'] / r['cached_s']:.0f}x "
            f"| {r['peak_mb']:.0f} | {r['cache_mb']:.1f} | {r['query_pts_s']:,.0f} "
            f"| {r['hits_per_pt']:.1f} |",
            flush=True,
        )
    print(
        "\n| network | tracked objects added by a cached load | tracked objects in the process "
        "| full gc ms | full gc ms after freeze_after_load | pickle bytes | unpickle ms |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(
            f"| {r['network']} | {r['objects_added']:,} | {r['tracked']:,} | {r['gc_ms']:.1f} "
            f"| {r['gc_frozen_ms']:.3f} | {r['pickle_bytes']:,} | {r['unpickle_ms']:.1f} |"
        )
    imports = import_figures(args.repeats)
    print(
        f"\nimport roadnets: {imports['import_ms']:.0f} ms (-X importtime, cumulative), "
        f"{imports['import_wall_ms']:.0f} ms wall; then a cached load of the default network "
        f"{imports['load_ms']:.1f} ms"
    )
    kernels = kernel_figures(cold=args.cold_kernels)
    line = (
        f"roadnets.warm_kernels(): {kernels['warm_s']:.2f} s with numba's cache warm "
        f"({kernels['warm_compiled']} compiled)"
    )
    if args.cold_kernels:
        line += (
            f", {kernels['cold_s']:.1f} s into an empty cache ({kernels['cold_compiled']} compiled)"
        )
    print(line)


if __name__ == "__main__":
    main()
