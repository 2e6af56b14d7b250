"""The HMM over a trace's observations: build the trellis, solve it, repair its breaks.

``solve`` scores the emissions and transitions of the observations in use, pads them into a
trellis and runs Viterbi and forward-backward (:mod:`mapmatch.hmm.viterbi`); where no
transition is possible the trace breaks. ``repair_breaks`` tries to join pieces by leaving out
the observation at a break (a two-observation trellis per try), then solves once more.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numba import njit

from mapmatch.hmm.candidates import Candidates, sigmas_radius
from mapmatch.hmm.emission import (
    angle_between,
    chord_pace,
    distance_score,
    heading_score,
    road_class_score,
    speed_weight,
)
from mapmatch.hmm.network_inputs import network_inputs
from mapmatch.hmm.observations import between_kernel, travel_arrays
from mapmatch.hmm.params import (
    P_CANDIDATE_MARGIN,
    P_CORE_RADIUS_SIGMAS,
    P_COURSE_PRUNE,
    P_FAR_CANDIDATES,
    P_MAX_CANDIDATES,
    P_MIN_LOG_TRANSITION,
    P_SEARCH_RADIUS,
    model_params,
)
from mapmatch.hmm.pathwalk import EPS_M
from mapmatch.hmm.routes import ARRIVAL_HELD, pairs_kernel, search_bound
from mapmatch.hmm.solution import Solution
from mapmatch.hmm.transition import (
    ROUTES_FROM_TABLE,
    ROUTES_SEARCHED,
    table_record,
    transitions_kernel,
    wants_table,
)
from mapmatch.hmm.viterbi import _posterior_kernel, viterbi_arrivals_kernel

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig
    from mapmatch.hmm.observations import Observations
    from mapmatch.types import BoolArray, FloatArray, IntArray
    from roadnets import RoadNetwork

__all__ = [
    "bridge_transitions",
    "cuts",
    "isolated",
    "model_fixes",
    "observation_arrays",
    "repair_breaks",
    "solve",
    "solve_kernel",
    "trace_inputs",
]


@njit(cache=True, nogil=True)
def _pieces(states, starts):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """``(start, stop)`` of each connected piece of a Viterbi path (as :func:`viterbi` gives)."""
    n = len(states)
    lo = np.empty(n, dtype=np.int64)
    hi = np.empty(n, dtype=np.int64)
    m = 0
    for start in range(n):
        if not (starts[start] and states[start] >= 0):
            continue
        stop = start + 1
        while stop < n and states[stop] >= 0 and not starts[stop]:
            stop += 1
        lo[m], hi[m] = start, stop
        m += 1
    return lo[:m], hi[:m]


@njit(cache=True, nogil=True)
def _best_places(rows, em, c_x, c_y, most):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    Keep, in place, the rows of the ``most`` road places with the best emission.

    ``rows`` are one fix's candidate rows (nearest first) and ``em`` their emissions. A
    place is a projection point: both directions of a two-way road share theirs, as do the
    edges meeting at a junction the fix projects onto, and they count once and are kept
    together (points within :data:`~mapmatch.hmm.pathwalk.EPS_M` of each other are one: a
    twin's projection may differ in its last bits). The kept rows stay nearest first, at the
    front; returns how many (at most all the rows: the search found
    :data:`~mapmatch.hmm.candidates.EDGES_PER_PLACE` x ``most``).
    """
    order = np.argsort(-em, kind="mergesort")
    take = np.zeros(len(rows), dtype=np.bool_)
    places = 0
    for j in order:
        twin = False
        for q in range(len(rows)):
            if (
                take[q]
                and abs(c_x[rows[q]] - c_x[rows[j]]) <= EPS_M
                and abs(c_y[rows[q]] - c_y[rows[j]]) <= EPS_M
            ):
                twin = True
                break
        if not twin:
            if places == most:
                continue
            places += 1
        take[j] = True
    kept = 0
    for q in range(len(rows)):
        if take[q]:
            rows[kept] = rows[q]
            em[kept] = em[q]
            kept += 1
    return kept


