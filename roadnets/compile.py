"""Compile drivable OSM ways into the directed network arrays.

Ways are split at every node shared with another way (or repeated within one) and at their
ends, as osmnx's simplified graphs are; each piece becomes one directed edge per permitted
direction. Lengths along the geometry are geodesic (WGS84 ellipsoid), positions planar in the
network's projection (see :mod:`roadnets.projection`).
"""

from __future__ import annotations

import itertools
import logging
import math
from collections import defaultdict
from typing import TYPE_CHECKING

import numpy as np

from roadnets.arrays import NetworkArrays
from roadnets.drivable import ROAD_CLASSES, direction_flags, road_speed_kph
from roadnets.errors import NetworkTooWideError
from roadnets.names import encode_names
from roadnets.projection import (
    EARTH_RADIUS_M,
    MAX_SCALE_ERROR,
    Projector,
    central_longitude,
    geodesic_steps,
    tm_scale_error,
)

if TYPE_CHECKING:
    from roadnets.osm_reader import OsmExtract, TurnRestriction

__all__ = ["choose_projector", "compile_network"]

_log = logging.getLogger("roadnets")

_CLASS_INDEX = {name: i for i, name in enumerate(ROAD_CLASSES)}


def choose_projector(extract: OsmExtract, source: str) -> Projector:
    """
    The transverse Mercator centred on the extract's drivable ways (see :mod:`roadnets.projection`).

    Raises
    ------
    NetworkTooWideError
        The ways reach so far east or west of their centre that the planar scale error would
        pass :data:`~roadnets.projection.MAX_SCALE_ERROR`.
    """
    lon = np.concatenate([way.lon for way in extract.ways])
    lat = np.concatenate([way.lat for way in extract.ways])
    centre_lon, west, east = central_longitude(lon)
    south, north = float(lat.min()), float(lat.max())
    error = tm_scale_error(lon, lat, centre_lon)
    if error > MAX_SCALE_ERROR:
        nearest_equator = 0.0 if south <= 0.0 <= north else min(abs(south), abs(north))
        width_km = (
            EARTH_RADIUS_M * math.radians(east - west) * math.cos(math.radians(nearest_equator))
        )
        half_m = EARTH_RADIUS_M * math.atanh(math.sqrt(1.0 - 1.0 / (1.0 + MAX_SCALE_ERROR) ** 2))
        raise NetworkTooWideError(
            source,
            lon_range=(west, east),
            lat_range=(south, north),
            width_km=width_km / 1000.0,
            scale_error=error,
            limit=MAX_SCALE_ERROR,
            max_width_km=2.0 * half_m / 1000.0,
        )
    return Projector.local(centre_lon, 0.5 * (south + north))


