"""The HMM's observations: runs of fixes of a car that barely moved, merged into one.

A stopped or crawling car reports many fixes scattered around one place. Each of them, taken on
its own, looks like a small move, forwards or backwards, and the only routes that explain a
backward move are a U-turn or a loop round a block or a roundabout. So, as Newson & Krumm thin
a stopped car's fixes, consecutive fixes within ``thinning_sigmas`` x sigma of their running
centroid become one observation at that centroid: a stop is one state, not many noisy ones. A
fix that leaves the group within seconds and is followed by one that comes back is a stray
(left out of the centroid, placed on the path afterwards); at sparse sampling the same pattern
is a car that drove somewhere and came back, and starts a group of its own. A moving car's
fixes at 1 s merge in twos or threes, which smooths the noise without losing distance: the path
still runs through every observation.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig
    from mapmatch.types import BoolArray, FloatArray, IntArray

__all__ = ["Observations", "Travel", "group_fixes", "merge_fixes"]


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

    def between(self, index: IntArray) -> tuple[FloatArray, FloatArray]:
        """Travel and slack between consecutive points ``index`` (NaN travel where unknown)."""
        i, j = index[:-1], index[1:]
        travel = np.full(len(i), np.nan)
        slack = np.zeros(len(i))
        if self.speed_m is not None and self.slack_m is not None:
            assert self.unknown_lo is not None
            assert self.unknown_hi is not None
            known = self.unknown_hi[j] == self.unknown_lo[i]
            travel = np.where(known, self.speed_m[j] - self.speed_m[i], np.nan)
            slack = np.where(known, self.slack_m[j] - self.slack_m[i], 0.0)
        if self.odometer_m is not None:
            with np.errstate(invalid="ignore"):
                odo = self.odometer_m[j] - self.odometer_m[i]
                exact = np.isfinite(odo) & (odo >= 0)
            travel = np.where(exact, odo, travel)
            slack = np.where(exact, 0.0, slack)
        return travel, slack


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


@njit(cache=True, nogil=True)
def _group_kernel(x, y, radius, solo, quick):  # type: ignore[no-untyped-def]  # pragma: no cover
    n = len(x)
    group = np.empty(n, dtype=np.int64)
    stray = np.zeros(n, dtype=np.bool_)
    g = 0
    sx, sy, count = x[0], y[0], 1.0
    group[0] = 0
    for i in range(1, n):
        cx, cy = sx / count, sy / count
        if solo[i] or solo[i - 1]:  # the ends stay fixes of their own: they bound the length
            g += 1
            sx, sy, count = x[i], y[i], 1.0
            group[i] = g
        elif np.hypot(x[i] - cx, y[i] - cy) <= radius[i] * np.sqrt(1.0 + 1.0 / count):
            sx += x[i]
            sy += y[i]
            count += 1.0
            group[i] = g
        elif quick[i] and (
            (not solo[i + 1] and np.hypot(x[i + 1] - cx, y[i + 1] - cy) <= radius[i + 1])
            or (
                not solo[i + 1]
                and not solo[i + 2]
                and np.hypot(x[i + 2] - cx, y[i + 2] - cy) <= radius[i + 2]
            )
        ):
            group[i] = g  # it left and one of the next two fixes is back: a stray here
            stray[i] = True
        else:
            g += 1
            sx, sy, count = x[i], y[i], 1.0
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
    solo = np.zeros(n + 2, dtype=bool)  # two spare entries: the kernel looks two ahead
    solo[[0, n - 1]] = True
    if segment_starts is not None and len(segment_starts):
        starts = np.asarray(segment_starts, dtype=np.int64)
        solo[starts] = solo[starts - 1] = True
    solo[n:] = True
    # a stray is noise, seen between fixes close in time (an outlier, a multipath jump); at
    # sparse sampling a fix that leaves and comes back is a car that drove somewhere and back
    quick = np.ones(n + 2, dtype=bool)
    if time_s is not None and n > 1:
        dt = np.diff(np.asarray(time_s, dtype=np.float64))
        longest = np.fmax(np.concatenate(([0.0], dt)), np.concatenate((dt, [0.0])))
        quick[:n] = ~(longest > config.outlier_max_gap_s)  # NaN (no times): quick
    group, stray = _group_kernel(
        np.asarray(x, np.float64), np.asarray(y, np.float64), radius, solo, quick
    )
    return np.asarray(group, dtype=np.int64), np.asarray(stray, dtype=bool)


def _mean_by(values: FloatArray, group: IntArray, weight: FloatArray, count: int) -> FloatArray:
    """Weighted mean of ``values`` per group, NaN values and zero weights left out."""
    ok = np.isfinite(values) & (weight > 0)
    total = np.bincount(group[ok], weights=(values * weight)[ok], minlength=count)
    norm = np.bincount(group[ok], weights=weight[ok], minlength=count)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.asarray(np.where(norm > 0, total / norm, np.nan), dtype=np.float64)


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
    group, stray = group_fixes(x, y, sigma_m, config, segment_starts, time_s)
    n = len(x)
    count = int(group[-1]) + 1 if n else 0
    starts = np.flatnonzero(np.diff(group, prepend=-1) != 0)
    first = starts.astype(np.int64)
    stop = np.append(starts[1:], n).astype(np.int64)
    member = (~stray).astype(np.float64)
    cx = _mean_by(x, group, member, count)
    cy = _mean_by(y, group, member, count)
    d = np.hypot(x - cx[group], y - cy[group]) + stray * 1e12
    order = np.lexsort((d, group))
    rep = order[np.flatnonzero(np.diff(group[order], prepend=-1) != 0)].astype(np.int64)
    speed = _mean_by(speed_mps, group, member, count)
    heading = None
    if heading_deg is not None:
        fastest = np.lexsort((-np.nan_to_num(speed_mps, nan=-1.0), group))
        pick = fastest[np.flatnonzero(np.diff(group[fastest], prepend=-1) != 0)]
        heading = heading_deg[pick]
    merged_travel = None
    if travel is not None:
        merged_travel = Travel(
            odometer_m=None
            if travel.odometer_m is None
            else _mean_by(travel.odometer_m, group, member, count),
            speed_m=None
            if travel.speed_m is None
            else _mean_by(travel.speed_m, group, member, count),
            slack_m=None
            if travel.slack_m is None
            else _mean_by(travel.slack_m, group, member, count),
            unknown_lo=None if travel.unknown_lo is None else travel.unknown_lo[first],
            unknown_hi=None if travel.unknown_hi is None else travel.unknown_hi[stop - 1],
        )
    radius = np.zeros(count)
    np.maximum.at(radius, group, radius_m)
    return Observations(
        first=first,
        stop=stop,
        rep=rep,
        of_fix=group,
        stray=stray,
        x=cx,
        y=cy,
        time_s=_mean_by(time_s, group, member, count),
        sigma_m=_mean_by(sigma_m, group, member, count),
        radius_m=radius,
        speed_mps=speed,
        heading_deg=heading,
        travel=merged_travel,
    )