#: The course between a fix's neighbours says which way it drove when they lie at most this
#: many seconds apart and at least this far (and 4 sigma) apart.
COURSE_MAX_GAP_S = 10.0
COURSE_MIN_M = 10.0


@njit(cache=True, nogil=True)
def _courses(used, ox, oy, otime, osigma, params):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    The course of each observation: the bearing of the chord between its used neighbours.

    NaN where it has none: an end, neighbours more than ``COURSE_MAX_GAP_S`` apart or closer
    than ``COURSE_MIN_M`` and 4 sigma, an observation not in ``used``, or
    ``course_prune_deg`` 0. The trellis drops the candidates that run more than
    ``course_prune_deg`` from it where the observation has no reported heading.
    """
    course = np.full(len(ox), np.nan)
    if params[P_COURSE_PRUNE] <= 0:
        return course
    for i in range(1, len(used) - 1):
        p, q = used[i - 1], used[i + 1]
        if not otime[q] - otime[p] <= COURSE_MAX_GAP_S:
            continue
        dx, dy = ox[q] - ox[p], oy[q] - oy[p]
        if np.hypot(dx, dy) >= max(COURSE_MIN_M, 4.0 * osigma[used[i]]):
            course[used[i]] = np.degrees(np.arctan2(dx, dy)) % 360.0
    return course


@njit(cache=True, nogil=True, inline="always")
def _core_reach(c_dist, lo, hi, sigma, params):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    The end of the rows ``lo:hi`` of one observation (nearest first) that enter the model.

    Every row within the core radius (``core_radius_sigmas`` x ``sigma``, at least
    ``search_radius_m``) and the ``far_candidates`` nearest beyond it; every row when none is
    within the core.
    """
    core_m = sigmas_radius(sigma, params[P_CORE_RADIUS_SIGMAS], params[P_SEARCH_RADIUS], np.inf)
    core = lo
    while core < hi and c_dist[core] <= core_m:
        core += 1
    if core == lo:
        return hi
    return min(hi, core + int(params[P_FAR_CANDIDATES]))


