"""The HMM's scores: log emission of each candidate, log transition of each candidate pair.

Everything is vectorised over all candidates (or all candidate pairs) of a whole trace.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from mapmatch.candidates import Candidates
    from mapmatch.config import MatchConfig
    from roadnets import PathTable, RoadNetwork

__all__ = [
    "ROUTE_SAME_EDGE",
    "ROUTE_STANDSTILL",
    "ROUTE_UTURN",
    "ROUTE_UTURN_AT_NODE",
    "ROUTE_VIA_GRAPH",
    "CandidatePairs",
    "candidate_pairs",
    "heading_weight",
    "log_emission",
    "log_heading",
    "log_transition",
    "route_search_bounds",
    "routes_between",
    "standstill_distances",
    "uturn_penalties",
    "uturn_routes",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: How a transition's route runs: forward along one edge, through the graph, a U-turn
#: mid-road, through the graph with a U-turn at a node (scored as a U-turn, assembled as a
#: graph route), or not at all: the next fix lies a little behind, which is noise around a
#: slow or stopped car, so the car holds its position (:func:`standstill_distances`).
ROUTE_SAME_EDGE, ROUTE_VIA_GRAPH, ROUTE_UTURN, ROUTE_UTURN_AT_NODE, ROUTE_STANDSTILL = 0, 1, 2, 3, 4


def log_emission(distance_m: FloatArray, *, sigma_m: FloatArray | float) -> FloatArray:
    """
    Log-likelihood of seeing each fix ``distance_m`` away from its candidate.

    Gaussian position error. The normalising constant is dropped because it is the same for
    every candidate of one fix.

    Parameters
    ----------
    distance_m
        Distance from each fix to its candidate road position, in metres.
    sigma_m
        Standard deviation of the position error, in metres (one value or one per candidate).

    Examples
    --------
    >>> log_emission(np.array([5.0, 10.0]), sigma_m=5.0)
    array([-0.5, -2. ])
    """
    return -0.5 * (distance_m / sigma_m) ** 2


def heading_weight(speed_mps: FloatArray, config: MatchConfig) -> FloatArray:
    """
    How much the heading counts at each speed: 0 when (nearly) stopped, 1 at road speeds.

    Examples
    --------
    >>> from mapmatch.config import MatchConfig
    >>> heading_weight(np.array([0.0, 5.5, 20.0, np.nan]), MatchConfig())
    array([0. , 0.5, 1. , 0. ])
    """
    lo, hi = config.heading_min_speed_mps, config.heading_full_speed_mps
    weight = np.clip((speed_mps - lo) / (hi - lo), 0.0, 1.0)
    return np.nan_to_num(weight, nan=0.0)


def log_heading(
    heading_deg: FloatArray, bearing_deg: FloatArray, weight: FloatArray, config: MatchConfig
) -> FloatArray:
    """
    Log-likelihood of the reported heading given the road direction at the candidate.

    A Gaussian on the angle between them (``heading_sigma_deg``), scaled by the speed weight
    and floored at ``-heading_max_penalty``. Unknown headings (NaN) score 0.

    Examples
    --------
    >>> from mapmatch.config import MatchConfig
    >>> log_heading(np.array([90.0, 90.0]), np.array([90.0, 270.0]), np.ones(2), MatchConfig())
    array([ -0., -12.])
    """
    diff = np.abs((heading_deg - bearing_deg + 180.0) % 360.0 - 180.0)
    score = np.maximum(-0.5 * (diff / config.heading_sigma_deg) ** 2, -config.heading_max_penalty)
    return np.nan_to_num(weight * score, nan=0.0)


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


def route_search_bounds(great_circle_m: FloatArray, config: MatchConfig) -> FloatArray:
    """Longest route worth searching after each fix: ``route_factor * gc + route_slack_m``."""
    return config.route_factor * great_circle_m + config.route_slack_m


def routes_between(
    net: RoadNetwork,
    cands: Candidates,
    pairs: CandidatePairs,
    table: PathTable,
) -> tuple[FloatArray, FloatArray, IntArray]:
    """
    Route distance, free-flow time and route kind of every candidate pair, driving forward.

    The route runs along the directed graph from candidate ``a``'s position to ``b``'s:
    forward along one edge when both are on it and ``b`` is ahead; otherwise to the end of
    ``a``'s edge, through the graph to the start of ``b``'s edge, and along it. Moves that
    hold the car still (``b`` a little behind ``a``) and U-turns in the middle of a road are
    alternatives scored separately (:func:`standstill_distances`, :func:`uturn_routes`).
    Unreachable pairs get ``inf``.

    Returns
    -------
    route_m, time_s, kind
        Metres along the road, seconds at the roads' speed limits, and
        :data:`ROUTE_SAME_EDGE`, :data:`ROUTE_VIA_GRAPH` or :data:`ROUTE_UTURN_AT_NODE`.
    """
    arrays = net.arrays
    ea, eb = cands.edge[pairs.a], cands.edge[pairs.b]
    oa, ob = cands.offset_m[pairs.a], cands.offset_m[pairs.b]
    len_a = arrays.edge_length_m[ea]
    speed_a, speed_b = arrays.edge_speed_mps[ea], arrays.edge_speed_mps[eb]

    mid_m, mid_s, first, last = table.lookup(arrays.edge_v[ea], arrays.edge_u[eb])
    route = (len_a - oa) + mid_m + ob
    time = (len_a - oa) / speed_a + mid_s + ob / speed_b
    kind = np.full(len(ea), ROUTE_VIA_GRAPH, dtype=np.int64)
    # turning back at a node (onto the twin, right away or at the end of the path) is a U-turn
    twin_a, twin_b = arrays.edge_twin[ea], arrays.edge_twin[eb]
    back_first = (first >= 0) & (first == twin_a)
    back_last = (last >= 0) & (last == twin_b)
    kind[(eb == twin_a) | back_first | back_last] = ROUTE_UTURN_AT_NODE

    ahead = (ea == eb) & (ob >= oa)
    route = np.where(ahead, ob - oa, route)
    time = np.where(ahead, (ob - oa) / speed_a, time)
    kind[ahead] = ROUTE_SAME_EDGE
    return route, time, kind


def standstill_distances(
    net: RoadNetwork,
    cands: Candidates,
    pairs: CandidatePairs,
    table: PathTable,
    tolerance_m: FloatArray,
) -> FloatArray:
    """
    How far behind ``a`` each candidate ``b`` lies along the road, where that is noise.

    ``b`` is behind ``a`` when driving forward from ``b`` reaches ``a`` (on the same edge,
    or across edges: the end of ``b``'s edge, through the graph, the start of ``a``'s edge).
    Within ``tolerance_m`` of ``a`` such a move is a slow or stopped car's fix scattering
    backwards: the car holds its position instead of driving round a block or a roundabout
    to explain it. ``inf`` where ``b`` is not that close behind.

    Examples
    --------
    >>> # 30 m along an edge, the next fix 8 m back on it, tolerance 20 m
    >>> float(np.where(30.0 - 22.0 <= 20.0, 30.0 - 22.0, np.inf))
    8.0
    """
    arrays = net.arrays
    ea, eb = cands.edge[pairs.a], cands.edge[pairs.b]
    oa, ob = cands.offset_m[pairs.a], cands.offset_m[pairs.b]
    mid_m = table.lookup(arrays.edge_v[eb], arrays.edge_u[ea])[0]
    back = (arrays.edge_length_m[eb] - ob) + mid_m + oa
    back = np.where((ea == eb) & (ob <= oa), oa - ob, back)
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
    Krumm's exponential, widened for long intervals), minus a speed-plausibility penalty when
    the route needs a speed well above the roads' limits, minus ``uturn_penalty`` for a
    U-turn in the middle of a road. When the trace says how far the car travelled between the
    fixes (``travel``: the distance, odometer increments or mean reported speed times ``dt``,
    NaN where unknown, and an extra slack for the latter), a route that differs from it by
    more than the tolerance (``travel_tolerance_m + travel_tolerance_frac * travel + slack``)
    costs the excess over ``travel_beta_m``. Inside the tolerance the term is flat, so the
    fused distance never pulls the matched length and the distance check stays independent.
    Unreachable pairs (``route = inf``) are ``-inf``.

    Examples
    --------
    >>> from mapmatch.config import MatchConfig
    >>> log_transition(np.array([10.0]), np.array([13.0]), np.array([1.0]),
    ...                np.array([1]), np.array([1.0]), np.array([5.0]), MatchConfig())
    array([-0.625])
    """
    # a step without a usable time (none known, or a repeated one) is a distance-only step:
    # no speed term, and the interval that widens beta is the one a car at the nominal speed
    # would need for the step
    timed = np.isfinite(dt_s) & (dt_s > 0)
    interval_s = np.where(timed, dt_s, great_circle_m / config.nominal_speed_mps)
    beta = config.beta_m + config.beta_per_s * interval_s + config.beta_per_sigma * sigma_m
    with np.errstate(invalid="ignore", divide="ignore"):
        score = -np.abs(great_circle_m - route_m) / beta
        needed = np.where(timed, np.maximum(route_m - 2.0 * sigma_m, 0.0) / dt_s, np.nan)
        limit = np.where(time_s > 0, route_m / time_s, np.inf)
        allowed = config.speed_factor * limit + config.speed_margin_mps
        excess = np.maximum(needed - allowed, 0.0)
    score = score - 0.5 * (np.nan_to_num(excess, nan=0.0) / config.speed_sigma_mps) ** 2
    if travel is not None:
        travel_m, slack_m = travel
        tolerance = config.travel_tolerance_m + config.travel_tolerance_frac * travel_m + slack_m
        with np.errstate(invalid="ignore", over="ignore"):
            off = np.maximum(np.abs(route_m - travel_m) - tolerance, 0.0)
        score = score - np.nan_to_num(off, nan=0.0) / config.travel_beta_m
    uturn = (kind == ROUTE_UTURN) | (kind == ROUTE_UTURN_AT_NODE)
    penalty = config.uturn_penalty if uturn_penalty is None else uturn_penalty
    score = np.where(uturn, score - penalty, score)
    return np.where(np.isfinite(route_m), score, -np.inf)


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
    diff = np.abs((heading_a - heading_b + 180.0) % 360.0 - 180.0)
    evidence = np.where(diff > 120.0, np.nan_to_num(weight, nan=0.0), 0.0)
    return np.asarray(
        config.uturn_penalty + evidence * (config.uturn_evidence_penalty - config.uturn_penalty),
        dtype=np.float64,
    )
