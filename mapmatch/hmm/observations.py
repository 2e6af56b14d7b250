"""The HMM's observations: runs of fixes of a car that barely moved, merged into one.

A stopped or crawling car reports many fixes scattered around one place. Each of them, taken on
its own, looks like a small move, forwards or backwards, and the only routes that explain a
backward move are a U-turn or a loop round a block or a roundabout. So, as Newson & Krumm thin
a stopped car's fixes, consecutive fixes within ``thinning_sigmas`` x sigma of their running
centroid become one observation at that centroid: a stop is one state, not many noisy ones. A
fix that leaves the group and is followed by one that comes back, the whole excursion within
``outlier_max_gap_s``, is a stray (left out of the centroid, placed on the path afterwards); a
longer excursion (sparse sampling, or 5 s fixes into a dead end and out) is a car that drove
somewhere and came back, and starts a group of its own. So does a fix the trace's own travel
(odometer, else integrated speed) says the car drove to: a travel longer than the straight line
by more than the thinning radius, over the step into the fix (5 s fixes into a 25 m dead end
and out lie within that radius of each other, and their centroid was a stop) or since the
group's first fix once the group holds two fixes (1 s fixes of a car that drives 25 m into a
dead end and back, scattered round one place by the noise, were one stop and lost the dead
end; one fix and its strays are one fix's word, which an outlier says just as well). A moving
car's fixes at 1 s merge in twos or threes, which smooths the noise without losing distance: the
path still runs through every observation.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from mapmatch.frozen import quick_init
from mapmatch.readonly import EMPTY_FLOAT, EMPTY_INT, kernel_array, kernel_column

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig
    from mapmatch.types import BoolArray, FloatArray, IntArray

__all__ = [
    "TRUSTED_SLACK_FRAC",
    "Observations",
    "Travel",
    "between_kernel",
    "group_fixes",
    "merge_fixes",
    "sigma_of_distances",
    "travel_arrays",
]


#: The sigma of a Gaussian over the median of its absolute values (its MAD).
MAD_TO_SIGMA = 1.4826


@njit(cache=True, nogil=True)
def sigma_of_distances(distance_m):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    The position sigma that distances from fixes to their roads show: 1.4826 x their median.

    The median absolute deviation of a Gaussian, robust to the few fixes far off their road.
    Compiled, for the kernels that estimate a scatter; callable from Python too.

    Examples
    --------
    >>> round(sigma_of_distances(np.array([1.0, 2.0, 3.0, 40.0])), 3)
    3.706
    """
    return MAD_TO_SIGMA * np.median(distance_m)


#: A travel between two observations says how far the car went, not just about how far, when
#: its slack is at most this share of it: an odometer's increment (no slack), or reported
#: speeds integrated over 1-5 s steps; not two speeds 15 s apart (the car may have braked).
TRUSTED_SLACK_FRAC = 0.25


@njit(cache=True, nogil=True)
def between_kernel(index, odometer, speed_m, slack_m, unknown_lo, unknown_hi):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Travel and slack between consecutive points ``index`` (NaN travel where unknown).

    The :class:`Travel` is given as its arrays (:func:`travel_arrays`; absent ones empty):
    the odometer's increment where both readings are known, else the speed integral where
    it is known all the way.
    """
    m = max(len(index) - 1, 0)
    travel = np.full(m, np.nan)
    slack = np.zeros(m)
    for k in range(m):
        i, j = index[k], index[k + 1]
        if len(speed_m) and unknown_hi[j] == unknown_lo[i]:
            travel[k] = speed_m[j] - speed_m[i]
            slack[k] = slack_m[j] - slack_m[i]
        if len(odometer):
            odo = odometer[j] - odometer[i]
            if np.isfinite(odo) and odo >= 0:
                travel[k] = odo
                slack[k] = 0.0
    return travel, slack


def travel_arrays(
    travel: Travel | None,
) -> tuple[FloatArray, FloatArray, FloatArray, IntArray, IntArray]:
    """A :class:`Travel`'s five arrays for the kernels, read-only, empty where absent."""
    t = travel
    if t is None:
        return EMPTY_FLOAT, EMPTY_FLOAT, EMPTY_FLOAT, EMPTY_INT, EMPTY_INT
    return (
        kernel_column(t.odometer_m, EMPTY_FLOAT),
        kernel_column(t.speed_m, EMPTY_FLOAT),
        kernel_column(t.slack_m, EMPTY_FLOAT),
        kernel_column(t.unknown_lo, EMPTY_INT),
        kernel_column(t.unknown_hi, EMPTY_INT),
    )