def compile_network(extract: OsmExtract, projector: Projector) -> NetworkArrays:
    """
    Build the directed network arrays from the drivable ways of an extract.

    Parameters
    ----------
    extract
        Drivable ways and turn restrictions (non-empty).
    projector
        The metric CRS the geometry is stored in.
    """
    ways = extract.ways
    all_ids = np.concatenate([way.node_ids for way in ways])
    lon_all = np.concatenate([way.lon for way in ways])
    lat_all = np.concatenate([way.lat for way in ways])
    x_all, y_all = projector.forward(lon_all, lat_all)
    # geodesic length of the step from each vertex to the next (across two ways: unused)
    step_all = np.append(geodesic_steps(lon_all, lat_all), 0.0)
    unique_ids, counts = np.unique(all_ids, return_counts=True)
    ends = np.concatenate([[way.node_ids[0], way.node_ids[-1]] for way in ways])
    is_graph_node = set(unique_ids[counts >= 2].tolist()) | set(ends.tolist())

    node_index: dict[int, int] = {}
    node_xy: list[tuple[float, float]] = []
    edges: list[tuple[int, int, int, float, int, bool, int]] = []  # u, v, way, speed, cls, ow, twin
    geoms: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # x, y, geodesic steps
    # a piece of road drawn twice (two ways through the same nodes, the same way round) is one
    # edge: the later copy is dropped, so a match does not hop between the copies
    drawn: dict[tuple[int, ...], int] = {}
    duplicates = 0
    start = 0
    for way in ways:
        n = len(way.node_ids)
        xs, ys = x_all[start : start + n], y_all[start : start + n]
        steps = step_all[start : start + n - 1]
        start += n
        forward, backward = direction_flags(way.tags)
        speed_fwd = road_speed_kph(way.tags, forward=True) / 3.6
        speed_bwd = road_speed_kph(way.tags, forward=False) / 3.6
        cls = _CLASS_INDEX[way.tags["highway"]]
        cuts = [i for i, nid in enumerate(way.node_ids.tolist()) if nid in is_graph_node]
        for a, b in itertools.pairwise(cuts):
            gx, gy, gs = xs[a : b + 1], ys[a : b + 1], steps[a:b]
            u = _node(node_index, node_xy, int(way.node_ids[a]), float(gx[0]), float(gy[0]))
            v = _node(node_index, node_xy, int(way.node_ids[b]), float(gx[-1]), float(gy[-1]))
            oneway = not (forward and backward)
            nodes = tuple(way.node_ids[a : b + 1].tolist())
            fwd = forward and nodes not in drawn
            bwd = backward and nodes[::-1] not in drawn
            duplicates += (forward and not fwd) + (backward and not bwd)
            first = len(edges)
            if fwd:
                drawn[nodes] = len(edges)
                edges.append((u, v, way.way_id, speed_fwd, cls, oneway, -1))
                geoms.append((gx, gy, gs))
            if bwd:
                twin = first if fwd else -1
                drawn[nodes[::-1]] = len(edges)
                edges.append((v, u, way.way_id, speed_bwd, cls, oneway, twin))
                geoms.append((gx[::-1], gy[::-1], gs[::-1]))
                if fwd:
                    edges[first] = (*edges[first][:6], first + 1)
    names: dict[int, str] = {}
    for way in ways:
        label = way.tags.get("name") or way.tags.get("ref")
        if label:
            names[way.way_id] = label
    if duplicates:
        _log.info("%d directed edges drawn twice by overlapping ways kept once", duplicates)
    return _to_arrays(node_index, node_xy, edges, geoms, extract.restrictions, names, projector)


def _node(
    index: dict[int, int], xy: list[tuple[float, float]], osm_id: int, x: float, y: float
) -> int:
    found = index.get(osm_id)
    if found is None:
        found = index[osm_id] = len(xy)
        xy.append((x, y))
    return found


