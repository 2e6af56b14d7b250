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
from numba import njit

from mapmatch.hmm.emission import flat_arrays
from mapmatch.hmm.params import P_ROUTE_FACTOR, P_ROUTE_REACH, P_ROUTE_SLACK, model_params
from roadnets.route_search import search_bounds

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig
    from mapmatch.hmm.candidates import Candidates
    from mapmatch.types import FloatArray, IntArray
    from roadnets import EdgeRoutes, RoadNetwork

__all__ = [
    "ARRIVAL_HELD",
    "ARRIVAL_SAME",
    "ARRIVAL_UNKNOWN",
    "ROUTE_SAME_EDGE",
    "ROUTE_STANDSTILL",
    "ROUTE_UTURN",
    "ROUTE_UTURN_AT_NODE",
    "ROUTE_VIA_GRAPH",
    "CandidatePairs",
    "candidate_pairs",
    "forward_route",
    "held_across",
    "held_behind",
    "pairs_kernel",
    "route_search_bounds",
    "routes_between",
    "search_bound",
    "standstill_distances",
    "uturn_route",
    "uturn_routes",
]


#: How a transition's route runs: forward along one edge, through the graph, a U-turn
#: mid-road, through the graph with a U-turn at a node (scored as a U-turn, assembled as a
#: graph route), or not at all: the next fix lies a little behind, which is noise around a
#: slow or stopped car, so the car holds its position (:func:`standstill_distances`).
ROUTE_SAME_EDGE, ROUTE_VIA_GRAPH, ROUTE_UTURN, ROUTE_UTURN_AT_NODE, ROUTE_STANDSTILL = 0, 1, 2, 3, 4

#: What a state knows of the edge the car drove onto its edge from (its *arrival*), when not
#: an edge: nothing yet (a piece's first fix), the same as the state before (the move stayed
#: on one edge), or nothing that lets it hold further back (it holds across edges already).
#: A fix held behind its predecessor on another edge is a held car only on the arrival edge.
ARRIVAL_UNKNOWN, ARRIVAL_SAME, ARRIVAL_HELD = -1, -2, -3


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


@njit(cache=True, nogil=True)
def pairs_kernel(ptr):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """``(step, a, b, a_rank, b_rank)`` of every candidate pair of consecutive fixes."""
    n_steps = max(len(ptr) - 2, 0)
    total = 0
    for t in range(n_steps):
        total += (ptr[t + 1] - ptr[t]) * (ptr[t + 2] - ptr[t + 1])
    step = np.empty(total, dtype=np.int64)
    a = np.empty(total, dtype=np.int64)
    b = np.empty(total, dtype=np.int64)
    a_rank = np.empty(total, dtype=np.int64)
    b_rank = np.empty(total, dtype=np.int64)
    k = 0
    for t in range(n_steps):
        for i in range(ptr[t + 1] - ptr[t]):
            for j in range(ptr[t + 2] - ptr[t + 1]):
                step[k], a[k], b[k] = t, ptr[t] + i, ptr[t + 1] + j
                a_rank[k], b_rank[k] = i, j
                k += 1
    return step, a, b, a_rank, b_rank


def candidate_pairs(ptr: IntArray) -> CandidatePairs:
    """
    All candidate pairs of consecutive fixes, in order of fix, then ``a``, then ``b``.

    Examples
    --------
    >>> pairs = candidate_pairs(np.array([0, 2, 3, 5]))
    >>> pairs.a.tolist(), pairs.b.tolist()
    ([0, 1, 2, 2], [2, 2, 3, 4])
    """
    return CandidatePairs(*pairs_kernel(np.ascontiguousarray(ptr, dtype=np.int64)))


_BIG = float(np.finfo(np.float64).max)


@njit(cache=True, nogil=True)
def search_bound(great_circle, dt, params):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Longest route worth searching after a step (see :func:`route_search_bounds`)."""
    bound = params[P_ROUTE_FACTOR] * great_circle + params[P_ROUTE_SLACK]
    reach = params[P_ROUTE_REACH] * dt  # nan_to_num: unknown 0, infinite the largest float
    reach = 0.0 if np.isnan(reach) else min(max(reach, -_BIG), _BIG)
    return max(bound, reach) if not np.isnan(bound) else bound


@njit(cache=True, nogil=True)
def _bounds(great_circle, dt, params):  # type: ignore[no-untyped-def]  # pragma: no cover
    out = np.empty(len(great_circle))
    for i in range(len(out)):
        out[i] = search_bound(great_circle[i], dt[i], params)
    return out


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
    shape, flat = flat_arrays(great_circle_m, dt_s)
    out = _bounds(*flat, model_params(config))  # type: ignore[call-arg]
    return np.asarray(out, dtype=np.float64).reshape(shape)


@njit(cache=True, nogil=True)
def forward_route(ea, eb, oa, ob, len_a, speed_a, speed_b, dist, time, uturns):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Route length, free-flow time and kind from ``(ea, oa)`` to ``(eb, ob)`` driving forward.

    ``dist, time, uturns`` are the router's route from the end of ``ea`` to the start of
    ``eb`` (``inf`` when none); along the edge when ``b`` is ahead on it.
    """
    if ea == eb and ob >= oa:
        return ob - oa, (ob - oa) / speed_a, ROUTE_SAME_EDGE
    route = (len_a - oa) + dist + ob
    free = (len_a - oa) / speed_a + time + ob / speed_b
    return route, free, ROUTE_UTURN_AT_NODE if uturns > 0 else ROUTE_VIA_GRAPH