@quick_init
@dataclass(frozen=True, slots=True)
class Travel:
    """
    Distance the trace says the car travelled up to each point, and how far off it may be.

    ``odometer_m`` is the odometer reading (NaN where unknown); ``speed_m`` the running
    integral of the reported speed over every step of the trace (trapezoids), ``slack_m`` its
    running uncertainty; ``unknown_lo``/``unknown_hi`` the running count of steps it could
    not integrate (a speed or a time missing) at the point's first and last fix. Between two
    points the distance is the odometer's increment where both readings are known, else the
    speed integral where it is known all the way.
    """

    odometer_m: FloatArray | None
    speed_m: FloatArray | None
    slack_m: FloatArray | None
    unknown_lo: IntArray | None
    unknown_hi: IntArray | None


@quick_init
@dataclass(frozen=True, slots=True)
class Observations:
    """
    The points the HMM sees: each a run of consecutive fixes ``first[k]..stop[k]-1``.

    ``x``/``y`` is the centroid of the run's fixes (strays left out), ``time_s`` their mean
    time (NaN without usable times), ``sigma_m`` their mean position sigma, ``radius_m`` the
    widest search radius, ``speed_mps`` the mean speed, ``heading_deg`` the heading of the
    fastest fix (the most trustworthy), ``rep`` the fix nearest the centroid (it names the
    observation in diagnostics). ``stray`` flags, per fix, the fixes left out of their
    run's centroid; ``of_fix`` maps each fix to its observation.
    """

    first: IntArray
    stop: IntArray
    rep: IntArray
    of_fix: IntArray
    stray: BoolArray
    x: FloatArray
    y: FloatArray
    time_s: FloatArray
    sigma_m: FloatArray
    radius_m: FloatArray
    speed_mps: FloatArray
    heading_deg: FloatArray | None
    travel: Travel | None

    def __len__(self) -> int:
        return len(self.first)


@njit(cache=True, nogil=True, inline="always")
def _soon(time_s, a, b, max_gap):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    Whether fix ``b`` comes at most ``max_gap`` after fix ``a`` (no times, NaN: it does).

    Times are sorted, so this also bounds every gap between the fixes in between.
    """
    return len(time_s) == 0 or not time_s[b] - time_s[a] > max_gap


@njit(cache=True, nogil=True, inline="always")
def _driven(x, y, a, i, travel, radius):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    Whether the trace's travel says the car drove from fix ``a`` to fix ``i``.

    It did when ``travel`` is longer than the straight line between the two fixes by more
    than ``radius``; an unknown travel (NaN) says nothing.
    """
    return travel - np.hypot(x[i] - x[a], y[i] - y[a]) > radius


