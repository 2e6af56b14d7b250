"""The ends of a matched path placed where the odometer puts them.

At 15-30 s sampling the matched length runs from the first fix's projection to the last's,
so the along-road error of those two fixes alone (10-20 m each) sets the length's error: more
than 1 % of a 3 km trip. An odometer says how far the car went between every pair of fixes;
a line through every fix's place along the path against its reading (the scale left free, so
an odometer reading a few per cent high or low moves nothing) puts the two ends where all the
fixes agree they were. Each end moves along its own road only (never from a junction, never
past one) and by at most a few sigmas, and the end fixes move with it.

This works on a finished match (its segments and per-fix places), so the live matcher's
close applies it to its record exactly as :func:`mapmatch.match` does to its own.
"""

from __future__ import annotations

import dataclasses
from itertools import pairwise
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from mapmatch._timing import SegmentPaths
from mapmatch.hmm.assemble import fixes_on_piece
from mapmatch.hmm.observations import sigma_of_distances
from mapmatch.readonly import EMPTY_FLOAT, kernel_column
from mapmatch.result import MatchedPoints, Segment
from roadnets.spatial_kernels import points_on_edges

if TYPE_CHECKING:
    from typing import Any

    from mapmatch.config import MatchConfig
    from mapmatch.types import FloatArray, IntArray
    from roadnets import RoadNetwork

__all__ = ["moved_ends", "odometer_ends", "odometer_fit"]

#: Fewer readings than this on a segment leave its ends where they are.
MIN_READINGS = 3
#: The shortest stretch an end correction leaves (metres).
MIN_STRETCH_M = 0.5
#: A reading farther off the fitted line than this many residual scales is left out.
REJECT_SCALES = 3.0


@njit(cache=True, nogil=True)
def odometer_fit(along, odometer, sigma):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    A line ``along = a + b * (odometer - odometer[0])`` through places and readings.

    Least squares; readings farther off it than 3 x the residual scale (1.4826 x the median
    absolute residual, at least ``sigma``) are left out and the line fitted again, three
    times. Returns ``(a, b, scale)``, or NaNs when fewer than three readings remain, they
    span no distance, or ``b`` is not within 0.8 .. 1.25 (the path is not the road the
    odometer measured).
    """
    n = len(along)
    keep = np.zeros(n, dtype=np.bool_)
    for k in range(n):
        keep[k] = np.isfinite(odometer[k]) and np.isfinite(along[k])
    if n < MIN_READINGS or not np.isfinite(odometer[0]):
        return np.nan, np.nan, np.nan
    base = odometer[0]
    a = b = scale = np.nan
    residual = np.empty(n)
    for _ in range(3):
        count = 0
        sx = sy = 0.0
        for k in range(n):
            if keep[k]:
                count += 1
                sx += odometer[k] - base
                sy += along[k]
        if count < MIN_READINGS:
            return np.nan, np.nan, np.nan
        mx, my = sx / count, sy / count
        sxx = sxy = 0.0
        for k in range(n):
            if keep[k]:
                dx = odometer[k] - base - mx
                sxx += dx * dx
                sxy += dx * (along[k] - my)
        if sxx <= 0.0:
            return np.nan, np.nan, np.nan
        b = sxy / sxx
        a = my - b * mx
        m = 0
        for k in range(n):
            if keep[k]:
                residual[m] = abs(along[k] - a - b * (odometer[k] - base))
                m += 1
        scale = max(sigma, sigma_of_distances(residual[:m]))
        for k in range(n):
            if np.isfinite(odometer[k]) and np.isfinite(along[k]):
                keep[k] = abs(along[k] - a - b * (odometer[k] - base)) <= REJECT_SCALES * scale
    if not 0.8 <= b <= 1.25:
        return np.nan, np.nan, np.nan
    return a, b, scale


@njit(cache=True, nogil=True)
def _along(edge, lo, hi, fix_edge, fix_off):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """Each fix's distance along the stretches, searched forward from the last one's (NaN: off)."""
    n = len(fix_edge)
    out = np.full(n, np.nan)
    base = np.empty(len(edge) + 1)
    base[0] = 0.0
    for i in range(len(edge)):
        base[i + 1] = base[i] + hi[i] - lo[i]
    at = 0
    for j in range(n):
        for i in range(at, len(edge)):
            if edge[i] == fix_edge[j] and lo[i] - 1e-6 <= fix_off[j] <= hi[i] + 1e-6:
                out[j] = base[i] + min(max(fix_off[j] - lo[i], 0.0), hi[i] - lo[i])
                at = i
                break
    return out


@njit(cache=True, nogil=True)
def moved_ends(edge, lo, hi, along, odometer, reach, edge_len):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    How far the path's start moves forward and its end moves on (metres, either may be < 0).

    ``along`` and ``odometer`` are the segment's model fixes' (the first and last fix of
    the segment first and last); ``reach`` is ``(sigma, sigmas)``.
    """
    sigma, sigmas = reach
    a, b, scale = odometer_fit(along, odometer, sigma)
    n = len(along)
    ends_known = np.isfinite(along[0]) and np.isfinite(along[n - 1])
    if not (np.isfinite(a) and ends_known and np.isfinite(odometer[n - 1])):
        return 0.0, 0.0  # an end fix off its path (placed where no stretch holds it)
    k = len(edge) - 1
    limit = sigmas * scale
    shift = 0.0
    if lo[0] > 0.0:  # not at a junction: an end that could not move out does not move in
        shift = min(max(a - along[0], -limit, -lo[0]), limit)
        shift = min(shift, max(hi[0] - lo[0] - MIN_STRETCH_M, 0.0))
    grow = 0.0
    last = lo[k] + shift if k == 0 else lo[k]
    if hi[k] < edge_len[edge[k]]:
        target = a + b * (odometer[n - 1] - odometer[0]) - along[n - 1]
        grow = min(max(target, -limit, MIN_STRETCH_M - (hi[k] - last)), limit)
        grow = min(grow, edge_len[edge[k]] - hi[k])
    return shift, grow


