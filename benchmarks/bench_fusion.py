"""
Fusion front-end benchmark on simulated raw logs (fixed seeds).

Prints position error (mean / 95th percentile, and at outage ends) with and without GNSS
outages and with and without map-aided feedback; fused-distance error against odometer-only
and GNSS-chord-only distances; odometer-scale estimates (EKF and RLS); filter speed with and
without numba.

    .venv/bin/python benchmarks/bench_fusion.py [--seeds 5]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

import numpy as np

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
    simulate_raw_log,
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


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=5)
    args = ap.parse_args()
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
