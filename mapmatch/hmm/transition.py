"""Log transition of every candidate pair: the best of its explanations.

(Over 400 lines on purpose: every explanation of a candidate pair (forward, mid-road U-turn,
holding) is scored in one compiled kernel.)

Newson & Krumm's exponential in ``|great-circle - route|`` with a scale that grows with the
interval and the position sigma, a speed-plausibility term against the roads' limits
(reference paper, eq. 24), a flat-bottomed term against the distance the trace says it
travelled, and the cost of a U-turn, lowered by heading evidence. :func:`transitions_kernel`
scores every pair's forward route, its U-turn in the middle of the road and its standstill,
and keeps the best.

The scores are compiled functions of one pair (:func:`transition_score`,
:func:`uturn_cost`); :func:`transitions_kernel` scores every pair of a trellis in one call,
its routes searched (or looked up in a precomputed table) from inside.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numba import njit

from mapmatch.hmm.emission import angle_between, distance_score, flat_arrays, speed_weight
from mapmatch.hmm.observations import TRUSTED_SLACK_FRAC
from mapmatch.hmm.params import (
    P_BETA_M,
    P_BETA_PER_S,
    P_BETA_PER_SIGMA,
    P_NOMINAL_SPEED,
    P_SPEED_FACTOR,
    P_SPEED_MARGIN,
    P_SPEED_SIGMA,
    P_STANDSTILL_M,
    P_STANDSTILL_SIGMAS,
    P_TRAVEL_BETA,
    P_TRAVEL_TOLERANCE_FRAC,
    P_TRAVEL_TOLERANCE_M,
    P_UTURN_EVIDENCE_PENALTY,
    P_UTURN_PENALTY,
    model_params,
)
from mapmatch.hmm.routes import (
    ARRIVAL_HELD,
    ARRIVAL_SAME,
    ARRIVAL_UNKNOWN,
    ROUTE_SAME_EDGE,
    ROUTE_STANDSTILL,
    ROUTE_UTURN,
    ROUTE_UTURN_AT_NODE,
    forward_route,
    held_across,
    held_behind,
    uturn_route,
)
from roadnets.route_search import route_pairs_kernel, searches_within, table_routes

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig
    from mapmatch.types import FloatArray, IntArray
    from roadnets import RoadNetwork

__all__ = [
    "ROUTES_FROM_TABLE",
    "ROUTES_MIXED",
    "ROUTES_SEARCHED",
    "TABLE_FROM_MEAN_BOUND_M",
    "TRAVEL_CHORD_SHARE",
    "driving_on_explains",
    "log_transition",
    "route_inputs",
    "transition_score",
    "transitions_kernel",
    "uturn_cost",
    "uturn_penalties",
    "wants_table",
]

_BIG = float(np.finfo(np.float64).max)

#: Share of a route's excess over the chord still charged where a trusted travel explains it.
#: With none (the smaller of the two gaps), a route that fits the odometer was as free as one
#: that fits the chord, and between such routes the chord no longer decided: on the accuracy
#: matrix's 15 s odometer cells mismatch rose 1.22 -> 1.28 %, and 3 of 20 Monaco 15 s peer
#: trips took a wrong road (mismatch 0.7 -> 8.3 %). A quarter keeps the mismatch (1.22 %;
#: realistic-15s 0.96 -> 0.94 %) and most of the length gained (30 s within 1 %: 62 -> 65 %,
#: none: 68 %; realistic-15s |error| p95 1.05 -> 0.85 %, none: 0.81 %).
TRAVEL_CHORD_SHARE = 0.25


@njit(cache=True, nogil=True, inline="always")
def _nan_to_num(v):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    if np.isnan(v):
        return 0.0
    return min(max(v, -_BIG), _BIG)


@njit(cache=True, nogil=True, inline="always")
def _max0(v):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """``np.maximum(v, 0.0)``: NaN stays NaN."""
    return v if np.isnan(v) or v > 0.0 else 0.0


@njit(cache=True, nogil=True, inline="always")
def _trusted(travel, slack):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """Whether the trace says how far it travelled, closely enough to judge a route by."""
    return np.isfinite(travel) and slack <= TRUSTED_SLACK_FRAC * travel


@njit(cache=True, nogil=True, inline="always")
def _travel_tolerance(travel, slack, params):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """How far a route may differ from the travel at no cost (NaN without a travel)."""
    return params[P_TRAVEL_TOLERANCE_M] + params[P_TRAVEL_TOLERANCE_FRAC] * travel + slack


@njit(cache=True, nogil=True, inline="always")
def transition_score(gc, route, time, uturn, dt, sigma, travel, slack, penalty, params):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    :func:`log_transition` of one pair: ``uturn`` whether it turns, ``penalty`` what that costs.

    ``travel`` is NaN where the trace says nothing of the distance travelled.
    """
    timed = np.isfinite(dt) and dt > 0
    interval = dt if timed else gc / params[P_NOMINAL_SPEED]
    beta = params[P_BETA_M] + params[P_BETA_PER_S] * interval + params[P_BETA_PER_SIGMA] * sigma
    # the route is as plausible as its better explanation: the straight line, or the travel
    # where the trace says how far the car went (a winding road is long against its chord),
    # which keeps a share of the chord's charge so the chord still decides between routes
    gap = abs(gc - route)
    if _trusted(travel, slack):
        gap = min(gap, abs(travel - route) + TRAVEL_CHORD_SHARE * gap)
    score = -gap / beta
    needed = _max0(route - 2.0 * sigma) / dt if timed else np.nan
    limit = route / time if time > 0 else np.inf
    allowed = params[P_SPEED_FACTOR] * limit + params[P_SPEED_MARGIN]
    excess = _max0(needed - allowed)
    score = score - 0.5 * (_nan_to_num(excess) / params[P_SPEED_SIGMA]) ** 2
    off = _max0(abs(route - travel) - _travel_tolerance(travel, slack, params))
    score = score - _nan_to_num(off) / params[P_TRAVEL_BETA]
    if uturn:
        score = score - penalty
    return score if np.isfinite(route) else -np.inf


