"""
The order of a trace's rows: time sort, true duplicates, shared times, plausible times.

The rows are sorted stably by time, true duplicates merged, the points sharing a time
counted, and the times judged for whether they can be right at all (the rules of
:mod:`mapmatch.trace`).
"""

from __future__ import annotations

from bisect import bisect_right
from typing import TYPE_CHECKING, Final

import numpy as np

if TYPE_CHECKING:
    from mapmatch.trace.checks import Checker
    from mapmatch.types import BoolArray, FloatArray, IntArray

__all__ = [
    "IMPLAUSIBLE_SHARE",
    "MAX_PLAUSIBLE_SPEED_MPS",
    "MOVING_STEP_M",
    "implausible_times",
    "merge_duplicates",
    "shared_times",
    "step_m",
    "time_order",
    "true_duplicates",
]

MAX_PLAUSIBLE_SPEED_MPS: Final = 70.0
"""Chord speed above which a step's times cannot be right: 70 m/s = 252 km/h, beyond any road
vehicle in ordinary traffic and well above what GNSS noise adds at 1 Hz."""


MOVING_STEP_M: Final = 1.0
"""Steps shorter than this (a stopped car, the same fix repeated) are not judged for speed."""


IMPLAUSIBLE_SHARE: Final = 0.5
"""Share of the moving steps that must be impossible for a trace's times to be set aside."""


_EARTH_RADIUS_M: Final = 6_371_008.8


def _longest_nondecreasing(values: FloatArray) -> int:
    """Length of the longest non-decreasing subsequence (patience sorting, O(n log n))."""
    tails: list[float] = []
    for x in values.tolist():
        i = bisect_right(tails, x)
        if i == len(tails):
            tails.append(x)
        else:
            tails[i] = x
    return len(tails)


def time_order(
    time_s: FloatArray, timed: bool, chk: Checker, warnings: list[str]
) -> tuple[IntArray, int]:
    """The stable time order of the rows (file order without times) and how many moved."""
    n = time_s.size
    steps = time_s[1:] - time_s[:-1]
    if not timed or np.all(steps >= 0):
        return np.arange(n, dtype=np.int64), 0
    order = np.argsort(time_s, kind="stable").astype(np.int64)
    reordered = n - _longest_nondecreasing(time_s)
    first_back = int(np.flatnonzero(steps < 0)[0]) + 1
    warnings.append(
        f"{reordered} row{'s' if reordered != 1 else ''} out of time order "
        f"{'were' if reordered != 1 else 'was'} sorted (first step back in time at "
        f"{chk.where(first_back)})"
    )
    return order, reordered


def true_duplicates(matrix: FloatArray, *, timed: bool) -> BoolArray:
    """
    Rows (in time order) that repeat an earlier row in every column (NaN equals NaN).

    With times (column 0, sorted), any earlier row of the same time counts; without, only
    the row before.

    Examples
    --------
    >>> m = np.array([[0.0, 1.0], [0.0, 2.0], [0.0, 1.0], [1.0, np.nan], [1.0, np.nan]])
    >>> true_duplicates(m, timed=True).tolist()
    [False, False, True, False, True]
    >>> true_duplicates(m[:, 1:], timed=False).tolist()
    [False, False, False, False, True]
    """
    if timed:  # only rows of one time can repeat each other: look at shared times only
        t = matrix[:, 0]
        shared = np.zeros(len(t), dtype=bool)
        shared[1:] = t[1:] == t[:-1]
        shared[:-1] |= shared[1:]
        dup = np.zeros(len(t), dtype=bool)
        seen: set[tuple[float | None, ...]] = set()
        for row in np.flatnonzero(shared).tolist():
            key = tuple(None if v != v else v for v in matrix[row].tolist())  # NaN equals NaN
            dup[row] = key in seen
            seen.add(key)
        return dup
    a, b = matrix[1:], matrix[:-1]
    same = ((a == b) | (np.isnan(a) & np.isnan(b))).all(axis=1)
    return np.concatenate(([False], same))


