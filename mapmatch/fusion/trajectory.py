"""
True vehicle trajectories for the raw-log simulator.

:class:`TrueTrajectory` is the contract between whoever makes ground truth (these builders, or
later random routes on real OSM networks in ``mapmatch.evaluation.simulate``) and
:func:`~mapmatch.fusion.simulate_raw_log`. The builders here drive a car along straight and
circular legs with stops, with bounded acceleration, on a local tangent plane.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from mapmatch.fusion.geo import LocalTangentPlane

if TYPE_CHECKING:
    from collections.abc import Sequence

    import numpy.typing as npt

    FloatArray = npt.NDArray[np.float64]

__all__ = ["Leg", "TrueTrajectory", "build_trajectory", "stop", "straight", "turn"]


@dataclass(frozen=True, slots=True, eq=False)
class TrueTrajectory:
    """
    Dense (typically 10 Hz) ground truth of a drive.

    Attributes
    ----------
    time_s
        Seconds (any epoch), strictly increasing, evenly spaced.
    lon, lat
        WGS84 degrees.
    heading_deg
        Degrees clockwise from north, in [0, 360).
    speed_mps
        Speed at each epoch, m/s.
    distance_m
        Cumulative distance driven, metres (0 at the first epoch).
    """

    time_s: FloatArray
    lon: FloatArray
    lat: FloatArray
    heading_deg: FloatArray
    speed_mps: FloatArray
    distance_m: FloatArray

    def __len__(self) -> int:
        return int(self.time_s.shape[0])

    @property
    def length_m(self) -> float:
        """Total distance driven, metres."""
        return float(self.distance_m[-1] - self.distance_m[0])


@dataclass(frozen=True, slots=True)
class Leg:
    """One piece of a drive: a straight, a circular turn or a stop. Use the helpers."""

    kind: Literal["straight", "turn", "stop"]
    length_m: float = 0.0
    turn_deg: float = 0.0
    speed_mps: float = 0.0
    duration_s: float = 0.0


def straight(length_m: float, speed_mps: float) -> Leg:
    """Drive ``length_m`` straight ahead at up to ``speed_mps``."""
    return Leg("straight", length_m=length_m, speed_mps=speed_mps)


def turn(angle_deg: float, radius_m: float, speed_mps: float) -> Leg:
    """Turn ``angle_deg`` (positive = left) on a circle of ``radius_m`` at up to ``speed_mps``."""
    return Leg(
        "turn",
        length_m=abs(math.radians(angle_deg)) * radius_m,
        turn_deg=angle_deg,
        speed_mps=speed_mps,
    )


def stop(duration_s: float) -> Leg:
    """Brake to a halt and stand still for ``duration_s`` (a red light)."""
    return Leg("stop", duration_s=duration_s)


def build_trajectory(
    legs: Sequence[Leg],
    *,
    origin_lon: float,
    origin_lat: float,
    start_heading_deg: float = 90.0,
    start_time_s: float = 0.0,
    dt_s: float = 0.1,
    accel_mps2: float = 1.5,
    decel_mps2: float = 2.0,
    initial_wait_s: float = 5.0,
) -> TrueTrajectory:
    """
    Drive the legs from rest and return the dense true trajectory.

    The car starts standing for ``initial_wait_s`` at the origin heading
    ``start_heading_deg`` (clockwise from north), accelerates at ``accel_mps2`` up to each leg's
    speed, brakes at ``decel_mps2`` for stops, slower legs and the end of the drive.

    Examples
    --------
    >>> tr = build_trajectory([straight(200.0, 10.0)], origin_lon=116.4, origin_lat=39.9)
    >>> round(tr.length_m, 3), round(float(tr.heading_deg[-1]), 6)
    (200.0, 90.0)
    """
    # geometry pieces: start s, length, curvature, speed; stops at s positions
    starts: list[float] = []
    lengths: list[float] = []
    curv: list[float] = []
    speeds: list[float] = []
    stops: list[tuple[float, float]] = []
    s_total = 0.0
    for leg in legs:
        if leg.kind == "stop":
            stops.append((s_total, leg.duration_s))
            continue
        starts.append(s_total)
        lengths.append(float(leg.length_m))
        curv.append(math.radians(leg.turn_deg) / leg.length_m if leg.kind == "turn" else 0.0)
        speeds.append(float(leg.speed_mps))
        s_total += leg.length_m
    stops.append((s_total, 0.0))
    # speed limit along s, with braking envelopes before slower pieces and stops
    ds = 0.25
    grid = np.arange(0.0, s_total + ds, ds)
    piece = np.clip(np.searchsorted(np.array(starts), grid, side="right") - 1, 0, None)
    vmax = np.array(speeds, dtype=np.float64)[piece]
    for s_stop, _ in stops:
        vmax[np.argmin(np.abs(grid - s_stop))] = 0.0
    vlim = vmax.copy()
    for i in range(grid.size - 2, -1, -1):
        vlim[i] = min(vlim[i], math.sqrt(vlim[i + 1] ** 2 + 2.0 * decel_mps2 * ds))
    # drive in time with 10 substeps per output epoch
    sub = 10
    h = dt_s / sub
    out_s: list[float] = []
    out_v: list[float] = []
    s = 0.0
    v = 0.0
    n_wait = round(initial_wait_s / dt_s)
    out_s += [0.0] * n_wait
    out_v += [0.0] * n_wait
    stop_i = 0
    if stops and stops[0][0] <= 0.0 and len(stops) > 1:
        stop_i = 1
    step = 0
    while True:
        s_stop, wait = stops[stop_i]
        if s >= s_stop - 1e-9:
            s = s_stop
            v = 0.0
            if stop_i == len(stops) - 1:
                break
            for _ in range(round(wait / dt_s)):
                out_s.append(s)
                out_v.append(0.0)
            stop_i += 1
            step = 0
            continue
        ahead = min(s + v * h + 0.5 * ds, s_total)
        limit = float(np.interp(ahead, grid, vlim))
        v_new = min(v + accel_mps2 * h, limit)
        if s_stop - s < 1.0:
            v_new = max(v_new, 0.3)
        s = min(s + 0.5 * (v + v_new) * h, s_stop)
        v = v_new
        step += 1
        if step % sub == 0:
            out_s.append(s)
            out_v.append(v)
    out_s.append(s_total)
    out_v.append(0.0)
    s_arr = np.array(out_s)
    x, y, yaw = _pose_at(s_arr, starts, lengths, curv, math.radians(90.0 - start_heading_deg))
    ltp = LocalTangentPlane(origin_lon, origin_lat)
    lon, lat = ltp.to_lonlat(x, y)
    return TrueTrajectory(
        time_s=np.asarray(start_time_s + dt_s * np.arange(s_arr.size), dtype=np.float64),
        lon=lon,
        lat=lat,
        heading_deg=np.mod(90.0 - np.degrees(yaw), 360.0),
        speed_mps=np.array(out_v),
        distance_m=s_arr,
    )


def _pose_at(
    s: FloatArray, starts: list[float], lengths: list[float], curv: list[float], yaw0: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Exact position and yaw (CCW from east) at arc lengths ``s`` along the pieces."""
    k = np.array(curv)
    length = np.array(lengths)
    x0 = np.zeros(k.size)
    y0 = np.zeros(k.size)
    psi0 = np.zeros(k.size)
    x, y, psi = 0.0, 0.0, yaw0
    for i in range(k.size):
        x0[i], y0[i], psi0[i] = x, y, psi
        dx, dy = _advance(psi, float(k[i]), float(length[i]))
        x, y, psi = x + dx, y + dy, psi + float(k[i] * length[i])
    idx = np.clip(np.searchsorted(np.array(starts), s, side="right") - 1, 0, k.size - 1)
    u = s - np.array(starts)[idx]
    ki = k[idx]
    p0 = psi0[idx]
    straight_ = np.abs(ki) < 1e-12
    safe_k = np.where(straight_, 1.0, ki)
    dx = np.where(straight_, u * np.cos(p0), (np.sin(p0 + ki * u) - np.sin(p0)) / safe_k)
    dy = np.where(straight_, u * np.sin(p0), -(np.cos(p0 + ki * u) - np.cos(p0)) / safe_k)
    return x0[idx] + dx, y0[idx] + dy, p0 + ki * u


def _advance(psi: float, k: float, length: float) -> tuple[float, float]:
    if abs(k) < 1e-12:
        return length * math.cos(psi), length * math.sin(psi)
    return (
        (math.sin(psi + k * length) - math.sin(psi)) / k,
        -(math.cos(psi + k * length) - math.cos(psi)) / k,
    )
