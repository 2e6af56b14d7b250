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
from numba import njit

from mapmatch.frozen import quick_init
from mapmatch.hmm.candidates import (
    Candidates,
    find_candidates,
    radius_of_sigma,
    sigma_radius_kernel,
)
from mapmatch.hmm.observations import Observations, Travel, merge_fixes, sigma_of_distances
from mapmatch.readonly import EMPTY_FLOAT, kernel_array, kernel_column, read_only

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
    "observations_of",
    "observe",
    "reported_travel",
    "speed_from_positions",
    "with_sigma",
]


@quick_init
@dataclass(frozen=True, slots=True)
class Fixes:
    """
    A trace's fixes in metres with the per-fix model inputs, every array read-only.

    ``time_s`` is NaN throughout when the trace has no usable times; ``speed_mps`` the
    reported speed, else one estimated from positions and times (NaN when neither is known);
    ``sigma_max_m`` the largest ``sigma_m``.
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
    sigma_max_m: float


def fixes_of(trace: Trace, x: FloatArray, y: FloatArray, config: MatchConfig) -> Fixes:
    """
    The model inputs of every fix: position sigma, search radius, speed and travel.

    Every array is read-only (:mod:`mapmatch.readonly`): a trace's columns are, and so the
    arrays computed or standing in for a missing column are made, so that the kernels that
    read them have one compiled variant whichever columns a trace has.
    """
    n = len(x)
    x, y = kernel_array(x), kernel_array(y)
    accuracy = kernel_column(trace.accuracy_m, EMPTY_FLOAT)
    time_s = kernel_array(trace.time_s if trace.has_time else np.full(n, np.nan))
    speeds = trace.speed_mps
    reported = None if speeds is None else kernel_array(speeds)
    travel_on = config.use_travel and (trace.odometer_m is not None or reported is not None)
    sigma, sigma_max, radius, speed, speed_m, slack_m, unknown = _fixes_kernel(
        x,
        y,
        time_s,
        accuracy,
        EMPTY_FLOAT if reported is None else reported,
        travel_on and reported is not None,
        float(config.sigma_m),
        float(config.search_radius_m),
        float(config.radius_accuracy_factor),
        float(config.max_search_radius_m),
        float(config.travel_accel_mps2),
        float(config.travel_tolerance_mps),
    )
    travel = None
    if travel_on:
        known = reported is not None
        unknown = read_only(unknown)
        travel = Travel(
            None if trace.odometer_m is None else read_only(trace.odometer_m),
            read_only(speed_m) if known else None,
            read_only(slack_m) if known else None,
            unknown if known else None,
            unknown if known else None,
        )
    heading = trace.heading_deg
    return Fixes(
        x,
        y,
        time_s,
        read_only(sigma),
        read_only(radius),
        read_only(speed) if reported is None else reported,
        None if heading is None else read_only(heading),
        travel,
        read_only(np.asarray(trace.segment_starts, dtype=np.int64)),
        float(sigma_max),
    )


@njit(cache=True, nogil=True)
def _fixes_kernel(  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    x, y, time_s, accuracy, reported, integrate, sigma_m, radius_m, factor, max_radius, accel, tol
):
    """
    Sigma (and the largest), search radius and speed of every fix, and the speed integral.

    What :func:`search_radii`, :func:`speed_from_positions` and :func:`reported_travel` give,
    in one call; ``accuracy`` and ``reported`` are empty when the trace has no such column.
    """
    n = len(x)
    sigma, radius = sigma_radius_kernel(n, accuracy, sigma_m, radius_m, factor, max_radius)
    dt = np.empty(max(n - 1, 0))
    for i in range(n - 1):
        dt[i] = time_s[i + 1] - time_s[i]
    speed = np.empty(0)
    if not len(reported):
        step = np.empty(len(dt))
        for i in range(n - 1):
            step[i] = np.hypot(x[i + 1] - x[i], y[i + 1] - y[i])
        speed = _speeds(step, dt)
    if integrate:
        speed_m, slack_m, unknown = _integrate(reported, dt, accel, tol)
    else:
        speed_m, slack_m, unknown = np.empty(0), np.empty(0), np.empty(0, dtype=np.int64)
    return sigma, sigma.max() if n else np.nan, radius, speed, speed_m, slack_m, unknown


@njit(cache=True, nogil=True)
def _speeds(step, dt):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """Speed at each fix: the mean of the steps' speeds before and after it (NaN: unknown)."""
    m = len(step)
    big = np.finfo(np.float64).max
    speed = np.full(max(m + 1, 1), np.nan)
    v = np.empty(m)
    for i in range(m):
        v[i] = step[i] / dt[i] if dt[i] > 0 else np.nan
    for i in range(m + 1 if m else 0):
        before = v[i - 1] if i > 0 else v[0]
        after = v[i] if i < m else v[m - 1]
        known = (1.0 if np.isfinite(before) else 0.0) + (1.0 if np.isfinite(after) else 0.0)
        total = _nan_to_num(before, big) + _nan_to_num(after, big)
        speed[i] = total / known if known > 0 else np.nan
    return speed


