"""
How a simulated trip is observed: fix times and outages, position noise, canyons, sensors.

Positions get Gaussian noise, white or AR(1)-correlated in time, outliers displaced in a random
direction and urban-canyon stretches pulled to one side of the road; GNSS outages take fixes
away; heading (noisier when slow) and speed get their own noise and the odometer a scale error.

Two random streams: ``rng`` draws what the older options always drew, in the order they always
drew it (so their trips stay as they were), ``extra`` the realistic options' stretches.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from mapmatch.evaluation.simulate.columns import strip_to_class
from mapmatch.evaluation.simulate.truth import EPOCH_S, TruthEvent, fixes_inside
from mapmatch.trace import Trace

if TYPE_CHECKING:
    from mapmatch.evaluation.simulate.config import SimulationConfig
    from mapmatch.evaluation.simulate.motion import Drive
    from mapmatch.types import FloatArray
    from roadnets import RoadNetwork

__all__ = ["Observation", "Span", "observe"]

#: A stretch of a trip: ``(start_s, end_s, distance_m)``, trip-relative seconds.
Span = tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class Observation:
    """
    What the receiver and the sensors reported of one drive, and the truth at each fix.

    ``trace`` the observed trace (epoch seconds, columns of ``cfg.input_class``);
    ``time_s`` its fixes' trip-relative times, ``distance_m`` the true distance along the
    route and ``true_x``/``true_y`` the true position (projected metres) at each;
    ``odometer_scale`` the odometer's factor; ``canyons`` the canyon stretches that have a
    fix (trip-relative times); ``outages`` every outage, the older per-minute ones first.
    """

    trace: Trace
    time_s: FloatArray
    distance_m: FloatArray
    true_x: FloatArray
    true_y: FloatArray
    odometer_scale: float
    canyons: list[TruthEvent]
    outages: list[Span]


def observe(
    net: RoadNetwork,
    drive: Drive,
    cfg: SimulationConfig,
    rng: np.random.Generator,
    extra: np.random.Generator,
    *,
    trace_id: str,
) -> Observation:
    """Sample ``drive`` every ``cfg.interval_s`` and observe it with ``cfg``'s errors."""
    sample_t, canyon_spans, canyon_sides, outages = _fix_times(drive, cfg, rng, extra)
    s = np.interp(sample_t, drive.dense_t, drive.dense_s)
    true_x, true_y = np.interp(s, drive.s_vert, drive.x), np.interp(s, drive.s_vert, drive.y)
    true_v = np.interp(sample_t, drive.dense_t, drive.dense_v)
    true_heading = _interp_angle(sample_t, drive.dense_t, drive.dense_heading)
    noise = _position_noise(rng, sample_t, cfg)
    outlier = rng.random(len(s)) < cfg.outlier_rate
    angle = rng.uniform(0, 2 * np.pi, len(s))
    obs_x = true_x + noise[:, 0] + outlier * cfg.outlier_m * np.sin(angle)
    obs_y = true_y + noise[:, 1] + outlier * cfg.outlier_m * np.cos(angle)
    canyons: list[TruthEvent] = []
    for (start, end, at), side in zip(canyon_spans, canyon_sides, strict=True):
        inside = (sample_t >= start) & (sample_t <= end)
        right = np.radians(true_heading[inside] + 90.0 * side)  # driving direction +- 90 deg
        obs_x[inside] += cfg.canyon_bias_m * np.sin(right)
        obs_y[inside] += cfg.canyon_bias_m * np.cos(right)
        first_fix, last_fix = fixes_inside(sample_t, start, end)
        canyons.append(
            TruthEvent("canyon", start, end, first_fix, last_fix, at, side, cfg.canyon_bias_m)
        )
    lon, lat = net.unproject(obs_x, obs_y)
    heading_sigma = cfg.heading_noise_deg + cfg.heading_noise_slow_deg * np.exp(-true_v)
    heading = (true_heading + rng.normal(0, 1, len(s)) * heading_sigma) % 360.0
    speed = np.maximum(true_v + rng.normal(0, cfg.speed_noise_mps, len(s)), 0.0)
    scale = 1.0 + cfg.odometer_bias
    scale += float(rng.uniform(-cfg.odometer_scale_error, cfg.odometer_scale_error))
    odometer = s * scale
    full = Trace(
        time=sample_t + EPOCH_S,
        lon=lon,
        lat=lat,
        heading=heading,
        speed=speed,
        accuracy=np.full(len(s), max(cfg.noise_m, 1.0)),
        odometer=odometer,
        trace_id=trace_id,
    )
    trace = strip_to_class(full, cfg.input_class) if cfg.input_class != "odometer" else full
    return Observation(
        trace=trace,
        time_s=sample_t,
        distance_m=s,
        true_x=true_x,
        true_y=true_y,
        odometer_scale=scale,
        canyons=canyons,
        outages=outages,
    )


