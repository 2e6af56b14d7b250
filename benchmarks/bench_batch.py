"""
Batch matching throughput: traces/s and points/s for 1 vs N local workers, and peak memory.

Simulates trips on a network (default: the embedded Monaco extract), writes them to one CSV,
then runs :func:`mapmatch.batch.run_batch` once per worker count, each in a fresh Python
process so that every run pays the same start-up (imports, network load from the cache,
compiled-code warm-up, pool start). "points/s (wall)" divides by the whole run; "matching
points/s per worker" by the seconds spent inside ``match()`` (each worker's warm-up match,
which loads the compiled kernels, reported apart). Peak memory is ``ru_maxrss`` of each
process that ran a task, as the tasks report it (with 1 worker that is the batch's own
process).

Usage::

    .venv/bin/python benchmarks/bench_batch.py                 # 200 traces, 1 vs 2 workers
    .venv/bin/python benchmarks/bench_batch.py --traces 500 --workers 1 2 4 --format csv
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from mapmatch.batch.outputs import FORMATS


def _child(args: argparse.Namespace) -> int:
    from mapmatch.batch import BatchOptions, run_batch

    options = BatchOptions(
        inputs=(args.input,),
        out_dir=Path(args.out),
        network=args.network,
        cache_dir=args.cache_dir,
        format=args.format,
        workers=args.child_workers,
        log_level=40,
    )
    report = run_batch(options)
    print(
        json.dumps(
            {
                "seconds": report.seconds,
                "ok": report.traces_ok,
                "failed": report.traces_failed,
                "points": report.points,
                "executor": report.executor,
                "match_s": report.match_s,
                "warmup_s": report.warmup_s,
                "rss_kib": report.worker_max_rss_kib,
                "busy_s": report.worker_busy_s,
                "cpu_s": report.worker_cpu_s,
            }
        )
    )
    return 0


def main() -> int:
    """Simulate, run each worker count in a child process, print a markdown table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument("--traces", type=int, default=200)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--network", default=None, help="OSM extract (default: embedded)")
    parser.add_argument("--format", default="geojson", choices=FORMATS)
    parser.add_argument("--interval-s", type=float, default=1.0)
    parser.add_argument("--route-length-m", type=float, default=2000.0)
    parser.add_argument("--seed", type=int, default=0)
    # internal: one measured run
    parser.add_argument("--child-workers", type=int, default=None, help=argparse.SUPPRESS)
    parser.add_argument("--input", help=argparse.SUPPRESS)
    parser.add_argument("--out", help=argparse.SUPPRESS)
    parser.add_argument("--cache-dir", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child_workers is not None:
        return _child(args)

    import roadnets
    from mapmatch.evaluation.simulate import SimulationConfig, simulate_trips, write_trips

    work = Path(tempfile.mkdtemp(prefix="bench-batch-"))
    cache_dir = work / "cache"
    net = roadnets.load(args.network, cache_dir=cache_dir)
    cfg = SimulationConfig(
        interval_s=args.interval_s, route_length_m=args.route_length_m, outlier_rate=0.01
    )
    trips = simulate_trips(net, cfg, count=args.traces, seed=args.seed)
    traces_csv, _ = write_trips(trips, work / "in")
    points = sum(len(t.trace) for t in trips)

    results = []
    for workers in args.workers:
        cmd = [sys.executable, __file__, "--child-workers", str(workers), "--input"]
        cmd += [str(traces_csv), "--out", str(work / f"out-{workers}"), "--format", args.format]
        cmd += ["--cache-dir", str(cache_dir)]
        if args.network:
            cmd += ["--network", args.network]
        done = subprocess.run(cmd, capture_output=True, text=True, check=True)
        results.append((workers, json.loads(done.stdout.strip().splitlines()[-1])))

    base = results[0][1]["seconds"]
    print(
        f"{args.traces} simulated traces, {points:,} points, {args.interval_s:g} s sampling, "
        f"network {net.network_id}, output {args.format}, machine "
        f"{__import__('os').cpu_count()} cores\n"
    )
    print(
        "| workers | executor | seconds | traces/s | points/s (wall) | matching points/s "
        "per worker | warm-up s | speed-up | failed | worker busy s (CPU s) "
        "| peak RSS per worker (MiB) |"
    )
    print("|---:|---|---:|---:|---:|---:|---:|---:|---:|---|---|")
    for workers, r in results:
        rss = ", ".join(f"{v / 1024:.0f}" for v in sorted(r["rss_kib"].values()))
        busy = ", ".join(f"{r['busy_s'][k]:.1f} ({r['cpu_s'][k]:.1f})" for k in sorted(r["busy_s"]))
        matching = r["points"] / r["match_s"] if r["match_s"] > 0 else float("nan")
        print(
            f"| {workers} | {r['executor']} | {r['seconds']:.2f} | {r['ok'] / r['seconds']:.1f} "
            f"| {r['points'] / r['seconds']:,.0f} | {matching:,.0f} | {r['warmup_s']:.2f} "
            f"| {base / r['seconds']:.2f} | {r['failed']} | {busy} | {rss} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
