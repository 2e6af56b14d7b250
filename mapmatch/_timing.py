"""
Where each fix lies along its segment's path, and when each edge was entered and left.

A fix's place on the path is the stretch of the path it is on (``edge_index``, the position
of its edge in the segment's edge list; an edge driven twice, around a block, is told apart
by the order of the fixes) and the metres driven from the segment's start to it
(``along_m``). Entry and exit times of each edge are interpolated linearly in distance
between the fixes around the edge's ends; a car waiting at a place spends that time on the
edge that ends there (the time at a distance is when the car left it). The fixes' distances
are made monotone first (a stopped car's fixes scatter back and forth a few metres). The
first edge is entered at the segment's first fix and the last one left at its last fix.
Without times (a trace matched by distance only) every time is NaN.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

if TYPE_CHECKING:
    from mapmatch.result import MatchResult, Segment
    from mapmatch.types import FloatArray, IntArray

__all__ = ["EdgeTimes", "PathPositions", "edge_times", "path_positions"]

_EPS_M = 1e-6


@dataclass(frozen=True, slots=True)
class PathPositions:
    """
    Each fix's place on its segment's path (``-1`` / NaN for unmatched fixes).

    Attributes
    ----------
    edge_index
        Position of the fix's edge in its segment's edge list.
    along_m
        Metres along the segment's path from its start to the fix's matched position.
    """

    edge_index: IntArray
    along_m: FloatArray


@dataclass(frozen=True, slots=True)
class EdgeTimes:
    """
    When one segment's edges were entered and left, epoch seconds (NaN without times).

    ``start_m`` / ``end_m`` are the metres along the segment's path where each driven
    stretch starts and ends.
    """

    start_m: FloatArray
    end_m: FloatArray
    entry_s: FloatArray
    exit_s: FloatArray


def _stretch_of(seg: Segment, edge: IntArray, offset_m: FloatArray) -> IntArray:
    """
    The position in ``seg``'s edge list of each fix (in time order) on ``edge`` at ``offset_m``.

    Most edges appear once in a path; for one driven twice the fixes take the first place
    at or after the previous fix's that holds their offset.
    """
    place: IntArray = _places(
        np.asarray(seg.edge, dtype=np.int64),
        np.asarray(seg.start_offset_m, dtype=np.float64),
        np.asarray(seg.end_offset_m, dtype=np.float64),
        np.asarray(edge, dtype=np.int64),
        np.asarray(offset_m, dtype=np.float64),
    )
    return place


@njit(cache=True, nogil=True)
def _places(seg_edge, start_m, end_m, edge, offset_m):  # type: ignore[no-untyped-def]  # pragma: no cover
    """:func:`_stretch_of` of a segment's edges and their driven stretches' offsets."""
    order = np.argsort(seg_edge, kind="mergesort")  # stable: equal edges in path order
    ranked = seg_edge[order]
    lo = np.searchsorted(ranked, edge, side="left")
    hi = np.searchsorted(ranked, edge, side="right")
    place = np.full(len(edge), -1, dtype=np.int64)
    for i in range(len(edge)):
        if hi[i] == lo[i]:
            continue
        if hi[i] - lo[i] == 1:
            place[i] = order[lo[i]]
            continue
        options = order[lo[i] : hi[i]]  # ascending: the sort is stable
        fits = options[
            (start_m[options] - _EPS_M <= offset_m[i]) & (offset_m[i] <= end_m[options] + _EPS_M)
        ]
        if len(fits) == 0:
            fits = options
        previous = place[i - 1] if i > 0 else 0
        place[i] = fits[-1]
        for f in fits:
            if f >= previous:
                place[i] = f
                break
    return place


@njit(cache=True, nogil=True)
def _place_fixes(  # type: ignore[no-untyped-def]  # pragma: no cover
    segment, point_segment, matched, edge, offset_m, seg_edge, start_m, end_m, edge_index, along
):
    """Fill ``edge_index`` and ``along`` for the matched fixes of ``segment``."""
    fixes = np.flatnonzero((point_segment == segment) & matched)
    if len(fixes) == 0 or len(seg_edge) == 0:
        return
    place = _places(seg_edge, start_m, end_m, edge[fixes], offset_m[fixes])
    driven = end_m - start_m
    start = np.empty(len(driven))
    total = 0.0
    for j in range(len(driven)):
        start[j] = total
        total += driven[j]
    for i in range(len(fixes)):
        k = place[i]
        if k < 0:
            continue
        f = fixes[i]
        into = min(max(offset_m[f] - start_m[k], 0.0), driven[k])
        edge_index[f] = k
        along[f] = start[k] + into


def path_positions(result: MatchResult) -> PathPositions:
    """Each fix's edge in its segment's list and metres along the segment's path."""
    p = result.points
    n = len(p.time_s)
    edge_index = np.full(n, -1, dtype=np.int64)
    along = np.full(n, np.nan)
    point_segment = np.asarray(p.segment, dtype=np.int64)
    matched = np.asarray(p.matched, dtype=np.bool_)
    edge = np.asarray(p.edge, dtype=np.int64)
    offset = np.asarray(p.offset_m, dtype=np.float64)
    for seg in result.segments:
        _place_fixes(
            seg.index,
            point_segment,
            matched,
            edge,
            offset,
            np.asarray(seg.edge, dtype=np.int64),
            np.asarray(seg.start_offset_m, dtype=np.float64),
            np.asarray(seg.end_offset_m, dtype=np.float64),
            edge_index,
            along,
        )
    return PathPositions(edge_index=edge_index, along_m=along)