def _to_arrays(
    node_index: dict[int, int],
    node_xy: list[tuple[float, float]],
    edges: list[tuple[int, int, int, float, int, bool, int]],
    geoms: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
    restrictions: list[TurnRestriction],
    names: dict[int, str],
    projector: Projector,
) -> NetworkArrays:
    n_nodes, n_edges = len(node_xy), len(edges)
    node_osm_id = np.fromiter(node_index.keys(), dtype=np.int64, count=n_nodes)
    xy = np.asarray(node_xy, dtype=np.float64).reshape(n_nodes, 2)
    u = np.array([e[0] for e in edges], dtype=np.int32)
    v = np.array([e[1] for e in edges], dtype=np.int32)
    keys = np.zeros(n_edges, dtype=np.int32)
    seen: dict[tuple[int, int], int] = defaultdict(int)
    for i, (a, b) in enumerate(zip(u.tolist(), v.tolist(), strict=True)):
        keys[i] = seen[(a, b)]
        seen[(a, b)] += 1

    sizes = np.array([len(g[0]) for g in geoms], dtype=np.int64)
    geom_ptr = np.concatenate(([0], np.cumsum(sizes)))
    geom_x = np.concatenate([g[0] for g in geoms]).astype(np.float64)
    geom_y = np.concatenate([g[1] for g in geoms]).astype(np.float64)
    # geodesic steps between consecutive vertices; none across two edges
    step = np.zeros(max(len(geom_x) - 1, 0), dtype=np.float64)
    inside = np.ones(len(step), dtype=bool)
    inside[geom_ptr[1:-1] - 1] = False
    step[inside] = np.concatenate([g[2] for g in geoms])
    cum = np.concatenate(([0.0], np.cumsum(step)))
    geom_cum = cum - np.repeat(cum[geom_ptr[:-1]], sizes)
    geom_lon, geom_lat = projector.inverse(geom_x, geom_y)
    length = geom_cum[geom_ptr[1:] - 1].copy()

    order = np.argsort(u, kind="stable")
    out_ptr = np.concatenate(([0], np.cumsum(np.bincount(u, minlength=n_nodes)))).astype(np.int64)

    twin = np.array([e[6] for e in edges], dtype=np.int32)
    indexed = np.flatnonzero((twin < 0) | (np.arange(n_edges) < twin))
    seg_counts = sizes[indexed] - 1
    seg_edge = np.repeat(indexed.astype(np.int32), seg_counts)
    seg_start = np.repeat(geom_ptr[indexed], seg_counts) + _ranges(seg_counts)

    way_id = np.array([e[2] for e in edges], dtype=np.int64)
    name_way_id, name_ptr, name_utf8 = encode_names(names)
    banned_in, banned_out, seq_ptr, seq_edge = _banned_turns(
        restrictions, u, v, way_id, node_osm_id, out_ptr, order
    )
    return NetworkArrays(
        node_osm_id=node_osm_id,
        node_x=xy[:, 0].copy(),
        node_y=xy[:, 1].copy(),
        edge_u=u,
        edge_v=v,
        edge_key=keys,
        edge_way_id=way_id,
        edge_length_m=length,
        edge_speed_mps=np.array([e[3] for e in edges], dtype=np.float64),
        edge_class=np.array([e[4] for e in edges], dtype=np.int8),
        edge_oneway=np.array([e[5] for e in edges], dtype=np.bool_),
        edge_twin=twin,
        edge_geom_ptr=geom_ptr.astype(np.int64),
        geom_x=geom_x,
        geom_y=geom_y,
        geom_cum_m=geom_cum,
        geom_lon=np.asarray(geom_lon, dtype=np.float64),
        geom_lat=np.asarray(geom_lat, dtype=np.float64),
        out_ptr=out_ptr,
        out_edge=order.astype(np.int32),
        seg_start=seg_start.astype(np.int64),
        seg_edge=seg_edge,
        banned_in=banned_in,
        banned_out=banned_out,
        banned_seq_ptr=seq_ptr,
        banned_seq_edge=seq_edge,
        name_way_id=name_way_id,
        name_ptr=name_ptr,
        name_utf8=name_utf8,
    )


def _ranges(counts: np.ndarray) -> np.ndarray:
    """``[0..c0-1, 0..c1-1, ...]`` for an array of counts."""
    total = int(counts.sum())
    starts = np.repeat(np.cumsum(counts) - counts, counts)
    return np.asarray(np.arange(total, dtype=np.int64) - starts, dtype=np.int64)