@njit(cache=True, nogil=True)
def solve_kernel(  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    network, cands, used, cut_after, obs, course, pace, travel, params
):
    """
    :func:`solve` in one call, routes searched inside.

    The used observations' candidates and emissions, the margin, the pairs and their
    transitions, the padded trellis, Viterbi and forward-backward. ``network`` is the
    network's :func:`~mapmatch.hmm.network_inputs.network_inputs`, ``cands`` the seven
    arrays of every observation's :class:`Candidates`, ``obs`` the observations' ``(x, y,
    time, sigma, speed, heading)`` (heading empty when unknown), ``course`` and ``pace`` their
    :func:`_courses` and :func:`~mapmatch.hmm.emission.chord_pace` (each worked out over
    ``used`` when empty), ``travel`` their :func:`~mapmatch.hmm.observations.travel_arrays`. Last in
    what it returns: each pair's route record with the records' states and predecessors
    (:attr:`Solution.route_records`), whether the steps' route search bounds make a sparse
    trace that asks for the route table (:func:`~mapmatch.hmm.routes.search_bound`,
    :func:`~mapmatch.hmm.transition.wants_table`), and the course and pace used.
    """
    graph, ws, scratch, uturn_cost_m, table = network.routing
    edge_speed, edge_class = network.edge_speed, network.edge_class
    c_ptr, c_edge, c_off, c_dist, c_x, c_y, c_bear = cands
    ox, oy, otime, osigma, ospeed, oheading = obs
    if len(course) != len(ox):  # not given: over the used observations
        course = _courses(used, ox, oy, otime, osigma, params)
    if len(pace) != len(ox):
        pace = chord_pace(used, ox, oy, otime)
    n = len(used)
    has_heading = len(oheading) > 0
    # the used observations' candidates and emissions, those within the margin of the best
    total = 0
    for i in range(n):
        total += c_ptr[used[i] + 1] - c_ptr[used[i]]
    rows = np.empty(total, dtype=np.int64)
    em_all = np.empty(total)
    ptr = np.zeros(n + 1, dtype=np.int64)
    margin = params[P_CANDIDATE_MARGIN]
    most = int(params[P_MAX_CANDIDATES])
    m = 0
    for i in range(n):
        u = used[i]
        lo = c_ptr[u]
        hi = _core_reach(c_dist, lo, c_ptr[u + 1], osigma[u], params)
        best = -np.inf
        weight = speed_weight(ospeed[u], params) if has_heading else 0.0
        for r in range(lo, hi):
            e = distance_score(c_dist[r], osigma[u], params)
            if has_heading:
                e += heading_score(oheading[u], c_bear[r], weight, params)
            e += road_class_score(edge_class[c_edge[r]], ospeed[u], pace[u], params)
            em_all[r - lo + m] = e
            best = max(best, e)
        # an observation without a reported heading (none in the trace, or NaN) has its course;
        # where that rules out every road it says nothing, and the margin alone decides
        reported = has_heading and not np.isnan(oheading[u])
        limit = params[P_COURSE_PRUNE] if not reported else 0.0
        for course_limit in (limit, 0.0):
            kept = m  # a first pass that kept nothing wrote nothing: the second reads the same
            for r in range(lo, hi):
                e = em_all[r - lo + m]
                if margin <= 0 or e >= best - margin:
                    if course_limit > 0 and angle_between(course[u], c_bear[r]) > course_limit:
                        continue  # NaN (no course) compares False: kept
                    rows[kept] = r
                    em_all[kept] = e
                    kept += 1
            if kept > m or course_limit <= 0:
                break
        if kept - m > most:
            kept = m + _best_places(rows[m:kept], em_all[m:kept], c_x, c_y, most)
        m = kept
        ptr[i + 1] = m
    rows, em = rows[:m], em_all[:m]
    edge, off, dist = c_edge[rows], c_off[rows], c_dist[rows]
    cx, cy, bear = c_x[rows], c_y[rows], c_bear[rows]
    # the pairs of consecutive observations' candidates and their transitions
    step_m = np.empty(max(n - 1, 0))
    dt = np.empty(max(n - 1, 0))
    for i in range(n - 1):
        u, v = used[i], used[i + 1]
        step_m[i] = np.hypot(ox[v] - ox[u], oy[v] - oy[u])
        dt[i] = otime[v] - otime[u]
    step_bounds = np.empty(len(step_m))
    for i in range(len(step_m)):
        step_bounds[i] = search_bound(step_m[i], dt[i], params)
    step, a, b, a_rank, b_rank = pairs_kernel(ptr)
    bounds = np.empty(len(step))
    for k in range(len(step)):
        bounds[k] = step_bounds[step[k]]
    odometer, speed_m, slack_m, unknown_lo, unknown_hi = travel
    if len(odometer) or len(speed_m):
        travel_m, slack = between_kernel(used, odometer, speed_m, slack_m, unknown_lo, unknown_hi)
    else:
        travel_m, slack = np.empty(0), np.empty(0)
    heading = oheading[used] if has_heading else oheading
    lt, kind, fits, searched, rec, moves = transitions_kernel(
        graph, ws, scratch, uturn_cost_m, table, edge_speed,
        edge, off, dist, cx, cy, bear, ptr, step, a, b, bounds,
        step_m, dt, osigma[used], ox[used], oy[used], travel_m, slack, heading, ospeed[used],
        params,
    )  # fmt: skip
    # the padded trellis
    width = 1
    for i in range(n):
        width = max(width, ptr[i + 1] - ptr[i])
    em_pad = np.full((n, width), -np.inf)
    for i in range(n):
        for r in range(ptr[i], ptr[i + 1]):
            em_pad[i, r - ptr[i]] = em[r]
    edge_pad = np.full((n, width), -1, dtype=np.int64)
    for i in range(n):
        for r in range(ptr[i], ptr[i + 1]):
            edge_pad[i, r - ptr[i]] = edge[r]
    tr_pad = np.full((max(n - 1, 0), width, width), -np.inf)
    kinds = np.full((max(n - 1, 0), width, width), -1, dtype=np.int64)
    pair = np.full((max(n - 1, 0), width, width), -1, dtype=np.int32)
    move_score, move_kind, move_arrival, arrival = moves
    floor = params[P_MIN_LOG_TRANSITION]
    for k in range(len(step)):
        t = step[k]
        score = lt[k]
        if cut_after[t] or score < floor:
            score = -np.inf
        if cut_after[t] or move_score[k] < floor:
            move_score[k] = -np.inf
        tr_pad[t, a_rank[k], b_rank[k]] = score
        kinds[t, a_rank[k], b_rank[k]] = kind[k]
        pair[t, a_rank[k], b_rank[k]] = -2 - k if arrival[k] == ARRIVAL_HELD else k
    if n:
        states, starts, _, moved = viterbi_arrivals_kernel(
            em_pad, tr_pad, pair, edge_pad, move_score, move_arrival, arrival
        )
    else:
        states, starts = np.empty(0, dtype=np.int64), np.zeros(0, dtype=np.bool_)
        moved = np.zeros((0, width), dtype=np.bool_)
    # where the best path's hold was not on its arrival edge, the path moved: say so
    for t in range(1, n):
        i, j = states[t - 1], states[t]
        if i >= 0 and j >= 0 and not starts[t] and moved[t, j]:
            k = -2 - pair[t - 1, i, j]
            tr_pad[t - 1, i, j] = move_score[k]
            kinds[t - 1, i, j] = move_kind[k]
    piece_lo, piece_hi = _pieces(states, starts)
    post = _posterior_kernel(em_pad, tr_pad, piece_lo, piece_hi)
    # the routes' records, their states and predecessors: each pair's route edge by edge
    if fits == ROUTES_FROM_TABLE:
        r_state, r_pred = table[3], table[10]
    elif fits == ROUTES_SEARCHED:
        r_state, r_pred = searched[3], searched[7].astype(np.int32)
    else:
        rec, r_state, r_pred = _merged_records(
            rec, states, pair, searched[3], searched[7], table[3], table[10]
        )
    return (
        (ptr, edge, off, dist, cx, cy, bear),
        states, piece_lo, piece_hi, post, kinds, em_pad, tr_pad,
        (rec, r_state, r_pred),
        wants_table(step_bounds),
        course, pace,
    )  # fmt: skip