@njit(cache=True, nogil=True)
def _ends_kernel(  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    paths, points, fix_x, fix_y, odometer, radius, reach, geometry
):  # fmt: skip
    """
    :func:`odometer_ends` up to the moved fixes' degrees: every segment's :func:`moved_ends`.

    ``paths`` is the segments' :class:`~mapmatch._timing.SegmentPaths` as ``(index, first,
    last, bounds, edge, start offsets, end offsets)``; ``points`` is ``(matched, interpolated,
    segment, edge, offset)`` of the fixes, ``fix_x``/``fix_y`` their projected positions,
    ``radius`` their search radii (empty: no limit), ``geometry`` the network's
    ``kernel_geometry``. Returns whether each segment moved, the segments' new start and end
    offsets (copies), the fixes' offsets (a copy), whether any fix moved, the fixes that
    moved onto the new ends with their new positions and distances, and the fixes lost (a
    move beyond their radius, and the path no longer through their old place).
    """
    seg_index, seg_first, seg_last, bounds, edge, seg_lo, seg_hi = paths
    matched, interpolated, segment, fix_edge, fix_offset = points
    n = len(fix_offset)
    lo, hi = seg_lo.copy(), seg_hi.copy()
    offset = fix_offset.copy()
    moved = np.zeros(n, dtype=np.bool_)
    # where the new path starts on each fix's edge, and ends (only the end edges have bounds)
    path_lo = np.full(n, -np.inf)
    path_hi = np.full(n, np.inf)
    changed = np.zeros(len(seg_index), dtype=np.bool_)
    chosen = np.empty(n, dtype=np.int64)
    for s in range(len(seg_index)):
        index, first, last = seg_index[s], seg_first[s], seg_last[s]
        a, b = bounds[s], bounds[s + 1]
        e = edge[a:b]
        m = 0
        for k in range(first, last + 1):
            if matched[k] and not interpolated[k] and segment[k] == index:
                chosen[m] = k
                m += 1
        if m < MIN_READINGS or chosen[0] != first or chosen[m - 1] != last:
            continue
        model = chosen[:m].copy()
        along = _along(e, lo[a:b], hi[a:b], fix_edge[model], offset[model])
        shift, grow = moved_ends(e, lo[a:b], hi[a:b], along, odometer[model], reach, geometry[0])
        if shift == 0.0 and grow == 0.0:
            continue
        changed[s] = True
        length = 0.0  # as Segment.length_m sums: in order
        for i in range(a, b):
            length += hi[i] - lo[i]
        c = 0
        for k in range(first, last + 1):
            if matched[k] and segment[k] == index:
                chosen[c] = k
                c += 1
        every = chosen[:c]
        places = _along(e, lo[a:b], hi[a:b], fix_edge[every], offset[every])
        lo[a] += shift
        hi[b - 1] += grow
        for j in range(c):
            k = every[j]
            if fix_edge[k] == e[0]:
                path_lo[k] = lo[a]
            if fix_edge[k] == e[-1]:
                path_hi[k] = hi[b - 1]
        if shift:  # the fixes at the old start, and any the new start passed
            for j in range(c):
                k = every[j]
                if (places[j] == places[0] or places[j] < shift) and fix_edge[k] == e[0]:
                    offset[k] = lo[a]
                    moved[k] = True
        if grow:  # the fixes at the old end, and any the new end fell short of
            for j in range(c):
                k = every[j]
                if (places[j] == places[c - 1] or places[j] > length + grow) and fix_edge[k] == e[
                    -1
                ]:
                    offset[k] = hi[b - 1]
                    moved[k] = True
    at = np.flatnonzero(moved)
    # the kernel itself: these edges and offsets are the path's own, nothing to check
    x, y = points_on_edges(fix_edge[at], offset[at], *geometry)
    go = np.empty(len(at), dtype=np.int64)
    lost = np.empty(len(at), dtype=np.int64)
    go_m = np.empty(len(at))
    n_go = n_lost = 0
    for j in range(len(at)):
        k = at[j]
        moved_m = np.hypot(x[j] - fix_x[k], y[j] - fix_y[k])
        if len(radius) and moved_m > radius[k]:  # too far: stays if the path still has it
            old = fix_offset[k]
            if path_lo[k] <= old <= path_hi[k]:
                offset[k] = old
            else:
                lost[n_lost] = k
                n_lost += 1
            continue
        x[n_go], y[n_go], go[n_go], go_m[n_go] = x[j], y[j], k, moved_m
        n_go += 1
    return (
        changed, lo, hi, offset, len(at) > 0,
        (go[:n_go], x[:n_go], y[:n_go], go_m[:n_go]), lost[:n_lost],
    )  # fmt: skip


