"""R-trees over the network's segments and the nearby-edge query.

(Over 400 lines on purpose: the two indexes over the same segment boxes and their query kernels
belong together.)

Two indexes over the same segment boxes:

- :func:`build_rtree`, a libspatialindex R-tree (the ``rtree`` package): ``net.rtree``, for
  users who want its API (nearest, intersection, ...). Probing it costs some 10-40 us per
  call through ctypes, and it must not be probed from two threads at once.
- :class:`PackedTree`, a static sort-tile-recursive R-tree packed into numpy arrays and probed
  from compiled code (:func:`roadnets.spatial_kernels.nearby_kernel`): ``net.segment_tree``.
  The matcher's hot path queries it for every fix in one call, without the GIL, and so does
  :meth:`RoadNetwork.nearby_edges <roadnets.RoadNetwork.nearby_edges>`.

Both give the same hits in the same order: where two segments tie (two segments of one road
meeting at a vertex both project a point onto that vertex), the one listed first by
libspatialindex's depth-first traversal was kept, and :class:`PackedTree` keeps that order
as each segment's ``rank`` (the order of a query covering every box is the order of every
other query), so matches do not change with the index that found them.
"""

from __future__ import annotations

from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from rtree import index as rtree_index

    from roadnets.arrays import NetworkArrays

__all__ = [
    "EdgeHits",
    "PackedTree",
    "build_packed_tree",
    "build_rtree",
    "packed_arrays",
    "query_edges",
    "query_packed",
]

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


def _segment_boxes(arrays: NetworkArrays) -> tuple[FloatArray, FloatArray]:
    """``(mins, maxs)``, each ``(n_segments, 2)``: the bounding box of every indexed segment."""
    a = arrays.seg_start
    x0, y0 = arrays.geom_x[a], arrays.geom_y[a]
    x1, y1 = arrays.geom_x[a + 1], arrays.geom_y[a + 1]
    mins = np.column_stack((np.minimum(x0, x1), np.minimum(y0, y1)))
    maxs = np.column_stack((np.maximum(x0, x1), np.maximum(y0, y1)))
    return mins, maxs


def build_rtree(arrays: NetworkArrays) -> rtree_index.Index:
    """Bulk-load an in-memory R-tree with the bounding box of every indexed segment."""
    from rtree import index as rtree_index  # libspatialindex: loaded when first needed

    mins, maxs = _segment_boxes(arrays)
    ids = np.arange(len(mins), dtype=np.int64)
    props = rtree_index.Property()
    props.dimension = 2
    return rtree_index.Index((ids, mins, maxs), properties=props)


#: Entries per node of a :class:`PackedTree`.
PACKED_FANOUT = 16


@dataclass(frozen=True, slots=True)
class PackedTree:
    """
    A static R-tree over the segment boxes, packed sort-tile-recursive into flat arrays.

    Node ``0`` is the root. Nodes ``0..n_inner-1`` are inner nodes whose children are the
    nodes ``child_lo[i]:child_hi[i]``; the others are leaves whose entries are the items
    ``child_lo[i]:child_hi[i]``. ``box`` holds each node's ``(min x, min y, max x, max y)``,
    ``item_box`` each item's and ``item_seg`` the segment it is. ``rank`` orders the
    segments as libspatialindex lists them (see the module docstring).
    """

    box: FloatArray
    child_lo: IntArray
    child_hi: IntArray
    n_inner: int
    item_box: FloatArray
    item_seg: IntArray
    rank: IntArray

    @property
    def nbytes(self) -> int:
        """Memory held by the arrays."""
        parts = (self.box, self.child_lo, self.child_hi, self.item_box, self.item_seg, self.rank)
        return sum(p.nbytes for p in parts)