@njit(cache=True, nogil=True)
def _time_at(along, time_s, at_m):  # type: ignore[no-untyped-def]  # pragma: no cover
    """When the car left each distance ``at_m``: linear between the fixes around it."""
    last = len(along) - 1
    out = np.empty(len(at_m))
    for j in range(len(at_m)):
        x = at_m[j]
        lo, hi = 0, len(along)  # the first fix past the place
        while lo < hi:
            mid = (lo + hi) // 2
            if along[mid] <= x:
                lo = mid + 1
            else:
                hi = mid
        i = lo - 1  # last fix at or before the place
        if i < 0:
            out[j] = time_s[0]
            continue
        if i >= last:
            out[j] = time_s[last]
            continue
        span = along[i + 1] - along[i]
        frac = (x - along[i]) / span if span > 0 else 0.0
        frac = min(max(frac, 0.0), 1.0)
        out[j] = time_s[i] + frac * (time_s[i + 1] - time_s[i])
    return out


@njit(cache=True, nogil=True)
def _segment_times(  # type: ignore[no-untyped-def]  # pragma: no cover
    segment, point_segment, matched, time_s, along_m, driven
):
    """Where ``segment``'s edges start and end along its path, and their entry and exit times."""
    m = len(driven)
    end = np.empty(m)
    total = 0.0
    for j in range(m):
        total += driven[j]
        end[j] = total
    start = end - driven
    entry = np.full(m, np.nan)
    exit_ = np.full(m, np.nan)
    keep = (point_segment == segment) & matched & np.isfinite(time_s) & np.isfinite(along_m)
    fixes = np.flatnonzero(keep)
    if len(fixes) and m:
        raw = along_m[fixes]
        times = time_s[fixes]
        # monotone in time: the mean of the running maximum and the running minimum
        # from the end, so one fix scattered forward during a stop does not move the
        # whole stop past an edge's end (nor one scattered back hold it before)
        n = len(raw)
        forward = np.empty(n)
        backward = np.empty(n)
        high = raw[0]
        for k in range(n):
            high = max(high, raw[k])
            forward[k] = high
        low = raw[n - 1]
        for k in range(n - 1, -1, -1):
            low = min(low, raw[k])
            backward[k] = low
        along = 0.5 * (forward + backward)
        entry = _time_at(along, times, start)
        exit_ = _time_at(along, times, end)
        entry[0] = times[0]
        exit_[-1] = times[-1]
    return start, end, entry, exit_


def edge_times(result: MatchResult, positions: PathPositions) -> list[EdgeTimes]:
    """Entry and exit time of every edge of every segment (see the module docstring)."""
    p = result.points
    matched = np.asarray(p.matched, dtype=np.bool_)
    segment = np.asarray(p.segment, dtype=np.int64)
    time_s = np.asarray(p.time_s, dtype=np.float64)
    along = np.asarray(positions.along_m, dtype=np.float64)
    out = []
    for seg in result.segments:
        driven = np.asarray(seg.driven_m, dtype=np.float64)
        start, end, entry, exit_ = _segment_times(
            seg.index, segment, matched, time_s, along, driven
        )
        out.append(EdgeTimes(start_m=start, end_m=end, entry_s=entry, exit_s=exit_))
    return out
