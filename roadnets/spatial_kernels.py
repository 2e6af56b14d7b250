"""Compiled spatial kernels: the packed tree's probe, nearby edges, places and paths on edges.

Separate from :mod:`roadnets.spatial` so that importing roadnets does not import numba.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from roadnets.tmerc import inverse_kernel

__all__ = [
    "bearings_kernel",
    "nearby_kernel",
    "path_polyline_kernel",
    "point_on_edge",
    "points_on_edges",
]


#: How much a packed tree's probe box is widened, metres: a segment the exact distance test
#: keeps is never missed by the box test because of rounding.
_PROBE_PAD_M = 1e-6


@njit(cache=True, nogil=True, inline="always")
def _bearing(dx, dy, reverse):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    Direction of travel along ``(dx, dy)`` (backwards if ``reverse``), degrees from north.

    Python's ``% 360.0`` to the bit without its C call: on ``(-180, 180]`` that is the value
    (``+0.0`` for ``-0.0``) or, below zero, the value plus 360; on ``[180, 540)``, minus 360
    past 360 (exact there).
    """
    bearing = math.degrees(math.atan2(dx, dy))
    bearing = bearing + 360.0 if bearing < 0.0 else bearing + 0.0  # + 0.0: -0.0 becomes 0.0
    if reverse:
        bearing += 180.0
        if bearing >= 360.0:
            bearing -= 360.0
    return bearing


@njit(cache=True, nogil=True)
def bearings_kernel(dx, dy, reverse):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    Direction of travel along segments ``(dx, dy)``, degrees clockwise from north.

    Reversed where ``reverse``: the bearing :func:`nearby_kernel` gives each row, for
    :func:`roadnets.spatial.query_edges`' rows, so that both queries agree to the bit.
    """
    out = np.empty(len(dx))
    for k in range(len(dx)):
        out[k] = _bearing(dx[k], dy[k], reverse[k])
    return out


@njit(cache=True, nogil=True)
def _probe(box, child_lo, child_hi, n_inner, item_box, item_seg, x0, y0, x1, y1, stack, found):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    How many segments' boxes meet ``[x0, x1] x [y0, y1]``; the first of them into ``found``.

    ``found`` takes the first ``len(found)``; ``stack`` holds at least one entry per tree
    node (every node is pushed at most once). A count above ``len(found)`` tells the caller
    to probe again with a larger ``found``: the arrays never grow inside the loop, which
    keeps it several times faster than a loop that may reallocate them.
    """
    n_found = 0
    capacity = len(found)
    stack[0] = 0
    top = 1
    while top > 0:
        top -= 1
        node = stack[top]
        if box[node, 0] > x1 or box[node, 2] < x0 or box[node, 1] > y1 or box[node, 3] < y0:
            continue
        if node < n_inner:
            for c in range(child_lo[node], child_hi[node]):
                stack[top] = c
                top += 1
        else:
            for k in range(child_lo[node], child_hi[node]):
                if (
                    item_box[k, 0] > x1
                    or item_box[k, 2] < x0
                    or item_box[k, 1] > y1
                    or item_box[k, 3] < y0
                ):
                    continue
                if n_found < capacity:
                    found[n_found] = item_seg[k]
                n_found += 1
    return n_found


