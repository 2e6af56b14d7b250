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
from typing import TYPE_CHECKING, Any

import numpy as np
from numba import njit

from mapmatch.frozen import quick_init

if TYPE_CHECKING:
    from collections.abc import Sequence

    from mapmatch.result import MatchResult, Segment
    from mapmatch.types import BoolArray, FloatArray, IntArray

__all__ = [
    "EdgeTimes",
    "PathPositions",
    "SegmentPaths",
    "edge_times",
    "kph",
    "path_positions",
    "place_and_time_kernel",
    "positions_and_times",
    "span_times",
    "speeds_kph",
]

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
    When each stretch of the segments' paths was entered and left, epoch seconds.

    One entry per stretch of :class:`SegmentPaths` (NaN without times). ``start_m`` /
    ``end_m`` are the metres along its segment's path where each driven stretch starts
    and ends.
    """

    start_m: FloatArray
    end_m: FloatArray
    entry_s: FloatArray
    exit_s: FloatArray


@quick_init
@dataclass(frozen=True, slots=True)
class SegmentPaths:
    """
    Every segment's path end to end: segment ``s`` has the stretches ``bounds[s]:bounds[s + 1]``.

    Attributes
    ----------
    index, first, last
        Each segment's index in the result, and its first and last fix.
    bounds
        Where each segment's stretches start (and the end), from 0.
    edge, start_m, end_m
        The stretches: network edge and the driven part of it (metres from its start).
    """

    index: IntArray
    first: IntArray
    last: IntArray
    bounds: IntArray
    edge: IntArray
    start_m: FloatArray
    end_m: FloatArray

    @classmethod
    def of(cls, segments: Sequence[Segment]) -> SegmentPaths:
        """The paths of ``segments`` (one segment's arrays as they are, not copied)."""
        if len(segments) == 1:
            s = segments[0]
            return cls(
                index=np.array([s.index], dtype=np.int64),
                first=np.array([s.first], dtype=np.int64),
                last=np.array([s.last], dtype=np.int64),
                bounds=np.array([0, len(s.edge)], dtype=np.int64),
                edge=s.edge,
                start_m=s.start_offset_m,
                end_m=s.end_offset_m,
            )
        bounds = np.zeros(len(segments) + 1, dtype=np.int64)
        np.cumsum([len(s.edge) for s in segments], out=bounds[1:])

        def joined(parts: list[Any], dtype: type) -> Any:
            return np.concatenate(parts, dtype=dtype) if parts else np.zeros(0, dtype=dtype)

        return cls(
            index=np.array([s.index for s in segments], dtype=np.int64),
            first=np.array([s.first for s in segments], dtype=np.int64),
            last=np.array([s.last for s in segments], dtype=np.int64),
            bounds=bounds,
            edge=joined([s.edge for s in segments], np.int64),
            start_m=joined([s.start_offset_m for s in segments], np.float64),
            end_m=joined([s.end_offset_m for s in segments], np.float64),
        )

    @property
    def sizes(self) -> IntArray:
        """How many stretches each segment has."""
        sizes: IntArray = self.bounds[1:] - self.bounds[:-1]
        return sizes

    def arrays(self) -> tuple[IntArray, IntArray, IntArray, FloatArray, FloatArray]:
        """``index``, ``bounds``, ``edge``, ``start_m`` and ``end_m``, as the kernels read them."""
        return self.index, self.bounds, self.edge, self.start_m, self.end_m


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


@njit(cache=True, nogil=True)
def _place_all(  # type: ignore[no-untyped-def]  # pragma: no cover
    seg_index, bounds, seg_edge, start_m, end_m, point_segment, matched, edge, offset_m
):
    """Each fix's ``edge_index`` and ``along`` (``-1`` / NaN off every path), all segments."""
    n = len(point_segment)
    edge_index = np.full(n, -1, dtype=np.int64)
    along = np.full(n, np.nan)
    for s in range(len(seg_index)):
        lo, hi = bounds[s], bounds[s + 1]
        _place_fixes(
            seg_index[s],
            point_segment,
            matched,
            edge,
            offset_m,
            seg_edge[lo:hi],
            start_m[lo:hi],
            end_m[lo:hi],
            edge_index,
            along,
        )
    return edge_index, along


def path_positions(result: MatchResult, paths: SegmentPaths | None = None) -> PathPositions:
    """
    Each fix's edge in its segment's list and metres along the segment's path.

    Parameters
    ----------
    result
        A match.
    paths
        Its segments' paths end to end, when already made (:meth:`SegmentPaths.of`).
    """
    paths = paths if paths is not None else SegmentPaths.of(result.segments)
    edge_index, along = _place_all(*paths.arrays(), *_fixes(result))
    return PathPositions(edge_index=edge_index, along_m=along)


def _fixes(result: MatchResult) -> tuple[IntArray, BoolArray, IntArray, FloatArray]:
    """The fixes' segment, matched flag, edge and offset, as the kernels read them."""
    p = result.points
    return (
        np.asarray(p.segment, dtype=np.int64),
        np.asarray(p.matched, dtype=np.bool_),
        np.asarray(p.edge, dtype=np.int64),
        np.asarray(p.offset_m, dtype=np.float64),
    )


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


@njit(cache=True, nogil=True)
def _time_all(  # type: ignore[no-untyped-def]  # pragma: no cover
    seg_index, bounds, start_m, end_m, point_segment, matched, time_s, along_m
):
    """:func:`_segment_times` of every segment: rows path start, path end, entry, exit."""
    out = np.empty((4, len(start_m)))
    for s in range(len(seg_index)):
        lo, hi = bounds[s], bounds[s + 1]
        driven = end_m[lo:hi] - start_m[lo:hi]
        start, end, entry, exit_ = _segment_times(
            seg_index[s], point_segment, matched, time_s, along_m, driven
        )
        out[0, lo:hi] = start
        out[1, lo:hi] = end
        out[2, lo:hi] = entry
        out[3, lo:hi] = exit_
    return out


@njit(cache=True, nogil=True)
def place_and_time_kernel(  # type: ignore[no-untyped-def]  # pragma: no cover
    seg_index, bounds, seg_edge, start_m, end_m, point_segment, matched, edge, offset_m, time_s
):
    """:func:`_place_all` and :func:`_time_all` in one call."""
    edge_index, along = _place_all(
        seg_index, bounds, seg_edge, start_m, end_m, point_segment, matched, edge, offset_m
    )
    times = _time_all(seg_index, bounds, start_m, end_m, point_segment, matched, time_s, along)
    return edge_index, along, times


@njit(cache=True, nogil=True, inline="always")
def kph(metres, seconds):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Metres over seconds in km/h; NaN where no time passed (or none is known)."""
    return 3.6 * metres / seconds if seconds > 0 else np.nan


@njit(cache=True, nogil=True)
def speeds_kph(metres, seconds):  # type: ignore[no-untyped-def]  # pragma: no cover
    """:func:`kph` of each entry."""
    out = np.empty(len(metres))
    for i in range(len(metres)):
        out[i] = kph(metres[i], seconds[i])
    return out


@njit(cache=True, nogil=True)
def span_times(entry_s, exit_s, bounds):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Each segment's first entry and last exit time, its edges ``bounds[s]:bounds[s + 1]``.

    NaN for a segment without edges (and where the times are).
    """
    count = len(bounds) - 1
    start = np.full(count, np.nan)
    end = np.full(count, np.nan)
    for s in range(count):
        if bounds[s + 1] > bounds[s]:
            start[s] = entry_s[bounds[s]]
            end[s] = exit_s[bounds[s + 1] - 1]
    return start, end


def _edge_times(times: FloatArray) -> EdgeTimes:
    start, end, entry, exit_ = times
    return EdgeTimes(start_m=start, end_m=end, entry_s=entry, exit_s=exit_)


def edge_times(
    result: MatchResult, positions: PathPositions, paths: SegmentPaths | None = None
) -> EdgeTimes:
    """
    Entry and exit time of every edge of every segment (see the module docstring).

    Parameters
    ----------
    result
        A match.
    positions
        Its fixes' places on the path (:func:`path_positions`).
    paths
        Its segments' paths end to end, when already made (:meth:`SegmentPaths.of`).

    Returns
    -------
    EdgeTimes
        One entry per stretch of :class:`SegmentPaths`, segments in order.
    """
    paths = paths if paths is not None else SegmentPaths.of(result.segments)
    seg_index, bounds, _, start_m, end_m = paths.arrays()
    segment, matched, _, _ = _fixes(result)
    time_s = np.asarray(result.points.time_s, dtype=np.float64)
    along = np.asarray(positions.along_m, dtype=np.float64)
    times = _time_all(seg_index, bounds, start_m, end_m, segment, matched, time_s, along)
    return _edge_times(times)


def positions_and_times(
    result: MatchResult, paths: SegmentPaths
) -> tuple[PathPositions, EdgeTimes]:
    """:func:`path_positions` and :func:`edge_times` of ``result``, in one compiled call."""
    time_s = np.asarray(result.points.time_s, dtype=np.float64)
    edge_index, along, times = place_and_time_kernel(*paths.arrays(), *_fixes(result), time_s)
    return PathPositions(edge_index=edge_index, along_m=along), _edge_times(times)
