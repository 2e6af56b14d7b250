from __future__ import annotations

from collections.abc import Callable  # noqa: TC003  (fixture annotations)
from types import SimpleNamespace

import numpy as np
import pytest

from mapmatch.fusion import (
    FusedTrack,
    LocalTangentPlane,
    RawLog,
    RoadFeedback,
    TrueTrajectory,
    build_trajectory,
    stop,
    straight,
    turn,
)

ORIGIN = (116.40, 39.90)  # Beijing; GNSS in WGS84 unless a test converts
T0 = 1_700_000_000.0


def city_loop(laps: int = 2, speed_mps: float = 12.0) -> TrueTrajectory:
    """Blocks of 400 m x 250 m with a red light and a 90-degree left turn at every corner."""
    legs = []
    for _ in range(laps):
        for side in (400.0, 250.0, 400.0, 250.0):
            legs += [straight(side, speed_mps), stop(20.0), turn(90.0, 12.0, 6.0)]
    return build_trajectory(legs, origin_lon=ORIGIN[0], origin_lat=ORIGIN[1], start_time_s=T0)


def arcs_and_straights() -> TrueTrajectory:
    legs = [
        straight(600.0, 15.0),
        turn(-120.0, 60.0, 10.0),
        straight(500.0, 14.0),
        turn(200.0, 40.0, 8.0),
        straight(700.0, 15.0),
        turn(-45.0, 100.0, 12.0),
        straight(400.0, 13.0),
    ]
    return build_trajectory(
        legs, origin_lon=ORIGIN[0], origin_lat=ORIGIN[1], start_heading_deg=30.0, start_time_s=T0
    )


def straight_line() -> TrueTrajectory:
    legs = [straight(1500.0, 13.0), stop(30.0), straight(1500.0, 14.0)]
    return build_trajectory(
        legs, origin_lon=ORIGIN[0], origin_lat=ORIGIN[1], start_heading_deg=300.0, start_time_s=T0
    )


def position_error_m(track: FusedTrack, truth: TrueTrajectory) -> np.ndarray:
    ltp = LocalTangentPlane(float(truth.lon[0]), float(truth.lat[0]))
    i0 = track.first_row
    tx, ty = ltp.to_xy(truth.lon[i0:], truth.lat[i0:])
    fx, fy = ltp.to_xy(track.lon, track.lat)
    return np.hypot(fx - tx, fy - ty)


def chord_sum_m(raw: RawLog) -> float:
    fix = raw.has_fix
    ltp = LocalTangentPlane(float(raw.lon[fix][0]), float(raw.lat[fix][0]))
    x, y = ltp.to_xy(raw.lon[fix], raw.lat[fix])
    return float(np.hypot(np.diff(x), np.diff(y)).sum())


def odometer_sum_m(raw: RawLog) -> float:
    return float((raw.odo_speed_mps[1:] * np.diff(raw.time_s)).sum())


@pytest.fixture(scope="session")
def trips() -> dict[str, Callable[[], TrueTrajectory]]:
    cache: dict[str, TrueTrajectory] = {}

    def make(name: str, builder: Callable[[], TrueTrajectory]) -> Callable[[], TrueTrajectory]:
        def get() -> TrueTrajectory:
            if name not in cache:
                cache[name] = builder()
            return cache[name]

        return get

    return {
        "city": make("city", city_loop),
        "arcs": make("arcs", arcs_and_straights),
        "straight": make("straight", straight_line),
    }


def road_feedback_from_truth(
    truth: TrueTrajectory,
    *,
    seed: int,
    along_sigma_m: float = 8.0,
    cross_sigma_m: float = 1.5,
    interval_s: float = 1.0,
) -> RoadFeedback:
    """A matched road position per second: the true centre-line point, displaced along the road
    by a slowly varying error (the matcher cannot resolve along-road position) and across it by
    lane-level noise, with the road's heading."""
    rng = np.random.default_rng(seed)
    every = round(interval_s / float(np.median(np.diff(truth.time_s))))
    idx = np.arange(0, len(truth), every)
    moving = truth.speed_mps[idx] > 0.5
    idx = idx[moving]
    ltp = LocalTangentPlane(float(truth.lon[0]), float(truth.lat[0]))
    x, y = ltp.to_xy(truth.lon[idx], truth.lat[idx])
    yaw = np.radians(90.0 - truth.heading_deg[idx])
    phi = np.exp(-interval_s / 20.0)  # along-road error correlated over ~20 s
    along = np.zeros(idx.size)
    along[0] = rng.normal(0.0, along_sigma_m)
    for i in range(1, idx.size):
        along[i] = phi * along[i - 1] + rng.normal(0.0, along_sigma_m * np.sqrt(1 - phi * phi))
    cross = rng.normal(0.0, cross_sigma_m, idx.size)
    fx = x + along * np.cos(yaw) - cross * np.sin(yaw)
    fy = y + along * np.sin(yaw) + cross * np.cos(yaw)
    lon, lat = ltp.to_lonlat(fx, fy)
    return RoadFeedback.from_arrays(
        truth.time_s[idx], lon, lat, truth.heading_deg[idx], along_sigma_m, cross_sigma_m
    )


@pytest.fixture(scope="session")
def h() -> SimpleNamespace:
    """The helpers above, for test modules (conftest is not importable under importlib mode)."""
    return SimpleNamespace(
        chord_sum_m=chord_sum_m,
        city_loop=city_loop,
        odometer_sum_m=odometer_sum_m,
        position_error_m=position_error_m,
        road_feedback_from_truth=road_feedback_from_truth,
    )
