"""Routes between the candidates of consecutive observations, and how each one runs.

Every pair of candidates of consecutive observations gets its forward route along the
directed graph (along one edge, or through the graph by the edge-based router that obeys turn
restrictions, :meth:`roadnets.RoadNetwork.edge_routes`); pairs on twin edges may also turn in
the middle of the road, and a fix a little behind the previous one may be a held car. The
route kinds say which explanation a transition uses.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig
    from mapmatch.hmm.candidates import Candidates
    from mapmatch.types import FloatArray, IntArray
    from roadnets import EdgeRoutes, RoadNetwork

__all__ = [
    "ROUTE_SAME_EDGE",
    "ROUTE_STANDSTILL",
    "ROUTE_UTURN",
    "ROUTE_UTURN_AT_NODE",
    "ROUTE_VIA_GRAPH",
    "CandidatePairs",
    "candidate_pairs",
    "route_search_bounds",
    "routes_between",
    "standstill_distances",
    "uturn_routes",
]


#: How a transition's route runs: forward along one edge, through the graph, a U-turn
#: mid-road, through the graph with a U-turn at a node (scored as a U-turn, assembled as a
#: graph route), or not at all: the next fix lies a little behind, which is noise around a
#: slow or stopped car, so the car holds its position (:func:`standstill_distances`).
ROUTE_SAME_EDGE, ROUTE_VIA_GRAPH, ROUTE_UTURN, ROUTE_UTURN_AT_NODE, ROUTE_STANDSTILL = 0, 1, 2, 3, 4


@dataclass(frozen=True, slots=True)
class CandidatePairs:
    """
    Every pair of candidates of consecutive fixes.

    ``step[i]`` is the fix ``t`` the pair leaves from; ``a[i]``/``b[i]`` are candidate rows of
    fix ``t`` and ``t + 1``; ``a_rank``/``b_rank`` their rank within their fix.
    """

    step: IntArray
    a: IntArray
    b: IntArray
    a_rank: IntArray
    b_rank: IntArray


def candidate_pairs(ptr: IntArray) -> CandidatePairs:
    """
    All candidate pairs of consecutive fixes, vectorised.

    Examples
    --------
    >>> pairs = candidate_pairs(np.array([0, 2, 3, 5]))
    >>> pairs.a.tolist(), pairs.b.tolist()
    ([0, 1, 2, 2], [2, 2, 3, 4])
    """
    counts = np.diff(ptr)
    n_from, n_to = counts[:-1], counts[1:]
    per_step = n_from * n_to
    step = np.repeat(np.arange(len(per_step), dtype=np.int64), per_step)
    first = np.concatenate(([0], np.cumsum(per_step)[:-1]))
    k = np.arange(int(per_step.sum()), dtype=np.int64) - first[step]
    width = n_to[step]
    a_rank, b_rank = k // width, k % width
    return CandidatePairs(step, ptr[step] + a_rank, ptr[step + 1] + b_rank, a_rank, b_rank)


def route_search_bounds(
    great_circle_m: FloatArray, dt_s: FloatArray, config: MatchConfig
) -> FloatArray:
    """
    Longest route worth searching after each fix.

    ``route_factor * gc + route_slack_m``, or ``route_reach_mps * dt`` when that is more: a
    detour round a banned turn between sparse fixes can be far longer than their distance.

    Examples
    --------
    >>> from mapmatch.config import MatchConfig
    >>> route_search_bounds(np.array([20.0, 20.0]), np.array([1.0, 60.0]), MatchConfig())
    array([340., 900.])
    """
    bound = config.route_factor * great_circle_m + config.route_slack_m
    reach = np.nan_to_num(config.route_reach_mps * dt_s, nan=0.0)
    return np.asarray(np.maximum(bound, reach), dtype=np.float64)


def routes_between(
    net: RoadNetwork,
    cands: Candidates,
    pairs: CandidatePairs,
    bounds_m: FloatArray,
) -> tuple[FloatArray, FloatArray, IntArray, EdgeRoutes]:
    """
    Route distance, free-flow time and route kind of every candidate pair, driving forward.

    The route runs along the directed graph from candidate ``a``'s position to ``b``'s:
    forward along one edge when both are on it and ``b`` is ahead; otherwise to the end of
    ``a``'s edge, by the edge-based router (every turn restriction obeyed, U-turns at nodes
    only where no legal alternative is near) to the start of ``b``'s edge, and along it,
    within ``bounds_m`` per pair. Moves that hold the car still (``b`` a little behind
    ``a``) and U-turns in the middle of a road are alternatives scored separately
    (:func:`standstill_distances`, :func:`uturn_routes`). Unreachable pairs get ``inf``.

    Returns
    -------
    route_m, time_s, kind, routes
        Metres along the road, seconds at the roads' speed limits,
        :data:`ROUTE_SAME_EDGE`, :data:`ROUTE_VIA_GRAPH` or :data:`ROUTE_UTURN_AT_NODE`,
        and the routes themselves (their edges, for the assembly).
    """
    arrays = net.arrays
    ea, eb = cands.edge[pairs.a], cands.edge[pairs.b]
    oa, ob = cands.offset_m[pairs.a], cands.offset_m[pairs.b]
    len_a = arrays.edge_length_m[ea]
    speed_a, speed_b = arrays.edge_speed_mps[ea], arrays.edge_speed_mps[eb]

    routes = net.edge_routes(ea, eb, bounds_m)
    route = (len_a - oa) + routes.distance_m + ob
    time = (len_a - oa) / speed_a + routes.time_s + ob / speed_b
    kind = np.full(len(ea), ROUTE_VIA_GRAPH, dtype=np.int64)
    kind[routes.uturns > 0] = ROUTE_UTURN_AT_NODE  # turning back onto a twin at a node

    ahead = (ea == eb) & (ob >= oa)
    route = np.where(ahead, ob - oa, route)
    time = np.where(ahead, (ob - oa) / speed_a, time)
    kind[ahead] = ROUTE_SAME_EDGE
    return route, time, kind, routes


def standstill_distances(
    net: RoadNetwork,
    cands: Candidates,
    pairs: CandidatePairs,
    tolerance_m: FloatArray,
) -> FloatArray:
    """
    How far behind ``a`` each candidate ``b`` lies along the road, where that is noise.

    ``b`` is behind ``a`` when driving forward from ``b`` reaches ``a`` (on the same edge,
    or across edges: the end of ``b``'s edge, by the router, the start of ``a``'s edge).
    Within ``tolerance_m`` of ``a`` such a move is a slow or stopped car's fix scattering
    backwards: the car holds its position instead of driving round a block or a roundabout
    to explain it. ``inf`` where ``b`` is not that close behind. Only pairs whose two places
    are that close in the plane are routed.

    Examples
    --------
    >>> # 30 m along an edge, the next fix 8 m back on it, tolerance 20 m
    >>> float(np.where(30.0 - 22.0 <= 20.0, 30.0 - 22.0, np.inf))
    8.0
    """
    arrays = net.arrays
    ea, eb = cands.edge[pairs.a], cands.edge[pairs.b]
    oa, ob = cands.offset_m[pairs.a], cands.offset_m[pairs.b]
    back = np.full(len(ea), np.inf)
    same = (ea == eb) & (ob <= oa)
    back[same] = (oa - ob)[same]
    gap = np.hypot(cands.x[pairs.a] - cands.x[pairs.b], cands.y[pairs.a] - cands.y[pairs.b])
    near = np.flatnonzero((ea != eb) & (gap <= tolerance_m))
    if len(near):
        routes = net.edge_routes(eb[near], ea[near], tolerance_m[near])
        back[near] = (arrays.edge_length_m[eb[near]] - ob[near]) + routes.distance_m + oa[near]
    return np.where(back <= tolerance_m, back, np.inf)


def uturn_routes(net: RoadNetwork, cands: Candidates, pairs: CandidatePairs) -> FloatArray:
    """
    Length of a U-turn in the middle of the road for pairs on twin edges, else ``inf``.

    The car on ``a`` at offset ``oa`` turns around onto ``b`` (the same road the other way,
    where that spot is at ``len - oa``) and drives on to ``ob``.

    Examples
    --------
    >>> # a 100 m two-way road: 30 m along one way, then 80 m along the other = 10 m back
    >>> float(np.abs(30.0 + 80.0 - 100.0))
    10.0
    """
    arrays = net.arrays
    ea, eb = cands.edge[pairs.a], cands.edge[pairs.b]
    oa, ob = cands.offset_m[pairs.a], cands.offset_m[pairs.b]
    u_route = np.abs(oa + ob - arrays.edge_length_m[ea])
    return np.where(eb == arrays.edge_twin[ea], u_route, np.inf)
