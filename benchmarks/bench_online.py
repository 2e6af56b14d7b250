"""Live matching benchmark (issue 17): per-fix latency at fleet load, accuracy against the lag.

    .venv/bin/python benchmarks/bench_online.py [--vehicles 1000] [--ticks 180]
        [--extract PATH] [--accuracy-extract PATH ...] [--accuracy-trips 12]
        [--lags 5,10,20,30,60,120,none] [--skip-load] [--skip-accuracy] [--json PATH]

1. Load: ``--vehicles`` simulated vehicles at 1 Hz in one process, one
   :class:`mapmatch.OnlineMatcher` each (default lag), for ``--ticks`` seconds of trip time:
   every tick each vehicle pushes its next fix (realistic noise: correlated errors, outliers,
   urban canyons, junction stops, outages; every column), in a shuffled order. Each push is
   timed on the wall clock and on the thread's CPU clock (the machine may be shared: the CPU
   clock does not count the time other processes hold the core). A vehicle whose trip ends
   closes it and starts the next. Reported: per-fix latency p50 / p99 / p99.9 / max, fixes per
   second of one core, and the share of one core 1,000 vehicles at 1 Hz take; memory per
   vehicle from ``tracemalloc`` (a second run of 100 vehicles) and from the matchers' own
   accounting (``OnlineMatcher.nbytes``).
2. Accuracy against the lag: ``--accuracy-trips`` realistic 1 s trips on each accuracy extract
   (default: the embedded Monaco and the Melbourne suburb of tests/data), matched offline
   (:func:`mapmatch.match`) and live at each lag; route mismatch against the truth (online and
   offline), the final length against the offline length, how long fixes take to settle, and
   the share that settles before the trip closes.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import random
import sys
import time
import tracemalloc
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import mapmatch  # noqa: E402
import roadnets  # noqa: E402
from mapmatch.evaluation.scoring import score_geojson  # noqa: E402
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trips  # noqa: E402
from mapmatch.online import OnlineMatcher  # noqa: E402

MELBOURNE = ROOT / "tests" / "data" / "melbourne-suburb_au.osm.pbf"


def fixes_of(trace: mapmatch.Trace) -> list[dict[str, float]]:
    """A trace's rows as the fixes a vehicle sends (unknown values left out)."""
    columns = {
        "heading": trace.heading_deg,
        "speed": trace.speed_mps,
        "accuracy": trace.accuracy_m,
        "odometer": trace.odometer_m,
    }
    out = []
    for i in range(len(trace.lon)):
        fix = {
            "time": float(trace.time_s[i]),
            "lat": float(trace.lat[i]),
            "lon": float(trace.lon[i]),
        }
        for name, values in columns.items():
            if values is not None and np.isfinite(values[i]):
                fix[name] = float(values[i])
        out.append(fix)
    return out