@njit(cache=True, nogil=True)
def _group_kernel(x, y, radius, solo, time_s, max_gap, step):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    :func:`group_fixes` over arrays.

    ``step[i]`` (empty: unknown) is the trace's travel from fix ``i`` to fix ``i + 1``
    (NaN where unknown). A step the travel says was driven starts a new group, and so does
    a fix the group's own travel says the car drove to since the group's first fix, once
    the group holds two fixes.
    """
    n = len(x)
    group = np.empty(n, dtype=np.int64)
    stray = np.zeros(n, dtype=np.bool_)
    g = 0
    sx, sy, count = x[0], y[0], 1.0
    start, span = 0, 0.0
    group[0] = 0
    for i in range(1, n):
        cx, cy = sx / count, sy / count
        moved = step[i - 1] if len(step) else np.nan
        # the ends stay fixes of their own (they bound the length), and a fix the car drove
        # to is no standing car's scatter, however close it lies: in one step (5 s fixes
        # into a dead end and out), or since the group's first fix once it holds two (1 s
        # fixes of a car that drives into a dead end and back while they stay near their
        # centroid; one fix alone is noise: a fix 30 m back at 15 m/s)
        if (
            solo[i]
            or solo[i - 1]
            or _driven(x, y, i - 1, i, moved, radius[i])
            or (count > 1 and _driven(x, y, start, i, span + moved, radius[i]))
        ):
            g += 1
            sx, sy, count = x[i], y[i], 1.0
            start, span = i, 0.0
            group[i] = g
        elif np.hypot(x[i] - cx, y[i] - cy) <= radius[i] * np.sqrt(1.0 + 1.0 / count):
            sx += x[i]
            sy += y[i]
            count += 1.0
            span += moved
            group[i] = g
        elif (
            not solo[i + 1]
            and _soon(time_s, i - 1, i + 1, max_gap)
            and np.hypot(x[i + 1] - cx, y[i + 1] - cy) <= radius[i + 1]
        ) or (
            not solo[i + 1]
            and not solo[i + 2]
            and _soon(time_s, i - 1, i + 2, max_gap)
            and np.hypot(x[i + 2] - cx, y[i + 2] - cy) <= radius[i + 2]
        ):
            # it left and one of the next two fixes is back, the whole excursion within
            # max_gap: a stray here; a longer one is a car that drove somewhere and back
            group[i] = g
            stray[i] = True
            span += moved
        else:
            g += 1
            sx, sy, count = x[i], y[i], 1.0
            start, span = i, 0.0
            group[i] = g
    return group, stray


def group_fixes(
    x: FloatArray,
    y: FloatArray,
    sigma_m: FloatArray,
    config: MatchConfig,
    segment_starts: IntArray | None = None,
    time_s: FloatArray | None = None,
) -> tuple[IntArray, BoolArray]:
    """
    Observation of each fix, and which fixes are strays of their observation.

    Consecutive fixes within ``thinning_sigmas`` x sigma of the running centroid of their
    group join it; ``thinning_sigmas = 0`` keeps every fix on its own.

    Examples
    --------
    >>> from mapmatch.config import MatchConfig
    >>> x = np.array([0.0, 1.0, 3.0, 40.0, 2.0, 30.0, 60.0])
    >>> group, stray = group_fixes(x, np.zeros(7), np.full(7, 5.0), MatchConfig())
    >>> group.tolist(), stray.tolist()
    ([0, 1, 1, 1, 1, 2, 3], [False, False, False, True, False, False, False])
    """
    n = len(x)
    if n == 0:
        return np.empty(0, dtype=np.int64), np.empty(0, dtype=bool)
    if config.thinning_sigmas <= 0:
        return np.arange(n, dtype=np.int64), np.zeros(n, dtype=bool)
    radius = config.thinning_sigmas * np.asarray(sigma_m, dtype=np.float64)
    # read-only, as merge_fixes hands them on (one compiled variant of each kernel)
    starts = kernel_column(segment_starts, EMPTY_INT)
    # a stray is noise, seen between fixes close in time (an outlier, a multipath jump); at
    # sparse sampling a fix that leaves and comes back is a car that drove somewhere and back
    times = kernel_column(time_s, EMPTY_FLOAT)
    group, stray = _group_kernel(
        kernel_array(x),
        kernel_array(y),
        radius,
        _solo(n, starts),
        times,
        float(config.outlier_max_gap_s),
        np.zeros(0),  # no travel steps: writable, as merge_fixes' own are (computed)
    )
    return np.asarray(group, dtype=np.int64), np.asarray(stray, dtype=bool)


@njit(cache=True, nogil=True)
def _solo(n, starts):  # type: ignore[no-untyped-def]  # pragma: no cover
    """The fixes that stay observations of their own: the ends, and those of each segment."""
    solo = np.zeros(n + 2, dtype=np.bool_)  # two spare entries: the kernel looks two ahead
    if n == 0:
        return solo
    solo[0] = solo[n - 1] = True
    for s in starts:
        solo[s] = True
        solo[s - 1 if s > 0 else n + 1] = True
    solo[n] = solo[n + 1] = True
    return solo


@njit(cache=True, nogil=True)
def _mean_into(values, group, stray, count):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Mean of ``values`` over each group's non-stray fixes, NaN values left out (NaN: none)."""
    total = np.zeros(count)
    norm = np.zeros(count)
    for i in range(len(values)):
        v = values[i]
        if not stray[i] and np.isfinite(v):
            total[group[i]] += v
            norm[group[i]] += 1.0
    out = np.empty(count)
    for g in range(count):
        out[g] = total[g] / norm[g] if norm[g] > 0 else np.nan
    return out


