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
    order = np.argsort(seg.edge, kind="stable")
    ranked = seg.edge[order]
    lo = np.searchsorted(ranked, edge, side="left")
    hi = np.searchsorted(ranked, edge, side="right")
    found = hi > lo
    place = np.where(found, order[np.minimum(lo, len(order) - 1)], -1)
    for i in np.flatnonzero(hi - lo > 1).tolist():
        options = order[lo[i] : hi[i]]  # ascending: the sort is stable
        fits = options[
            (seg.start_offset_m[options] - _EPS_M <= offset_m[i])
            & (offset_m[i] <= seg.end_offset_m[options] + _EPS_M)
        ]
        if len(fits) == 0:
            fits = options
        previous = int(place[i - 1]) if i > 0 else 0
        later = fits[fits >= previous]
        place[i] = int(later[0]) if len(later) else int(fits[-1])
    return np.asarray(place, dtype=np.int64)


def _fixes_of(result: MatchResult, seg: Segment) -> IntArray:
    p = result.points
    return np.flatnonzero((p.segment == seg.index) & p.matched)


def path_positions(result: MatchResult) -> PathPositions:
    """Each fix's edge in its segment's list and metres along the segment's path."""
    p = result.points
    n = len(p.time_s)
    edge_index = np.full(n, -1, dtype=np.int64)
    along = np.full(n, np.nan)
    for seg in result.segments:
        fixes = _fixes_of(result, seg)
        if len(fixes) == 0 or len(seg.edge) == 0:
            continue
        place = _stretch_of(seg, p.edge[fixes], p.offset_m[fixes])
        ok = place >= 0
        k = place[ok]
        driven = seg.driven_m
        start = np.concatenate(([0.0], np.cumsum(driven)[:-1]))
        into = np.clip(p.offset_m[fixes[ok]] - seg.start_offset_m[k], 0.0, driven[k])
        edge_index[fixes[ok]] = k
        along[fixes[ok]] = start[k] + into
    return PathPositions(edge_index=edge_index, along_m=along)


def _time_at(along: FloatArray, time_s: FloatArray, at_m: FloatArray) -> FloatArray:
    """When the car left each distance ``at_m``: linear between the fixes around it."""
    last = len(along) - 1
    i = np.searchsorted(along, at_m, side="right") - 1  # last fix at or before the place
    i0 = np.clip(i, 0, last)
    i1 = np.clip(i + 1, 0, last)
    span = along[i1] - along[i0]
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = np.where(span > 0, (at_m - along[i0]) / span, 0.0)
    t = time_s[i0] + np.clip(frac, 0.0, 1.0) * (time_s[i1] - time_s[i0])
    t = np.where(i < 0, time_s[0], t)
    return np.asarray(np.where(i >= last, time_s[last], t), dtype=np.float64)


def edge_times(result: MatchResult, positions: PathPositions) -> list[EdgeTimes]:
    """Entry and exit time of every edge of every segment (see the module docstring)."""
    p = result.points
    out = []
    for seg in result.segments:
        driven = seg.driven_m
        end = np.cumsum(driven)
        start = end - driven
        entry = np.full(len(driven), np.nan)
        exit_ = np.full(len(driven), np.nan)
        fixes = _fixes_of(result, seg)
        fixes = fixes[np.isfinite(p.time_s[fixes]) & np.isfinite(positions.along_m[fixes])]
        if len(fixes) and len(driven):
            raw = positions.along_m[fixes]
            # monotone in time: the mean of the running maximum and the running minimum
            # from the end, so one fix scattered forward during a stop does not move the
            # whole stop past an edge's end (nor one scattered back hold it before)
            forward = np.maximum.accumulate(raw)
            along = 0.5 * (forward + np.minimum.accumulate(raw[::-1])[::-1])
            times = p.time_s[fixes]
            entry = _time_at(along, times, start)
            exit_ = _time_at(along, times, end)
            entry[0] = times[0]
            exit_[-1] = times[-1]
        out.append(EdgeTimes(start_m=start, end_m=end, entry_s=entry, exit_s=exit_))
    return out
