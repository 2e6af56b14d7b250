"""The compiled gathers of :mod:`roadnets.names`: way names, and edges with their names.

Separate from :mod:`roadnets.names` so that importing roadnets (and loading a network) does
not import numba.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["edge_records_kernel", "gather_edges", "gather_names"]


@njit(cache=True, nogil=True, inline="always")
def _find_name(ids, ptr, way, k, start, size):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Note where ``way``'s name starts and its length as entry ``k``; return the length."""
    i = np.searchsorted(ids, way)
    if i < len(ids) and ids[i] == way:
        start[k] = ptr[i]
        size[k] = ptr[i + 1] - ptr[i]
    return size[k]


@njit(cache=True, nogil=True, inline="always")
def _joined(blob, start, size, total):  # type: ignore[no-untyped-def]  # pragma: no cover
    """The names ``blob[start:start + size]`` NUL-separated, ``total`` bytes."""
    joined = np.zeros(total, dtype=np.uint8)
    at = 0
    for k in range(len(start)):
        if k:
            at += 1  # the NUL after the previous name
        for j in range(start[k], start[k] + size[k]):
            joined[at] = blob[j]
            at += 1
    return joined


@njit(cache=True, nogil=True)
def gather_names(ids, ptr, blob, ways):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    The UTF-8 bytes of each way's name (nothing where it has none), NUL-separated.

    Also where each name starts in ``blob`` and how long it is (0 for none). ``ids`` are
    the sorted named ways, name ``i`` is ``blob[ptr[i]:ptr[i + 1]]``.
    """
    n = len(ways)
    start = np.zeros(n, dtype=np.int64)
    size = np.zeros(n, dtype=np.int64)
    total = max(n - 1, 0)
    for k in range(n):
        total += _find_name(ids, ptr, ways[k], k, start, size)
    return _joined(blob, start, size, total), start, size


@njit(cache=True, nogil=True)
def edge_records_kernel(  # type: ignore[no-untyped-def]  # pragma: no cover
    edge, node_osm_id, edge_u, edge_v, edge_key, edge_way_id, edge_length_m, edge_speed_mps,
    edge_class, ids, ptr,
):  # fmt: skip
    """
    What the network's arrays say about each of the edges ``edge``, and where their names are.

    Returns one row per column of whole numbers: the OSM ``u``, ``v``, ``key`` and way, the
    road class index, then where each way's name starts in the names' bytes and its length
    (0 for none); one row per column of reals: the length and the speed limit in km/h
    (``edge_speed_mps * 3.6``); and the bytes the names take NUL-separated. Raises
    ``IndexError`` for an edge outside the arrays.
    """
    n = len(edge)
    whole = np.zeros((7, n), dtype=np.int64)
    real = np.empty((2, n), dtype=np.float64)
    start, size = whole[5], whole[6]
    total = max(n - 1, 0)
    for k in range(n):
        e = edge[k]
        if e < 0 or e >= len(edge_u):
            msg = "an edge index is out of range for the network"
            raise IndexError(msg)
        whole[0, k] = node_osm_id[edge_u[e]]
        whole[1, k] = node_osm_id[edge_v[e]]
        whole[2, k] = edge_key[e]
        whole[3, k] = edge_way_id[e]
        whole[4, k] = edge_class[e]
        real[0, k] = edge_length_m[e]
        real[1, k] = np.float64(edge_speed_mps[e]) * 3.6
        total += _find_name(ids, ptr, whole[3, k], k, start, size)
    return whole, real, total


@njit(cache=True, nogil=True)
def gather_edges(  # type: ignore[no-untyped-def]  # pragma: no cover
    edge, node_osm_id, edge_u, edge_v, edge_key, edge_way_id, edge_length_m, edge_speed_mps,
    edge_class, ids, ptr, blob,
):  # fmt: skip
    """
    :func:`edge_records_kernel`, the names gathered as :func:`gather_names` gives them.

    (Three arrays rather than ten: each array returned costs a few hundred ns.)
    """
    whole, real, total = edge_records_kernel(
        edge, node_osm_id, edge_u, edge_v, edge_key, edge_way_id, edge_length_m,
        edge_speed_mps, edge_class, ids, ptr,
    )  # fmt: skip
    return whole, real, _joined(blob, whole[5], whole[6], total)