@njit(cache=True, nogil=True)
def nearby_kernel(  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    box,
    child_lo,
    child_hi,
    n_inner,
    item_box,
    item_seg,
    rank,
    seg_start,
    seg_edge,
    geom_x,
    geom_y,
    geom_cum,
    edge_twin,
    edge_length,
    x,
    y,
    radius,
    max_per_point,
    separation,
):
    """
    Every directed edge within ``radius[i]`` of each point, projected, nearest first.

    The compiled body of :func:`roadnets.spatial.query_packed`: the rows of
    :func:`roadnets.spatial.query_edges` in the same order. Per point, the segments the
    tree finds are projected in ``rank`` order and kept within the radius; the nearest place
    of each edge (and any other one ``separation`` metres along it, as
    ``roadnets.spatial._nearest_places`` keeps them) stays, the reverse twin of each is
    added, and the rows are sorted by distance, then edge; at most ``max_per_point`` are
    kept (``<= 0``: all). Returns ``(ptr, edge, distance, offset, x, y, bearing)``, the
    rows of point ``i`` at ``ptr[i]:ptr[i + 1]``; ``bearing`` is the direction of travel on
    the row's edge there, degrees clockwise from north.
    """
    n = len(x)
    ptr = np.zeros(n + 1, dtype=np.int64)
    cap = max(16, n * (max_per_point if max_per_point > 0 else 16))
    out_f = np.empty((cap, 6))  # distance, offset, x, y, dx, dy of each row kept
    out_i = np.empty((cap, 2), dtype=np.int64)  # edge, reverse twin (1) or not (0)
    stack = np.empty(len(box), dtype=np.int64)
    found = np.empty(256, dtype=np.int64)
    # one point's rows: those found (0..m-1), then the twins of those kept
    row_f = np.empty((512, 6))
    row_e = np.empty(512, dtype=np.int64)
    order = np.empty(512, dtype=np.int64)
    local = np.empty(512, dtype=np.int64)
    count = 0
    for i in range(n):
        px, py, r = x[i], y[i], radius[i]
        pad = r + _PROBE_PAD_M
        x0, y0, x1, y1 = px - pad, py - pad, px + pad, py + pad
        tree = (box, child_lo, child_hi, n_inner, item_box, item_seg)
        n_found = _probe(*tree, x0, y0, x1, y1, stack, found)
        if n_found > len(found):
            found = np.empty(2 * n_found, dtype=np.int64)
            _probe(*tree, x0, y0, x1, y1, stack, found)
        ptr[i + 1] = count
        if n_found == 0:
            continue
        _sort_by_rank(found, n_found, rank)
        if 2 * n_found > len(row_e):
            size = 2 * n_found
            row_f = np.empty((size, 6))
            row_e = np.empty(size, dtype=np.int64)
            order = np.empty(size, dtype=np.int64)
            local = np.empty(size, dtype=np.int64)
        # project in rank order, keep those within the radius
        m = 0
        for k in range(n_found):
            seg = found[k]
            start = seg_start[seg]
            ax, ay = geom_x[start], geom_y[start]
            dx, dy = geom_x[start + 1] - ax, geom_y[start + 1] - ay
            seg_len2 = dx * dx + dy * dy
            t = ((px - ax) * dx + (py - ay) * dy) / seg_len2 if seg_len2 > 0 else 0.0
            t = min(max(t, 0.0), 1.0)
            qx, qy = ax + t * dx, ay + t * dy
            ex, ey = px - qx, py - qy
            d = math.sqrt(ex * ex + ey * ey)  # not hypot: a libm call, a tenth of the kernel
            if not d <= r:
                continue
            row_e[m] = seg_edge[seg]
            row_f[m, 0] = d
            row_f[m, 1] = geom_cum[start] + t * (geom_cum[start + 1] - geom_cum[start])
            row_f[m, 2] = qx
            row_f[m, 3] = qy
            row_f[m, 4] = dx
            row_f[m, 5] = dy
            order[m] = m
            m += 1
        if m == 0:
            continue
        # the nearest place of each edge (and others far enough along it), by edge and offset
        _sort_rows(order, m, row_e, row_f, 1, True)
        n_local = 0
        for k in range(m):
            row = order[k]
            same_prev = k > 0 and row_e[order[k - 1]] == row_e[row]
            same_next = k + 1 < m and row_e[order[k + 1]] == row_e[row]
            d = row_f[row, 0]
            if (not same_prev or d <= row_f[order[k - 1], 0]) and (
                not same_next or d <= row_f[order[k + 1], 0]
            ):
                local[n_local] = row
                n_local += 1
        n_keep = 0
        for k in range(n_local):  # order[] now takes the rows kept, by edge and offset
            row = local[k]
            if k > 0:
                prev = local[k - 1]
                close = row_e[prev] == row_e[row] and row_f[row, 1] - row_f[prev, 1] < separation
                if close and row_f[row, 0] >= row_f[prev, 0]:
                    continue
            if k + 1 < n_local:
                nxt = local[k + 1]
                close = row_e[nxt] == row_e[row] and row_f[nxt, 1] - row_f[row, 1] < separation
                if close and row_f[row, 0] > row_f[nxt, 0]:
                    continue
            order[n_keep] = row
            n_keep += 1
        # the kept places, then their reverse twins (rows m..), sorted by distance, then edge
        total = n_keep
        for k in range(n_keep):
            row = order[k]
            twin = edge_twin[row_e[row]]
            if twin >= 0:
                j = m + total - n_keep
                row_e[j] = twin
                row_f[j, 0] = row_f[row, 0]
                row_f[j, 1] = edge_length[twin] - row_f[row, 1]
                for c in range(2, 6):
                    row_f[j, c] = row_f[row, c]
                order[total] = j
                total += 1
        _sort_rows(order, total, row_e, row_f, 0, False)
        take = total if max_per_point <= 0 else min(total, max_per_point)
        if count + take > len(out_i):
            size = max(2 * len(out_i), count + take)
            grown_f = np.empty((size, 6))
            grown_f[:count] = out_f[:count]
            grown_i = np.empty((size, 2), dtype=np.int64)
            grown_i[:count] = out_i[:count]
            out_f, out_i = grown_f, grown_i
        for k in range(take):
            row = order[k]
            e = row_e[row]
            out_i[count, 0] = e
            out_i[count, 1] = 1 if row >= m else 0
            out_f[count, 0] = row_f[row, 0]
            out_f[count, 1] = min(max(row_f[row, 1], 0.0), edge_length[e])
            for c in range(2, 6):
                out_f[count, c] = row_f[row, c]
            count += 1
        ptr[i + 1] = count
    bearing = np.empty(count)
    for k in range(count):
        bearing[k] = _bearing(out_f[k, 4], out_f[k, 5], out_i[k, 1] == 1)
    return (
        ptr,
        out_i[:count, 0].copy(),
        out_f[:count, 0].copy(),
        out_f[:count, 1].copy(),
        out_f[:count, 2].copy(),
        out_f[:count, 3].copy(),
        bearing,
    )


