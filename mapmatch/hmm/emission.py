"""Log emission of every candidate: distance to the road, and heading agreement at speed.

Gaussian in the distance (Newson & Krumm), floored so that an outlier cannot veto the true
road; plus a Gaussian on the angle between the reported heading and the road direction whose
weight rises with speed (reference paper, section 6, eq. 23); and a cost for a service road
under a car faster than such roads are driven (:func:`road_class_score`).

The scores are compiled functions of one candidate (:func:`distance_score`,
:func:`heading_score`, :func:`speed_weight`, :func:`road_class_score`) that the trellis kernel
calls; the functions below apply them to arrays.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numba import njit

from mapmatch.hmm.params import (
    P_HEADING_FULL_SPEED,
    P_HEADING_MAX_PENALTY,
    P_HEADING_MIN_SPEED,
    P_HEADING_SIGMA,
    P_MAX_EMISSION_PENALTY,
    P_SERVICE_PENALTY,
    P_SERVICE_SPEED,
    model_params,
)
from roadnets.drivable import ROAD_CLASSES

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig
    from mapmatch.hmm.candidates import Candidates
    from mapmatch.hmm.observations import Observations
    from mapmatch.types import FloatArray, IntArray

__all__ = [
    "chord_pace",
    "distance_emission",
    "distance_score",
    "emissions",
    "emissions_kernel",
    "flat_arrays",
    "heading_score",
    "heading_weight",
    "log_emission",
    "log_heading",
    "road_class_score",
    "speed_weight",
]

_LOGE2 = float(np.log(2.0))
#: The edge class of OSM ``highway=service`` (parking aisles, driveways, access roads).
SERVICE_CLASS = ROAD_CLASSES.index("service")
#: Seconds of fixes around an observation whose chord gives its pace (:func:`chord_pace`).
PACE_WINDOW_S = 4.0


def log_emission(distance_m: FloatArray, *, sigma_m: FloatArray | float) -> FloatArray:
    """
    Log-likelihood of seeing each fix ``distance_m`` away from its candidate.

    Gaussian position error. The normalising constant is dropped because it is the same for
    every candidate of one fix.

    Parameters
    ----------
    distance_m
        Distance from each fix to its candidate road position, in metres.
    sigma_m
        Standard deviation of the position error, in metres (one value or one per candidate).

    Examples
    --------
    >>> log_emission(np.array([5.0, 10.0]), sigma_m=5.0)
    array([-0.5, -2. ])
    """
    return -0.5 * (distance_m / sigma_m) ** 2


@njit(cache=True, nogil=True)
def _logaddexp(x, y):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """``np.logaddexp`` of two values (numpy's algorithm)."""
    if x == y:
        return x + _LOGE2
    tmp = x - y
    if tmp > 0:
        return x + np.log1p(np.exp(-tmp))
    if tmp <= 0:
        return y + np.log1p(np.exp(tmp))
    return tmp


@njit(cache=True, nogil=True, inline="always")
def distance_score(distance, sigma, params):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Gaussian log emission of a distance, floored at ``-max_emission_penalty``."""
    em = -0.5 * (distance / sigma) ** 2
    floor = params[P_MAX_EMISSION_PENALTY]
    if floor > 0:
        em = _logaddexp(em, -floor)
    return em


@njit(cache=True, nogil=True, inline="always")
def speed_weight(speed, params):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """How much the heading counts at ``speed`` (0 when unknown)."""
    lo, hi = params[P_HEADING_MIN_SPEED], params[P_HEADING_FULL_SPEED]
    weight = (speed - lo) / (hi - lo)
    if np.isnan(weight):
        return 0.0
    return min(max(weight, 0.0), 1.0)


@njit(cache=True, nogil=True)
def chord_pace(used, x, y, time_s):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    Each used observation's pace: the straight line over the used ones around it, over time.

    One entry per observation (NaN for those not in ``used``, and without times). The window
    grows on both sides until it spans :data:`PACE_WINDOW_S` (or the trace ends). A chord cuts
    curves, so the pace is never above the speed driven, and over 4 s the fixes' noise moves it
    little: a car standing in a car park reads about 2 m/s at 5 m of noise, where the speed
    from neighbouring 1 s steps reads 7.
    """
    n = len(used)
    out = np.full(len(x), np.nan)
    for i in range(n):
        j, k = i, i
        while time_s[used[k]] - time_s[used[j]] < PACE_WINDOW_S and (j > 0 or k < n - 1):
            j = max(j - 1, 0)
            k = min(k + 1, n - 1)
        a, b = used[j], used[k]
        span = time_s[b] - time_s[a]
        if span > 0:
            out[used[i]] = np.hypot(x[b] - x[a], y[b] - y[a]) / span
    return out


@njit(cache=True, nogil=True, inline="always")
def road_class_score(edge_class, speed, pace, params):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    Log prior of the road's class at the car's speed.

    ``-service_penalty`` on a service road when the car is faster than ``service_speed_mps``
    by both its ``speed`` (reported, else from its neighbouring steps) and its :func:`chord_pace`
    (either alone where the other is unknown); else 0. Parking aisles and driveways beside a
    main road lie within the position noise of it; a car that moves that fast is on the main
    road, and one that starts or stops in a car park keeps it.
    """
    if edge_class != SERVICE_CLASS:
        return 0.0
    limit = params[P_SERVICE_SPEED]
    fast = not (speed <= limit) and not (pace <= limit)  # NaN: unknown, says nothing
    if fast and not (np.isnan(speed) and np.isnan(pace)):
        return -params[P_SERVICE_PENALTY]
    return 0.0


@njit(cache=True, nogil=True, inline="always")
def angle_between(a, b):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    Absolute difference of two directions, degrees in [0, 180] (NaN when one is NaN).

    NaN returns before the modulo: libm's ``fmod`` takes a slow path on NaN (about 125 ns a
    call against 9 on the benchmark machine), and a sparse trace's observations have no
    course, so the trellis asked it once per candidate for nothing.
    """
    turned = a - b + 180.0
    if np.isnan(turned):
        return abs(turned)
    return abs(turned % 360.0 - 180.0)


@njit(cache=True, nogil=True, inline="always")
def heading_score(heading, bearing, weight, params):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Weighted log-likelihood of the heading given the road direction (0 when unknown)."""
    diff = angle_between(heading, bearing)
    score = -0.5 * (diff / params[P_HEADING_SIGMA]) ** 2
    floor = -params[P_HEADING_MAX_PENALTY]
    if not np.isnan(score) and score < floor:
        score = floor
    value = weight * score
    return 0.0 if np.isnan(value) else value


@njit(cache=True, nogil=True)
def emissions_kernel(distance, sigma, heading, bearing, weight, params):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Log emission of each candidate (``heading`` empty: no heading term)."""
    n = len(distance)
    em = np.empty(n)
    for k in range(n):
        em[k] = distance_score(distance[k], sigma[k], params)
        if len(heading):
            em[k] += heading_score(heading[k], bearing[k], weight[k], params)
    return em


def flat_arrays(*values: Any) -> tuple[tuple[int, ...], list[FloatArray]]:
    """The values broadcast together: their shape, and each as a new flat float array."""
    arrays = [np.asarray(v, dtype=np.float64) for v in values]
    shape = np.broadcast_shapes(*(a.shape for a in arrays))
    return shape, [np.array(np.broadcast_to(a, shape), dtype=np.float64).ravel() for a in arrays]


def distance_emission(
    distance_m: FloatArray, sigma_m: FloatArray, config: MatchConfig
) -> FloatArray:
    """Gaussian log emission of a distance to the road, floored at ``-max_emission_penalty``."""
    shape, (d, sigma) = flat_arrays(distance_m, sigma_m)
    none = np.empty(0)
    em = emissions_kernel(d, sigma, none, none, none, model_params(config))
    return np.asarray(em, dtype=np.float64).reshape(shape)


@njit(cache=True, nogil=True)
def _weights(speed, params):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    out = np.empty(len(speed))
    for i in range(len(speed)):
        out[i] = speed_weight(speed[i], params)
    return out


def heading_weight(speed_mps: FloatArray, config: MatchConfig) -> FloatArray:
    """
    How much the heading counts at each speed: 0 when (nearly) stopped, 1 at road speeds.

    Examples
    --------
    >>> from mapmatch.config import MatchConfig
    >>> heading_weight(np.array([0.0, 5.5, 20.0, np.nan]), MatchConfig())
    array([0. , 0.5, 1. , 0. ])
    """
    speed = np.ascontiguousarray(speed_mps, dtype=np.float64)
    out = _weights(speed.ravel(), model_params(config))
    return np.asarray(out, dtype=np.float64).reshape(speed.shape)


@njit(cache=True, nogil=True)
def _headings(heading, bearing, weight, params):  # type: ignore[no-untyped-def]  # pragma: no cover
    out = np.empty(len(heading))
    for i in range(len(heading)):
        out[i] = heading_score(heading[i], bearing[i], weight[i], params)
    return out


def log_heading(
    heading_deg: FloatArray, bearing_deg: FloatArray, weight: FloatArray, config: MatchConfig
) -> FloatArray:
    """
    Log-likelihood of the reported heading given the road direction at the candidate.

    A Gaussian on the angle between them (``heading_sigma_deg``), scaled by the speed weight
    and floored at ``-heading_max_penalty``. Unknown headings (NaN) score 0.

    Examples
    --------
    >>> from mapmatch.config import MatchConfig
    >>> log_heading(np.array([90.0, 90.0]), np.array([90.0, 270.0]), np.ones(2), MatchConfig())
    array([ -0., -12.])
    """
    shape, flat = flat_arrays(heading_deg, bearing_deg, weight)
    out = _headings(*flat, model_params(config))  # type: ignore[call-arg]
    return np.asarray(out, dtype=np.float64).reshape(shape)


def emissions(
    fixes: Observations, cands: Candidates, fix_of: IntArray, config: MatchConfig
) -> FloatArray:
    """Log emission of every candidate: distance to the road, and heading when known."""
    params = model_params(config)
    none = np.empty(0)
    heading = weight = none
    if fixes.heading_deg is not None:
        heading = np.ascontiguousarray(fixes.heading_deg[fix_of], dtype=np.float64)
        weight = _weights(np.ascontiguousarray(fixes.speed_mps, np.float64), params)[fix_of]
    em = emissions_kernel(
        np.ascontiguousarray(cands.distance_m, np.float64),
        np.ascontiguousarray(fixes.sigma_m[fix_of], np.float64),
        heading,
        np.ascontiguousarray(cands.bearing_deg, np.float64),
        np.ascontiguousarray(weight, np.float64),
        params,
    )
    return np.asarray(em, dtype=np.float64)
