"""Geometry of paths of edge stretches, compiled: places on edges, vertices, projections."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numba import njit

from roadnets.spatial_kernels import point_on_edge

if TYPE_CHECKING:
    from roadnets import RoadNetwork

__all__ = ["network_geometry", "point_on_edge", "project_kernel", "stretch_vertices"]


def network_geometry(net: RoadNetwork) -> tuple[Any, ...]:
    """``(edge_len, geom_ptr, geom_x, geom_y, geom_cum, vertex_pos)``: what these kernels read."""
    return net.kernel_geometry


@njit(cache=True, nogil=True)
def stretch_vertices(edge, start_m, end_m, geom):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Vertices of a path of edge stretches with their distance along it, in order.

    The stretches' ends (interpolated) and the edges' vertices between them; ``geom`` is
    ``(edge_len, geom_ptr, geom_x, geom_y, geom_cum, vertex_pos)``. Where two have the same
    distance, a stretch's start comes before the vertices, and they before its end.
    """
    geom_ptr, geom_x, geom_y, geom_cum = geom[1], geom[2], geom[3], geom[4]
    n = len(edge)
    base = np.empty(n)
    acc = 0.0
    inner = 0
    for i in range(n):
        base[i] = acc
        acc += end_m[i] - start_m[i]
        for v in range(geom_ptr[edge[i]], geom_ptr[edge[i] + 1]):
            if start_m[i] < geom_cum[v] < end_m[i]:
                inner += 1
    total = 2 * n + inner
    x = np.empty(total)
    y = np.empty(total)
    along = np.empty(total)
    for i in range(n):
        x[i], y[i] = point_on_edge(edge[i], start_m[i], *geom)
        along[i] = base[i]
        k = n + inner + i
        x[k], y[k] = point_on_edge(edge[i], end_m[i], *geom)
        along[k] = base[i] + end_m[i] - start_m[i]
    k = n
    for i in range(n):
        for v in range(geom_ptr[edge[i]], geom_ptr[edge[i] + 1]):
            if start_m[i] < geom_cum[v] < end_m[i]:
                x[k], y[k] = geom_x[v], geom_y[v]
                along[k] = base[i] + geom_cum[v] - start_m[i]
                k += 1
    order = np.argsort(along, kind="mergesort")
    return x[order], y[order], along[order]


@njit(cache=True, nogil=True)
def project_kernel(px, py, lo, hi, vx, vy, va):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Nearest point of a polyline (vertices ``vx, vy`` at distances ``va``) within [lo, hi]."""
    n = len(px)
    along = np.empty(n)
    dist = np.empty(n)
    nv = len(va)
    for i in range(n):
        best_d = np.inf
        best_a = lo[i]
        k0 = max(np.searchsorted(va, lo[i], side="right") - 1, 0)
        k1 = min(np.searchsorted(va, hi[i], side="left"), nv - 1)
        if nv == 1 or k0 >= k1:
            k = min(k0, nv - 1)
            best_a = min(max(va[k], lo[i]), hi[i])
            best_d = np.hypot(px[i] - vx[k], py[i] - vy[k])
        for k in range(k0, k1):
            seg = va[k + 1] - va[k]
            ax, ay = vx[k], vy[k]
            dx, dy = vx[k + 1] - ax, vy[k + 1] - ay
            d2 = dx * dx + dy * dy
            t = ((px[i] - ax) * dx + (py[i] - ay) * dy) / d2 if d2 > 0 and seg > 0 else 0.0
            a = va[k] + min(max(t, 0.0), 1.0) * seg
            a = min(max(a, lo[i]), hi[i])
            f = (a - va[k]) / seg if seg > 0 else 0.0
            qx, qy = ax + f * dx, ay + f * dy
            ex, ey = px[i] - qx, py[i] - qy
            d = np.sqrt(ex * ex + ey * ey)  # not hypot: a libm call, slower than the rest
            if d < best_d:
                best_d = d
                best_a = a
        along[i] = best_a
        dist[i] = best_d
    return along, dist
