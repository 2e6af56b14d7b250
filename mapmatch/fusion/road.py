"""
Road geometry for map-aided fusion: road bearings and feedback from a match result.

The matcher snaps each fused fix onto a directed edge at an offset; this module turns those
snapped positions into :class:`~mapmatch.fusion.RoadFeedback` pseudo-measurements (position
with a small cross-road and a large along-road error, and the road's direction of travel) for
a second pass of :func:`~mapmatch.fusion.fuse`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mapmatch.fusion.feedback import RoadFeedback
from mapmatch.fusion.geo import LocalTangentPlane

if TYPE_CHECKING:
    import numpy.typing as npt

    from mapmatch.result import MatchResult
    from roadnets import RoadNetwork

    FloatArray = npt.NDArray[np.float64]
    IntArray = npt.NDArray[np.int64]

__all__ = ["road_bearing_deg", "road_feedback_from_match"]


def road_bearing_deg(net: RoadNetwork, edge: npt.ArrayLike, offset_m: npt.ArrayLike) -> FloatArray:
    """
    Direction of travel of directed ``edge`` at ``offset_m``, degrees clockwise from true north.

    The bearing is that of the geometry segment containing the offset (offsets are clipped
    to the edge). It is measured on the WGS84 ellipsoid (both segment ends are unprojected and
    compared in a local east/north plane), so the grid convergence of the network's metric
    CRS does not bias it.

    Parameters
    ----------
    net
        The road network (:func:`roadnets.load`).
    edge
        Edge indices into ``net.arrays``.
    offset_m
        Metres from each edge's start.

    Returns
    -------
    FloatArray
        Bearings in ``[0, 360)``.
    """
    a = net.arrays
    e = np.atleast_1d(np.asarray(edge, dtype=np.int64))
    off = np.atleast_1d(np.asarray(offset_m, dtype=np.float64))
    e, off = np.broadcast_arrays(e, off)
    i = net.segment_at(e, off)
    x0, y0 = a.geom_x[i], a.geom_y[i]
    x1, y1 = a.geom_x[i + 1], a.geom_y[i + 1]
    if e.size == 0:
        return np.empty(0)
    lon0, lat0 = net.unproject(x0, y0)
    lon1, lat1 = net.unproject(x1, y1)
    return _bearing_deg(
        np.asarray(lon0, dtype=np.float64),
        np.asarray(lat0, dtype=np.float64),
        np.asarray(lon1, dtype=np.float64),
        np.asarray(lat1, dtype=np.float64),
    )


def _bearing_deg(
    lon0: FloatArray, lat0: FloatArray, lon1: FloatArray, lat1: FloatArray
) -> FloatArray:
    out = np.empty(lon0.shape[0])
    for k in range(lon0.shape[0]):
        ltp = LocalTangentPlane(float(lon0[k]), float(lat0[k]))
        dx, dy = ltp.to_xy(lon1[k], lat1[k])
        out[k] = np.degrees(np.arctan2(float(dx), float(dy)))
    return np.mod(out, 360.0)


def _bend_deg(
    net: RoadNetwork, edge: IntArray, offset_m: FloatArray, window_m: float
) -> FloatArray:
    """Largest change of road direction within ``window_m`` either side, on the edge."""
    a = net.arrays
    length = a.edge_length_m[edge]
    here = road_bearing_deg(net, edge, offset_m)
    before = road_bearing_deg(net, edge, np.maximum(offset_m - window_m, 0.0))
    after = road_bearing_deg(net, edge, np.minimum(offset_m + window_m, length))
    d1 = np.abs((here - before + 180.0) % 360.0 - 180.0)
    d2 = np.abs((after - here + 180.0) % 360.0 - 180.0)
    return np.asarray(np.maximum(d1, d2), dtype=np.float64)


def road_feedback_from_match(
    result: MatchResult,
    net: RoadNetwork,
    *,
    accuracy_m: npt.ArrayLike | None = None,
    min_confidence: float = 0.5,
    use_interpolated: bool = True,
    cross_sigma_m: float = 2.0,
    along_sigma_floor_m: float = 10.0,
    along_accuracy_factor: float = 3.0,
    straight_window_m: float = 10.0,
    max_bend_deg: float = 10.0,
    junction_m: float = 10.0,
) -> RoadFeedback:
    """
    Turn a match result's snapped points into road pseudo-measurements for :func:`fuse`.

    A fix gives one entry when it was matched (not an outlier; fixes the matcher left out of
    its model and placed on the path afterwards count when ``use_interpolated``) with
    ``confidence >= min_confidence``, lies on a straight stretch
    (the road turns by at most ``max_bend_deg`` within ``straight_window_m`` on either side)
    and at least ``junction_m`` from either end of its edge (where the next edge of the path
    may turn): there the road heading is the vehicle's heading. The position is the snapped
    point (``result.points.lon/lat``), the heading the bearing of the edge's geometry segment
    at ``result.points.offset_m`` (:func:`road_bearing_deg`, from the network arrays; the
    match result does not carry it).

    The snapped point is the fused fix projected onto the road, so it carries no along-road
    information the filter does not already have; its along-road sigma is therefore large:
    ``max(along_sigma_floor_m, along_accuracy_factor * accuracy_m)``.

    Parameters
    ----------
    result
        A match of a fused trace (:func:`mapmatch.match`).
    net
        The network matched on.
    accuracy_m
        1-sigma horizontal accuracy of each fix of the matched trace (e.g.
        ``trace.accuracy_m``), metres; None uses ``along_sigma_floor_m`` alone.
    min_confidence
        Minimum posterior probability of the chosen candidate.
    use_interpolated
        Also use fixes the matcher left out of its model (strays of a stopped car, fixes
        dropped to join a break) at their place on the matched path. Their along-road
        position is rough, but the road's position across and its direction are right.
    cross_sigma_m
        1-sigma cross-road error of a snapped position (lane offset), metres.
    along_sigma_floor_m, along_accuracy_factor
        Along-road 1-sigma, see above.
    straight_window_m, max_bend_deg, junction_m
        Where the road heading is trusted, see above.

    Returns
    -------
    RoadFeedback
        Possibly empty (no fix qualified).
    """
    pts = result.points
    n = pts.time_s.shape[0]
    keep = (
        pts.matched
        & (use_interpolated | ~pts.interpolated)
        & ~pts.outlier
        & (pts.edge >= 0)
        & np.isfinite(pts.lon)
        & np.isfinite(pts.lat)
        & np.isfinite(pts.offset_m)
        & (np.nan_to_num(pts.confidence, nan=0.0) >= min_confidence)
    )
    if accuracy_m is None:
        acc = np.full(n, along_sigma_floor_m)
    else:
        acc = np.broadcast_to(np.asarray(accuracy_m, dtype=np.float64), (n,))
        acc = np.where(np.isfinite(acc), acc, along_sigma_floor_m)
    idx = np.flatnonzero(keep)
    edge = pts.edge[idx].astype(np.int64)
    offset = pts.offset_m[idx]
    length = net.arrays.edge_length_m[edge]
    inner = (offset >= junction_m) & (offset <= length - junction_m)
    idx, edge, offset = idx[inner], edge[inner], offset[inner]
    straight = _bend_deg(net, edge, offset, straight_window_m) <= max_bend_deg
    idx, edge, offset = idx[straight], edge[straight], offset[straight]
    heading = road_bearing_deg(net, edge, offset)
    along = np.maximum(along_sigma_floor_m, along_accuracy_factor * acc[idx])
    return RoadFeedback.from_arrays(
        pts.time_s[idx],
        pts.lon[idx],
        pts.lat[idx],
        heading,
        along,
        np.full(idx.size, cross_sigma_m),
    )
