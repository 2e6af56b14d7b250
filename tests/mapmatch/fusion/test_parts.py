from __future__ import annotations

import numpy as np
import pytest

from mapmatch.fusion import LocalTangentPlane, build_trajectory, stop, straight, turn
from mapmatch.fusion.calibration import ScalarRLS, rls_odometer_scale


def test_trajectory_turns_and_lengths() -> None:
    legs = [straight(100.0, 10.0), turn(90.0, 20.0, 6.0), stop(10.0), turn(-180.0, 10.0, 5.0)]
    tr = build_trajectory(legs, origin_lon=10.0, origin_lat=50.0, start_heading_deg=0.0)
    expected = 100.0 + np.pi / 2 * 20.0 + np.pi * 10.0
    assert tr.length_m == pytest.approx(expected, abs=1e-9)
    assert tr.heading_deg[-1] == pytest.approx(90.0, abs=1e-6)  # north, left 90, right 180
    ltp = LocalTangentPlane(10.0, 50.0)
    x, y = ltp.to_xy(tr.lon[-1], tr.lat[-1])
    assert float(x) == pytest.approx(-20.0, abs=1e-6)
    assert float(y) == pytest.approx(140.0, abs=1e-6)
    assert tr.speed_mps.max() <= 10.0
    assert (np.diff(tr.distance_m) >= 0.0).all()
    assert (tr.speed_mps == 0.0).sum() >= 100  # the stop and the initial wait


def test_local_tangent_plane_round_trip() -> None:
    ltp = LocalTangentPlane(116.4, 39.9)
    x = np.array([-3000.0, 0.0, 2500.0])
    y = np.array([1000.0, 0.0, -4000.0])
    lon, lat = ltp.to_lonlat(x, y)
    bx, by = ltp.to_xy(lon, lat)
    np.testing.assert_allclose(bx, x, atol=1e-6)
    np.testing.assert_allclose(by, y, atol=1e-6)
    # one degree of latitude is about 111 km
    _, y1 = ltp.to_xy(116.4, 40.9)
    assert float(y1) == pytest.approx(111_050.0, rel=2e-3)


def test_scalar_rls_converges_with_noise() -> None:
    rng = np.random.default_rng(0)
    rls = ScalarRLS()
    for phi in rng.uniform(50.0, 150.0, 400):
        rls.update(phi, 0.97 * phi + rng.normal(0.0, 3.0))
    assert rls.k == pytest.approx(0.97, abs=2e-3)
    assert rls.n == 400


def test_rls_odometer_scale_on_exact_data() -> None:
    t = np.arange(0.0, 200.0, 0.1)
    yaw = 0.3 + 0.002 * t  # gentle curve
    v = 10.0
    true_step = np.full(t.size, v * 0.1)
    true_step[0] = 0.0
    yaw_mid = yaw - 0.001 * 0.1
    x = np.cumsum(true_step * np.cos(yaw_mid))
    y = np.cumsum(true_step * np.sin(yaw_mid))
    used = (np.arange(t.size) % 10) == 0
    est = rls_odometer_scale(
        t, np.full(t.size, 1.04 * v), yaw, x, y, used, stretch_m=100.0, max_gap_s=5.0
    )
    assert np.isnan(est[0])
    assert est[-1] == pytest.approx(1.04, rel=1e-4)
