"""The model inputs of every fix: position sigma, search radius, speed, travel, observations.

``fixes_of`` turns a validated trace into arrays in metres with what the model needs per fix:
its position sigma (the fix's accuracy, else ``sigma_m``), its search radius, its speed
(reported, else estimated from positions and times) and the distance the trace says it
travelled (:class:`~mapmatch.hmm.observations.Travel`); ``observe`` merges the fixes into the
HMM's observations and finds their candidates. Traces without an accuracy column may have a
larger position error than assumed: ``estimated_sigma_m`` measures it from the fixes.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from mapmatch.hmm.candidates import Candidates, find_candidates, search_radii
from mapmatch.hmm.observations import Observations, Travel, merge_fixes

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig
    from mapmatch.trace import Trace
    from mapmatch.types import FloatArray, IntArray
    from roadnets import RoadNetwork

__all__ = [
    "Fixes",
    "estimated_sigma_m",
    "fixes_of",
    "hold_limit_m",
    "observe",
    "reported_travel",
    "speed_from_positions",
    "with_sigma",
]


@dataclass(frozen=True, slots=True)
class Fixes:
    """
    A trace's fixes in metres with the per-fix model inputs.

    ``time_s`` is NaN throughout when the trace has no usable times; ``speed_mps`` the
    reported speed, else one estimated from positions and times (NaN when neither is known).
    """

    x: FloatArray
    y: FloatArray
    time_s: FloatArray
    sigma_m: FloatArray
    radius_m: FloatArray
    speed_mps: FloatArray
    heading_deg: FloatArray | None
    travel: Travel | None
    segment_starts: IntArray


def fixes_of(trace: Trace, x: FloatArray, y: FloatArray, config: MatchConfig) -> Fixes:
    """The model inputs of every fix: position sigma, search radius, speed and travel."""
    n = len(x)
    radius = search_radii(trace.accuracy_m, n, config)
    sigma = np.full(n, config.sigma_m)
    if trace.accuracy_m is not None:
        sigma = np.fmax(sigma, trace.accuracy_m)
    time_s = trace.time_s if trace.has_time else np.full(n, np.nan)
    dt = np.diff(time_s)
    speed = trace.speed_mps
    if speed is None:
        speed = speed_from_positions(np.hypot(np.diff(x), np.diff(y)), dt)
    return Fixes(
        x,
        y,
        time_s,
        sigma,
        radius,
        speed,
        trace.heading_deg,
        reported_travel(trace, dt, config),
        np.asarray(trace.segment_starts, dtype=np.int64),
    )


def reported_travel(trace: Trace, dt_s: FloatArray, config: MatchConfig) -> Travel | None:
    """
    How far the trace says the car went, from the odometer and the reported speeds.

    The speed is integrated over every step of the trace, fixes the model leaves out
    included, so a stop between two model fixes is seen. Each step's slack is what the
    trapezoid may miss: the speed may have changed by up to ``travel_accel_mps2`` in between
    (at most ``a * dt**2 / 4``) and each reported speed is off by up to
    ``travel_tolerance_mps`` (``* dt``). So the slack is small at 1 s (about 1 m a step) and
    grows quickly with sparse sampling, where speeds at the ends say little of the distance.
    ``None`` when ``use_travel`` is off or the trace has neither column.
    """
    if not config.use_travel or (trace.odometer_m is None and trace.speed_mps is None):
        return None
    speed_m = slack_m = unknown = None
    if trace.speed_mps is not None:
        v = trace.speed_mps
        step = 0.5 * (v[:-1] + v[1:]) * dt_s
        missing = ~np.isfinite(step)
        slack = config.travel_accel_mps2 * dt_s**2 / 4 + config.travel_tolerance_mps * dt_s
        speed_m = np.concatenate(([0.0], np.cumsum(np.where(missing, 0.0, step))))
        slack_m = np.concatenate(([0.0], np.cumsum(np.where(missing, 0.0, slack))))
        unknown = np.concatenate(([0], np.cumsum(missing))).astype(np.int64)
    return Travel(trace.odometer_m, speed_m, slack_m, unknown, unknown)


def speed_from_positions(step_m: FloatArray, dt_s: FloatArray) -> FloatArray:
    """Speed at each fix from the distance to its neighbours (NaN where times say nothing)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        v = np.where(dt_s > 0, step_m / dt_s, np.nan)
    if len(v) == 0:
        return np.full(1, np.nan)
    padded = np.concatenate(([v[0]], v, [v[-1]]))
    before, after = padded[:-1], padded[1:]
    known = np.isfinite(before).astype(np.float64) + np.isfinite(after)
    total = np.nan_to_num(before) + np.nan_to_num(after)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.asarray(np.where(known > 0, total / known, np.nan), dtype=np.float64)


def observe(net: RoadNetwork, fixes: Fixes, config: MatchConfig) -> tuple[Observations, Candidates]:
    """The HMM's observations of the fixes and their candidates."""
    obs = merge_fixes(
        fixes.x,
        fixes.y,
        fixes.time_s,
        fixes.sigma_m,
        fixes.radius_m,
        fixes.speed_mps,
        fixes.heading_deg,
        fixes.travel,
        config,
        fixes.segment_starts,
    )
    return obs, find_candidates(net, obs.x, obs.y, obs.radius_m, config)


def estimated_sigma_m(obs: Observations, cands: Candidates) -> float:
    """
    The trace's own position error, as Newson & Krumm estimate it.

    1.4826 x the median distance of its fixes to the nearest road (the median absolute
    deviation of a Gaussian). Only observations of one fix count (a merged one averages its
    noise away), and only when they are most of the trace's, at least 10: where fixes merge,
    the single ones are those that stood out, and their median would overstate the noise.
    NaN otherwise.
    """
    has = cands.counts > 0
    single = has & (obs.stop - obs.first == 1)
    if single.sum() < max(10, 0.5 * has.sum()):
        return float("nan")
    nearest = cands.distance_m[cands.ptr[:-1][single]]  # rows of a fix are nearest first
    return float(1.4826 * np.median(nearest))


def with_sigma(fixes: Fixes, sigma_m: float, config: MatchConfig) -> Fixes:
    """The fixes with a larger position sigma and the search radius that goes with it."""
    wide = min(config.radius_accuracy_factor * sigma_m, config.max_search_radius_m)
    return dataclasses.replace(
        fixes,
        sigma_m=np.fmax(fixes.sigma_m, sigma_m),
        radius_m=np.fmax(fixes.radius_m, wide),
    )


def hold_limit_m(fixes: Fixes, config: MatchConfig) -> float:
    """How far behind the path's front a fix may scatter and still be a held car's."""
    return float(max(config.standstill_m, config.standstill_sigmas * fixes.sigma_m.max()))
