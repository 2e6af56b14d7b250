from __future__ import annotations

import numpy as np
import pytest

from mapmatch.trace.chinacrs import (
    bd09_to_gcj02,
    bd09_to_wgs84,
    gcj02_to_bd09,
    gcj02_to_wgs84,
    in_china,
    wgs84_to_bd09,
    wgs84_to_gcj02,
)

# Published reference vectors of the widely used open-source implementation
# (wandergis/coordtransform README), Tiananmen area, input (116.404, 39.915).
WGS_TO_GCJ = (116.41024449916938, 39.91640428150164)
GCJ_TO_BD = (116.41036949371029, 39.92133699351021)
BD_TO_GCJ = (116.39762729119315, 39.90865673957631)  # closed-form inverse, ~1e-7 deg
WGS_TO_BD = (116.41662724378733, 39.922699552216216)
GCJ_TO_WGS_ONE_STEP = (116.39775550083061, 39.91359571849836)  # one-step inverse
BD_TO_WGS_ONE_STEP = (116.3913836995125, 39.907253214522164)


@pytest.mark.parametrize(
    ("func", "expected"),
    [(wgs84_to_gcj02, WGS_TO_GCJ), (gcj02_to_bd09, GCJ_TO_BD), (wgs84_to_bd09, WGS_TO_BD)],
)
def test_forward_transforms_match_published_reference(func, expected) -> None:
    lon, lat = func(116.404, 39.915)
    assert float(lon) == pytest.approx(expected[0], abs=1e-11)
    assert float(lat) == pytest.approx(expected[1], abs=1e-11)


@pytest.mark.parametrize(
    ("func", "expected"),
    [
        (bd09_to_gcj02, BD_TO_GCJ),
        (gcj02_to_wgs84, GCJ_TO_WGS_ONE_STEP),
        (bd09_to_wgs84, BD_TO_WGS_ONE_STEP),
    ],
)
def test_inverse_transforms_close_to_published_one_step_inverse(func, expected) -> None:
    # The one-step inverses of the reference implementation are off by up to ~1e-5 deg;
    # ours iterates, so agree to a few metres (5e-5 deg) but not bit for bit.
    lon, lat = func(116.404, 39.915)
    assert float(lon) == pytest.approx(expected[0], abs=5e-5)
    assert float(lat) == pytest.approx(expected[1], abs=5e-5)


def test_gcj02_offset_is_hundreds_of_metres_in_beijing() -> None:
    lon, lat = wgs84_to_gcj02(116.404, 39.915)
    dx = (float(lon) - 116.404) * 111_320 * np.cos(np.radians(39.915))
    dy = (float(lat) - 39.915) * 110_574
    assert 300 < np.hypot(dx, dy) < 700


def _grid() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(7)
    lon = rng.uniform(73.0, 135.0, 2000)
    lat = rng.uniform(18.0, 53.0, 2000)
    return lon, lat


def test_gcj02_inverse_round_trip_below_1e_minus_6_deg() -> None:
    lon, lat = _grid()
    back_lon, back_lat = gcj02_to_wgs84(*wgs84_to_gcj02(lon, lat))
    assert np.max(np.abs(back_lon - lon)) < 1e-8
    assert np.max(np.abs(back_lat - lat)) < 1e-8
    # and the other way round: the inverse really inverts the forward transform
    g_lon, g_lat = wgs84_to_gcj02(*gcj02_to_wgs84(lon, lat))
    assert np.max(np.abs(g_lon - lon)) < 1e-8
    assert np.max(np.abs(g_lat - lat)) < 1e-8


def test_bd09_round_trips() -> None:
    lon, lat = _grid()
    b_lon, b_lat = bd09_to_gcj02(*gcj02_to_bd09(lon, lat))
    assert np.max(np.abs(b_lon - lon)) < 1e-8
    assert np.max(np.abs(b_lat - lat)) < 1e-8
    w_lon, w_lat = bd09_to_wgs84(*wgs84_to_bd09(lon, lat))
    assert np.max(np.abs(w_lon - lon)) < 1e-8
    assert np.max(np.abs(w_lat - lat)) < 1e-8


@pytest.mark.parametrize(
    "func",
    [wgs84_to_gcj02, gcj02_to_wgs84, gcj02_to_bd09, bd09_to_gcj02, wgs84_to_bd09, bd09_to_wgs84],
)
def test_points_outside_china_are_unchanged(func) -> None:
    lon = np.array([-0.1246, 2.35, 151.21, 139.75, -74.0])
    lat = np.array([51.5007, 48.85, -33.87, 35.68, 40.7])
    out_lon, out_lat = func(lon, lat)
    np.testing.assert_array_equal(out_lon, lon)
    np.testing.assert_array_equal(out_lat, lat)


def test_bounding_rule_edges() -> None:
    assert in_china(72.004, 30.0)
    assert not in_china(72.0039, 30.0)
    assert in_china(137.8347, 30.0)
    assert not in_china(137.8348, 30.0)
    assert in_china(100.0, 0.8293)
    assert not in_china(100.0, 0.8292)
    assert in_china(100.0, 55.8271)
    assert not in_china(100.0, 55.8272)


def test_vectorised_shapes_and_mixed_inside_outside() -> None:
    lon = np.array([[116.404, 2.35], [121.47, -74.0]])
    lat = np.array([[39.915, 48.85], [31.23, 40.7]])
    out_lon, out_lat = wgs84_to_gcj02(lon, lat)
    assert out_lon.shape == (2, 2)
    assert out_lon[0, 0] == pytest.approx(WGS_TO_GCJ[0], abs=1e-11)
    assert out_lon[0, 1] == 2.35
    assert out_lat[1, 1] == 40.7
    assert out_lon[1, 0] != 121.47
