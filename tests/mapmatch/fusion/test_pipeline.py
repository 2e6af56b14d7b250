"""Fusion on real roads: raw logs from simulated OSM drives, fuse -> match -> feedback -> fuse."""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING

import numpy as np
import pytest

from mapmatch.evaluation.simulate import SimulatedTrip, SimulationConfig, simulate_trip
from mapmatch.fusion import (
    FusedTrack,
    FusionConfig,
    LocalTangentPlane,
    RawLog,
    RawLogSimConfig,
    TrueTrajectory,
    fuse_and_match,
    road_bearing_deg,
    road_feedback_from_match,
    simulate_trip_raw_log,
    true_trajectory_of,
    write_raw_logs,
)

if TYPE_CHECKING:
    from pathlib import Path

    import roadnets

_TRIPS: dict[tuple[int, float], SimulatedTrip] = {}


def drive(net: roadnets.RoadNetwork, seed: int, route_length_m: float) -> SimulatedTrip:
    """A random drive on ``net`` (cached: the same seed gives the same trip)."""
    key = (seed, route_length_m)
    if key not in _TRIPS:
        cfg = SimulationConfig(route_length_m=route_length_m)
        _TRIPS[key] = simulate_trip(net, cfg, seed=seed, trace_id=f"drive-{seed}")
    return _TRIPS[key]


def pick_drive(
    net: roadnets.RoadNetwork,
    seed: int,
    route_length_m: float,
    *,
    length_m: tuple[float, float] = (1000.0, 3000.0),
    driving_s: tuple[float, float] | None = None,
    min_speed_mps: float = 4.0,
) -> SimulatedTrip:
    """
    The first drive from ``seed`` on whose length is within ``length_m`` and, when
    ``driving_s`` is given, that drives at ``min_speed_mps`` on average in that window and
    goes on for 30 s after it (so an outage there happens on the road, not at a red light).
    Choosing by property rather than by a bare seed keeps the tests meaningful when the
    trip generator of :mod:`mapmatch.evaluation.simulate` changes.
    """
    for s in range(seed, seed + 30):
        trip = drive(net, s, route_length_m)
        if not length_m[0] <= trip.length_m <= length_m[1]:
            continue
        if driving_s is not None:
            t = trip.dense_time_s - trip.dense_time_s[0]
            window = (t >= driving_s[0]) & (t < driving_s[1])
            if t[-1] < driving_s[1] + 30.0 or trip.dense_speed_mps[window].mean() < min_speed_mps:
                continue
        return trip
    pytest.fail(f"no suitable drive for seeds {seed}..{seed + 29}")


def position_error_m(track: FusedTrack, truth: TrueTrajectory) -> np.ndarray:
    ltp = LocalTangentPlane(float(truth.lon[0]), float(truth.lat[0]))
    tx, ty = ltp.to_xy(truth.lon[track.first_row :], truth.lat[track.first_row :])
    fx, fy = ltp.to_xy(track.lon, track.lat)
    return np.hypot(fx - tx, fy - ty)


def chord_sum_m(raw: RawLog, first_row: int) -> float:
    fix = raw.has_fix.copy()
    fix[:first_row] = False
    ltp = LocalTangentPlane(float(raw.lon[fix][0]), float(raw.lat[fix][0]))
    x, y = ltp.to_xy(raw.lon[fix], raw.lat[fix])
    return float(np.hypot(np.diff(x), np.diff(y)).sum())


def odometer_sum_m(raw: RawLog, first_row: int) -> float:
    return float((raw.odo_speed_mps[first_row + 1 :] * np.diff(raw.time_s[first_row:])).sum())


def great_circle_bearing_deg(lon0: float, lat0: float, lon1: float, lat1: float) -> float:
    """Initial bearing on the sphere (an independent formula for the check)."""
    p0, p1 = math.radians(lat0), math.radians(lat1)
    dl = math.radians(lon1 - lon0)
    y = math.sin(dl) * math.cos(p1)
    x = math.cos(p0) * math.sin(p1) - math.sin(p0) * math.cos(p1) * math.cos(dl)
    return math.degrees(math.atan2(y, x)) % 360.0


# --- 1. raw logs from real-road drives -------------------------------------------------------