@njit(cache=True, nogil=True)
def _sort_by_rank(found, n, rank):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """Sort ``found[:n]`` (distinct segments) by their rank, in place."""
    if n > 64:
        keys = np.empty(n, dtype=np.int64)
        for k in range(n):
            keys[k] = rank[found[k]]
        by = np.argsort(keys)
        found[:n] = found[:n][by]
        return
    for k in range(1, n):
        item = found[k]
        key = rank[item]
        j = k - 1
        while j >= 0 and rank[found[j]] > key:
            found[j + 1] = found[j]
            j -= 1
        found[j + 1] = item


@njit(cache=True, nogil=True)
def _sort_rows(order, n, row_e, row_f, col, edge_first):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Stable sort of ``order[:n]`` by edge, then ``row_f[:, col]`` (or the other way round)."""
    if n > 64:
        part = order[:n].copy()
        if edge_first:
            part = part[np.argsort(row_f[part, col], kind="mergesort")]
            part = part[np.argsort(row_e[part], kind="mergesort")]
        else:
            part = part[np.argsort(row_e[part], kind="mergesort")]
            part = part[np.argsort(row_f[part, col], kind="mergesort")]
        order[:n] = part
        return
    for k in range(1, n):
        item = order[k]
        e, v = row_e[item], row_f[item, col]
        j = k - 1
        while j >= 0:
            other = order[j]
            oe, ov = row_e[other], row_f[other, col]
            by_edge = oe > e or (oe == e and ov > v)
            by_value = ov > v or (ov == v and oe > e)
            if not (by_edge if edge_first else by_value):
                break
            order[j + 1] = other
            j -= 1
        order[j + 1] = item


@njit(cache=True, nogil=True)
def point_on_edge(edge, offset, edge_len, geom_ptr, geom_x, geom_y, geom_cum, vertex_pos):  # type: ignore[no-untyped-def]  # pragma: no cover
    """:meth:`RoadNetwork.point_on_edge <roadnets.RoadNetwork.point_on_edge>` of one place."""
    offset = min(max(offset, 0.0), edge_len[edge])
    base = vertex_pos[geom_ptr[edge]]
    i = np.searchsorted(vertex_pos, base + offset, side="right") - 1
    i = min(max(i, geom_ptr[edge]), geom_ptr[edge + 1] - 2)
    seg = geom_cum[i + 1] - geom_cum[i]
    t = (offset - geom_cum[i]) / seg if seg > 0 else 0.0
    t = min(max(t, 0.0), 1.0)
    return geom_x[i] + t * (geom_x[i + 1] - geom_x[i]), geom_y[i] + t * (geom_y[i + 1] - geom_y[i])


@njit(cache=True, nogil=True)
def points_on_edges(edge, offset, edge_len, geom_ptr, geom_x, geom_y, geom_cum, vertex_pos):  # type: ignore[no-untyped-def]  # pragma: no cover
    """:func:`point_on_edge` of every place; a NaN offset gives a NaN position."""
    x = np.empty(len(edge))
    y = np.empty(len(edge))
    for k in range(len(edge)):
        if np.isnan(offset[k]):
            x[k] = y[k] = np.nan
        else:
            x[k], y[k] = point_on_edge(
                edge[k], offset[k], edge_len, geom_ptr, geom_x, geom_y, geom_cum, vertex_pos
            )
    return x, y


@njit(cache=True, nogil=True, inline="always")
def _append(xs, ys, vertex, n, x, y, v):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    Append ``(x, y)``, network vertex ``v`` (-1: a point between vertices); the new count.

    Not when it lies within 1e-9 m of the last point.
    """
    if n > 0 and abs(x - xs[n - 1]) < 1e-9 and abs(y - ys[n - 1]) < 1e-9:
        return n
    xs[n] = x
    ys[n] = y
    vertex[n] = v
    return n + 1