@njit(cache=True, nogil=True, inline="always")
def travel_explains_turn(gc, route, travel, slack, params):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    Whether the distance the trace says it travelled is evidence of a U-turn route.

    It is when that travel is trusted (its slack at most :data:`TRUSTED_SLACK_FRAC` of it),
    fits the route within the travel tolerance, and is longer than the straight line by more
    than that: an odometer that reads 120 m between fixes 15 m apart, with the turn round 60 m
    up a spur, says the car went there and came back.
    """
    if not _trusted(travel, slack):
        return False
    tolerance = _travel_tolerance(travel, slack, params)
    return abs(route - travel) <= tolerance and travel - gc > tolerance


@njit(cache=True, nogil=True)
def _scores(gc, route, time, kind, dt, sigma, travel, slack, penalty, params):  # type: ignore[no-untyped-def]  # pragma: no cover
    out = np.empty(len(gc))
    for k in range(len(gc)):
        turn = kind[k] == ROUTE_UTURN or kind[k] == ROUTE_UTURN_AT_NODE
        out[k] = transition_score(
            gc[k], route[k], time[k], turn, dt[k], sigma[k], travel[k], slack[k], penalty[k], params
        )
    return out


def log_transition(
    great_circle_m: FloatArray,
    route_m: FloatArray,
    time_s: FloatArray,
    kind: IntArray,
    dt_s: FloatArray,
    sigma_m: FloatArray,
    config: MatchConfig,
    travel: tuple[FloatArray, FloatArray] | None = None,
    uturn_penalty: FloatArray | float | None = None,
) -> FloatArray:
    """
    Log-likelihood of moving between two candidates of consecutive fixes.

    ``-|great-circle - route| / beta`` with ``beta = beta_m + beta_per_s * dt`` (Newson &
    Krumm's exponential, widened for long intervals; where the trace says how far the car
    went, a travel with a slack of at most :data:`TRUSTED_SLACK_FRAC` of it, the smaller of
    that and ``|travel - route|`` plus :data:`TRAVEL_CHORD_SHARE` of it, so a winding road is
    not charged fully for its chord), minus a
    speed-plausibility penalty when the route needs a speed well above the roads' limits,
    minus ``uturn_penalty`` for a U-turn in the middle of a road. When the trace says how far
    the car travelled between the fixes (``travel``: the distance, odometer increments or
    mean reported speed times ``dt``, NaN where unknown, and an extra slack for the latter),
    a route that differs from it by more than the tolerance (``travel_tolerance_m +
    travel_tolerance_frac * travel + slack``) costs the excess over ``travel_beta_m``.
    Inside the tolerance that term is flat, so the fused distance never pulls the matched
    length and the distance check stays independent.
    Unreachable pairs (``route = inf``) are ``-inf``. A step without a usable time (none
    known, or a repeated one) is a distance-only step: no speed term, and the interval that
    widens beta is the one a car at the nominal speed would need for the step.

    Examples
    --------
    >>> from mapmatch.config import MatchConfig
    >>> log_transition(np.array([10.0]), np.array([13.0]), np.array([1.0]),
    ...                np.array([1]), np.array([1.0]), np.array([5.0]), MatchConfig())
    array([-0.625])
    """
    travel_m, slack_m = (np.nan, 0.0) if travel is None else travel
    penalty = config.uturn_penalty if uturn_penalty is None else uturn_penalty
    values = (great_circle_m, route_m, time_s, kind, dt_s, sigma_m, travel_m, slack_m, penalty)
    shape, flat = flat_arrays(*values)
    flat[3] = flat[3].astype(np.int64)
    out = _scores(*flat, model_params(config))  # type: ignore[call-arg]
    return np.asarray(out, dtype=np.float64).reshape(shape)


@njit(cache=True, nogil=True)
def uturn_cost(heading_a, heading_b, weight, params):  # type: ignore[no-untyped-def]  # pragma: no cover
    """What a U-turn between two fixes costs given their headings (see :func:`uturn_penalties`)."""
    evidence = (
        (0.0 if np.isnan(weight) else weight)
        if angle_between(heading_a, heading_b) > 120.0
        else 0.0
    )
    plain = params[P_UTURN_PENALTY]
    return plain + evidence * (params[P_UTURN_EVIDENCE_PENALTY] - plain)


@njit(cache=True, nogil=True)
def _uturn_costs(heading_a, heading_b, weight, params):  # type: ignore[no-untyped-def]  # pragma: no cover
    out = np.empty(len(heading_a))
    for k in range(len(out)):
        out[k] = uturn_cost(heading_a[k], heading_b[k], weight[k], params)
    return out


def uturn_penalties(
    heading_a: FloatArray, heading_b: FloatArray, weight: FloatArray, config: MatchConfig
) -> FloatArray:
    """
    What a U-turn between two fixes costs, given the evidence their headings give.

    Turning round needs evidence: without it a U-turn costs ``uturn_penalty``, so noise
    that a small backward move explains is never taken for one. Headings that point more
    than 120 degrees apart, at speeds where headings count (``weight``, the smaller of the
    two fixes' heading weights), lower the cost towards ``uturn_evidence_penalty``.

    Examples
    --------
    >>> from mapmatch.config import MatchConfig
    >>> cfg = MatchConfig()
    >>> p = uturn_penalties(np.array([0.0, 0.0]), np.array([180.0, 10.0]), np.ones(2), cfg)
    >>> bool(p[0] == cfg.uturn_evidence_penalty), bool(p[1] == cfg.uturn_penalty)
    (True, True)
    """
    shape, flat = flat_arrays(heading_a, heading_b, weight)
    out = _uturn_costs(*flat, model_params(config))  # type: ignore[call-arg]
    return np.asarray(out, dtype=np.float64).reshape(shape)


#: Mean search bound (m) of a trace's steps from which it asks the network for its route
#: table (built in the background, within the memory budget): a sparse trace, whose searches
#: the table answers 1.2-1.9 times faster (15-30 s). Once there, the table answers every pair
#: whose search fits in its bound (:func:`_pair_routes`): with its hashed look-ups
#: (:mod:`roadnets.record_index`) within a few per cent of the searches at 1 s (0.94-1.04x), so
#: a dense trace uses it too but never asks for it.
TABLE_FROM_MEAN_BOUND_M = 400.0


@njit(cache=True, nogil=True)
def wants_table(bounds_m):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    Whether steps with these route search bounds make a sparse trace, which asks for the table.

    Examples
    --------
    >>> wants_table(np.array([320.0, 340.0])), wants_table(np.array([600.0, 900.0]))
    (False, True)
    """
    total = 0.0
    for bound in bounds_m:
        total += bound
    return len(bounds_m) > 0 and total >= TABLE_FROM_MEAN_BOUND_M * len(bounds_m)


#: Where :func:`_pair_routes` took a trellis's routes from: searches, the route table, or both
#: (the pairs whose searches fit in the table's bound from it, the others searched; their
#: records told apart by :func:`table_record`).
ROUTES_SEARCHED, ROUTES_FROM_TABLE, ROUTES_MIXED = 0, 1, 2


@njit(cache=True, nogil=True, inline="always")
def table_record(rec):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """The table's record a pair's ``rec`` of :data:`ROUTES_MIXED` routes names (-1: a search's)."""
    return -2 - rec if rec <= -2 else -1


@njit(cache=True, nogil=True, inline="always")
def _search_arrival(rec, from_edge, searched, state_edge):  # type: ignore[no-untyped-def]  # pragma: no cover
    """The edge a searched route (record ``rec``) drives onto its target from (none: unknown)."""
    if rec < 0:
        return ARRIVAL_UNKNOWN
    before = searched[7][rec]  # the record's predecessor
    return from_edge if before < 0 else state_edge[searched[3][before]]


@njit(cache=True, nogil=True)
def _pair_routes(graph, ws, scratch, uturn_cost_m, table, from_edge, to_edge, bounds):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Routes of edge pairs: from the precomputed table where their searches fit in it, else searched.

    Returns where they came from (:data:`ROUTES_SEARCHED`, :data:`ROUTES_FROM_TABLE` or
    :data:`ROUTES_MIXED`), the searches' output of
    :func:`~roadnets.route_search.route_pairs_kernel` (empty when none ran) and per pair its
    record (a search's, else the table's; with both, a table record ``r`` is written ``-2 - r``,
    :func:`table_record`), length, time, U-turns and the edge it drives onto its target edge
    from: the route's last edge before the target, ``from_edge`` when the target follows at
    once, :data:`~mapmatch.hmm.routes.ARRIVAL_UNKNOWN` without a route. Where some pairs' searches
    fit in the table and others not, each pair gets the route the searches of all would give
    it (:func:`~roadnets.route_search.searches_within`): the table is a speed-up, never a
    change of answer.
    """
    t_bound, t_sources, t_ptr, t_state, t_index, t_dist, t_time, t_turns, copy_ptr, copy_state = (
        table[:10]
    )
    state_edge = graph[2]
    n = len(bounds)
    columns = (t_sources, t_ptr, t_state, t_index, t_dist, t_time, t_turns, table[10],
               copy_ptr, copy_state)  # fmt: skip
    within = np.zeros(n, dtype=np.bool_)
    n_within = 0
    if t_bound > -np.inf:  # no table (bound -inf) answers nothing, even with no pairs
        n_within = n
        for k in range(n):  # every bound fits, a trace's usual case: no sources to group
            if bounds[k] > t_bound:
                within = searches_within(from_edge, bounds, t_bound, scratch[0])
                n_within = 0
                for i in range(n):
                    n_within += within[i]
                break
    e_i, e_f = np.empty(0, dtype=np.int64), np.empty(0)
    if t_bound > -np.inf and n_within == n:
        rec, dist, time, turns, arrival = table_routes(
            columns, state_edge, from_edge, to_edge, bounds, uturn_cost_m, scratch[0]
        )
        searched = (
            e_i, e_f, e_i, np.empty(0, dtype=np.int32), e_f, e_f, np.empty(0, dtype=np.int16),
            e_i, e_i, e_i, e_i,
        )  # fmt: skip
        return ROUTES_FROM_TABLE, searched, rec, dist, time, turns, arrival
    if n_within == 0:
        out = route_pairs_kernel(graph, from_edge, to_edge, bounds, uturn_cost_m, ws, scratch)
        searched = out[:11]
        rec = out[11]
        arrival = np.empty(len(rec), dtype=np.int64)
        for k in range(len(rec)):
            arrival[k] = _search_arrival(rec[k], from_edge[k], searched, state_edge)
        return ROUTES_SEARCHED, searched, rec, out[12], out[13], out[14], arrival
    on_table = np.flatnonzero(within)
    apart = np.flatnonzero(~within)
    out = route_pairs_kernel(
        graph, from_edge[apart], to_edge[apart], bounds[apart], uturn_cost_m, ws, scratch
    )
    searched = out[:11]
    rec = np.full(n, -1, dtype=np.int64)
    dist, time = np.full(n, np.inf), np.full(n, np.inf)
    turns = np.zeros(n, dtype=np.int64)
    arrival = np.full(n, ARRIVAL_UNKNOWN, dtype=np.int64)
    for m in range(len(apart)):
        k = apart[m]
        r = out[11][m]
        rec[k], dist[k], time[k], turns[k] = r, out[12][m], out[13][m], out[14][m]
        arrival[k] = _search_arrival(r, from_edge[k], searched, state_edge)
    t_rec, t_dist, t_time, t_turns_out, t_arrival = table_routes(
        columns, state_edge, from_edge[on_table], to_edge[on_table], bounds[on_table],
        uturn_cost_m, scratch[0],
    )  # fmt: skip
    for m in range(len(on_table)):
        k = on_table[m]
        rec[k] = -2 - t_rec[m] if t_rec[m] >= 0 else -1
        dist[k], time[k], turns[k], arrival[k] = t_dist[m], t_time[m], t_turns_out[m], t_arrival[m]
    return ROUTES_MIXED, searched, rec, dist, time, turns, arrival


@njit(cache=True, nogil=True, inline="always")
def dead_end_ahead(edge, trans_ptr, trans_to, state_edge, edge_twin):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Whether ``edge`` ends where the only way on is back along its own road (a dead end)."""
    twin = edge_twin[edge]
    if twin < 0:
        return False
    ways_on = 0  # successors other than the way back (a loop, not a generator: compiled)
    for k in range(trans_ptr[edge], trans_ptr[edge + 1]):
        ways_on += state_edge[trans_to[k]] != twin
    return ways_on == 0


@njit(cache=True, nogil=True)
def driving_on_explains(edge, from_m, heading, lo, hi, c_edge, c_off, c_bear):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Whether driving on along ``edge`` explains a heading that turned round.

    It does when a candidate among rows ``lo:hi`` lies ahead of ``from_m`` on ``edge`` with
    the road there pointing within 90 degrees of ``heading``. On a hairpin or a winding
    mountain road the heading reverses between two sparse fixes without any U-turn; only
    where the road itself does not turn so is a reversal evidence.
    """
    for r in range(lo, hi):
        if c_edge[r] == edge and c_off[r] >= from_m and angle_between(heading, c_bear[r]) < 90.0:
            return True
    return False


@njit(cache=True, nogil=True)
def transitions_kernel(  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    graph, ws, scratch, uturn_cost_m, table, edge_speed,
    c_edge, c_off, c_dist, c_x, c_y, c_bear, c_ptr,
    step, a, b, bounds,
    step_m, dt, sigma, fix_x, fix_y, travel_m, slack_m, heading, speed,
    params,
):  # fmt: skip
    """
    Log transition and route kind of every candidate pair: the best of its explanations.

    ``c_ptr`` gives each used observation's candidate rows, ``c_bear`` their road direction;
    ``step_m, dt, travel_m, slack_m`` are per step between the used observations,
    ``sigma, fix_x, fix_y, heading, speed`` per used observation (``travel_m`` and
    ``heading`` empty when unknown). Returns the scores, the kinds, the forward routes
    (:func:`_pair_routes`: whether the table answered, the searches and each pair's record)
    and ``(move score, move kind, move arrival, arrival)``: each pair's best explanation
    that moves the car, and the edge the car arrives on ``b``'s edge from
    with that move and with the best explanation (:data:`~mapmatch.hmm.routes.ARRIVAL_SAME`,
    :data:`~mapmatch.hmm.routes.ARRIVAL_HELD`, or an edge), for the Viterbi pass's check of
    holds across edges (:func:`~mapmatch.hmm.viterbi.viterbi_arrivals_kernel`).
    """
    edge_len, edge_twin = graph[6], graph[5]
    n = len(a)
    ea, eb = c_edge[a], c_edge[b]
    oa, ob = c_off[a], c_off[b]
    fits, searched, rec, r_dist, r_time, r_turns, move_arrival = _pair_routes(
        graph, ws, scratch, uturn_cost_m, table, ea, eb, bounds
    )
    lt = np.empty(n)
    kind = np.empty(n, dtype=np.int64)
    step_sigma = np.empty(n)
    tolerance = np.empty(n)
    penalty = np.empty(n)
    last_step, last_a = -1, -1  # pairs come in runs of one step and one a: each priced once
    step_penalty = a_penalty = params[P_UTURN_PENALTY]
    for k in range(n):
        t = step[k]
        s = max(sigma[t], sigma[t + 1])
        step_sigma[k] = s
        tolerance[k] = max(params[P_STANDSTILL_M], params[P_STANDSTILL_SIGMAS] * s)
        if len(heading) and (t != last_step or a[k] != last_a):
            if t != last_step:
                w = min(speed_weight(speed[t], params), speed_weight(speed[t + 1], params))
                step_penalty = uturn_cost(heading[t], heading[t + 1], w, params)
            a_penalty = step_penalty
            if step_penalty < params[P_UTURN_PENALTY] and driving_on_explains(
                ea[k], oa[k], heading[t + 1], c_ptr[t + 1], c_ptr[t + 2], c_edge, c_off, c_bear
            ):
                a_penalty = params[P_UTURN_PENALTY]
            last_step, last_a = t, a[k]
        penalty[k] = a_penalty
        e1, e2 = ea[k], eb[k]
        route, free, kind[k] = forward_route(
            e1, e2, oa[k], ob[k], edge_len[e1], edge_speed[e1], edge_speed[e2],
            r_dist[k], r_time[k], r_turns[k],
        )  # fmt: skip
        travel, slack = (travel_m[t], slack_m[t]) if len(travel_m) else (np.nan, 0.0)
        # at a dead end's end turning is no choice, so a U-turn there costs what evidence does:
        # the route from a dead-end edge onto its twin turns at the end node, and a U-turn in
        # the middle of such an edge counts when the fixes reached the end (within a held
        # car's scatter)
        dead_end = e2 == edge_twin[e1] and dead_end_ahead(
            e1, graph[0], graph[1], graph[2], edge_twin
        )
        forced = min(penalty[k], params[P_UTURN_EVIDENCE_PENALTY])
        turn = kind[k] == ROUTE_UTURN_AT_NODE
        # and a turn round the travel explains costs what evidence does too
        evidence = dead_end or (
            turn and travel_explains_turn(step_m[t], route, travel, slack, params)
        )
        lt[k] = transition_score(
            step_m[t], route, free, turn, dt[t], s, travel, slack,
            forced if evidence else penalty[k], params,
        )  # fmt: skip
        # a U-turn in the middle of the road
        u = uturn_route(e2, oa[k], ob[k], edge_len[e1], edge_twin[e1])
        if np.isfinite(u):
            cost = penalty[k]
            short_of_end = edge_len[e1] - max(oa[k], edge_len[e1] - ob[k])
            if (dead_end and short_of_end <= tolerance[k]) or travel_explains_turn(
                step_m[t], u, travel, slack, params
            ):
                cost = forced
            score = transition_score(
                step_m[t], u, u / edge_speed[e1], True, dt[t], s, travel, slack, cost, params
            )
            if score > lt[k]:
                lt[k] = score
                kind[k] = ROUTE_UTURN
    # the moves alone, and the edge each drives onto b's edge from: a hold across edges is a
    # held car only where the car arrived on b's edge, which the Viterbi pass checks against
    # the state's own arrival (elsewhere the move is what the pair scores)
    moved = lt.copy()
    for k in range(n):
        if kind[k] == ROUTE_SAME_EDGE:
            move_arrival[k] = ARRIVAL_SAME
        elif kind[k] == ROUTE_UTURN:
            move_arrival[k] = ea[k]
    arrival = move_arrival.copy()
    move_kind = kind.copy()
    # holding still: b a little behind a, on its edge or across edges
    back, near, reach = held_behind(
        ea, eb, oa, ob, c_x[a], c_y[a], c_x[b], c_y[b], tolerance, edge_len, scratch[0]
    )
    if len(near):
        _, _, _, dist_back, _, _, _ = _pair_routes(
            graph, ws, scratch, uturn_cost_m, table, eb[near], ea[near], reach
        )
        held_across(back, near, ea, eb, oa, ob, edge_len, dist_back, tolerance)
    for k in range(n):
        if not np.isfinite(back[k]):
            continue
        t = step[k]
        fb = t + 1
        at_a = np.hypot(fix_x[fb] - c_x[a[k]], fix_y[fb] - c_y[a[k]])
        # never better than b's own emission: holding is an explanation of b, not a bonus
        extra = min(
            distance_score(at_a, sigma[fb], params)
            - distance_score(c_dist[b[k]], sigma[fb], params),
            0.0,
        )
        travel, slack = (travel_m[t], slack_m[t]) if len(travel_m) else (np.nan, 0.0)
        score = transition_score(
            step_m[t], 0.0, 0.0, False, dt[t], step_sigma[k], travel, slack, penalty[k], params
        )
        score = score + extra
        if score > lt[k]:
            lt[k] = score
            kind[k] = ROUTE_STANDSTILL
            arrival[k] = ARRIVAL_SAME if ea[k] == eb[k] else ARRIVAL_HELD
    moves = (moved, move_kind, move_arrival, arrival)
    return lt, kind, fits, searched, rec, moves


#: The table argument of :func:`transitions_kernel` when the network has no usable table.
_NO_TABLE = (
    -np.inf,
    np.zeros(0, dtype=np.int64),
    np.zeros(1, dtype=np.int64),
    np.zeros(0, dtype=np.int32),
    (np.zeros(1, dtype=np.int64), np.zeros(0, dtype=np.uint16)),
    np.zeros(0),
    np.zeros(0),
    np.zeros(0, dtype=np.int16),
    np.zeros(1, dtype=np.int64),
    np.zeros(0, dtype=np.int32),
    np.zeros(0, dtype=np.int32),
)


def route_inputs(net: RoadNetwork) -> tuple[Any, ...]:
    """
    ``(graph, ws, scratch, uturn_cost_m, table)``: what :func:`transitions_kernel` routes with.

    The network's search arrays and this thread's scratch (:mod:`roadnets.routes`), and the
    precomputed route table of :meth:`~roadnets.RoadNetwork.precompute_routes` when the
    network has one the matcher's searches may use (by length, the default U-turn cost);
    a table with bound ``-inf`` otherwise. Kept per thread with the rest of the network's
    kernel inputs (:func:`~mapmatch.hmm.network_inputs.network_inputs`).
    """
    from roadnets.routes import DEFAULT_UTURN_COST_M, scratch, search_graph

    table = net.precomputed_routes
    ws, group = scratch(net.arrays, net.turns)
    graph = search_graph(net.arrays, net.turns)
    if table is not None and not table.weighted and table.uturn_cost_m == DEFAULT_UTURN_COST_M:
        bound = float(table.bounds_m.min(initial=np.inf))
        t = (bound, table.sources, table.ptr, table.state, table.index(), table.distance_m,
             table.time_s, table.uturns, net.turns.copy_ptr, net.turns.copy_state,
             table.pred)  # fmt: skip
    else:
        t = _NO_TABLE
    return graph, ws, group, DEFAULT_UTURN_COST_M, t