def _fix_times(
    drive: Drive, cfg: SimulationConfig, rng: np.random.Generator, extra: np.random.Generator
) -> tuple[FloatArray, list[Span], list[int], list[Span]]:
    """
    The fixes' times with the outages cut out; the canyon stretches, their sides, the outages.

    Stretches that begin after the last fix are left out; an outage must end before it. The
    trip's first fix is always seen.
    """
    sample_t = np.arange(0.0, drive.dense_t[-1], cfg.interval_s)
    canyon_spans = _events_along(extra, cfg.canyon_per_km, cfg.canyon_s, drive)
    canyon_sides = [1 if extra.random() < 0.5 else -1 for _ in canyon_spans]
    seen = [c[0] < sample_t[-1] for c in canyon_spans]
    canyon_spans = [c for c, ok in zip(canyon_spans, seen, strict=True) if ok]
    canyon_sides = [d for d, ok in zip(canyon_sides, seen, strict=True) if ok]
    outage_spans = _events_along(extra, cfg.outage_per_km, cfg.outage_range_s, drive)
    outage_spans = [o for o in outage_spans if o[1] < sample_t[-1]]
    keep = np.ones(len(sample_t), dtype=bool)
    legacy_outages: list[Span] = []
    if cfg.outage_rate > 0:
        for start in sample_t[rng.random(len(sample_t)) < cfg.outage_rate * cfg.interval_s / 60]:
            keep &= ~((sample_t > start) & (sample_t <= start + cfg.outage_s))
            legacy_outages.append(
                (float(start), float(start) + cfg.outage_s, drive.distance_at(start))
            )
    if outage_spans:
        dark = np.zeros(len(sample_t), dtype=bool)
        for start, end, _ in outage_spans:
            dark |= (sample_t > start) & (sample_t < end)
        dark[0] = False  # the trip's first fix is always seen
        keep &= ~dark
    return sample_t[keep], canyon_spans, canyon_sides, legacy_outages + outage_spans


def _events_along(
    rng: np.random.Generator, per_km: float, duration_s: tuple[float, float], drive: Drive
) -> list[Span]:
    """
    Stretches placed along the route as a Poisson process: ``(start_s, end_s, distance_m)``.

    Starts are ``per_km`` per km of road apart on average (exponential gaps, counted from the
    end of the previous stretch, so stretches never overlap); each lasts a duration drawn
    uniformly from ``duration_s``.
    """
    out: list[Span] = []
    if per_km <= 0:
        return out
    at = 0.0
    while True:
        at += float(rng.exponential(1000.0 / per_km))
        if at >= drive.total_m:
            return out
        start = drive.arrive_s(at)
        end = start + float(rng.uniform(*duration_s))
        out.append((start, end, at))
        at = drive.distance_at(end)


def _interp_angle(t: FloatArray, tp: FloatArray, deg: FloatArray) -> FloatArray:
    """Angles ``deg`` (degrees) at ``tp`` interpolated at ``t`` along the shorter way round."""
    rad = np.radians(deg)
    s = np.interp(t, tp, np.sin(rad))
    c = np.interp(t, tp, np.cos(rad))
    return np.degrees(np.arctan2(s, c)) % 360.0


def _position_noise(rng: np.random.Generator, t: FloatArray, cfg: SimulationConfig) -> FloatArray:
    """
    Position error per axis at times ``t``, metres: white, or AR(1) with time constant tau.

    The stationary std is ``cfg.noise_m`` whatever the correlation and the gaps between fixes:
    ``e[i] = rho e[i-1] + sqrt(1 - rho^2) w[i]`` with ``rho = exp(-dt / tau)``.
    """
    white = rng.normal(0.0, cfg.noise_m, (len(t), 2))
    tau = cfg.correlation_time_s
    if tau <= 0 or len(t) < 2:
        return white
    noise = np.empty_like(white)
    noise[0] = white[0]
    rho = np.exp(-np.diff(t) / tau)
    for i in range(1, len(t)):
        noise[i] = rho[i - 1] * noise[i - 1] + np.sqrt(1 - rho[i - 1] ** 2) * white[i]
    return noise
