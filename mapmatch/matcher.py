"""``mapmatch.match``: a trace and a road network in, the roads driven out.

The stages, each vectorised over the whole trace: project the fixes, find candidates (one
R-tree query), score emissions, build every candidate pair of consecutive fixes, route them
(one bounded many-source Dijkstra), score transitions, run Viterbi and forward-backward on
the padded trellis, and assemble segments.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from mapmatch.candidates import Candidates, find_candidates, search_radii
from mapmatch.config import MatchConfig
from mapmatch.distance import check_distance, chord_length_m
from mapmatch.errors import NoCandidatesError
from mapmatch.models import (
    ROUTE_SAME_EDGE,
    ROUTE_UTURN,
    candidate_pairs,
    heading_weight,
    log_emission,
    log_heading,
    log_transition,
    route_search_bounds,
    routes_between,
    uturn_routes,
)
from mapmatch.result import MatchedEdge, MatchedPoints, MatchResult, MatchStats, Segment
from mapmatch.viterbi import posteriors, viterbi

if TYPE_CHECKING:
    from roadnets import PathTable, RoadNetwork

    from mapmatch.trace import Trace

__all__ = ["match"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


def match(
    trace: Trace,
    net: RoadNetwork,
    config: MatchConfig | None = None,
    *,
    fused_distance_m: float | None = None,
) -> MatchResult:
    """
    Match a trace onto a road network.

    Parameters
    ----------
    trace
        The validated trace (at least two fixes, sorted by time).
    net
        The road network, from :func:`roadnets.load`.
    config
        Matcher parameters; the defaults of :class:`MatchConfig` otherwise.
    fused_distance_m
        Trip distance the vehicle reported, used by the distance check when the trace has
        no odometer column.

    Returns
    -------
    MatchResult
        Segments, snapped points, matched length, distance check and stats.

    Raises
    ------
    NoCandidatesError
        No fix has a road within its search radius.
    """
    config = config or MatchConfig()
    timings: dict[str, float] = {}
    clock = time.perf_counter()

    x, y = net.project(trace.lon, trace.lat)
    n = len(x)
    radius = search_radii(trace.accuracy_m, n, config)
    cands = find_candidates(net, x, y, radius, config)
    if len(cands) == 0:
        raise NoCandidatesError(trace.trace_id, float(radius.max()))
    clock = _lap(timings, "candidates", clock)

    sigma = np.full(n, config.sigma_m)
    if trace.accuracy_m is not None:
        sigma = np.fmax(sigma, trace.accuracy_m)
    step_m = np.hypot(np.diff(x), np.diff(y))
    dt = np.diff(trace.time_s)
    speed = trace.speed_mps if trace.speed_mps is not None else _speed_from_positions(step_m, dt)
    point_of = np.repeat(np.arange(n), cands.counts)
    em = log_emission(cands.distance_m, sigma_m=sigma[point_of])
    if trace.heading_deg is not None:
        weight = heading_weight(speed, config)
        em += log_heading(
            trace.heading_deg[point_of], cands.bearing_deg, weight[point_of], config
        )
    clock = _lap(timings, "emission", clock)

    pairs = candidate_pairs(cands.ptr)
    bounds = route_search_bounds(step_m, config)
    leaving = point_of < n - 1
    table = net.shortest_paths(
        net.arrays.edge_v[cands.edge[leaving]], bounds[point_of[leaving]]
    )
    route, free_time, kind = routes_between(net, cands, pairs, table, config)
    gc, step_dt = step_m[pairs.step], dt[pairs.step]
    step_sigma = np.maximum(sigma[pairs.step], sigma[pairs.step + 1])
    lt = log_transition(gc, route, free_time, kind, step_dt, step_sigma, config)
    u_route = uturn_routes(net, cands, pairs)
    u_kind = np.full(len(kind), ROUTE_UTURN)
    u_time = u_route / net.arrays.edge_speed_mps[cands.edge[pairs.a]]
    lu = log_transition(gc, u_route, u_time, u_kind, step_dt, step_sigma, config)
    use_u = lu > lt
    lt = np.where(use_u, lu, lt)
    kind = np.where(use_u, ROUTE_UTURN, kind)
    clock = _lap(timings, "routing", clock)

    width = int(cands.counts.max())
    em_pad = np.full((n, width), -np.inf)
    em_pad[point_of, np.arange(len(cands)) - cands.ptr[point_of]] = em
    tr_pad = np.full((max(n - 1, 0), width, width), -np.inf)
    tr_pad[pairs.step, pairs.a_rank, pairs.b_rank] = lt
    kind_pad = np.full(tr_pad.shape, -1, dtype=np.int64)
    kind_pad[pairs.step, pairs.a_rank, pairs.b_rank] = kind
    best = viterbi(em_pad, tr_pad)
    post = posteriors(em_pad, tr_pad, best.pieces)
    clock = _lap(timings, "viterbi", clock)

    rows = np.where(best.states >= 0, cands.ptr[:-1] + best.states, -1)
    segments = _assemble_segments(net, cands, rows, best.states, best.pieces, kind_pad, table)
    points = _matched_points(net, trace, cands, rows, best.states, post, best.pieces)
    matched_length = float(sum(s.length_m for s in segments))
    complete = len(best.pieces) == 1 and bool(points.matched.all())
    check = check_distance(
        trace_id=trace.trace_id,
        matched_length_m=matched_length,
        complete=complete,
        band=config.distance_band,
        odometer_m=trace.odometer_m,
        fused_distance_m=fused_distance_m,
        chord_m=chord_length_m(x, y),
    )
    _lap(timings, "result", clock)
    timings["total"] = sum(timings.values())
    stats = MatchStats(
        points=n,
        matched_points=int(points.matched.sum()),
        candidates=len(cands),
        reordered_rows=trace.report.reordered_rows,
        duplicate_time_rows=len(trace.report.duplicate_time_rows),
        timings_s=timings,
        warnings=tuple(trace.report.warnings),
    )
    return MatchResult(
        trace_id=trace.trace_id,
        network={"id": net.network_id, "source": net.source, "crs": net.crs},
        segments=segments,
        points=points,
        breaks=best.breaks,
        matched_length_m=matched_length,
        distance_check=check,
        stats=stats,
    )


def _lap(timings: dict[str, float], name: str, since: float) -> float:
    now = time.perf_counter()
    timings[name] = now - since
    return now


def _speed_from_positions(step_m: FloatArray, dt_s: FloatArray) -> FloatArray:
    """Speed at each fix from the distance to its neighbours (when the trace has none)."""
    v = step_m / dt_s
    padded = np.concatenate(([v[0]], v, [v[-1]]))
    return 0.5 * (padded[:-1] + padded[1:])


def _assemble_segments(
    net: RoadNetwork,
    cands: Candidates,
    rows: IntArray,
    states: IntArray,
    pieces: list[tuple[int, int]],
    kind_pad: IntArray,
    table: PathTable,
) -> list[Segment]:
    """Edges driven between consecutive chosen candidates of each piece, and geometry."""
    arrays = net.arrays
    edge_len = arrays.edge_length_m
    segments: list[Segment] = []
    for index, (start, stop) in enumerate(pieces):
        first = rows[start]
        # each entry: [edge, start offset, end offset]
        entries: list[list[float]] = [
            [int(cands.edge[first]), cands.offset_m[first], cands.offset_m[first]]
        ]
        for t in range(start, stop - 1):
            ra, rb = rows[t], rows[t + 1]
            ea, eb = int(cands.edge[ra]), int(cands.edge[rb])
            ob = float(cands.offset_m[rb])
            move = kind_pad[t, states[t], states[t + 1]]
            current = entries[-1]
            if move == ROUTE_SAME_EDGE:
                current[2] = max(current[2], ob)
            elif move == ROUTE_UTURN:
                turn = max(current[2], edge_len[ea] - ob)
                current[2] = turn
                entries.append([eb, edge_len[ea] - turn, ob])
            else:
                current[2] = edge_len[ea]
                for e in table.edges(int(arrays.edge_v[ea]), int(arrays.edge_u[eb]), arrays.edge_u):
                    entries.append([e, 0.0, edge_len[e]])
                entries.append([eb, 0.0, ob])
        segments.append(_segment(net, index, start, stop - 1, entries))
    return segments


def _segment(
    net: RoadNetwork, index: int, first: int, last: int, entries: list[list[float]]
) -> Segment:
    arrays = net.arrays
    edge_ids = np.array([int(e[0]) for e in entries], dtype=np.int64)
    u, v, key = net.edge_osm_ids(edge_ids)
    edges: list[MatchedEdge] = []
    xs: list[FloatArray] = []
    ys: list[FloatArray] = []
    for i, (edge, lo, hi) in enumerate(entries):
        e = int(edge)
        edges.append(
            MatchedEdge(
                edge=e,
                u=int(u[i]),
                v=int(v[i]),
                key=int(key[i]),
                osm_way_ids=(int(arrays.edge_way_id[e]),),
                length_m=float(arrays.edge_length_m[e]),
                start_offset_m=float(lo),
                end_offset_m=float(hi),
            )
        )
        px, py = net.edge_polyline(e, float(lo), float(hi))
        if xs:
            px, py = px[1:], py[1:]
        xs.append(px)
        ys.append(py)
    lon, lat = net.unproject(np.concatenate(xs), np.concatenate(ys))
    return Segment(index=index, first=first, last=last, edges=edges, lon=lon, lat=lat)


def _matched_points(
    net: RoadNetwork,
    trace: Trace,
    cands: Candidates,
    rows: IntArray,
    states: IntArray,
    post: FloatArray,
    pieces: list[tuple[int, int]],
) -> MatchedPoints:
    n = len(rows)
    matched = rows >= 0
    safe = np.where(matched, rows, 0)
    edge = np.where(matched, cands.edge[safe], -1)
    u, v, key = net.edge_osm_ids(np.where(matched, edge, 0))
    lon, lat = net.unproject(cands.x[safe], cands.y[safe])
    nan = np.full(n, np.nan)
    confidence = np.where(matched, post[np.arange(n), np.maximum(states, 0)], 0.0)
    segment = np.full(n, -1, dtype=np.int64)
    for index, (start, stop) in enumerate(pieces):
        segment[start:stop] = index
    return MatchedPoints(
        time_s=trace.time_s,
        raw_lon=trace.lon,
        raw_lat=trace.lat,
        matched=matched,
        edge=edge,
        u=np.where(matched, u, -1),
        v=np.where(matched, v, -1),
        key=np.where(matched, key, -1).astype(np.int64),
        offset_m=np.where(matched, cands.offset_m[safe], nan),
        distance_m=np.where(matched, cands.distance_m[safe], nan),
        lon=np.where(matched, lon, nan),
        lat=np.where(matched, lat, nan),
        confidence=np.clip(confidence, 0.0, 1.0),
        segment=segment,
    )