class Vehicle:
    """One simulated vehicle: a trip's fixes pushed one per tick, a new trip when it ends."""

    def __init__(self, net: roadnets.RoadNetwork, trips: list[list[dict[str, float]]], seed: int):
        self.net, self.trips = net, trips
        self.rng = random.Random(seed)
        self.trip = self.rng.randrange(len(trips))
        self.at = self.rng.randrange(len(trips[self.trip]) // 2)  # somewhere in its first half
        self.shift = 0.0
        self.live = OnlineMatcher(net, trip_id=f"v{seed}")
        self.closed = 0

    def fix(self) -> dict[str, float]:
        fixes = self.trips[self.trip]
        if self.at >= len(fixes):  # the trip ended: close it, start the next one
            self.live.close()
            self.closed += 1
            last = fixes[-1]["time"] + self.shift
            self.trip = self.rng.randrange(len(self.trips))
            self.at = 0
            fixes = self.trips[self.trip]
            self.shift = last + 60.0 - fixes[0]["time"]
            self.live = OnlineMatcher(self.net, trip_id=f"{self.live.trip_id}+")
        fix = dict(fixes[self.at])
        fix["time"] += self.shift
        self.at += 1
        return fix


def percentiles(values: list[float]) -> dict[str, float]:
    a = np.asarray(values) * 1e3
    return {
        "p50_ms": float(np.percentile(a, 50)),
        "p99_ms": float(np.percentile(a, 99)),
        "p99.9_ms": float(np.percentile(a, 99.9)),
        "max_ms": float(a.max()),
        "mean_ms": float(a.mean()),
    }


def run_load(
    net: roadnets.RoadNetwork, trips: list[list[dict[str, float]]], vehicles: int, ticks: int
) -> dict[str, Any]:
    """Every vehicle pushes one fix per tick; each push timed (wall and thread CPU)."""
    warm = OnlineMatcher(net)
    for fix in trips[0][:400]:
        warm.push(fix)
    warm.position()
    warm.close()
    fleet = [Vehicle(net, trips, seed) for seed in range(vehicles)]
    for v in fleet:  # a few fixes in, so that the first tick is no trip start for everyone
        for _ in range(5):
            v.live.push(v.fix())
    wall: list[float] = []
    cpu: list[float] = []
    order = list(range(vehicles))
    shuffle = random.Random(0)
    started_cpu = time.thread_time()
    started = time.perf_counter()
    for _ in range(ticks):
        shuffle.shuffle(order)
        for i in order:
            v = fleet[i]
            fix = v.fix()
            t0, c0 = time.perf_counter(), time.thread_time()
            v.live.push(fix)
            cpu.append(time.thread_time() - c0)
            wall.append(time.perf_counter() - t0)
    elapsed = time.perf_counter() - started
    elapsed_cpu = time.thread_time() - started_cpu
    pushes = len(wall)
    push_cpu = float(sum(cpu))
    return {
        "vehicles": vehicles,
        "ticks": ticks,
        "pushes": pushes,
        "trips_closed": sum(v.closed for v in fleet),
        "wall": percentiles(wall),
        "cpu": percentiles(cpu),
        "fixes_per_s_one_core": pushes / push_cpu,
        "core_share_at_1hz": push_cpu / ticks * (1000 / vehicles),
        "loop_s": elapsed,
        "loop_cpu_s": elapsed_cpu,
        "nbytes_per_vehicle": float(np.mean([v.live.nbytes for v in fleet])),
        "tail_fixes_mean": float(np.mean([v.live.tail_fixes for v in fleet])),
    }


def run_memory(
    net: roadnets.RoadNetwork, trips: list[list[dict[str, float]]], vehicles: int, ticks: int
) -> dict[str, float]:
    """Python-level memory a vehicle's matcher holds after ``ticks`` fixes (tracemalloc)."""
    tracemalloc.start()
    before = tracemalloc.take_snapshot()
    fleet = [Vehicle(net, trips, 10_000 + seed) for seed in range(vehicles)]
    for _ in range(ticks):
        for v in fleet:
            v.live.push(v.fix())
    after = tracemalloc.take_snapshot()
    tracemalloc.stop()
    grown = sum(s.size_diff for s in after.compare_to(before, "filename"))
    settled = float(np.mean([v.live.settled_fixes for v in fleet]))
    return {
        "vehicles": vehicles,
        "ticks": ticks,
        "bytes_per_vehicle": grown / vehicles,
        "settled_fixes_per_vehicle": settled,
        "tail_fixes_per_vehicle": float(np.mean([v.live.tail_fixes for v in fleet])),
    }


def run_accuracy(
    net: roadnets.RoadNetwork, trips: list[Any], lags: list[float | None]
) -> list[dict[str, Any]]:
    """Online against offline at each lag, on the same trips."""
    offline = []
    for trip in trips:
        result = mapmatch.match(trip.trace, net)
        offline.append((result, score_geojson(result.to_geojson(), trip.truth_record())))
    rows = []
    for lag in lags:
        mismatch, length, settle, early = [], [], [], []
        for trip, (off, off_score) in zip(trips, offline, strict=True):
            fixes = fixes_of(trip.trace)
            live = OnlineMatcher(net, lag=lag)
            times = np.array([f["time"] for f in fixes])
            settled_at = np.full(len(fixes), np.nan)
            for fix in fixes:
                update = live.push(fix)
                if update.settled_fixes:
                    lo = update.first_fix
                    settled_at[lo : lo + update.settled_fixes] = fix["time"]
            early.append(float(np.isfinite(settled_at).mean()))
            settle.extend((settled_at - times)[np.isfinite(settled_at)].tolist())
            on = live.close()
            score = score_geojson(on.to_geojson(), trip.truth_record())
            mismatch.append((score.mismatch, off_score.mismatch))
            length.append((on.matched_length_m - off.matched_length_m) / off.matched_length_m)
        m = np.array(mismatch)
        rel = np.array(length)
        rows.append(
            {
                "lag_s": lag,
                "mismatch_online": float(m[:, 0].mean()),
                "mismatch_offline": float(m[:, 1].mean()),
                "mismatch_delta_pp": float(100 * (m[:, 0].mean() - m[:, 1].mean())),
                "length_delta_mean_pct": float(100 * rel.mean()),
                "length_delta_abs_max_pct": float(100 * np.abs(rel).max()),
                "trips_equal_length": int(np.count_nonzero(np.abs(rel) < 1e-9)),
                "trips": len(trips),
                "settle_p50_s": float(np.median(settle)) if settle else math.nan,
                "settle_p95_s": float(np.percentile(settle, 95)) if settle else math.nan,
                "settled_live_share": float(np.mean(early)),
            }
        )
    return rows


def _ms(d: dict[str, float]) -> str:
    return (
        f"{d['p50_ms']:.3f} | {d['p99_ms']:.3f} | {d['p99.9_ms']:.2f} | {d['max_ms']:.1f} | "
        f"{d['mean_ms']:.3f}"
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--vehicles", type=int, default=1000)
    parser.add_argument("--ticks", type=int, default=180, help="seconds of trip time (default 180)")
    parser.add_argument("--extract", type=Path, help="network of the load run (default: Monaco)")
    parser.add_argument("--accuracy-extract", type=Path, action="append")
    parser.add_argument("--accuracy-trips", type=int, default=12)
    parser.add_argument("--lags", default="5,10,20,30,60,120,none")
    parser.add_argument("--skip-load", action="store_true")
    parser.add_argument("--skip-accuracy", action="store_true")
    parser.add_argument("--json", type=Path, help="also write the figures to this file")
    args = parser.parse_args()
    logging.disable(logging.WARNING)  # verdicts other than pass are logged per trip
    out: dict[str, Any] = {}
    realistic = SimulationConfig.realistic(interval_s=1.0, route_length_m=4000.0)

    if not args.skip_load:
        net = roadnets.load(args.extract) if args.extract else roadnets.load()
        trips = [fixes_of(t.trace) for t in simulate_trips(net, realistic, count=60, seed=100)]
        load = run_load(net, trips, args.vehicles, args.ticks)
        memory = run_memory(net, trips, 100, 120)
        out["load"], out["memory"] = load, memory
        print(f"## Load: {load['vehicles']} vehicles x 1 Hz for {load['ticks']} s, one process\n")
        print("| clock | p50 ms | p99 ms | p99.9 ms | max ms | mean ms |")
        print("|---|---|---|---|---|---|")
        print(f"| per-fix wall | {_ms(load['wall'])} |")
        print(f"| per-fix CPU | {_ms(load['cpu'])} |")
        print(
            f"\n{load['pushes']:,} pushes ({load['trips_closed']} trips closed on the way): "
            f"{load['fixes_per_s_one_core']:,.0f} fixes/s on one core; 1,000 vehicles at 1 Hz "
            f"take {100 * load['core_share_at_1hz']:.0f} % of one core. Memory per vehicle: "
            f"{memory['bytes_per_vehicle'] / 1024:.0f} KiB after {memory['ticks']} fixes "
            f"(tracemalloc, {memory['tail_fixes_per_vehicle']:.0f} fixes in the tail, "
            f"{memory['settled_fixes_per_vehicle']:.0f} settled); the matchers count "
            f"{load['nbytes_per_vehicle'] / 1024:.0f} KiB each after {load['ticks'] + 5} s."
        )

    if not args.skip_accuracy:
        lags = [None if x.strip() == "none" else float(x) for x in args.lags.split(",")]
        extracts = args.accuracy_extract or [None, MELBOURNE]
        out["accuracy"] = {}
        for path in extracts:
            net = roadnets.load(path) if path else roadnets.load()
            name = Path(path).name if path else "monaco (embedded)"
            trips = simulate_trips(
                net, SimulationConfig.realistic(interval_s=1.0), count=args.accuracy_trips, seed=11
            )
            rows = run_accuracy(net, trips, lags)
            out["accuracy"][name] = rows
            print(f"\n## Accuracy against the lag: {name}, {len(trips)} realistic 1 s trips\n")
            print(
                "| lag s | mismatch online | offline | delta pp | length vs offline mean | "
                "max abs | trips equal | settled p50 / p95 s | settled live |"
            )
            print("|---|---|---|---|---|---|---|---|---|")
            for r in rows:
                lag = "none" if r["lag_s"] is None else f"{r['lag_s']:g}"
                print(
                    f"| {lag} | {100 * r['mismatch_online']:.2f} % | "
                    f"{100 * r['mismatch_offline']:.2f} % | {r['mismatch_delta_pp']:+.2f} | "
                    f"{r['length_delta_mean_pct']:+.3f} % | {r['length_delta_abs_max_pct']:.3f} % "
                    f"| {r['trips_equal_length']}/{r['trips']} | {r['settle_p50_s']:.0f} / "
                    f"{r['settle_p95_s']:.0f} | {100 * r['settled_live_share']:.0f} % |"
                )
    if args.json:
        args.json.write_text(json.dumps(out, indent=2, default=str), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