@njit(cache=True, nogil=True)
def _travel_steps(odometer, speed_m, slack_m, unknown_lo, unknown_hi):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    The trace's travel over each step between consecutive fixes (empty: no travel known).

    The odometer's increment, else the speed integral (NaN where unknown). The travel
    itself, not less its slack: an integrated speed's slack bounds the worst case (19 m at
    5 s), and with it speeds would hardly ever say a step was driven (on the noise-free
    truth it recovers 5 trips instead of 10, on the accuracy matrix none with speeds alone).
    """
    n = max(len(odometer), len(speed_m))
    if n == 0:
        return np.zeros(0)
    travel, _ = between_kernel(np.arange(n), odometer, speed_m, slack_m, unknown_lo, unknown_hi)
    return travel


@njit(cache=True, nogil=True)
def _merge_kernel(  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    x, y, time_s, sigma, radius_m, speed, heading, odometer, speed_m, slack_m,
    unknown_lo, unknown_hi, starts, thinning, max_gap,
):  # fmt: skip
    """:func:`merge_fixes` in one pass (optional arrays absent when empty)."""
    n = len(x)
    solo = _solo(n, starts)
    if n == 0:
        group = np.empty(0, dtype=np.int64)
        stray = np.zeros(0, dtype=np.bool_)
    elif thinning <= 0:
        group = np.arange(n)
        stray = np.zeros(n, dtype=np.bool_)
    else:
        times = time_s if len(time_s) == n else np.empty(0)
        radius = thinning * sigma
        step = _travel_steps(odometer, speed_m, slack_m, unknown_lo, unknown_hi)
        group, stray = _group_kernel(x, y, radius, solo, times, max_gap, step)
    count = group[-1] + 1 if n else 0
    first = np.empty(count, dtype=np.int64)
    stop = np.empty(count, dtype=np.int64)
    for i in range(n):
        if i == 0 or group[i] != group[i - 1]:
            first[group[i]] = i
        if i == n - 1 or group[i + 1] != group[i]:
            stop[group[i]] = i + 1
    cx = _mean_into(x, group, stray, count)
    cy = _mean_into(y, group, stray, count)
    rep = np.empty(count, dtype=np.int64)
    pick = np.empty(count, dtype=np.int64)
    big = np.finfo(np.float64).max
    radius = np.zeros(count)
    for g in range(count):
        best = np.inf
        fastest = np.inf
        for i in range(first[g], stop[g]):
            d = np.hypot(x[i] - cx[g], y[i] - cy[g]) + (1e12 if stray[i] else 0.0)
            if d < best or i == first[g]:
                best = d
                rep[g] = i
            v = speed[i]  # the fastest fix's heading: -nan_to_num(speed, nan=-1) lowest
            v = -1.0 if np.isnan(v) else (big if v == np.inf else (-big if v == -np.inf else v))
            if -v < fastest or i == first[g]:
                fastest = -v
                pick[g] = i
            radius[g] = max(radius[g], radius_m[i])
    heading_out = np.empty(count if len(heading) else 0)
    for g in range(len(heading_out)):
        heading_out[g] = heading[pick[g]]
    empty = np.empty(0)
    odo = _mean_into(odometer, group, stray, count) if len(odometer) else empty
    spd = _mean_into(speed_m, group, stray, count) if len(speed_m) else empty
    slack = _mean_into(slack_m, group, stray, count) if len(slack_m) else empty
    lo = np.empty(count if len(unknown_lo) else 0, dtype=np.int64)
    hi = np.empty(count if len(unknown_hi) else 0, dtype=np.int64)
    for g in range(len(lo)):
        lo[g] = unknown_lo[first[g]]
    for g in range(len(hi)):
        hi[g] = unknown_hi[stop[g] - 1]
    return (
        first, stop, rep, group, stray, cx, cy,
        _mean_into(time_s, group, stray, count),
        _mean_into(sigma, group, stray, count),
        radius,
        _mean_into(speed, group, stray, count),
        heading_out, odo, spd, slack, lo, hi,
    )  # fmt: skip


def merge_fixes(
    x: FloatArray,
    y: FloatArray,
    time_s: FloatArray,
    sigma_m: FloatArray,
    radius_m: FloatArray,
    speed_mps: FloatArray,
    heading_deg: FloatArray | None,
    travel: Travel | None,
    config: MatchConfig,
    segment_starts: IntArray | None = None,
) -> Observations:
    """
    Merge the fixes of a trace into the HMM's observations (see the module docstring).

    ``travel`` holds per-fix running values; the observation's are the means over its
    centroid fixes (its place along the road), the unknown-step counts at its first and
    last fix.
    """
    f8 = np.float64
    t = travel
    out = _merge_kernel(
        np.ascontiguousarray(x, f8),
        np.ascontiguousarray(y, f8),
        np.ascontiguousarray(time_s, f8),
        np.ascontiguousarray(sigma_m, f8),
        np.ascontiguousarray(radius_m, f8),
        np.ascontiguousarray(speed_mps, f8),
        EMPTY_FLOAT if heading_deg is None else np.ascontiguousarray(heading_deg, f8),
        *travel_arrays(t),
        EMPTY_INT if segment_starts is None else np.ascontiguousarray(segment_starts, np.int64),
        float(config.thinning_sigmas),
        float(config.outlier_max_gap_s),
    )
    first, stop, rep, group, stray, cx, cy, time_m, sigma, radius, speed = out[:11]
    heading, odo, spd, slack, lo, hi = out[11:]
    merged_travel = None
    if t is not None:
        merged_travel = Travel(
            odometer_m=None if t.odometer_m is None else odo,
            speed_m=None if t.speed_m is None else spd,
            slack_m=None if t.slack_m is None else slack,
            unknown_lo=None if t.unknown_lo is None else lo,
            unknown_hi=None if t.unknown_hi is None else hi,
        )
    return Observations(
        first=first,
        stop=stop,
        rep=rep,
        of_fix=group,
        stray=stray,
        x=cx,
        y=cy,
        time_s=time_m,
        sigma_m=sigma,
        radius_m=radius,
        speed_mps=speed,
        heading_deg=None if heading_deg is None else heading,
        travel=merged_travel,
    )
