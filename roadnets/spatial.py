"""R-tree over the network's segments and the vectorised nearby-edge query."""

from __future__ import annotations

from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from rtree import index as rtree_index

    from roadnets.arrays import NetworkArrays

__all__ = ["EdgeHits", "build_rtree", "query_edges"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True, slots=True)
class EdgeHits:
    """
    Directed edges near query points, sorted by point, then distance.

    Attributes
    ----------
    point
        Index of the query point each row belongs to.
    edge
        Directed edge index. Both directions of a two-way road appear as their own rows, and
        an edge that passes a point twice (a hairpin) appears once for each pass.
    distance_m
        Distance from the point to its projection on the edge, metres.
    offset_m
        Distance along the edge from its start to the projection, metres (geodesic, as
        ``edge_length_m``: the projection's planar fraction of its segment times the
        segment's geodesic length).
    x, y
        The projection, metres in the network CRS.
    bearing_deg
        Direction of travel of the edge at the projection, degrees clockwise from north.
    """

    point: IntArray
    edge: IntArray
    distance_m: FloatArray
    offset_m: FloatArray
    x: FloatArray
    y: FloatArray
    bearing_deg: FloatArray

    def __len__(self) -> int:
        return len(self.point)


def build_rtree(arrays: NetworkArrays) -> rtree_index.Index:
    """Bulk-load an in-memory R-tree with the bounding box of every indexed segment."""
    from rtree import index as rtree_index  # libspatialindex: loaded when first needed

    a = arrays.seg_start
    x0, y0 = arrays.geom_x[a], arrays.geom_y[a]
    x1, y1 = arrays.geom_x[a + 1], arrays.geom_y[a + 1]
    mins = np.column_stack((np.minimum(x0, x1), np.minimum(y0, y1)))
    maxs = np.column_stack((np.maximum(x0, x1), np.maximum(y0, y1)))
    ids = np.arange(len(a), dtype=np.int64)
    props = rtree_index.Property()
    props.dimension = 2
    return rtree_index.Index((ids, mins, maxs), properties=props)


#: Two nearest places on one edge closer than this along it are one place (metres).
PLACE_SEPARATION_M = 20.0


def _nearest_places(
    point: IntArray, edge: IntArray, offset: FloatArray, dist: FloatArray
) -> IntArray:
    """
    Rows to keep: the nearest place of each edge to each point, and any other.

    An edge may come near a point again further along (a hairpin passes a point twice); each
    such place is a candidate of its own.

    A row is kept when it is a local minimum of the distance along its edge (among the
    segments in reach) and no nearer kept place of the same edge lies within
    :data:`PLACE_SEPARATION_M` along it.
    """
    order = np.lexsort((offset, edge, point))
    p, e, o, d = point[order], edge[order], offset[order], dist[order]
    same_prev = np.zeros(len(p), dtype=bool)
    same_prev[1:] = (p[1:] == p[:-1]) & (e[1:] == e[:-1])
    same_next = np.zeros(len(p), dtype=bool)
    same_next[:-1] = same_prev[1:]
    d_prev = np.concatenate(([np.inf], d[:-1]))
    d_next = np.concatenate((d[1:], [np.inf]))
    local = (~same_prev | (d <= d_prev)) & (~same_next | (d <= d_next))
    order, p, e, o, d = order[local], p[local], e[local], o[local], d[local]
    # of two minima of one edge close together (e.g. both ends of a shared vertex), the nearer
    close = np.zeros(len(p), dtype=bool)
    close[1:] = (p[1:] == p[:-1]) & (e[1:] == e[:-1]) & (o[1:] - o[:-1] < PLACE_SEPARATION_M)
    worse_than_prev = close & (d >= np.concatenate(([np.inf], d[:-1])))
    worse_than_next = np.zeros(len(p), dtype=bool)
    worse_than_next[:-1] = close[1:] & (d[:-1] > d[1:])
    return np.asarray(order[~(worse_than_prev | worse_than_next)], dtype=np.int64)


#: Consecutive query points in one square of this size share one R-tree probe (metres).
BLOCK_M = 100.0