def _str_pack(box: FloatArray, fanout: int) -> IntArray:
    """Order of ``box`` rows that tiles them into groups of ``fanout`` (sort-tile-recursive)."""
    n = len(box)
    cx = 0.5 * (box[:, 0] + box[:, 2])
    cy = 0.5 * (box[:, 1] + box[:, 3])
    groups = -(-n // fanout)
    slices = max(int(np.ceil(np.sqrt(groups))), 1)
    per_slice = slices * fanout
    by_x = np.argsort(cx, kind="stable")
    slice_of = np.empty(n, dtype=np.int64)
    slice_of[by_x] = np.arange(n) // per_slice
    return np.asarray(np.lexsort((cy, slice_of)), dtype=np.int64)


def _group_boxes(below: FloatArray, starts: IntArray) -> FloatArray:
    """The box around each run ``starts[i]:starts[i + 1]`` of rows of ``below``."""
    return np.column_stack(
        (
            np.minimum.reduceat(below[:, 0], starts),
            np.minimum.reduceat(below[:, 1], starts),
            np.maximum.reduceat(below[:, 2], starts),
            np.maximum.reduceat(below[:, 3], starts),
        )
    )


def build_packed_tree(arrays: NetworkArrays, rank: IntArray | None = None) -> PackedTree:
    """
    Pack the segment boxes into a :class:`PackedTree`.

    ``rank`` orders the segments for ties (:func:`rtree_rank`); the segment index when not
    given. Vectorised: about a microsecond per segment.
    """
    mins, maxs = _segment_boxes(arrays)
    n = len(mins)
    fan = PACKED_FANOUT
    item_box = np.column_stack((mins, maxs)).reshape(n, 4)
    order = _str_pack(item_box, fan) if n else np.zeros(0, dtype=np.int64)
    item_box = np.ascontiguousarray(item_box[order])
    if n:
        starts = np.arange(0, n, fan, dtype=np.int64)
        levels = [(_group_boxes(item_box, starts), starts, np.minimum(starts + fan, n))]
    else:  # one leaf without entries, a box nothing meets
        zero = np.zeros(1, dtype=np.int64)
        levels = [(np.full((1, 4), np.nan), zero, zero)]
    while len(levels[-1][0]) > 1:  # tile each level's nodes, then group them under parents
        box, lo, hi = levels[-1]
        tile = _str_pack(box, fan)
        levels[-1] = (box[tile], lo[tile], hi[tile])
        count = len(box)
        starts = np.arange(0, count, fan, dtype=np.int64)
        levels.append(
            (_group_boxes(levels[-1][0], starts), starts, np.minimum(starts + fan, count))
        )
    # number the nodes from the root down; an inner node's children are in the next level
    levels.reverse()
    first = np.cumsum([0] + [len(box) for box, _, _ in levels])
    child_lo = [
        lo + (first[k + 1] if k + 1 < len(levels) else 0) for k, (_, lo, _) in enumerate(levels)
    ]
    child_hi = [
        hi + (first[k + 1] if k + 1 < len(levels) else 0) for k, (_, _, hi) in enumerate(levels)
    ]
    return PackedTree(
        box=np.ascontiguousarray(np.concatenate([box for box, _, _ in levels]), dtype=np.float64),
        child_lo=np.concatenate(child_lo).astype(np.int64),
        child_hi=np.concatenate(child_hi).astype(np.int64),
        n_inner=int(first[-2]),
        item_box=item_box,
        item_seg=order.astype(np.int64),
        rank=np.ascontiguousarray(np.arange(n) if rank is None else rank, dtype=np.int64),
    )


def rtree_rank(tree: rtree_index.Index, n_segments: int) -> IntArray:
    """
    Each segment's position in the order libspatialindex lists the segments of ``tree``.

    Its queries walk the tree depth first, so one query covering every box lists the
    segments in an order every other query's hits follow.
    """
    if n_segments == 0:
        return np.zeros(0, dtype=np.int64)
    lo_x, lo_y, hi_x, hi_y = tree.bounds
    pad = 1.0 + abs(hi_x - lo_x) + abs(hi_y - lo_y)
    everything = np.array([[lo_x - pad, lo_y - pad]]), np.array([[hi_x + pad, hi_y + pad]])
    ids, _ = tree.intersection_v(*everything)  # type: ignore[no-untyped-call]
    rank = np.full(n_segments, -1, dtype=np.int64)
    rank[np.asarray(ids, dtype=np.int64)] = np.arange(len(ids), dtype=np.int64)
    if (rank < 0).any():
        msg = "the R-tree does not hold every segment"
        raise ValueError(msg)
    return rank


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
    from roadnets.spatial_kernels import bearings_kernel  # numba: imported when first needed

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
    ex, ey = px - qx, py - qy
    dist = np.sqrt(ex * ex + ey * ey)  # as nearby_kernel works it out, to the bit
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
    dx, dy = dx[keep], dy[keep]

    twin = arrays.edge_twin[edge].astype(np.int64)
    has_twin = twin >= 0
    point = np.concatenate((point, point[has_twin]))
    edge = np.concatenate((edge, twin[has_twin]))
    dist = np.concatenate((dist, dist[has_twin]))
    length = arrays.edge_length_m[twin[has_twin]]
    offset = np.concatenate((offset, length - offset[has_twin]))
    qx = np.concatenate((qx, qx[has_twin]))
    qy = np.concatenate((qy, qy[has_twin]))
    reverse = np.concatenate((np.zeros(len(dx), dtype=bool), np.ones(len(length), dtype=bool)))
    bearing = bearings_kernel(
        np.concatenate((dx, dx[has_twin])), np.concatenate((dy, dy[has_twin])), reverse
    )

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


def query_packed(
    tree: PackedTree,
    arrays: NetworkArrays,
    x: FloatArray,
    y: FloatArray,
    radius_m: FloatArray,
    *,
    max_per_point: int | None = None,
) -> EdgeHits:
    """
    :func:`query_edges` on a :class:`PackedTree`: the same rows, without locks or ctypes.

    The probe and everything after it run compiled, without the GIL, so threads query one
    network at once.
    """
    # copies of their own, read-only as the matcher's are: one compiled variant for both
    x = np.array(x, dtype=np.float64)
    y = np.array(y, dtype=np.float64)
    radius = np.array(np.broadcast_to(np.asarray(radius_m, dtype=np.float64), x.shape))
    for column in (x, y, radius):
        column.flags.writeable = False
    from roadnets.spatial_kernels import nearby_kernel  # numba: imported when first needed

    top = 0 if max_per_point is None else int(max_per_point)
    args = (*packed_arrays(tree, arrays), x, y, radius, top, PLACE_SEPARATION_M)
    ptr, edge, dist, offset, qx, qy, bearing = nearby_kernel(*args)
    point = np.repeat(np.arange(len(x), dtype=np.int64), np.diff(ptr))
    return EdgeHits(point, edge, dist, offset, qx, qy, bearing)


def packed_arrays(tree: PackedTree, arrays: NetworkArrays) -> tuple[Any, ...]:
    """The first arguments of :func:`~roadnets.spatial_kernels.nearby_kernel`: tree and network."""
    return (
        tree.box,
        tree.child_lo,
        tree.child_hi,
        tree.n_inner,
        tree.item_box,
        tree.item_seg,
        tree.rank,
        arrays.seg_start,
        arrays.seg_edge,
        arrays.geom_x,
        arrays.geom_y,
        arrays.geom_cum_m,
        arrays.edge_twin,
        arrays.edge_length_m,
    )