@njit(cache=True, nogil=True, inline="always")
def _end_vertex(e, x, y, geom_ptr, geom_x, geom_y):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """Edge ``e``'s first or last vertex if ``(x, y)`` is exactly that vertex, else -1."""
    for v in (geom_ptr[e], geom_ptr[e + 1] - 1):
        if x == geom_x[v] and y == geom_y[v]:
            return v
    return -1


@njit(cache=True, nogil=True)
def _path_walk(edge, start_m, end_m, geom):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    :func:`path_polyline_kernel`'s points, and the network vertex each one is (-1: none).

    A stretch's end counts as its edge's end vertex only where it is that vertex exactly.
    """
    geom_ptr, geom_x, geom_y, geom_cum_m = geom[1], geom[2], geom[3], geom[4]
    cap = 2 * len(edge)
    for k in range(len(edge)):
        cap += geom_ptr[edge[k] + 1] - geom_ptr[edge[k]]
    xs = np.empty(cap)
    ys = np.empty(cap)
    vertex = np.empty(cap, dtype=np.int64)
    n = 0
    for k in range(len(edge)):
        e, lo, hi = edge[k], start_m[k], end_m[k]
        sx, sy = point_on_edge(e, lo, *geom)
        ex, ey = point_on_edge(e, hi, *geom)
        sv = _end_vertex(e, sx, sy, geom_ptr, geom_x, geom_y)
        ev = _end_vertex(e, ex, ey, geom_ptr, geom_x, geom_y)
        if lo - 1.0 > hi + 1.0:  # backwards: no vertex lies between
            n = _append(xs, ys, vertex, n, ex, ey, ev)
            n = _append(xs, ys, vertex, n, sx, sy, sv)
            continue
        n = _append(xs, ys, vertex, n, sx, sy, sv)
        for v in range(geom_ptr[e], geom_ptr[e + 1]):
            if lo < geom_cum_m[v] < hi:
                n = _append(xs, ys, vertex, n, geom_x[v], geom_y[v], v)
        n = _append(xs, ys, vertex, n, ex, ey, ev)
    return xs[:n], ys[:n], vertex[:n]


@njit(cache=True, nogil=True)
def path_polyline_kernel(edge, start_m, end_m, geom):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    Vertices of a path of edge stretches (see :meth:`~roadnets.RoadNetwork.path_polyline`).

    ``geom`` is :attr:`~roadnets.RoadNetwork.kernel_geometry`.

    Per stretch: its start, the edge's vertices strictly between start and end, its end (the
    end first when it lies more than 2 m before the start); a point within 1e-9 m of the one
    before it is left out.
    """
    xs, ys, _ = _path_walk(edge, start_m, end_m, geom)
    return xs, ys


@njit(cache=True, nogil=True)
def path_lonlat_kernel(edge, start_m, end_m, geom, vertex_lonlat, inverse):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    :func:`path_polyline_kernel`'s vertices unprojected to WGS84 lon/lat degrees, in one call.

    ``vertex_lonlat`` is the network's ``(geom_lon, geom_lat)``: the vertices' own degrees,
    read rather than unprojected again (the same numbers); only the points between vertices
    (a path's ends, mostly) are unprojected, by ``inverse``, the network's
    :attr:`~roadnets.tmerc.TransverseMercator.inverse_parameters`.
    """
    geom_lon, geom_lat = vertex_lonlat
    xs, ys, vertex = _path_walk(edge, start_m, end_m, geom)
    read = np.maximum(vertex, 0)  # the points between vertices are overwritten below
    lon, lat = geom_lon[read], geom_lat[read]
    between = np.flatnonzero(vertex < 0)
    lon[between], lat[between] = inverse_kernel(xs[between], ys[between], *inverse)
    return lon, lat
