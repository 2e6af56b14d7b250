"""The compiled gathers of :mod:`roadnets.names`: way names, and edges with their names.

Separate from :mod:`roadnets.names` so that importing roadnets (and loading a network) does
not import numba.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["gather_edges", "gather_names"]


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
def gather_edges(  # type: ignore[no-untyped-def]  # pragma: no cover
    edge, node_osm_id, edge_u, edge_v, edge_key, edge_way_id, edge_length_m, edge_speed_mps,
    edge_class, ids, ptr, blob,
):  # fmt: skip
    """
    What the network's arrays say about each of the edges ``edge``, and their ways' names.

    Returns the OSM ``u``, ``v``, ``key`` and way, the length, the speed limit in km/h
    (``edge_speed_mps * 3.6``), the road class index, then the names as
    :func:`gather_names` gives them (NUL-separated bytes, starts and lengths in ``blob``).
    Raises ``IndexError`` for an edge outside the arrays.
    """
    n = len(edge)
    u = np.empty(n, dtype=np.int64)
    v = np.empty(n, dtype=np.int64)
    key = np.empty(n, dtype=np.int64)
    way = np.empty(n, dtype=np.int64)
    length_m = np.empty(n, dtype=np.float64)
    speed_kph = np.empty(n, dtype=np.float64)
    road_class = np.empty(n, dtype=np.int64)
    start = np.zeros(n, dtype=np.int64)
    size = np.zeros(n, dtype=np.int64)
    total = max(n - 1, 0)
    for k in range(n):
        e = edge[k]
        if e < 0 or e >= len(edge_u):
            msg = "an edge index is out of range for the network"
            raise IndexError(msg)
        u[k] = node_osm_id[edge_u[e]]
        v[k] = node_osm_id[edge_v[e]]
        key[k] = edge_key[e]
        way[k] = edge_way_id[e]
        length_m[k] = edge_length_m[e]
        speed_kph[k] = np.float64(edge_speed_mps[e]) * 3.6
        road_class[k] = edge_class[e]
        total += _find_name(ids, ptr, way[k], k, start, size)
    joined = _joined(blob, start, size, total)
    return u, v, key, way, length_m, speed_kph, road_class, joined, start, size