def moves_ends(odometer_m: FloatArray | None, config: MatchConfig) -> bool:
    """Whether :func:`odometer_ends` may move segments' ends: an odometer, and the setting on."""
    return odometer_m is not None and config.odometer_end_sigmas > 0


def odometer_ends(
    net: RoadNetwork,
    segments: list[Segment],
    points: MatchedPoints,
    odometer_m: FloatArray | None,
    config: MatchConfig,
    radius_m: FloatArray | None = None,
    fix_xy: tuple[FloatArray, FloatArray] | None = None,
) -> tuple[list[Segment], MatchedPoints]:
    """
    The segments with their ends where the odometer puts them, and the points with them.

    For each segment, a line through its model fixes' places along its path against their
    odometer readings (:func:`odometer_fit`) gives where its first and last fix were; the
    path's start and end move there, at most ``config.odometer_end_sigmas`` residual scales
    (at least ``config.sigma_m``) and only along their own edge, never from or past a
    junction. Fixes left before the new start or past the new end move onto it. Without an
    odometer, or with ``odometer_end_sigmas`` 0, the segments and points come back as given.

    With ``radius_m`` (every fix's search radius), no fix moves farther from itself than its
    radius: one that would keeps its place where the path still runs through it, and is
    otherwise left unmatched, an outlier, as assembly leaves a fix the path does not explain.
    ``fix_xy`` are the fixes' projected positions when already known (``net.project`` of
    the points' ``raw_lon`` and ``raw_lat``).
    """
    if not moves_ends(odometer_m, config) or not segments:
        return segments, points
    paths = SegmentPaths.of(segments)
    fix_x, fix_y = net.project(points.raw_lon, points.raw_lat) if fix_xy is None else fix_xy
    p = points
    changed, lo, hi, offset, any_moved, went, lost = _ends_kernel(
        (paths.index, paths.first, paths.last, paths.bounds, paths.edge, paths.start_m,
         paths.end_m),
        (p.matched, p.interpolated, p.segment, p.edge, p.offset_m),
        fix_x, fix_y, kernel_column(odometer_m, EMPTY_FLOAT),
        kernel_column(radius_m, EMPTY_FLOAT),
        (float(config.sigma_m), float(config.odometer_end_sigmas)), net.kernel_geometry,
    )  # fmt: skip
    out = [
        Segment(s.index, s.first, s.last, s.edge, lo[a:b], hi[a:b], net=net) if change else s
        for s, change, (a, b) in zip(
            segments, changed.tolist(), pairwise(paths.bounds.tolist()), strict=True
        )
    ]
    if not any_moved:
        return out, points
    go, x, y, moved_m = went
    lon, lat = points.lon.copy(), points.lat.copy()
    lon[go], lat[go] = net.unproject(x, y)
    distance = points.distance_m.copy()
    distance[go] = moved_m
    placed = dataclasses.replace(points, offset_m=offset, lon=lon, lat=lat, distance_m=distance)
    if not len(lost):
        return out, placed
    return _unmatched(out, placed, lost, net)


def _unmatched(
    segments: list[Segment], points: MatchedPoints, lost: IntArray, net: RoadNetwork
) -> tuple[list[Segment], MatchedPoints]:
    """The points with the fixes ``lost`` unmatched outliers; the segments between those left."""
    matched = points.matched.copy()
    matched[lost] = False
    outlier = points.outlier.copy()
    outlier[lost] = True
    off = {"edge": -1, "u": -1, "v": -1, "key": -1, "segment": -1, "offset_m": np.nan,
           "distance_m": np.nan, "lon": np.nan, "lat": np.nan, "confidence": 0.0}  # fmt: skip
    fields: dict[str, Any] = {"matched": matched, "outlier": outlier}
    for name, value in off.items():
        column = getattr(points, name).copy()
        column[lost] = value
        fields[name] = column
    fields["interpolated"] = points.interpolated & matched
    points = dataclasses.replace(points, **fields)
    kept = []
    for seg in segments:
        first, last = fixes_on_piece(fields["segment"], seg.first, seg.last, seg.index)
        if (first, last) == (seg.first, seg.last):
            kept.append(seg)
            continue
        lo, hi = seg.start_offset_m, seg.end_offset_m
        kept.append(Segment(seg.index, int(first), int(last), seg.edge, lo, hi, net=net))
    return kept, points