@njit(cache=True, nogil=True)
def _integrate(reported, dt, accel, tol):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Running trapezoid integral of the speeds, its slack and the steps it could not take."""
    n = len(reported)
    speed_m = np.zeros(n)
    slack_m = np.zeros(n)
    unknown = np.zeros(n, dtype=np.int64)
    for i in range(1, n):
        d = dt[i - 1]
        step = 0.5 * (reported[i - 1] + reported[i]) * d
        if np.isfinite(step):
            speed_m[i] = speed_m[i - 1] + step
            slack_m[i] = slack_m[i - 1] + (accel * d**2 / 4 + tol * d)
            unknown[i] = unknown[i - 1]
        else:
            speed_m[i] = speed_m[i - 1]
            slack_m[i] = slack_m[i - 1]
            unknown[i] = unknown[i - 1] + 1
    return speed_m, slack_m, unknown


@njit(cache=True, nogil=True, inline="always")
def _nan_to_num(v, big):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """``np.nan_to_num`` of one value."""
    if np.isnan(v):
        return 0.0
    if v == np.inf:
        return big
    if v == -np.inf:
        return -big
    return v


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
    if trace.speed_mps is None:
        return Travel(trace.odometer_m, None, None, None, None)
    speed_m, slack_m, unknown = _integrate(
        np.ascontiguousarray(trace.speed_mps, np.float64),
        np.ascontiguousarray(dt_s, np.float64),
        float(config.travel_accel_mps2),
        float(config.travel_tolerance_mps),
    )
    return Travel(trace.odometer_m, speed_m, slack_m, unknown, unknown)


def speed_from_positions(step_m: FloatArray, dt_s: FloatArray) -> FloatArray:
    """Speed at each fix from the distance to its neighbours (NaN where times say nothing)."""
    f8 = np.float64
    speed = _speeds(np.ascontiguousarray(step_m, f8), np.ascontiguousarray(dt_s, f8))
    return np.asarray(speed, dtype=np.float64)


def observations_of(fixes: Fixes, config: MatchConfig) -> Observations:
    """The fixes merged into the HMM's observations (:func:`merge_fixes` on their columns)."""
    return merge_fixes(
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


def observe(
    net: RoadNetwork,
    fixes: Fixes,
    config: MatchConfig,
    previous: tuple[Observations, Candidates] | None = None,
) -> tuple[Observations, Candidates]:
    """
    The HMM's observations of the fixes and their candidates.

    Candidates depend on the observations' places and search radii only, so when
    ``previous`` (an earlier :func:`observe` of the same trace, with another sigma) has the
    same ones, its candidates are reused instead of searched again.
    """
    obs = observations_of(fixes, config)
    if previous is not None:
        old = previous[0]
        if all(
            np.array_equal(a, b)
            for a, b in ((obs.x, old.x), (obs.y, old.y), (obs.radius_m, old.radius_m))
        ):
            return obs, previous[1]
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
    return float(_nearest_sigma_kernel(cands.ptr, cands.distance_m, obs.first, obs.stop))


@njit(cache=True, nogil=True)
def _nearest_sigma_kernel(c_ptr, c_dist, first, stop):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """:func:`estimated_sigma_m` on the arrays (rows of an observation are nearest first)."""
    with_roads = 0
    single = 0
    nearest = np.empty(len(first))
    for i in range(len(first)):
        if c_ptr[i + 1] > c_ptr[i]:
            with_roads += 1
            if stop[i] - first[i] == 1:
                nearest[single] = c_dist[c_ptr[i]]
                single += 1
    if single < max(10, 0.5 * with_roads):
        return np.nan
    return sigma_of_distances(nearest[:single])


def with_sigma(fixes: Fixes, sigma_m: float, config: MatchConfig) -> Fixes:
    """The fixes with a larger position sigma and the search radius that goes with it."""
    return dataclasses.replace(
        fixes,
        sigma_m=read_only(np.fmax(fixes.sigma_m, sigma_m)),
        radius_m=read_only(np.fmax(fixes.radius_m, radius_of_sigma(sigma_m, config))),
        sigma_max_m=float(np.fmax(fixes.sigma_max_m, sigma_m)),
    )


def hold_limit_m(fixes: Fixes, config: MatchConfig) -> float:
    """How far behind the path's front a fix may scatter and still be a held car's."""
    return float(max(config.standstill_m, config.standstill_sigmas * fixes.sigma_max_m))