def test_true_trajectory_follows_the_trip(default_net) -> None:
    trip = pick_drive(default_net, 0, 1200.0)
    tr = true_trajectory_of(trip)
    assert len(tr) == trip.dense_time_s.size
    assert np.allclose(np.diff(tr.time_s), 0.1, atol=1e-5)  # 10 Hz
    # length_m-consistent: the dense truth ends within a fraction of a second of the last fix
    assert tr.length_m == pytest.approx(trip.length_m, rel=2e-3)
    assert 1000.0 < tr.length_m < 3000.0
    # the 1 Hz true fixes of the trip lie on the dense trajectory
    t_fix = trip.trace.time_s
    lon = np.interp(t_fix, tr.time_s, tr.lon)
    lat = np.interp(t_fix, tr.time_s, tr.lat)
    ltp = LocalTangentPlane(float(tr.lon[0]), float(tr.lat[0]))
    x, y = ltp.to_xy(lon, lat)
    tx, ty = ltp.to_xy(trip.true_lon, trip.true_lat)
    assert np.hypot(x - tx, y - ty).max() < 0.5
    assert ((tr.heading_deg >= 0.0) & (tr.heading_deg < 360.0)).all()


def test_raw_log_of_a_real_road_drive_has_the_sensor_errors(default_net) -> None:
    trip = pick_drive(default_net, 5, 1800.0, driving_s=(60.0, 90.0), min_speed_mps=2.5)
    cfg = RawLogSimConfig(outages_s=((60.0, 90.0),), odo_scale=0.97, multipath_prob=0.05)
    raw, sim = simulate_trip_raw_log(trip, cfg, seed=3)
    again, _ = simulate_trip_raw_log(trip, cfg, seed=3)
    np.testing.assert_array_equal(raw.lon, again.lon)
    assert raw.source == trip.trace.trace_id
    assert len(raw) == trip.dense_time_s.size
    assert not raw.has_fix[sim.in_outage].any()
    assert sim.in_outage.sum() == 300  # 30 s at 10 Hz
    assert sim.multipath.sum() >= 5
    # odometer reads 0.97 of the true distance
    odo_m = odometer_sum_m(raw, 0)
    assert odo_m / sim.trajectory.length_m == pytest.approx(0.97, abs=2e-3)
    # good fixes scatter metres around the road, multipath jumps tens of metres
    err = np.full(len(raw), np.nan)
    ltp = LocalTangentPlane(float(trip.dense_lon[0]), float(trip.dense_lat[0]))
    fx, fy = ltp.to_xy(raw.lon, raw.lat)
    tx, ty = ltp.to_xy(trip.dense_lon, trip.dense_lat)
    err = np.hypot(fx - tx, fy - ty)
    good = raw.has_fix & ~sim.multipath & ~sim.bad_fix
    assert 1.0 < np.median(err[good]) < 6.0
    assert np.median(err[sim.multipath]) > 15.0
    assert np.nanmax(raw.hdop[good]) <= 3.0


def test_write_raw_logs_round_trips(default_net, tmp_path: Path) -> None:
    trips = [drive(default_net, 0, 1200.0), drive(default_net, 6, 2400.0)]
    cfg = RawLogSimConfig(outages_s=((30.0, 45.0),))
    paths = write_raw_logs(trips, tmp_path, cfg, seed=7)
    assert [p.name for p in paths] == ["drive-0.raw.csv", "drive-6.raw.csv"]
    assert trips[0].length_m != trips[1].length_m
    for i, (trip, path) in enumerate(zip(trips, paths, strict=True)):
        expected, _ = simulate_trip_raw_log(trip, cfg, seed=7 + i)
        back = RawLog.from_file(path)
        assert len(back) == len(expected)
        for name in ("time_s", "odo_speed_mps", "gyro_z_dps", "lon", "lat", "hdop"):
            np.testing.assert_allclose(getattr(back, name), getattr(expected, name), rtol=1e-8)
        truth = (tmp_path / f"{trip.trace.trace_id}.truth.csv").read_text().splitlines()
        assert truth[0].split(",")[:6] == ["time", "lat", "lon", "heading", "speed", "distance"]
        assert len(truth) == len(expected) + 1
    records = [json.loads(line) for line in (tmp_path / "truth.jsonl").read_text().splitlines()]
    assert [r["trace_id"] for r in records] == ["drive-0", "drive-6"]
    assert records[1]["raw_file"] == "drive-6.raw.csv"
    assert records[1]["seed"] == 8
    assert records[0]["outages_s"] == [[30.0, 45.0]]
    assert records[0]["true_distance_m"] == pytest.approx(trips[0].length_m, rel=2e-3)


