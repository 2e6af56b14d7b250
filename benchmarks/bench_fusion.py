"""
Fusion front-end benchmark on simulated raw logs (fixed seeds).

Prints position error (mean / 95th percentile, and at outage ends) with and without GNSS
outages and with and without map-aided feedback; fused-distance error against odometer-only
and GNSS-chord-only distances; odometer-scale estimates (EKF and RLS); filter speed with and
without numba. Then the same on real roads: random drives on the embedded Monaco network (and
on ``shared/data/osm/andorra_2020.osm.pbf`` when it exists), raw logs from
:func:`mapmatch.fusion.simulate_trip_raw_log`, fused and matched by
:func:`mapmatch.fusion.fuse_and_match` without and with map-aided feedback: position error,
fused / odometer / chord distance errors, matched-length error and distance-check verdicts.

    .venv/bin/python benchmarks/bench_fusion.py [--seeds 5] [--trips 10] [--skip-synthetic]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

import roadnets
from mapmatch.errors import NoCandidatesError
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trip
from mapmatch.fusion import (
    FusedTrack,
    FusionConfig,
    LocalTangentPlane,
    RawLog,
    RawLogSimConfig,
    RoadFeedback,
    TrueTrajectory,
    build_trajectory,
    fuse,
    fuse_and_match,
    simulate_raw_log,
    simulate_trip_raw_log,
    stop,
    straight,
    turn,
)

ORIGIN = (116.40, 39.90)


def city_loop() -> TrueTrajectory:
    legs = []
    for _ in range(3):
        for side in (400.0, 250.0, 400.0, 250.0):
            legs += [straight(side, 12.0), stop(20.0), turn(90.0, 12.0, 6.0)]
    return build_trajectory(legs, origin_lon=ORIGIN[0], origin_lat=ORIGIN[1])


def arcs() -> TrueTrajectory:
    legs = [
        straight(600.0, 15.0), turn(-120.0, 60.0, 10.0), straight(500.0, 14.0),
        turn(200.0, 40.0, 8.0), straight(700.0, 15.0), turn(-45.0, 100.0, 12.0),
        straight(400.0, 13.0), stop(30.0), straight(900.0, 14.0),
    ]  # fmt: skip
    return build_trajectory(legs, origin_lon=ORIGIN[0], origin_lat=ORIGIN[1], start_heading_deg=30)


def feedback_from_truth(tr: TrueTrajectory, seed: int) -> RoadFeedback:
    """Matched road positions at 1 Hz: centre line + along-road (8 m, correlated) and
    cross-road (1.5 m) errors, with the road heading."""
    rng = np.random.default_rng(seed)
    idx = np.arange(0, len(tr), 10)
    idx = idx[tr.speed_mps[idx] > 0.5]
    ltp = LocalTangentPlane(float(tr.lon[0]), float(tr.lat[0]))
    x, y = ltp.to_xy(tr.lon[idx], tr.lat[idx])
    yaw = np.radians(90.0 - tr.heading_deg[idx])
    phi = np.exp(-1.0 / 20.0)
    along = np.zeros(idx.size)
    along[0] = rng.normal(0.0, 8.0)
    for i in range(1, idx.size):
        along[i] = phi * along[i - 1] + rng.normal(0.0, 8.0 * np.sqrt(1 - phi * phi))
    cross = rng.normal(0.0, 1.5, idx.size)
    lon, lat = ltp.to_lonlat(
        x + along * np.cos(yaw) - cross * np.sin(yaw), y + along * np.sin(yaw) + cross * np.cos(yaw)
    )
    return RoadFeedback.from_arrays(tr.time_s[idx], lon, lat, tr.heading_deg[idx], 8.0, 1.5)


def errors(track: FusedTrack, tr: TrueTrajectory) -> np.ndarray:
    ltp = LocalTangentPlane(float(tr.lon[0]), float(tr.lat[0]))
    tx, ty = ltp.to_xy(tr.lon[track.first_row :], tr.lat[track.first_row :])
    fx, fy = ltp.to_xy(track.lon, track.lat)
    return np.hypot(fx - tx, fy - ty)


def chord_m(raw: RawLog) -> float:
    f = raw.has_fix
    ltp = LocalTangentPlane(float(raw.lon[f][0]), float(raw.lat[f][0]))
    x, y = ltp.to_xy(raw.lon[f], raw.lat[f])
    return float(np.hypot(np.diff(x), np.diff(y)).sum())


SCENARIOS = {
    # name: (sim config kwargs, fusion config kwargs, road feedback?)
    "no outage": ({}, {}, False),
    "2 x 30 s outages": ({"outages_s": ((100.0, 130.0), (250.0, 280.0))}, {}, False),
    "120 s outage, cheap gyro": (
        {"outages_s": ((150.0, 270.0),), "gyro_bias_walk_dps_per_sqrt_s": 0.02,
         "gyro_noise_dps": 0.1},
        {"gyro_bias_walk_dps_per_sqrt_s": 0.02}, False,
    ),
    "120 s outage, cheap gyro + road feedback": (
        {"outages_s": ((150.0, 270.0),), "gyro_bias_walk_dps_per_sqrt_s": 0.02,
         "gyro_noise_dps": 0.1},
        {"gyro_bias_walk_dps_per_sqrt_s": 0.02}, True,
    ),
}  # fmt: skip


ANDORRA = Path(__file__).resolve().parents[2] / "shared" / "data" / "osm" / "andorra_2020.osm.pbf"
CHEAP_GYRO = {"gyro_bias_walk_dps_per_sqrt_s": 0.02, "gyro_noise_dps": 0.1}
ROAD_SCENARIOS: dict[str, tuple[dict[str, Any], dict[str, Any]]] = {
    # name: (sim config kwargs, fusion config kwargs); each run without and with feedback
    "no outage": ({}, {}),
    "30 s outage": ({"outages_s": ((60.0, 90.0),)}, {}),
    "90 s outage, cheap gyro": (
        {"outages_s": ((60.0, 150.0),), **CHEAP_GYRO},
        {"gyro_bias_walk_dps_per_sqrt_s": 0.02},
    ),
}


def road_rows(net: roadnets.RoadNetwork, label: str, n_trips: int) -> None:
    """Fuse and match ``n_trips`` real-road drives per scenario; print one row per variant."""
    scales = (0.97, 1.03, 1.015, 0.985)
    lengths = (1200.0, 2000.0, 3000.0)
    trips = [
        simulate_trip(
            net, SimulationConfig(route_length_m=lengths[i % 3]), seed=i, trace_id=f"{label}-{i}"
        )
        for i in range(n_trips)
    ]
    km = sum(t.length_m for t in trips) / 1e3
    print(f"\n{label}: {n_trips} drives, {km:.1f} km, 1.2-3 km targets, odometer scales {scales}")
    hdr = (
        f"{'scenario':36s} {'fb':>3s} {'mean':>6s} {'p95':>6s} {'out-end':>8s} "
        f"{'|dist|%':>8s} {'max%':>6s} {'odo|%|':>7s} {'chord|%|':>9s} {'match|%|':>9s} "
        f"{'match max%':>10s}  verdicts"
    )
    print(hdr)
    print("-" * (len(hdr) + 20))
    for name, (sim_kw, fus_kw) in ROAD_SCENARIOS.items():
        acc: dict[bool, dict[str, list[float]]] = {
            fb: {k: [] for k in ("e", "end", "d", "o", "c", "m")} for fb in (False, True)
        }
        verdicts: dict[bool, Counter[str]] = {False: Counter(), True: Counter()}
        errs: dict[bool, list[np.ndarray]] = {False: [], True: []}
        for i, trip in enumerate(trips):
            cfg = RawLogSimConfig(odo_scale=scales[i % len(scales)], **sim_kw)
            raw, sim = simulate_trip_raw_log(trip, cfg, seed=i)
            try:
                fm = fuse_and_match(raw, net, fusion_config=FusionConfig(**fus_kw))
            except NoCandidatesError:
                for fb in (False, True):
                    verdicts[fb]["no-match"] += 1
                continue
            tr = sim.trajectory
            passes = ((False, fm.first_track, fm.first_result), (True, fm.track, fm.result))
            for fb, trk, res in passes:
                a = acc[fb]
                i0 = trk.first_row
                e = errors(trk, tr)
                errs[fb].append(e)
                a["end"] += [float(e[k - i0]) for k in sim.outage_ends]
                true_m = float(tr.distance_m[-1] - tr.distance_m[i0])
                a["d"].append(100 * abs(trk.distance_m / true_m - 1))
                odo_m = float((raw.odo_speed_mps[i0 + 1 :] * np.diff(raw.time_s[i0:])).sum())
                a["o"].append(100 * abs(odo_m / true_m - 1))
                a["c"].append(100 * abs(chord_m(raw) / true_m - 1))
                a["m"].append(100 * abs(res.matched_length_m / true_m - 1))
                verdicts[fb][res.distance_check.verdict] += 1
        for fb in (False, True):
            a = acc[fb]
            e = np.concatenate(errs[fb]) if errs[fb] else np.array([np.nan])
            end = f"{np.mean(a['end']):8.2f}" if a["end"] else f"{'-':>8s}"
            counts = " ".join(
                f"{k} {verdicts[fb][k]}"
                for k in ("pass", "over", "under", "incomplete", "no-match")
                if verdicts[fb][k]
            )
            print(
                f"{name:36s} {'yes' if fb else 'no':>3s} {e.mean():6.2f} "
                f"{np.percentile(e, 95):6.2f} {end} {np.mean(a['d']):8.3f} "
                f"{np.max(a['d']):6.2f} {np.mean(a['o']):7.2f} {np.mean(a['c']):9.1f} "
                f"{np.mean(a['m']):9.3f} {np.max(a['m']):10.2f}  {counts}"
            )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--trips", type=int, default=10, help="real-road drives per network")
    ap.add_argument("--skip-synthetic", action="store_true", help="real-road rows only")
    args = ap.parse_args()
    if not args.skip_synthetic:
        synthetic(args)
    print("\n== real roads: fuse -> match (fb no) -> road feedback -> fuse -> match (fb yes) ==")
    networks: list[tuple[str, str | None]] = [("monaco (embedded)", None)]
    if ANDORRA.exists():
        networks.append(("andorra_2020", str(ANDORRA)))
    for label, source in networks:
        t0 = time.perf_counter()
        net = roadnets.load(source)
        print(f"\nloaded {label} in {time.perf_counter() - t0:.1f} s: {net.info().edges} edges")
        t0 = time.perf_counter()
        road_rows(net, label.split()[0], args.trips)
        print(f"({time.perf_counter() - t0:.1f} s)")
    print(
        "\nfb: map-aided feedback (second pass); errors in metres; out-end: mean error at the "
        "last epoch of each outage;\n|dist|%: fused distance vs true distance driven, mean "
        "and max |error|; odo / chord: raw odometer and\nGNSS chord-sum distance, mean "
        "|error|; match: matched length vs true distance, mean and max |error|;\nverdicts: "
        "distance check of the match (fused odometer vs matched length, band -4 % .. +1 %)."
    )


def synthetic(args: argparse.Namespace) -> None:
    trips = {"city loop 3 laps": city_loop(), "arcs + straights": arcs()}
    scales = (0.97, 1.03)
    print("trips:", ", ".join(f"{k} ({v.length_m:.0f} m)" for k, v in trips.items()))
    print(f"seeds 0..{args.seeds - 1}, odometer scales {scales}; errors in metres\n")
    hdr = (
        f"{'scenario':42s} {'mean':>6s} {'p95':>6s} {'max':>6s} {'out-end':>8s} "
        f"{'dist%':>7s} {'|dist|max%':>10s} {'odo|max%':>9s} {'chord|max%':>10s} "
        f"{'scale|max%':>10s} {'rls|max%':>9s}"
    )
    print(hdr)
    print("-" * len(hdr))
    for name, (sim_kw, fus_kw, use_fb) in SCENARIOS.items():
        errs, ends, d, o, c, sc, rl = [], [], [], [], [], [], []
        for tr in trips.values():
            for seed in range(args.seeds):
                scale = scales[seed % 2]
                raw, sim = simulate_raw_log(
                    tr,
                    RawLogSimConfig(odo_scale=scale, **sim_kw),
                    seed=seed,  # type: ignore[arg-type]
                )
                fb = feedback_from_truth(tr, seed) if use_fb else None
                trk = fuse(raw, FusionConfig(**fus_kw), road_feedback=fb)  # type: ignore[arg-type]
                e = errors(trk, tr)
                errs.append(e)
                ends += [float(e[i - trk.first_row]) for i in sim.outage_ends]
                true_m = tr.distance_m[-1] - tr.distance_m[trk.first_row]
                d.append(100 * (trk.distance_m / true_m - 1))
                odo_m = float((raw.odo_speed_mps[1:] * np.diff(raw.time_s)).sum())
                o.append(100 * (odo_m / tr.length_m - 1))
                c.append(100 * (chord_m(raw) / tr.length_m - 1))
                sc.append(100 * (trk.odo_scale[-1] / scale - 1))
                rl.append(100 * (trk.odo_scale_rls[-1] / scale - 1))
        e = np.concatenate(errs)
        end = f"{np.mean(ends):8.2f}" if ends else f"{'-':>8s}"
        print(
            f"{name:42s} {e.mean():6.2f} {np.percentile(e, 95):6.2f} {e.max():6.2f} {end} "
            f"{np.mean(d):+7.3f} {np.max(np.abs(d)):10.3f} {np.max(np.abs(o)):9.2f} "
            f"{np.max(np.abs(c)):10.1f} {np.max(np.abs(sc)):10.3f} {np.max(np.abs(rl)):9.3f}"
        )
    print(
        "\nout-end: mean error at the last epoch of each outage; dist%: fused distance error "
        "(mean), |dist|max%: worst |error|;\nodo / chord: raw odometer and GNSS chord-sum "
        "distance, worst |error|; scale / rls: odometer scale, EKF state and RLS check, "
        "worst |error|.\nTaximeter band (JJG 517): -4 % .. +1 %."
    )
    # speed of the filter loop
    raw, _ = simulate_raw_log(trips["city loop 3 laps"], RawLogSimConfig(), seed=0)
    fuse(raw)
    t0 = time.perf_counter()
    for _ in range(5):
        fuse(raw)
    jit_s = (time.perf_counter() - t0) / 5
    print(f"\nfuse() on {len(raw)} epochs: {1e3 * jit_s:.1f} ms with numba", end="")
    if os.environ.get("MAPMATCH_FUSION_NO_NUMBA"):
        print(" (disabled)")
        return
    code = (
        "import time; from mapmatch.fusion import *; import benchmarks.bench_fusion as b;"
        "raw,_=simulate_raw_log(b.city_loop(), RawLogSimConfig(), seed=0);"
        "t=time.perf_counter(); fuse(raw); print(time.perf_counter()-t)"
    )
    env = dict(os.environ, MAPMATCH_FUSION_NO_NUMBA="1")
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    py_s = float(out.stdout.strip().splitlines()[-1])
    print(f", {1e3 * py_s:.0f} ms as plain Python ({py_s / jit_s:.0f}x)")


if __name__ == "__main__":
    main()