def _banned_turns(
    restrictions: list[TurnRestriction],
    u: np.ndarray,
    v: np.ndarray,
    way_id: np.ndarray,
    node_osm_id: np.ndarray,
    out_ptr: np.ndarray,
    out_edge: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """
    Compile turn restrictions into banned edge pairs and banned edge sequences.

    A via-node restriction bans edge pairs ``(in, out)`` at its node. A via-way restriction
    bans sequences ``from edge, the via ways' edges end to end, to edge`` (an ``only_*`` one:
    every other edge leaving the end of the via chain). Restrictions whose ways are missing or
    do not meet are left out and counted in a log line.

    Returns
    -------
    banned_in, banned_out, seq_ptr, seq_edge
        The pairs, and the sequences as a CSR (sequence ``i`` is
        ``seq_edge[seq_ptr[i]:seq_ptr[i + 1]]``, at least three edges).
    """
    by_way: dict[int, list[int]] = defaultdict(list)
    for e, w in enumerate(way_id.tolist()):
        by_way[w].append(e)
    node_of = {int(osm): i for i, osm in enumerate(node_osm_id.tolist())}
    banned: set[tuple[int, int]] = set()
    sequences: set[tuple[int, ...]] = set()
    unresolved = 0
    for r in restrictions:
        if r.via_node is None:
            found = _via_way_sequences(r, by_way, u, v, out_ptr, out_edge)
            sequences.update(found)
            unresolved += not found
            continue
        via = node_of.get(r.via_node, -1)
        into = [e for e in by_way.get(r.from_way, []) if v[e] == via]
        onto = {e for e in by_way.get(r.to_way, []) if u[e] == via}
        if not into or not onto:
            unresolved += 1
            continue
        leaving = out_edge[out_ptr[via] : out_ptr[via + 1]].tolist()
        forbidden = [e for e in leaving if e not in onto] if r.only else sorted(onto)
        banned.update((a, b) for a in into for b in forbidden)
    if unresolved:
        _log.info(
            "%d of %d turn restrictions do not apply to the drivable graph "
            "(their ways are missing from the extract or do not meet)",
            unresolved,
            len(restrictions),
        )
    pairs = np.array(sorted(banned), dtype=np.int32).reshape(-1, 2)
    ordered = sorted(sequences)
    seq_ptr = np.concatenate(([0], np.cumsum([len(q) for q in ordered], dtype=np.int64)))
    seq_edge = np.array([e for q in ordered for e in q], dtype=np.int32)
    return pairs[:, 0].copy(), pairs[:, 1].copy(), seq_ptr.astype(np.int64), seq_edge


def _via_way_sequences(
    r: TurnRestriction,
    by_way: dict[int, list[int]],
    u: np.ndarray,
    v: np.ndarray,
    out_ptr: np.ndarray,
    out_edge: np.ndarray,
) -> list[tuple[int, ...]]:
    """Banned edge sequences of one via-way restriction (empty when it does not resolve)."""
    chains: list[tuple[list[int], int]] = []  # (from edge + via edges, node at the end)
    first_ends = _way_ends(by_way.get(r.via_ways[0], []), u, v)
    via_edges = {e for w in r.via_ways for e in by_way.get(w, [])}
    for start in first_ends:
        for e_from in by_way.get(r.from_way, []):
            if int(v[e_from]) != start or e_from in via_edges:
                continue
            path, node = [e_from], start
            for w in r.via_ways:
                edges = by_way.get(w, [])
                ends = _way_ends(edges, u, v)
                if node not in ends or len(ends) != 2:
                    break
                walked = _walk(edges, u, v, node, ends[1] if ends[0] == node else ends[0])
                if walked is None:
                    break
                path += walked
                node = int(v[walked[-1]])
            else:
                chains.append((path, node))
    out: list[tuple[int, ...]] = []
    to_edges = set(by_way.get(r.to_way, []))
    for path, node in chains:
        leaving = out_edge[out_ptr[node] : out_ptr[node + 1]].tolist()
        onto = [e for e in leaving if e in to_edges]
        if not onto:
            continue
        forbidden = [e for e in leaving if e not in to_edges] if r.only else onto
        out.extend((*path, e) for e in forbidden)
    return out


def _way_ends(edges: list[int], u: np.ndarray, v: np.ndarray) -> list[int]:
    """End nodes of a way from its edges: nodes on one piece of it only (sorted)."""
    pieces = {(min(int(u[e]), int(v[e])), max(int(u[e]), int(v[e]))) for e in edges}
    count: dict[int, int] = defaultdict(int)
    for a, b in pieces:
        count[a] += 1
        count[b] += 1
    return sorted(n for n, c in count.items() if c == 1)


def _walk(edges: list[int], u: np.ndarray, v: np.ndarray, start: int, end: int) -> list[int] | None:
    """The way's edges driven from node ``start`` to node ``end``; ``None`` if not drivable."""
    leaving: dict[int, list[int]] = defaultdict(list)
    for e in edges:
        leaving[int(u[e])].append(e)
    path: list[int] = []
    node, previous = start, -1
    while node != end:
        onward = [e for e in leaving.get(node, []) if int(v[e]) != previous]
        if len(onward) != 1 or len(path) > len(edges):
            return None
        path.append(onward[0])
        previous, node = node, int(v[onward[0]])
    return path