@njit(cache=True, nogil=True)
def _merged_records(rec, states, pair, s_state, s_pred, t_state, t_pred):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    One record space for routes that came from searches and from the table (``ROUTES_MIXED``).

    The searches' records, then the table's routes of the chosen path's pairs, each followed
    back to its source and numbered anew: what the path walk reads (it walks the chosen pairs'
    routes only). Returns each pair's record in it (-1 for the table's routes of pairs off the
    path), and the records' states and predecessors.
    """
    steps = len(states) - 1
    chosen = np.full(max(steps, 0), -1, dtype=np.int64)  # each step's chosen pair
    extra = 0
    for t in range(steps):
        i, j = states[t], states[t + 1]
        if i < 0 or j < 0 or pair[t, i, j] == -1:
            continue
        k = pair[t, i, j]
        k = -2 - k if k <= -2 else k  # a held arrival's pair
        chosen[t] = k
        r = table_record(rec[k])
        while r >= 0:
            extra += 1
            r = t_pred[r]
    m = len(s_state)
    state = np.empty(m + extra, dtype=np.int32)
    pred = np.empty(m + extra, dtype=np.int32)
    for r in range(m):
        state[r], pred[r] = s_state[r], s_pred[r]
    out = rec.copy()
    for k in range(len(out)):
        if out[k] <= -2:
            out[k] = -1
    at = m
    for t in range(steps):
        k = chosen[t]
        r = table_record(rec[k]) if k >= 0 else -1
        if r < 0:
            continue
        out[k] = at
        while r >= 0:
            state[at] = t_state[r]
            r = t_pred[r]
            pred[at] = at + 1 if r >= 0 else -1
            at += 1
    return out, state, pred


def solve(
    net: RoadNetwork,
    fixes: Observations,
    all_cands: Candidates,
    used: IntArray,
    cut_after: BoolArray,
    config: MatchConfig,
    course: FloatArray | None = None,
    pace: FloatArray | None = None,
) -> Solution:
    """
    Score the trellis over the ``used`` fixes and find the best sequence.

    ``course`` and ``pace`` are each observation's course (:func:`_courses`) and pace
    (:func:`~mapmatch.hmm.emission.chord_pace`), which choose its candidates; worked out from
    ``used`` when not given, and kept in the solution: a trellis over some of a solution's
    observations (the detour search's bridges, :func:`bridge_transitions`) is given the
    solution's, so that its observations keep the same candidates.
    """
    inputs = trace_inputs(fixes, all_cands, config)
    out = _solve_arrays(
        net, inputs, used, cut_after, _NOT_GIVEN if course is None else course,
        _NOT_GIVEN if pace is None else pace,
    )  # fmt: skip
    cand_arrays, states, piece_lo, piece_hi, post, kinds, em_pad, tr_pad, records = out[:9]
    course, pace = out[10], out[11]
    cands = Candidates(*cand_arrays)
    return Solution(
        used, cands, states, piece_lo, piece_hi, post, kinds, records, em_pad, tr_pad, course, pace
    )


#: ``course`` or ``pace`` of :func:`solve_kernel` when it works them out itself.
_NOT_GIVEN = np.empty(0)


def trace_inputs(
    fixes: Observations, all_cands: Candidates, config: MatchConfig
) -> tuple[Any, ...]:
    """
    What :func:`solve_kernel` reads of a trace whichever of its fixes are used.

    ``(cands, obs, travel, params)``: every observation's candidate arrays,
    :func:`observation_arrays`, :func:`~mapmatch.hmm.observations.travel_arrays` and
    :func:`~mapmatch.hmm.params.model_params`; computed once, they serve every solve of
    the trace (:func:`bridge_transitions`).
    """
    c = all_cands
    return (
        (c.ptr, c.edge, c.offset_m, c.distance_m, c.x, c.y, c.bearing_deg),
        observation_arrays(fixes),
        travel_arrays(fixes.travel),
        model_params(config),
    )


def _solve_arrays(
    net: RoadNetwork,
    inputs: tuple[Any, ...],
    used: IntArray,
    cut_after: BoolArray,
    course: FloatArray,
    pace: FloatArray,
) -> tuple[Any, ...]:
    """
    :func:`solve_kernel` over the ``used`` fixes of a trace (:func:`trace_inputs`).

    ``course`` and ``pace``: each observation's course and pace the candidates are chosen by
    (:func:`_courses`, :func:`~mapmatch.hmm.emission.chord_pace`; empty: worked out inside).

    A sparse trace (its steps' route search bounds) asks the network for its route table,
    which the next traces may use.
    """
    cand_arrays, obs, travel, params = inputs
    out: tuple[Any, ...] = solve_kernel(
        network_inputs(net),  # read each time: the table may have come meanwhile
        cand_arrays,
        np.ascontiguousarray(used, dtype=np.int64),
        np.ascontiguousarray(cut_after, dtype=np.bool_),
        obs,
        course,
        pace,
        travel,
        params,
    )
    if out[9] and not net.route_table_requested:
        net.request_route_table()  # a sparse trace: the next ones may use the table
    return out


def bridge_transitions(
    net: RoadNetwork,
    inputs: tuple[Any, ...],
    pair: IntArray,
    cut_after: BoolArray,
    solution: Solution,
) -> FloatArray:
    """
    The log transitions of the two-fix trellis over ``pair``: what :func:`solve` scores.

    ``inputs`` are the trace's :func:`trace_inputs`, ``solution`` the one the pair belongs to
    (its :attr:`Solution.course_deg` and :attr:`Solution.pace_mps`: the pair's observations
    keep that solution's candidates and ranks); the result has shape ``(1, width, width)`` (the
    pair's candidates by rank, padded with ``-inf``). Spares the rest of a
    :class:`Solution`: its candidates, its routes' edges.
    """
    tr_pad: FloatArray = _solve_arrays(
        net, inputs, pair, cut_after, solution.course_deg, solution.pace_mps
    )[7]
    return tr_pad


def observation_arrays(obs: Observations) -> tuple[FloatArray, ...]:
    """``(x, y, time, sigma, speed, heading)`` of the observations (heading empty: unknown)."""
    heading = np.empty(0) if obs.heading_deg is None else obs.heading_deg
    f8 = np.float64
    return tuple(
        np.ascontiguousarray(v, f8)
        for v in (obs.x, obs.y, obs.time_s, obs.sigma_m, obs.speed_mps, heading)
    )


@njit(cache=True, nogil=True)
def _model_fixes(ptr, outlier, segment_starts, first):  # type: ignore[no-untyped-def]  # pragma: no cover
    """:func:`model_fixes` over arrays."""
    n = len(first)
    used = np.empty(n, dtype=np.int64)
    missing_before = np.empty(n, dtype=np.int64)
    m = 0
    missing = 0
    for k in range(n):
        has = ptr[k + 1] > ptr[k]
        if not has:
            lone = (k == 0 or ptr[k] > ptr[k - 1]) and (k == n - 1 or ptr[k + 2] > ptr[k + 1])
            if not lone:
                missing += 1
        elif not outlier[k]:
            used[m] = k
            m += 1
        segment = np.searchsorted(segment_starts, first[k], side="right")
        missing_before[k] = missing + segment
    used = used[:m]
    cut_after = np.empty(max(m - 1, 0), dtype=np.bool_)
    for i in range(m - 1):
        cut_after[i] = missing_before[used[i + 1]] > missing_before[used[i]]
    return used, missing_before, cut_after


def model_fixes(
    cands: Candidates, outlier: BoolArray, segment_starts: IntArray, first: IntArray
) -> tuple[IntArray, IntArray, BoolArray]:
    """
    The observations the model uses, the breaks before each, and where the trellis is cut.

    ``used`` are the observations with a candidate that are not outliers; ``missing_before``
    counts, for each observation, the stretches of observations without a road nearby (not
    a lone stray one, :func:`isolated`) and the starts of new trace segments (a GPX trkseg,
    ``segment_starts``) before it; ``cut_after`` marks the used observations after which one
    of those lies (:func:`cuts`): the trace splits there.
    """
    used, missing_before, cut_after = _model_fixes(
        cands.ptr,
        np.ascontiguousarray(outlier, dtype=np.bool_),
        np.ascontiguousarray(segment_starts, dtype=np.int64),
        first,
    )
    return used, missing_before, cut_after


def cuts(used: IntArray, missing_before: IntArray) -> BoolArray:
    """Where a stretch of fixes with no road nearby, or a segment start, lies between them."""
    return np.asarray(missing_before[used[1:]] > missing_before[used[:-1]], dtype=bool)


def isolated(flag: BoolArray) -> BoolArray:
    """Flagged entries whose neighbours are both unflagged (a lone stray fix)."""
    padded = np.concatenate(([False], flag, [False]))
    return np.asarray(flag & ~padded[:-2] & ~padded[2:], dtype=bool)


def repair_breaks(
    net: RoadNetwork,
    fixes: Observations,
    cands: Candidates,
    solution: Solution,
    missing_before: IntArray,
    config: MatchConfig,
) -> tuple[Solution, int] | None:
    """
    Join pieces by leaving out the fix at (or just before) a break.

    For each of the first ``max_break_repairs`` breaks that is not a stretch without roads,
    the fix at the break, else the one before, is left out when the fixes on either side of it
    can be connected (a two-fix trellis, so each try costs next to nothing); the whole trace
    is then solved once more. ``None`` when that does not reduce the number of breaks.
    """
    used = solution.used
    cut_after = cuts(used, missing_before)
    drops: list[int] = []
    for start in solution.breaks[: config.max_break_repairs]:
        if cut_after[start - 1]:
            continue  # a stretch without roads: a real break
        for drop in (start, start - 1):
            if drop <= 0 or drop >= len(used) - 1 or drop in drops or drop - 1 in drops:
                continue
            pair = used[[drop - 1, drop + 1]]
            if not solve(net, fixes, cands, pair, cuts(pair, missing_before), config).breaks:
                drops.append(drop)
                break
    if not drops:
        return None
    kept = np.delete(used, drops)
    trial = solve(net, fixes, cands, kept, cuts(kept, missing_before), config)
    if len(trial.breaks) >= len(solution.breaks):
        return None
    return trial, len(drops)
