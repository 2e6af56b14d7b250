from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from mapmatch.fusion import (
    TRACE_COLUMNS,
    FusionConfig,
    FusionConfigError,
    NoGnssFixError,
    RawLog,
    RawLogSimConfig,
    fuse,
    simulate_raw_log,
)
from mapmatch.trace.chinacrs import wgs84_to_gcj02


@pytest.mark.parametrize("trip", ["city", "arcs", "straight"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_30s_outage_at_urban_speed_stays_under_15m(h, trips, trip, seed) -> None:
    truth = trips[trip]()
    start = {"city": 120.0, "arcs": 120.0, "straight": 50.0}[trip]  # while driving
    cfg = RawLogSimConfig(outages_s=((start, start + 30.0),))
    raw, sim = simulate_raw_log(truth, cfg, seed=seed)
    track = fuse(raw)
    err = h.position_error_m(track, truth)
    end = int(sim.outage_ends[0]) - track.first_row
    assert truth.speed_mps[sim.in_outage].mean() > 8.0  # really at urban speed
    assert err[end] < 15.0
    # the covariance grows honestly during the outage and covers the error
    before = end - 300
    assert track.accuracy_m[end] > 1.5 * track.accuracy_m[before]
    assert err[end] < 3.5 * track.accuracy_m[end]


@pytest.mark.parametrize(("trip", "scale", "seed"), [
    ("city", 0.97, 0), ("city", 1.03, 1), ("arcs", 1.05, 2), ("straight", 0.98, 3),
])  # fmt: skip
def test_odometer_scale_converges_within_half_a_percent(trips, trip, scale, seed) -> None:
    raw, _ = simulate_raw_log(trips[trip](), RawLogSimConfig(odo_scale=scale), seed=seed)
    track = fuse(raw)
    assert track.odo_scale[0] == 1.0  # starts from the uncalibrated prior
    assert abs(track.odo_scale[-1] / scale - 1.0) < 0.005
    assert track.odo_scale_sigma[-1] < 0.005
    # the independent RLS check agrees to within 1.5 %
    assert abs(track.odo_scale_rls[-1] / scale - 1.0) < 0.015


def test_gyro_bias_and_scale_are_estimated(trips) -> None:
    raw, sim = simulate_raw_log(trips["city"](), RawLogSimConfig(gyro_bias_dps=0.4), seed=5)
    track = fuse(raw)
    assert track.gyro_bias_dps[0] == 0.0
    assert abs(track.gyro_bias_dps[-1] - sim.gyro_bias_dps[-1]) < 0.02
    assert abs(track.gyro_scale[-1] - sim.gyro_scale) < 0.005


TRIP_CASES = [
    ("city", 1.03, None, ((100.0, 130.0),)),
    ("city", 0.97, 4.0, ((250.0, 300.0),)),
    ("arcs", 1.04, None, ((60.0, 90.0),)),
    ("arcs", 0.98, 10.0, ()),
    ("straight", 1.02, None, ((150.0, 200.0),)),
    ("straight", 0.96, None, ()),
]


@pytest.mark.parametrize(("trip", "scale", "ppm", "outages"), TRIP_CASES)
def test_fused_distance_in_taximeter_band_and_best(h, trips, trip, scale, ppm, outages) -> None:
    truth = trips[trip]()
    cfg = RawLogSimConfig(odo_scale=scale, pulses_per_m=ppm, outages_s=outages)
    raw, _ = simulate_raw_log(truth, cfg, seed=11)
    track = fuse(raw)
    assert track.first_row == 0
    true_m = truth.length_m
    fused_err = track.distance_m / true_m - 1.0
    assert -0.04 <= fused_err <= 0.01  # JJG 517 taximeter band
    odo_err = h.odometer_sum_m(raw) / true_m - 1.0
    chord_err = h.chord_sum_m(raw) / true_m - 1.0
    assert abs(fused_err) < abs(odo_err)
    assert abs(fused_err) < abs(chord_err)


def test_stopped_vehicle_holds_position_and_heading(h, trips) -> None:
    truth = trips["city"]()
    raw, _ = simulate_raw_log(truth, RawLogSimConfig(gyro_noise_dps=0.2), seed=3)
    track = fuse(raw)
    stopped = truth.speed_mps[track.first_row :] == 0.0
    runs = np.flatnonzero(np.diff(stopped.astype(int)) == 1) + 1
    checked = 0
    for start in runs:
        end = start
        while end + 1 < stopped.size and stopped[end + 1]:
            end += 1
        if end - start < 100:  # only the 20 s red lights
            continue
        a, b = start + 10, end  # after the ZUPT window has filled
        # the heading does not drift while standing (it may only get better: the zero
        # angular rate update refines the bias, and with it the correlated heading error)
        err = (track.heading_deg - truth.heading_deg[track.first_row :] + 180.0) % 360.0 - 180.0
        assert abs(err[b]) <= abs(err[a]) + 0.02
        assert abs(err[b]) < 1.0
        assert abs(track.odometer_m[b] - track.odometer_m[a]) < 1e-9
        assert track.speed_mps[a:b].max() < 0.05
        checked += 1
    assert checked >= 7


def test_quality_gate_and_innovation_test(h, trips) -> None:
    truth = trips["city"]()
    cfg = RawLogSimConfig(multipath_prob=0.05, bad_fix_prob=0.05)
    raw, sim = simulate_raw_log(truth, cfg, seed=4)
    track = fuse(raw)
    status = track.gnss_status
    mp = sim.multipath[track.first_row :]
    bad = sim.bad_fix[track.first_row :]
    assert (status[bad] == 2).all()  # few satellites / high HDOP: never used
    assert (status[mp] == 3).mean() > 0.9  # multipath jumps fail the chi-square test
    good = (status > 0) & ~mp & ~bad
    assert (status[good] == 1).mean() > 0.98  # and good fixes pass it
    # without gating the jumps pull the track off
    loose = FusionConfig(max_hdop=100.0, min_sats=0, chi2_gate_position=1e9)
    err_gated = h.position_error_m(track, truth)
    err_loose = h.position_error_m(fuse(raw, loose), truth)
    assert np.percentile(err_gated, 95) < 0.7 * np.percentile(err_loose, 95)


@pytest.mark.parametrize("seed", [0, 3])
def test_road_feedback_bounds_drift_in_long_outage(h, seed) -> None:
    truth = h.city_loop(laps=3)
    walk = 0.02  # cheap gyro: bias wanders 0.2 deg/s in two minutes
    cfg = RawLogSimConfig(
        outages_s=((250.0, 370.0),), gyro_bias_walk_dps_per_sqrt_s=walk, gyro_noise_dps=0.1
    )
    raw, sim = simulate_raw_log(truth, cfg, seed=seed)
    fcfg = FusionConfig(gyro_bias_walk_dps_per_sqrt_s=walk)
    feedback = h.road_feedback_from_truth(truth, seed=seed)
    plain = fuse(raw, fcfg)
    aided = fuse(raw, fcfg, road_feedback=feedback)
    out = sim.in_outage
    err_plain = h.position_error_m(plain, truth)[out]
    err_aided = h.position_error_m(aided, truth)[out]
    assert err_aided.max() < 4.0
    assert err_aided.max() < 0.6 * err_plain.max()
    assert aided.road_feedback_used[out].sum() > 60
    # hardly ever while GNSS is good (only after a few gated/rejected fixes in a row)
    assert aided.road_feedback_used[~out].sum() < 5


def test_feedback_far_from_track_is_rejected(h, trips) -> None:
    truth = trips["arcs"]()
    raw, _ = simulate_raw_log(truth, RawLogSimConfig(outages_s=((60.0, 120.0),)), seed=1)
    fb = h.road_feedback_from_truth(truth, seed=1)
    wrong = dataclasses.replace(fb, lat=fb.lat + 0.001)  # a parallel road 110 m north
    track = fuse(raw, road_feedback=wrong)
    assert not track.road_feedback_used.any()


def test_to_dataframe_has_exactly_the_trace_columns(trips) -> None:
    raw, _ = simulate_raw_log(trips["arcs"](), RawLogSimConfig(), seed=0)
    track = fuse(raw)
    df = track.to_dataframe()
    assert tuple(df.columns) == TRACE_COLUMNS == (
        "time", "lat", "lon", "heading", "speed", "accuracy", "odometer",
    )  # fmt: skip
    assert len(df) == len(track)
    thin = track.to_dataframe(interval_s=1.0)
    assert np.allclose(np.diff(thin["time"].to_numpy()[:-1]), 1.0, atol=0.051)
    assert thin["odometer"].iloc[-1] == track.distance_m
    assert df["heading"].between(0.0, 360.0).all()
    assert (df["accuracy"] > 0.0).all()
    assert (np.diff(df["odometer"].to_numpy()) >= 0.0).all()


def test_gcj02_log_fuses_like_wgs84_log(trips) -> None:
    raw, _ = simulate_raw_log(trips["arcs"](), RawLogSimConfig(), seed=2)
    fix = raw.has_fix
    df = pd.DataFrame({
        "time": raw.time_s, "odo_speed_mps": raw.odo_speed_mps, "gyro_z_dps": raw.gyro_z_dps,
        "lat": raw.lat, "lon": raw.lon, "hdop": raw.hdop, "sats": raw.sats,
    })  # fmt: skip
    df.loc[fix, "lon"], df.loc[fix, "lat"] = wgs84_to_gcj02(raw.lon[fix], raw.lat[fix])
    a = fuse(RawLog.from_dataframe(df.assign(lat=raw.lat, lon=raw.lon)))
    b = fuse(RawLog.from_dataframe(df, crs="gcj02"))
    c = fuse(RawLog.from_dataframe(df))  # forgot crs: hundreds of metres off
    assert np.max(np.abs(a.lat - b.lat)) < 1e-7
    assert np.max(np.abs(a.lon - b.lon)) < 1e-7
    assert np.max(np.abs(a.lon - c.lon)) > 1e-3


def test_no_usable_fix_raises(trips) -> None:
    raw, _ = simulate_raw_log(trips["arcs"](), RawLogSimConfig(), seed=0)
    with pytest.raises(NoGnssFixError, match=r"none with sats >= 50"):
        fuse(raw, FusionConfig(min_sats=50))


def test_config_errors_name_field_and_value() -> None:
    with pytest.raises(FusionConfigError, match=r"odo_scale_sigma must be >= 0 \(got -0.1\)"):
        FusionConfig(odo_scale_sigma=-0.1)
    with pytest.raises(FusionConfigError, match=r"max_hdop must be finite"):
        FusionConfig(max_hdop=float("nan"))
    with pytest.raises(ValueError, match="rls_forgetting"):
        FusionConfig(rls_forgetting=0.5)


def test_simulator_is_deterministic_and_keeps_truth(h, trips) -> None:
    truth = trips["arcs"]()
    cfg = RawLogSimConfig(outages_s=((30.0, 60.0),))
    a, sim = simulate_raw_log(truth, cfg, seed=9)
    b, _ = simulate_raw_log(truth, cfg, seed=9)
    c, _ = simulate_raw_log(truth, cfg, seed=10)
    np.testing.assert_array_equal(a.gyro_z_dps, b.gyro_z_dps)
    assert not np.array_equal(a.gyro_z_dps, c.gyro_z_dps)
    assert not a.has_fix[sim.in_outage].any()
    assert sim.in_outage.sum() == 300
    moving = truth.speed_mps[1:] > 1.0
    odo_m = (a.odo_speed_mps[1:] * np.diff(a.time_s))[moving].sum()
    ratio = odo_m / np.diff(truth.distance_m)[moving].sum()
    assert ratio == pytest.approx(1.03, rel=2e-3)