@njit(cache=True, nogil=True)
def uturn_route(eb, oa, ob, len_a, twin_a):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Length of a U-turn in the middle of ``a``'s road onto ``b`` (``inf``: not its twin)."""
    return abs(oa + ob - len_a) if eb == twin_a else np.inf


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
    routes = net.edge_routes(ea, eb, bounds_m)
    route, time, kind = _forward_routes(
        ea,
        eb,
        cands.offset_m[pairs.a],
        cands.offset_m[pairs.b],
        arrays.edge_length_m,
        arrays.edge_speed_mps,
        routes.distance_m,
        routes.time_s,
        routes.uturns,
    )
    return route, time, kind, routes


@njit(cache=True, nogil=True)
def _forward_routes(ea, eb, oa, ob, edge_len, edge_speed, dist, time, uturns):  # type: ignore[no-untyped-def]  # pragma: no cover
    n = len(ea)
    route, free = np.empty(n), np.empty(n)
    kind = np.empty(n, dtype=np.int64)
    for k in range(n):
        a, b = ea[k], eb[k]
        route[k], free[k], kind[k] = forward_route(
            a,
            b,
            oa[k],
            ob[k],
            edge_len[a],
            edge_speed[a],
            edge_speed[b],
            dist[k],
            time[k],
            uturns[k],
        )
    return route, free, kind


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
    are that close in the plane, and whose way along their own edges is, are routed
    (:func:`held_behind`).

    Examples
    --------
    >>> # 30 m along an edge, the next fix 8 m back on it, tolerance 20 m
    >>> float(np.where(30.0 - 22.0 <= 20.0, 30.0 - 22.0, np.inf))
    8.0
    """
    arrays = net.arrays
    ea, eb = cands.edge[pairs.a], cands.edge[pairs.b]
    oa, ob = cands.offset_m[pairs.a], cands.offset_m[pairs.b]
    tol = np.ascontiguousarray(tolerance_m, dtype=np.float64)
    ax, ay, bx, by = cands.x[pairs.a], cands.y[pairs.a], cands.x[pairs.b], cands.y[pairs.b]
    slot = np.full(len(arrays.edge_length_m), -1, dtype=np.int64)
    back, near, reach = held_behind(ea, eb, oa, ob, ax, ay, bx, by, tol, arrays.edge_length_m, slot)
    if len(near):
        routes = net.edge_routes(eb[near], ea[near], reach)
        held_across(back, near, ea, eb, oa, ob, arrays.edge_length_m, routes.distance_m, tol)
    return np.asarray(back, dtype=np.float64)


@njit(cache=True, nogil=True)
def held_behind(ea, eb, oa, ob, ax, ay, bx, by, tolerance, edge_len, slot):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    How far ``b`` lies behind ``a`` on one edge, and the pairs to route from ``b`` to ``a``.

    ``back`` is the distance where ``b`` is behind ``a`` on their edge within the tolerance,
    ``inf`` elsewhere; ``near`` the pairs on different edges close enough in the plane whose
    way along the road (the rest of ``b``'s edge and ``a``'s offset, before any route between
    the edges) fits in the tolerance too, and ``reach`` the bound to route each with: that of
    the search from its ``b`` edge over every pair close in the plane
    (:func:`~roadnets.route_search.search_bounds`), so the routes are those routing every
    such pair gives. ``slot`` as there.
    """
    n = len(ea)
    back = np.full(n, np.inf)
    near = np.empty(n, dtype=np.int64)
    m = 0
    for k in range(n):
        if ea[k] == eb[k]:
            if ob[k] <= oa[k] and oa[k] - ob[k] <= tolerance[k]:
                back[k] = oa[k] - ob[k]
            continue
        dx, dy = ax[k] - bx[k], ay[k] - by[k]
        if dx * dx + dy * dy <= tolerance[k] * tolerance[k]:  # every pair: no libm hypot
            near[m] = k
            m += 1
    near = near[:m]
    reach = search_bounds(eb[near], tolerance[near], slot)
    kept = 0
    for i in range(m):
        k = near[i]
        if (edge_len[eb[k]] - ob[k]) + oa[k] <= tolerance[k]:  # no route makes it shorter
            near[kept] = k
            reach[kept] = reach[i]
            kept += 1
    return back, near[:kept], reach[:kept]


@njit(cache=True, nogil=True)
def held_across(back, near, ea, eb, oa, ob, edge_len, dist, tolerance):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Fill in ``back`` for the pairs ``near``, given the routes from ``eb`` to ``ea``."""
    for i in range(len(near)):
        k = near[i]
        d = (edge_len[eb[k]] - ob[k]) + dist[i] + oa[k]
        if d <= tolerance[k]:
            back[k] = d


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
    return np.asarray(
        _uturn_routes(ea, eb, oa, ob, arrays.edge_length_m, arrays.edge_twin), dtype=np.float64
    )


@njit(cache=True, nogil=True)
def _uturn_routes(ea, eb, oa, ob, edge_len, edge_twin):  # type: ignore[no-untyped-def]  # pragma: no cover
    out = np.empty(len(ea))
    for k in range(len(ea)):
        out[k] = uturn_route(eb[k], oa[k], ob[k], edge_len[ea[k]], edge_twin[ea[k]])
    return out