def _point_segment_pairs(
    tree: rtree_index.Index,
    x: FloatArray,
    y: FloatArray,
    radius: FloatArray,
    lock: AbstractContextManager[Any] | None = None,
) -> tuple[IntArray, IntArray]:
    """
    (point, segment) pairs whose segment box meets the point's search box, or a little more.

    Runs of consecutive points in the same :data:`BLOCK_M` square (a trace sampled every
    second is one run for several fixes) share one R-tree probe with their joint search box;
    every point of a run is paired with every segment found for it. The exact distance test
    follows in :func:`query_edges`, so the extra pairs only cost arithmetic, while the
    per-probe cost of the tree is paid once per run instead of once per point.
    """
    n = len(x)
    key = np.floor(x / BLOCK_M) * 1e7 + np.floor(y / BLOCK_M)
    first = np.ones(n, dtype=bool)
    first[1:] = key[1:] != key[:-1]
    starts = np.flatnonzero(first)
    sizes = np.diff(np.append(starts, n))
    mins = np.column_stack(
        (np.minimum.reduceat(x - radius, starts), np.minimum.reduceat(y - radius, starts))
    )
    maxs = np.column_stack(
        (np.maximum.reduceat(x + radius, starts), np.maximum.reduceat(y + radius, starts))
    )
    with lock or nullcontext():
        found, counts = tree.intersection_v(mins, maxs)  # type: ignore[no-untyped-call]
    counts = counts.astype(np.int64)
    found_start = np.cumsum(counts) - counts
    per_block = sizes * counts
    block = np.repeat(np.arange(len(starts)), per_block)
    k = np.arange(int(per_block.sum()), dtype=np.int64) - np.repeat(
        np.cumsum(per_block) - per_block, per_block
    )
    width = counts[block]
    point = starts[block] + k // width
    seg = found[found_start[block] + k % width].astype(np.int64)
    return point.astype(np.int64), seg


def query_edges(
    tree: rtree_index.Index,
    arrays: NetworkArrays,
    x: FloatArray,
    y: FloatArray,
    radius_m: FloatArray,
    *,
    max_per_point: int | None = None,
    lock: AbstractContextManager[Any] | None = None,
) -> EdgeHits:
    """
    Every directed edge within a radius of each point, with its projection.

    Parameters
    ----------
    tree
        The R-tree from :func:`build_rtree` over ``arrays``.
    arrays
        The compiled network.
    x, y
        Query points, metres in the network CRS.
    radius_m
        Search radius per point (or one value broadcast to all), metres.
    max_per_point
        Keep only this many nearest directed edges per point.
    lock
        Held around the R-tree probe: libspatialindex indexes must not be queried from two
        threads at once.
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    radius = np.broadcast_to(np.asarray(radius_m, dtype=np.float64), x.shape)
    point, seg = _point_segment_pairs(tree, x, y, radius, lock)
    start = arrays.seg_start[seg]
    ax, ay = arrays.geom_x[start], arrays.geom_y[start]
    dx, dy = arrays.geom_x[start + 1] - ax, arrays.geom_y[start + 1] - ay
    px, py = x[point], y[point]
    seg_len2 = dx * dx + dy * dy
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(seg_len2 > 0, ((px - ax) * dx + (py - ay) * dy) / seg_len2, 0.0)
    t = np.clip(t, 0.0, 1.0)
    qx, qy = ax + t * dx, ay + t * dy
    dist = np.hypot(px - qx, py - qy)
    near = dist <= radius[point]
    point, seg, dist, t, qx, qy = point[near], seg[near], dist[near], t[near], qx[near], qy[near]
    dx, dy, start = dx[near], dy[near], start[near]
    edge = arrays.seg_edge[seg].astype(np.int64)
    # the planar fraction of the segment times its geodesic length: offsets along an edge
    # add up to its (geodesic) length whatever the projection's scale there
    cum = arrays.geom_cum_m
    offset = cum[start] + t * (cum[start + 1] - cum[start])

    keep = _nearest_places(point, edge, offset, dist)
    point, edge, offset = point[keep], edge[keep], offset[keep]
    dist, qx, qy = dist[keep], qx[keep], qy[keep]
    bearing = np.degrees(np.arctan2(dx[keep], dy[keep])) % 360.0

    twin = arrays.edge_twin[edge].astype(np.int64)
    has_twin = twin >= 0
    point = np.concatenate((point, point[has_twin]))
    edge = np.concatenate((edge, twin[has_twin]))
    dist = np.concatenate((dist, dist[has_twin]))
    length = arrays.edge_length_m[twin[has_twin]]
    offset = np.concatenate((offset, length - offset[has_twin]))
    qx = np.concatenate((qx, qx[has_twin]))
    qy = np.concatenate((qy, qy[has_twin]))
    bearing = np.concatenate((bearing, (bearing[has_twin] + 180.0) % 360.0))

    order = np.lexsort((edge, dist, point))
    if max_per_point is not None:
        sorted_point = point[order]
        group_start = np.searchsorted(sorted_point, sorted_point, side="left")
        rank = np.arange(len(order)) - group_start
        order = order[rank < max_per_point]
    return EdgeHits(
        point=point[order],
        edge=edge[order],
        distance_m=dist[order],
        offset_m=np.clip(offset[order], 0.0, arrays.edge_length_m[edge[order]]),
        x=qx[order],
        y=qy[order],
        bearing_deg=bearing[order],
    )