def step_m(lon: FloatArray, lat: FloatArray) -> FloatArray:
    """
    Distance between consecutive positions, metres (equirectangular at the step's latitude).

    Within 0.1 % of the great circle for steps under 100 km away from the poles, which is
    all a speed check needs.

    Examples
    --------
    >>> round(float(step_m(np.array([7.42, 7.43]), np.array([43.73, 43.73]))[0]), 1)
    803.5
    """
    rad = np.pi / 180.0
    dlon = (lon[1:] - lon[:-1] + 180.0) % 360.0 - 180.0  # the short way across the antimeridian
    mid = (lat[1:] + lat[:-1]) * (0.5 * rad)
    return np.asarray(
        _EARTH_RADIUS_M * rad * np.hypot(dlon * np.cos(mid), lat[1:] - lat[:-1]), dtype=np.float64
    )


def implausible_times(time_s: FloatArray, lon: FloatArray, lat: FloatArray) -> str | None:
    """
    The warning when the times cannot be right (the rule of :mod:`mapmatch.trace`), else None.

    Examples
    --------
    >>> lon = 7.42 + np.arange(5) * 0.0013  # about 100 m apart
    >>> implausible_times(np.arange(5.0), lon, np.full(5, 43.73))[:46]
    'the times cannot be right: 4 of 4 moving steps'
    >>> implausible_times(np.arange(5.0) * 10, lon, np.full(5, 43.73)) is None
    True
    """
    step = step_m(lon, lat)
    dt = time_s[1:] - time_s[:-1]
    moving = step >= MOVING_STEP_M
    elapsed = dt > 0
    speed = np.divide(step, dt, out=np.full(step.shape, np.inf), where=elapsed)  # inf: no time
    impossible = moving & (speed > MAX_PLAUSIBLE_SPEED_MPS)
    n_moving, n_bad = int(np.count_nonzero(moving)), int(np.count_nonzero(impossible))
    if n_moving == 0 or n_bad < IMPLAUSIBLE_SHARE * n_moving:
        return None
    timed_speeds = speed[moving & np.isfinite(speed)]
    median = f"; median {np.median(timed_speeds):.3g} m/s" if timed_speeds.size else ""
    no_time = int(np.count_nonzero(moving & ~elapsed))
    return (
        f"the times cannot be right: {n_bad} of {n_moving} moving steps imply more than "
        f"{MAX_PLAUSIBLE_SPEED_MPS:g} m/s ({no_time} with no time between two positions"
        f"{median}); matched by distance only, the times are kept for the output"
    )


def merge_duplicates(
    columns: list[FloatArray], order: IntArray, *, timed: bool, chk: Checker, warnings: list[str]
) -> tuple[IntArray, IntArray]:
    """
    Merge true duplicates: the rows to keep (in time order) and the merged input rows (sorted).

    ``columns`` are every column of the input rows (the times first when ``timed``), to be
    taken in time ``order``. A trace is never merged below 2 points: two identical fixes
    stay a trace.
    """
    n = order.size
    if timed:
        t = columns[0][order]
        if not (t[1:] == t[:-1]).any():  # no shared time: no row can repeat another
            return order, order[:0]
    matrix = np.column_stack([c[order] for c in columns])
    dup = true_duplicates(matrix, timed=timed)
    if dup.sum() > n - 2:  # never below 2 points: two identical fixes stay a trace
        dup[np.flatnonzero(dup)[0]] = False
        warnings.append(
            f"all {n} rows are one fix repeated; 2 are kept so the trace stays a trace "
            "(its matched length is 0)"
        )
    merged = np.sort(order[dup])
    if merged.size:
        many = merged.size != 1
        warnings.append(
            f"{chk.rows_phrase(merged)} repeat{'' if many else 's'} an earlier row exactly "
            f"(same time, position and other fields) and {'were' if many else 'was'} "
            "merged into it"
        )
    return order[~dup], merged


def shared_times(time_s: FloatArray, kept: IntArray, chk: Checker, warnings: list[str]) -> int:
    """Points kept whose time equals the previous point's (``time_s`` of the input rows)."""
    t = time_s[kept]
    zero = np.flatnonzero(t[1:] == t[:-1]) + 1
    shared = int(zero.size)
    if shared:
        warnings.append(
            f"{shared} point{'s' if shared != 1 else ''} share{'' if shared != 1 else 's'}"
            f" the time of the point before (first at {chk.where(int(kept[zero[0]]))}); "
            "all are kept in file order and those steps are matched by distance only"
        )
    return shared
