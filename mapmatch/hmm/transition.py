"""Log transition of every candidate pair: the best of its explanations.

Newson & Krumm's exponential in ``|great-circle - route|`` with a scale that grows with the
interval and the position sigma, a speed-plausibility term against the roads' limits
(reference paper, eq. 24), a flat-bottomed term against the distance the trace says it
travelled, and the cost of a U-turn, lowered by heading evidence. ``transitions`` scores every
pair's forward route, its U-turn in the middle of the road and its standstill, and keeps the
best.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mapmatch.hmm.emission import distance_emission, heading_weight
from mapmatch.hmm.routes import (
    ROUTE_STANDSTILL,
    ROUTE_UTURN,
    ROUTE_UTURN_AT_NODE,
    CandidatePairs,
    routes_between,
    standstill_distances,
    uturn_routes,
)

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig
    from mapmatch.hmm.candidates import Candidates
    from mapmatch.hmm.observations import Observations
    from mapmatch.types import FloatArray, IntArray
    from roadnets import EdgeRoutes, RoadNetwork

__all__ = ["log_transition", "transitions", "uturn_penalties"]


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


def transitions(
    net: RoadNetwork,
    fixes: Observations,
    cands: Candidates,
    pairs: CandidatePairs,
    bounds_m: FloatArray,
    used: IntArray,
    step_m: FloatArray,
    config: MatchConfig,
) -> tuple[FloatArray, IntArray, EdgeRoutes]:
    """
    Log transition and route kind of every candidate pair: the best of its explanations.

    Driving forward (along the edge or through the graph) is scored for every pair; a U-turn
    in the middle of the road where ``b`` is on the reverse of ``a``'s edge; and holding still
    where ``b`` lies a little behind ``a``. A held car is where ``a`` is, so the standstill
    is also charged the emission ``b``'s fix has at ``a``'s place instead of its own.
    """
    arrays = net.arrays
    route, free_time, kind, routes = routes_between(net, cands, pairs, bounds_m)
    gc, dt = step_m[pairs.step], np.diff(fixes.time_s[used])[pairs.step]
    sigma = fixes.sigma_m[used]
    step_sigma = np.maximum(sigma[pairs.step], sigma[pairs.step + 1])
    travel = fixes.travel.between(used) if fixes.travel is not None else None
    step_travel = None if travel is None else (travel[0][pairs.step], travel[1][pairs.step])
    uturn_cost: FloatArray | float = config.uturn_penalty
    if fixes.heading_deg is not None:
        weight = heading_weight(fixes.speed_mps[used], config)
        heading = fixes.heading_deg[used]
        uturn_cost = uturn_penalties(
            heading[pairs.step],
            heading[pairs.step + 1],
            np.minimum(weight[pairs.step], weight[pairs.step + 1]),
            config,
        )
    lt = log_transition(gc, route, free_time, kind, dt, step_sigma, config, step_travel, uturn_cost)

    def consider(
        where: IntArray, route_m: FloatArray, time_s: FloatArray, move: int, extra: FloatArray
    ) -> None:
        sub = None if step_travel is None else (step_travel[0][where], step_travel[1][where])
        moves = np.full(len(where), move)
        cost = uturn_cost[where] if isinstance(uturn_cost, np.ndarray) else uturn_cost
        score = log_transition(
            gc[where], route_m, time_s, moves, dt[where], step_sigma[where], config, sub, cost
        )
        score = score + extra
        better = score > lt[where]
        lt[where[better]] = score[better]
        kind[where[better]] = move

    u_route = uturn_routes(net, cands, pairs)
    twins = np.flatnonzero(np.isfinite(u_route))  # a U-turn in place is possible
    if len(twins):
        u_time = u_route[twins] / arrays.edge_speed_mps[cands.edge[pairs.a[twins]]]
        consider(twins, u_route[twins], u_time, ROUTE_UTURN, np.zeros(len(twins)))

    tolerance = np.maximum(config.standstill_m, config.standstill_sigmas * step_sigma)
    back = standstill_distances(net, cands, pairs, tolerance)
    held = np.flatnonzero(np.isfinite(back))
    if len(held):
        fix_b = used[pairs.step[held] + 1]
        a_row, b_row = pairs.a[held], pairs.b[held]
        at_a = np.hypot(fixes.x[fix_b] - cands.x[a_row], fixes.y[fix_b] - cands.y[a_row])
        sigma_b = fixes.sigma_m[fix_b]
        # never better than b's own emission: holding is an explanation of b, not a bonus
        extra = np.minimum(
            distance_emission(at_a, sigma_b, config)
            - distance_emission(cands.distance_m[b_row], sigma_b, config),
            0.0,
        )
        zero = np.zeros(len(held))
        consider(held, zero, zero, ROUTE_STANDSTILL, extra)
    return lt, kind, routes