def test_write_raw_logs_pulse_counts(default_net, tmp_path: Path) -> None:
    trip = drive(default_net, 0, 1200.0)
    cfg = RawLogSimConfig(pulses_per_m=4.0)
    (path,) = write_raw_logs([trip], tmp_path, cfg, seed=1)
    header = path.read_text().splitlines()[0].split(",")
    assert "odo_count" in header
    assert "odo_speed_mps" not in header
    expected, _ = simulate_trip_raw_log(trip, cfg, seed=1)
    back = RawLog.from_file(path, pulses_per_m=4.0)
    np.testing.assert_allclose(back.odo_speed_mps, expected.odo_speed_mps, atol=1e-6)


# --- 2. road bearing and feedback from a match ------------------------------------------------


def test_road_bearing_is_the_geographic_direction_of_travel(default_net) -> None:
    a = default_net.arrays
    twins = np.flatnonzero(a.edge_twin >= 0)[:40]
    for e in twins:
        lo = int(a.edge_geom_ptr[e])
        length = float(a.edge_length_m[e])
        off = 0.5 * float(a.geom_cum_m[lo + 1])  # inside the first geometry segment
        (lon0, lon1), (lat0, lat1) = default_net.unproject(
            a.geom_x[lo : lo + 2], a.geom_y[lo : lo + 2]
        )
        expected = great_circle_bearing_deg(lon0, lat0, lon1, lat1)
        got = float(road_bearing_deg(default_net, e, off)[0])
        # sphere vs ellipsoid differ by < 0.3 deg; the UTM grid bearing is 1.1 deg off here
        assert abs((got - expected + 180.0) % 360.0 - 180.0) < 0.3
        # the twin edge runs the same geometry the other way
        back = float(road_bearing_deg(default_net, a.edge_twin[e], length - off)[0])
        assert abs((back - got) % 360.0 - 180.0) < 0.05


def test_feedback_from_match_is_on_the_true_road_with_its_heading(default_net) -> None:
    trip = pick_drive(default_net, 7, 3000.0)
    raw, sim = simulate_trip_raw_log(trip, RawLogSimConfig(), seed=7)
    fm = fuse_and_match(raw, default_net, feedback=False)
    fb = road_feedback_from_match(fm.result, default_net, accuracy_m=fm.trace.accuracy_m)
    assert len(fb) > 0.3 * len(fm.trace)  # thinned fixes count, at their place on the path
    tr = sim.trajectory
    t_lon = np.interp(fb.time_s, tr.time_s, tr.lon)
    t_lat = np.interp(fb.time_s, tr.time_s, tr.lat)
    ltp = LocalTangentPlane(float(tr.lon[0]), float(tr.lat[0]))
    fx, fy = ltp.to_xy(fb.lon, fb.lat)
    tx, ty = ltp.to_xy(t_lon, t_lat)
    assert np.percentile(np.hypot(fx - tx, fy - ty), 95) < 6.0
    k = np.clip(np.searchsorted(tr.time_s, fb.time_s), 0, len(tr) - 1)
    moving = tr.speed_mps[k] > 2.0
    dh = np.abs((fb.road_heading_deg - tr.heading_deg[k] + 180.0) % 360.0 - 180.0)
    assert np.percentile(dh[moving], 95) < 5.0
    assert (fb.cross_sigma_m == 2.0).all()
    assert (fb.along_sigma_m >= 10.0).all()
    # stricter filters give fewer entries; an impossible confidence gives none
    # (fixes merged into one observation at a stop are in the model; strays are not)
    model_only = road_feedback_from_match(fm.result, default_net, use_interpolated=False)
    assert 0 < len(model_only) <= len(fb)
    assert not fm.result.points.interpolated[np.isin(fm.trace.time_s, model_only.time_s)].any()
    fewer = road_feedback_from_match(fm.result, default_net, max_bend_deg=1.0, junction_m=30.0)
    assert 0 < len(fewer) < len(fb)
    assert len(road_feedback_from_match(fm.result, default_net, min_confidence=1.01)) == 0


