"""``fuse``: raw GNSS + odometer + gyro log in, fused positions and distance out."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from mapmatch.fusion.calibration import rls_odometer_scale
from mapmatch.fusion.config import FusionConfig
from mapmatch.fusion.ekf import FIX_GATED, FIX_USED, NO_FIX, PARAM_NAMES, run_filter
from mapmatch.fusion.errors import NoGnssFixError
from mapmatch.fusion.geo import LocalTangentPlane
from mapmatch.fusion.track import FusedTrack

if TYPE_CHECKING:
    import numpy.typing as npt

    from mapmatch.fusion.feedback import RoadFeedback
    from mapmatch.fusion.rawlog import RawLog

    FloatArray = npt.NDArray[np.float64]

__all__ = ["fuse"]


def fuse(
    raw: RawLog, config: FusionConfig | None = None, *, road_feedback: RoadFeedback | None = None
) -> FusedTrack:
    """
    Fuse a raw GNSS/odometer/gyro log into positions, heading, speed and distance.

    A loosely coupled extended Kalman filter (see :mod:`mapmatch.fusion.ekf`) dead-reckons
    from odometer speed and gyro yaw rate, corrects with GNSS fixes that pass the quality gate
    (satellites, HDOP) and the chi-square innovation test, estimates odometer scale, gyro bias
    and gyro scale online, holds still when the odometer says the vehicle is stopped, and
    optionally takes matched road positions as pseudo-measurements.

    Parameters
    ----------
    raw
        A validated raw log (:meth:`RawLog.from_file` / :meth:`RawLog.from_dataframe`).
    config
        Filter parameters; defaults when None.
    road_feedback
        Matched road positions to feed back (applied only where GNSS has been absent for
        ``config.road_feedback_min_gnss_gap_s``).

    Returns
    -------
    FusedTrack
        One entry per sensor epoch from the first usable GNSS fix on.

    Raises
    ------
    NoGnssFixError
        No fix passes the quality gate.
    """
    cfg = config or FusionConfig()
    n = len(raw)
    t = raw.time_s
    dt = np.empty(n)
    dt[1:] = np.diff(t)
    dt[0] = dt[1] if n > 1 else 0.1
    has_fix = raw.has_fix
    quality_ok = has_fix & ~(raw.sats < cfg.min_sats) & ~(raw.hdop > cfg.max_hdop)
    candidates = np.flatnonzero(quality_ok)
    if candidates.size == 0:
        detail = f"{int(has_fix.sum())} fix(es), none with sats >= {cfg.min_sats}"
        detail += f" and hdop <= {cfg.max_hdop:g}"
        raise NoGnssFixError(raw.source, detail)
    ltp = LocalTangentPlane(float(raw.lon[candidates[0]]), float(raw.lat[candidates[0]]))
    fx, fy = ltp.to_xy(raw.lon, raw.lat)
    hdop = np.where(np.isfinite(raw.hdop), raw.hdop, 1.0)
    fsig = cfg.gnss_uere_m * np.maximum(hdop, 0.5)
    fix_state = np.where(quality_ok, FIX_USED, np.where(has_fix, FIX_GATED, NO_FIX))
    fix_state = fix_state.astype(np.int8)
    gyro = np.radians(raw.gyro_z_dps)
    odo = raw.odo_speed_mps
    gyaw = np.radians(90.0 - raw.gnss_course_deg)
    stopped = _stopped_mask(odo, dt, cfg)
    i0, yaw0, yaw_sigma = _initial_heading(raw, fx, fy, fsig, fix_state, odo, gyro, dt, cfg)
    fix_state[:i0] = np.where(fix_state[:i0] == FIX_USED, NO_FIX, fix_state[:i0])

    s0 = cfg.initial_odo_scale
    x0 = np.array([fx[i0], fy[i0], yaw0, odo[i0] / s0, 0.0, s0, 0.0])
    p0 = np.diag(
        [
            fsig[i0] ** 2,
            fsig[i0] ** 2,
            yaw_sigma**2,
            1.0,
            math.radians(cfg.gyro_bias_sigma_dps) ** 2,
            cfg.odo_scale_sigma**2,
            cfg.gyro_scale_sigma**2 if cfg.estimate_gyro_scale else 0.0,
        ]
    )
    fb = _feedback_arrays(road_feedback, t, dt, ltp)
    states, pdiag, ppos, status, fb_used, dist = run_filter(
        t, odo, gyro, stopped, fix_state, fx, fy, fsig,
        raw.gnss_speed_mps, gyaw, *fb, i0, x0, p0, _params(cfg, raw, dt),
    )  # fmt: skip

    sl = slice(i0, n)
    lon, lat = ltp.to_lonlat(states[sl, 0], states[sl, 1])
    yaw = states[sl, 2]
    rls = rls_odometer_scale(
        t[sl],
        odo[sl],
        yaw,
        fx[sl],
        fy[sl],
        status[sl] == FIX_USED,
        stretch_m=cfg.rls_stretch_m,
        max_gap_s=cfg.rls_max_gap_s,
        forgetting=cfg.rls_forgetting,
    )
    pxx, pxy, pyy = ppos[sl, 0], ppos[sl, 1], ppos[sl, 2]
    lam_max = 0.5 * (pxx + pyy) + np.sqrt(0.25 * (pxx - pyy) ** 2 + pxy**2)
    return FusedTrack(
        time_s=t[sl].copy(),
        lon=lon,
        lat=lat,
        heading_deg=np.mod(90.0 - np.degrees(yaw), 360.0),
        speed_mps=np.maximum(states[sl, 3], 0.0),
        accuracy_m=np.sqrt(lam_max),
        odometer_m=dist[sl],
        odo_scale=states[sl, 5],
        odo_scale_sigma=np.sqrt(pdiag[sl, 5]),
        gyro_bias_dps=np.degrees(states[sl, 4]),
        gyro_scale=1.0 + states[sl, 6],
        odo_scale_rls=rls,
        gnss_status=status[sl],
        road_feedback_used=fb_used[sl],
        first_row=int(i0),
    )


def _params(cfg: FusionConfig, raw: RawLog, dt: FloatArray) -> FloatArray:
    r_odo = cfg.odo_speed_sigma_mps**2
    if raw.pulses_per_m is not None:
        # pulse quantisation: one pulse over a typical interval, uniform error
        r_odo += (1.0 / (raw.pulses_per_m * float(np.median(dt)))) ** 2 / 12.0
    values = {
        "q_pos": cfg.position_walk_m_per_sqrt_s**2,
        "q_yaw": math.radians(cfg.gyro_arw_deg_per_sqrt_s) ** 2,
        "q_speed": cfg.accel_sigma_mps2**2,
        "q_bias": math.radians(cfg.gyro_bias_walk_dps_per_sqrt_s) ** 2,
        "q_odo_scale": cfg.odo_scale_walk_per_sqrt_s**2,
        "q_gyro_scale": 1e-10 if cfg.estimate_gyro_scale else 0.0,
        "r_odo": r_odo,
        "r_zupt": cfg.zupt_sigma_mps**2,
        "chi2_pos": cfg.chi2_gate_position,
        "max_rejects": float(cfg.max_consecutive_rejects),
        "sigma_gnss_speed": cfg.gnss_speed_sigma_mps,
        "course_floor": math.radians(cfg.gnss_course_sigma_floor_deg),
        "min_course_speed": cfg.min_course_speed_mps,
        "chi2_vel": cfg.chi2_gate_velocity,
        "sigma_road_yaw": math.radians(cfg.road_heading_sigma_deg),
        "road_min_gap": cfg.road_feedback_min_gnss_gap_s,
        "chi2_road": cfg.chi2_gate_road,
    }
    return np.array([values[name] for name in PARAM_NAMES])


def _stopped_mask(odo: FloatArray, dt: FloatArray, cfg: FusionConfig) -> npt.NDArray[np.bool_]:
    """Epochs where the odometer has read (near) zero for the whole ZUPT window."""
    moving = (np.abs(odo) > cfg.zupt_speed_mps).astype(np.int64)
    w = max(1, round(cfg.zupt_window_s / float(np.median(dt))))
    csum = np.concatenate(([0], np.cumsum(moving)))
    idx = np.arange(odo.shape[0])
    lo = np.maximum(idx + 1 - w, 0)
    return np.asarray((csum[idx + 1] - csum[lo]) == 0)


def _initial_heading(
    raw: RawLog,
    fx: FloatArray,
    fy: FloatArray,
    fsig: FloatArray,
    fix_state: npt.NDArray[np.int8],
    odo: FloatArray,
    gyro: FloatArray,
    dt: FloatArray,
    cfg: FusionConfig,
) -> tuple[int, float, float]:
    """
    Choose the first epoch and its heading (radians CCW from east) with a 1-sigma.

    The start is the first quality fix that agrees with the next one within a few sigma of
    the odometer distance (so a multipath jump does not seed the filter). The heading is the
    receiver course when the vehicle is fast enough, else the rotation that aligns the
    dead-reckoned path (raw gyro, raw odometer) with the GNSS displacement once the vehicle
    is ``heading_init_baseline_m`` away ([DR] 4.2: heading only from GNSS at speed).
    """
    cand = np.flatnonzero(fix_state == FIX_USED)
    step = odo * dt
    step[0] = 0.0
    cum = np.cumsum(step)
    ok = np.ones(cand.size, dtype=bool)  # agrees with the next quality fix
    ok_prev = np.ones(cand.size, dtype=bool)  # agrees with the previous one
    if cand.size > 1:
        d_gnss = np.hypot(np.diff(fx[cand]), np.diff(fy[cand]))
        d_odo = np.abs(np.diff(cum[cand]))
        tol = 4.0 * np.hypot(fsig[cand[1:]], fsig[cand[:-1]]) + 0.1 * d_odo
        ok[:-1] = np.abs(d_gnss - d_odo) <= tol
        ok_prev[1:] = ok[:-1]
    i0 = int(cand[np.argmax(ok)])
    course_speed = raw.gnss_speed_mps[i0]
    if np.isfinite(raw.gnss_course_deg[i0]) and course_speed >= cfg.min_course_speed_mps:
        floor = math.radians(cfg.gnss_course_sigma_floor_deg)
        sig = 3.0 * max(cfg.gnss_speed_sigma_mps / float(course_speed), floor)
        return i0, math.radians(90.0 - float(raw.gnss_course_deg[i0])), sig
    yaw_rel = np.cumsum(gyro * dt)
    yaw_mid = yaw_rel - 0.5 * gyro * dt
    px = np.cumsum(step * np.cos(yaw_mid))
    py = np.cumsum(step * np.sin(yaw_mid))
    later = cand[(cand > i0) & ok_prev]
    if later.size:
        dist = np.hypot(fx[later] - fx[i0], fy[later] - fy[i0])
        far = np.flatnonzero(dist >= cfg.heading_init_baseline_m)
        if far.size:
            j = int(later[far[0]])
            gnss_dir = math.atan2(fy[j] - fy[i0], fx[j] - fx[i0])
            dr_dir = math.atan2(py[j] - py[i0], px[j] - px[i0])
            yaw0 = gnss_dir - dr_dir + float(yaw_rel[i0])
            sig = math.atan2(2.0 * math.hypot(fsig[i0], fsig[j]), float(dist[far[0]]))
            return i0, yaw0, sig + 0.05
    return i0, 0.0, math.pi


def _feedback_arrays(
    fb: RoadFeedback | None, t: FloatArray, dt: FloatArray, ltp: LocalTangentPlane
) -> tuple[npt.NDArray[np.bool_], FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    n = t.shape[0]
    has = np.zeros(n, dtype=bool)
    arrays = [np.full(n, np.nan) for _ in range(5)]
    if fb is None or len(fb) == 0:
        return has, arrays[0], arrays[1], arrays[2], arrays[3], arrays[4]
    idx = np.clip(np.searchsorted(t, fb.time_s), 1, n - 1)
    nearer_prev = np.abs(fb.time_s - t[idx - 1]) < np.abs(fb.time_s - t[idx])
    idx = np.where(nearer_prev, idx - 1, idx)
    close = np.abs(fb.time_s - t[idx]) <= 0.5 * dt[idx] + 1e-9
    idx = idx[close]
    x, y = ltp.to_xy(fb.lon[close], fb.lat[close])
    has[idx] = True
    arrays[0][idx] = x
    arrays[1][idx] = y
    arrays[2][idx] = np.radians(90.0 - fb.road_heading_deg[close])
    arrays[3][idx] = fb.along_sigma_m[close]
    arrays[4][idx] = fb.cross_sigma_m[close]
    return has, arrays[0], arrays[1], arrays[2], arrays[3], arrays[4]
