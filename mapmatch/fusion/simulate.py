"""
Raw-log simulator: a true trajectory in, a realistic raw sensor log out, with the truth kept.

GNSS fixes at ``gnss_interval_s`` with white noise scaled by HDOP plus a slowly varying
(first-order Gauss-Markov) error, occasional poor fixes (few satellites, high HDOP, large error),
multipath jumps that look like good fixes, and outage windows without any fix; a wheel
odometer with a scale error (speed or cumulative pulses); a yaw gyro with a drifting bias,
a scale error and white noise. Sensor values on row ``k`` are the means over
``(t[k-1], t[k]]``, as :mod:`mapmatch.fusion.rawlog` specifies.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from mapmatch.fusion.geo import LocalTangentPlane
from mapmatch.fusion.rawlog import RawLog

if TYPE_CHECKING:
    import numpy.typing as npt

    from mapmatch.fusion.trajectory import TrueTrajectory

    FloatArray = npt.NDArray[np.float64]

__all__ = ["RawLogSimConfig", "SimTruth", "simulate_raw_log"]


@dataclass(frozen=True, slots=True, kw_only=True)
class RawLogSimConfig:
    """Error model of the simulated sensors (defaults: car, MEMS gyro, consumer GNSS)."""

    gnss_interval_s: float = 1.0  # fix rate
    gnss_uere_m: float = 2.5  # white error per axis at HDOP 1, metres (1 sigma)
    gnss_correlated_sigma_m: float = 1.0  # Gauss-Markov error per axis (1 sigma)
    gnss_correlation_time_s: float = 30.0
    hdop_min: float = 0.7  # HDOP = hdop_min + exponential(hdop_scale), capped at 3
    hdop_scale: float = 0.4
    bad_fix_prob: float = 0.03  # poor fixes: 3-4 satellites, HDOP 5-10, error uere * HDOP
    multipath_prob: float = 0.02  # good-looking fixes jumped by multipath_offset_m
    multipath_offset_m: tuple[float, float] = (15.0, 60.0)
    outages_s: tuple[tuple[float, float], ...] = ()  # (start, end) seconds after the first row
    gnss_velocity: bool = True  # receiver speed and course columns
    gnss_speed_sigma_mps: float = 0.1
    odo_scale: float = 1.03  # odometer reading / true distance
    odo_speed_sigma_mps: float = 0.03  # white noise on odometer speed
    pulses_per_m: float | None = None  # emit odo_count pulses instead of odo_speed_mps
    gyro_bias_dps: float = 0.3  # initial bias
    gyro_bias_walk_dps_per_sqrt_s: float = 0.001
    gyro_noise_dps: float = 0.05  # white noise per sample
    gyro_scale_error: float = 0.01  # true rate = (reading - bias) * (1 + error)


@dataclass(frozen=True, slots=True, eq=False)
class SimTruth:
    """What the simulator knows and the filter must estimate."""

    trajectory: TrueTrajectory
    odo_scale: float
    gyro_bias_dps: FloatArray
    gyro_scale: float
    in_outage: npt.NDArray[np.bool_]
    multipath: npt.NDArray[np.bool_]
    bad_fix: npt.NDArray[np.bool_]

    @property
    def outage_ends(self) -> npt.NDArray[np.intp]:
        """Row index of the last epoch of each outage."""
        o = self.in_outage.astype(np.int8)
        return np.flatnonzero(np.diff(o) == -1)


def simulate_raw_log(
    truth: TrueTrajectory, config: RawLogSimConfig, *, seed: int
) -> tuple[RawLog, SimTruth]:
    """
    Simulate the raw sensor log a car driving ``truth`` would record.

    Parameters
    ----------
    truth
        Dense, evenly sampled true trajectory (its rate is the sensor rate).
    config
        Sensor error model.
    seed
        Seed of the random generator; the same seed gives the same log.

    Returns
    -------
    tuple of RawLog and SimTruth
        The validated raw log and the truth (trajectory, odometer scale, gyro bias history,
        outage / multipath / bad-fix flags per row).

    Examples
    --------
    >>> from mapmatch.fusion.trajectory import build_trajectory, straight
    >>> tr = build_trajectory([straight(100.0, 10.0)], origin_lon=116.4, origin_lat=39.9)
    >>> raw, sim = simulate_raw_log(tr, RawLogSimConfig(), seed=1)
    >>> len(raw) == len(tr), sim.odo_scale
    (True, 1.03)
    """
    rng = np.random.default_rng(seed)
    n = len(truth)
    t = truth.time_s
    dt = np.empty(n)
    dt[1:] = np.diff(t)
    dt[0] = dt[1]
    rel_t = t - t[0]
    ltp = LocalTangentPlane(float(truth.lon[0]), float(truth.lat[0]))
    x, y = ltp.to_xy(truth.lon, truth.lat)

    # odometer: interval means, scaled, noisy (or cumulative pulses)
    step = np.zeros(n)
    step[1:] = np.diff(truth.distance_m)
    data: dict[str, FloatArray] = {"time": t.copy()}
    if config.pulses_per_m is not None:
        data["odo_count"] = np.floor(
            np.cumsum(step) * config.odo_scale * config.pulses_per_m + rng.uniform()
        )
    else:
        odo = step / dt * config.odo_scale
        odo = odo + rng.normal(0.0, config.odo_speed_sigma_mps, n) * (odo > 0.0)
        data["odo_speed_mps"] = np.maximum(odo, 0.0)

    # gyro: interval-mean true yaw rate, scale error, drifting bias, white noise
    yaw = np.unwrap(np.radians(90.0 - truth.heading_deg))
    rate_dps = np.zeros(n)
    rate_dps[1:] = np.degrees(np.diff(yaw)) / dt[1:]
    walk = rng.normal(0.0, config.gyro_bias_walk_dps_per_sqrt_s, n) * np.sqrt(dt)
    bias = config.gyro_bias_dps + np.cumsum(walk) - walk[0]
    noise = rng.normal(0.0, config.gyro_noise_dps, n)
    data["gyro_z_dps"] = rate_dps / (1.0 + config.gyro_scale_error) + bias + noise

    # GNSS epochs
    every = max(1, round(config.gnss_interval_s / float(np.median(dt))))
    is_epoch = (np.arange(n) % every) == 0
    in_outage = np.zeros(n, dtype=bool)
    for start, end in config.outages_s:
        in_outage |= (rel_t >= start) & (rel_t < end)
    fix = is_epoch & ~in_outage
    m = int(fix.sum())
    hdop = np.minimum(config.hdop_min + rng.exponential(config.hdop_scale, m), 3.0)
    sats = rng.integers(6, 13, m).astype(np.float64)
    bad = rng.uniform(size=m) < config.bad_fix_prob
    hdop[bad] = rng.uniform(5.0, 10.0, int(bad.sum()))
    sats[bad] = rng.integers(3, 5, int(bad.sum()))
    multi = (rng.uniform(size=m) < config.multipath_prob) & ~bad
    # Gauss-Markov error sampled at the fix times
    t_fix = t[fix]
    gm = np.zeros((m, 2))
    sigma = config.gnss_correlated_sigma_m
    if m:
        gm[0] = rng.normal(0.0, sigma, 2)
        for i in range(1, m):
            phi = math.exp(-(t_fix[i] - t_fix[i - 1]) / config.gnss_correlation_time_s)
            gm[i] = phi * gm[i - 1] + rng.normal(0.0, sigma * math.sqrt(1.0 - phi * phi), 2)
    err = rng.normal(0.0, 1.0, (m, 2)) * (config.gnss_uere_m * hdop)[:, None] + gm
    ang = rng.uniform(0.0, 2.0 * math.pi, int(multi.sum()))
    dist = rng.uniform(*config.multipath_offset_m, int(multi.sum()))
    err[multi, 0] += dist * np.cos(ang)
    err[multi, 1] += dist * np.sin(ang)
    lon_f, lat_f = ltp.to_lonlat(x[fix] + err[:, 0], y[fix] + err[:, 1])
    lon = np.full(n, np.nan)
    lat = np.full(n, np.nan)
    lon[fix], lat[fix] = lon_f, lat_f
    hd = np.full(n, np.nan)
    st = np.full(n, np.nan)
    hd[fix], st[fix] = hdop, sats
    data.update(lat=lat, lon=lon, hdop=hd, sats=st)
    if config.gnss_velocity:
        v_true = truth.speed_mps[fix]
        g_speed = np.maximum(v_true + rng.normal(0.0, config.gnss_speed_sigma_mps, m), 0.0)
        course_sigma = np.degrees(config.gnss_speed_sigma_mps / np.maximum(v_true, 0.1))
        course = np.mod(truth.heading_deg[fix] + rng.normal(0.0, 1.0, m) * course_sigma, 360.0)
        course[v_true < 0.5] = np.nan
        gs = np.full(n, np.nan)
        gc = np.full(n, np.nan)
        gs[fix], gc[fix] = g_speed, course
        data.update(gnss_speed_mps=gs, gnss_course_deg=gc)
    raw = RawLog.from_dataframe(
        pd.DataFrame(data), pulses_per_m=config.pulses_per_m, source="<simulated>"
    )
    multipath = np.zeros(n, dtype=bool)
    bad_fix = np.zeros(n, dtype=bool)
    multipath[np.flatnonzero(fix)[multi]] = True
    bad_fix[np.flatnonzero(fix)[bad]] = True
    sim = SimTruth(
        trajectory=truth,
        odo_scale=config.odo_scale,
        gyro_bias_dps=bias,
        gyro_scale=1.0 + config.gyro_scale_error,
        in_outage=in_outage,
        multipath=multipath,
        bad_fix=bad_fix,
    )
    return raw, sim