def test_without_feedback_one_pass(default_net) -> None:
    trip = drive(default_net, 0, 1200.0)
    raw, _ = simulate_trip_raw_log(trip, RawLogSimConfig(), seed=0)
    fm = fuse_and_match(raw, default_net, feedback=False)
    assert fm.feedback is None
    assert fm.result is fm.first_result
    assert fm.track is fm.first_track
    assert fm.trace.trace_id == "drive-0"
    assert fuse_and_match(raw, default_net, trace_id="x", feedback=False).trace.trace_id == "x"
    assert fm.distance_check is fm.result.distance_check
    assert fm.distance_check.source == "odometer"
    assert fm.distance_check.fused_length_m == pytest.approx(fm.distance_m, abs=1e-6)


# --- 3. acceptance: distance band on real roads, feedback in long outages ---------------------

REAL_ROAD_TRIPS = [
    # (first trip seed, target route length m, odometer scale, GNSS outages)
    (0, 1200.0, 1.03, ()),
    (100, 1800.0, 0.97, ((60.0, 90.0),)),
    (200, 2400.0, 1.02, ()),
    (300, 2500.0, 0.985, ((60.0, 90.0),)),
    (400, 1800.0, 0.97, ((100.0, 130.0),)),
    (500, 2400.0, 1.02, ()),
]


@pytest.mark.parametrize(("seed", "route_m", "scale", "outages"), REAL_ROAD_TRIPS)
def test_real_road_trip_passes_distance_check_and_beats_raw_sensors(
    default_net, seed, route_m, scale, outages
) -> None:
    window = outages[0] if outages else None
    trip = pick_drive(default_net, seed, route_m, driving_s=window, min_speed_mps=2.5)
    cfg = RawLogSimConfig(odo_scale=scale, outages_s=outages)
    raw, sim = simulate_trip_raw_log(trip, cfg, seed=seed)
    assert sim.outage_ends.size == len(outages)
    fm = fuse_and_match(raw, default_net)
    check = fm.distance_check
    assert check.verdict == "pass", check
    assert -0.04 <= check.relative_error <= 0.01
    assert fm.result.breaks == []
    tr = sim.trajectory
    i0 = fm.track.first_row
    true_m = float(tr.distance_m[-1] - tr.distance_m[i0])
    assert true_m == pytest.approx(trip.length_m, rel=5e-3)
    fused_err = abs(fm.distance_m / true_m - 1.0)
    odo_err = abs(odometer_sum_m(raw, i0) / true_m - 1.0)
    chord_err = abs(chord_sum_m(raw, i0) / true_m - 1.0)
    assert fused_err < 0.01
    assert fused_err < odo_err
    assert fused_err < chord_err
    # the matched road length agrees with the true route length too
    assert fm.result.matched_length_m == pytest.approx(true_m, rel=0.01)
    assert np.percentile(position_error_m(fm.track, tr), 95) < 10.0


@pytest.mark.parametrize("outage", [(60.0, 150.0), (60.0, 180.0)])
def test_map_aided_feedback_cuts_end_of_long_outage_error(default_net, outage) -> None:
    walk = 0.02  # a cheap gyro whose bias wanders during the outage
    cfg = RawLogSimConfig(
        outages_s=(outage,), gyro_bias_walk_dps_per_sqrt_s=walk, gyro_noise_dps=0.1
    )
    fcfg = FusionConfig(gyro_bias_walk_dps_per_sqrt_s=walk)
    plain, aided = [], []
    seed = 1000
    for k in range(3):
        trip = pick_drive(default_net, seed, 3000.0, length_m=(1500.0, 5000.0), driving_s=outage)
        seed = int(trip.trace.trace_id.split("-")[1]) + 1
        raw, sim = simulate_trip_raw_log(trip, cfg, seed=k)
        fm = fuse_and_match(raw, default_net, fusion_config=fcfg)
        tr = sim.trajectory
        end = int(sim.outage_ends[0]) - fm.track.first_row
        plain.append(float(position_error_m(fm.first_track, tr)[end]))
        aided.append(float(position_error_m(fm.track, tr)[end]))
        out = sim.in_outage[fm.track.first_row :]
        used = fm.track.road_feedback_used
        assert used[out].sum() >= 5
        assert used[~out].sum() <= 0.1 * used[out].sum()  # GNSS rules where it is good
        assert not fm.first_track.road_feedback_used.any()
        assert aided[-1] <= plain[-1] + 1.0
    assert np.mean(plain) > 10.0  # the outage really hurt without the map
    assert np.mean(aided) < 0.4 * np.mean(plain), (plain, aided)
