"""``mapmatch.match``: a trace and a road network in, the roads driven out.

The stages, each vectorised over the whole trace: project the fixes and find their candidates
(one R-tree query), leave out outliers and the near-duplicate fixes of a stopped car, score
emissions, build every candidate pair of consecutive fixes, route them (one bounded
many-source Dijkstra), score transitions, run Viterbi and forward-backward on the padded
trellis, try to join pieces by leaving out the fix at a break, and assemble segments. Fixes
left out of the model get their position on the matched path interpolated by time.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from mapmatch.assemble import assemble
from mapmatch.candidates import Candidates, find_candidates, search_radii
from mapmatch.config import MatchConfig
from mapmatch.distance import Evidence, check_distance, chord_length_m
from mapmatch.errors import NoCandidatesError
from mapmatch.models import (
    ROUTE_STANDSTILL,
    ROUTE_UTURN,
    CandidatePairs,
    candidate_pairs,
    heading_weight,
    log_emission,
    log_heading,
    log_transition,
    route_search_bounds,
    routes_between,
    standstill_distances,
    uturn_penalties,
    uturn_routes,
)
from mapmatch.observations import Observations, Travel, merge_fixes
from mapmatch.result import Diagnostics, MatchResult, MatchStats, Segment
from mapmatch.selection import find_off_road_runs, find_outliers
from mapmatch.solution import Solution
from mapmatch.trace import check_match_inputs
from mapmatch.viterbi import posteriors, viterbi

if TYPE_CHECKING:
    from mapmatch.trace import Trace
    from roadnets import PathTable, RoadNetwork

__all__ = ["match"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True, slots=True)
class Fixes:
    """
    A trace's fixes in metres with the per-fix model inputs.

    ``time_s`` is NaN throughout when the trace has no usable times; ``speed_mps`` the
    reported speed, else one estimated from positions and times (NaN when neither is known).
    """

    x: FloatArray
    y: FloatArray
    time_s: FloatArray
    sigma_m: FloatArray
    radius_m: FloatArray
    speed_mps: FloatArray
    heading_deg: FloatArray | None
    travel: Travel | None
    segment_starts: IntArray


def match(
    trace: Trace,
    net: RoadNetwork,
    config: MatchConfig | None = None,
    *,
    fused_distance_m: float | None = None,
    diagnostics: bool = False,
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
    diagnostics
        Also return every candidate with its scores (``result.diagnostics``), for inspection.

    Returns
    -------
    MatchResult
        Segments, snapped points, matched length, distance check and stats.

    Raises
    ------
    NoCandidatesError
        No fix has a road within its search radius.
    InputTypeError
        ``trace`` is not a :class:`Trace` or ``net`` not a :class:`~roadnets.RoadNetwork`.
    """
    check_match_inputs(trace, net)
    config = config or MatchConfig()
    timings: dict[str, float] = {}
    clock = time.perf_counter()

    x, y = net.project(trace.lon, trace.lat)
    n = len(x)
    fixes = _fixes(trace, x, y, config)
    obs, cands = _observe(net, fixes, config)
    if trace.accuracy_m is None and config.estimate_sigma:
        sigma = _estimated_sigma_m(obs, cands)
        if sigma > 1.25 * config.sigma_m:  # noisier than assumed: look again, wider
            fixes = _with_sigma(fixes, sigma, config)
            obs, cands = _observe(net, fixes, config)
    if len(cands) == 0:
        raise NoCandidatesError(trace.trace_id, float(fixes.radius_m.max()))
    clock = _lap(timings, "candidates", clock)

    has_cands = cands.counts > 0
    outlier = _outliers(fixes, obs, cands, config)
    lonely = _isolated(~has_cands)
    used = np.flatnonzero(has_cands & ~outlier)
    # a stretch of fixes with no road nearby (not a lone stray fix), and the start of a new
    # segment of the trace file (a GPX trkseg), split the trace
    segment = np.searchsorted(trace.segment_starts, obs.first, side="right")
    missing_before = np.cumsum(~has_cands & ~lonely, dtype=np.int64) + segment
    cut_after = _cuts(used, missing_before)
    clock = _lap(timings, "selection", clock)

    solution = _solve(net, obs, cands, used, cut_after, config)
    repairs = 0
    if solution.breaks and config.max_break_repairs:
        repaired = _repair_breaks(net, obs, cands, solution, missing_before, config)
        if repaired is not None:
            solution, repairs = repaired
    clock = _lap(timings, "hmm", clock)

    assembled = assemble(
        net,
        trace,
        x,
        y,
        obs,
        solution,
        outlier[obs.of_fix],
        fixes.radius_m,
        _hold_limit_m(fixes, config),
        config,
    )
    matched_length = float(sum(s.length_m for s in assembled.segments))
    points = assembled.points
    complete = len(assembled.segments) == 1 and bool(points.matched[[0, -1]].all())
    check = check_distance(
        trace_id=trace.trace_id,
        matched_length_m=matched_length,
        complete=complete,
        band=config.distance_band,
        odometer_m=trace.odometer_m,
        fused_distance_m=fused_distance_m,
        chord_m=chord_length_m(x, y),
        evidence=_evidence(trace, fixes, config),
        uturns=_uturns(net, assembled.segments),
    )
    _lap(timings, "result", clock)
    timings["total"] = sum(timings.values())
    stats = MatchStats(
        points=n,
        matched_points=int(points.matched.sum()),
        candidates=len(cands),
        reordered_rows=trace.report.reordered_rows,
        input_rows=trace.report.input_rows,
        merged_rows=len(trace.report.merged_rows),
        shared_time_rows=trace.report.shared_time_rows,
        dropped_rows=trace.report.dropped_rows,
        time_source=trace.report.time_source,
        timings_s=timings,
        warnings=tuple(trace.report.warnings),
        model_points=len(solution.used),
        outliers=int(points.outlier.sum()),
        break_repairs=repairs,
    )
    return MatchResult(
        trace_id=trace.trace_id,
        network={"id": net.network_id, "source": Path(net.source).name, "crs": net.crs},
        segments=assembled.segments,
        points=points,
        breaks=[s.first for s in assembled.segments[1:]],
        matched_length_m=matched_length,
        distance_check=check,
        stats=stats,
        diagnostics=_diagnostics(net, obs, solution) if diagnostics else None,
    )


def _outliers(fixes: Fixes, obs: Observations, cands: Candidates, config: MatchConfig) -> BoolArray:
    """
    Displaced observations, judged among those near a road.

    Short runs far from every road between observations on a road are displaced
    (:func:`find_off_road_runs`). Then each is compared with where its neighbours put it
    (:func:`find_outliers`); of two displaced ones in a row only the worse is caught at first,
    so that test runs again without the ones found, up to three times.
    """
    near = np.flatnonzero(cands.counts > 0)
    nearest = np.full(len(obs), np.inf)
    nearest[near] = cands.distance_m[cands.ptr[near]]  # rows of a fix are nearest first
    gaps = fixes.time_s[obs.first[1:]] - fixes.time_s[obs.stop[:-1] - 1]
    outlier = find_off_road_runs(nearest, obs.sigma_m, gaps, config)
    for _ in range(3):
        kept = near[~outlier[near]]
        travel = obs.travel.between(kept) if obs.travel is not None else None
        gap = fixes.time_s[obs.first[kept[1:]]] - fixes.time_s[obs.stop[kept[:-1]] - 1]
        found = find_outliers(
            obs.x[kept], obs.y[kept], obs.time_s[kept], obs.sigma_m[kept], config, travel, gap
        )
        if not found.any():
            break
        outlier[kept[found]] = True
    return outlier


def _observe(
    net: RoadNetwork, fixes: Fixes, config: MatchConfig
) -> tuple[Observations, Candidates]:
    """The HMM's observations of the fixes and their candidates."""
    obs = merge_fixes(
        fixes.x,
        fixes.y,
        fixes.time_s,
        fixes.sigma_m,
        fixes.radius_m,
        fixes.speed_mps,
        fixes.heading_deg,
        fixes.travel,
        config,
        fixes.segment_starts,
    )
    return obs, find_candidates(net, obs.x, obs.y, obs.radius_m, config)


def _estimated_sigma_m(obs: Observations, cands: Candidates) -> float:
    """
    The trace's own position error, as Newson & Krumm estimate it.

    1.4826 x the median distance of its fixes to the nearest road (the median absolute
    deviation of a Gaussian). Only observations of one fix count (a merged one averages its
    noise away), and only when they are most of the trace's, at least 10: where fixes merge,
    the single ones are those that stood out, and their median would overstate the noise.
    NaN otherwise.
    """
    has = cands.counts > 0
    single = has & (obs.stop - obs.first == 1)
    if single.sum() < max(10, 0.5 * has.sum()):
        return float("nan")
    nearest = cands.distance_m[cands.ptr[:-1][single]]  # rows of a fix are nearest first
    return float(1.4826 * np.median(nearest))


def _with_sigma(fixes: Fixes, sigma_m: float, config: MatchConfig) -> Fixes:
    """The fixes with a larger position sigma and the search radius that goes with it."""
    wide = min(config.radius_accuracy_factor * sigma_m, config.max_search_radius_m)
    return dataclasses.replace(
        fixes,
        sigma_m=np.fmax(fixes.sigma_m, sigma_m),
        radius_m=np.fmax(fixes.radius_m, wide),
    )


def _evidence(trace: Trace, fixes: Fixes, config: MatchConfig) -> Evidence:
    """The strongest input the matched length rests on (see :class:`DistanceCheck`)."""
    if fixes.travel is not None and trace.odometer_m is not None:
        return "odometer"
    if trace.heading_deg is not None and bool(np.isfinite(fixes.speed_mps).any()):
        return "heading"
    return "positions"


def _uturns(net: RoadNetwork, segments: list[Segment]) -> int:
    """U-turns on the matched path: an edge followed by its reverse, at a node or mid-road."""
    twin = net.arrays.edge_twin
    total = 0
    for segment in segments:
        edges = np.array([e.edge for e in segment.edges], dtype=np.int64)
        total += int(np.count_nonzero(twin[edges[:-1]] == edges[1:]))
    return total


def _hold_limit_m(fixes: Fixes, config: MatchConfig) -> float:
    """How far behind the path's front a fix may scatter and still be a held car's."""
    return float(max(config.standstill_m, config.standstill_sigmas * fixes.sigma_m.max()))


def _fixes(trace: Trace, x: FloatArray, y: FloatArray, config: MatchConfig) -> Fixes:
    """The model inputs of every fix: position sigma, search radius, speed and travel."""
    n = len(x)
    radius = search_radii(trace.accuracy_m, n, config)
    sigma = np.full(n, config.sigma_m)
    if trace.accuracy_m is not None:
        sigma = np.fmax(sigma, trace.accuracy_m)
    time_s = trace.time_s if trace.has_time else np.full(n, np.nan)
    dt = np.diff(time_s)
    speed = trace.speed_mps
    if speed is None:
        speed = _speed_from_positions(np.hypot(np.diff(x), np.diff(y)), dt)
    return Fixes(
        x,
        y,
        time_s,
        sigma,
        radius,
        speed,
        trace.heading_deg,
        _travel(trace, dt, config),
        np.asarray(trace.segment_starts, dtype=np.int64),
    )


def _travel(trace: Trace, dt_s: FloatArray, config: MatchConfig) -> Travel | None:
    """
    How far the trace says the car went, from the odometer and the reported speeds.

    The speed is integrated over every step of the trace, fixes the model leaves out
    included, so a stop between two model fixes is seen. Each step's slack is what the
    trapezoid may miss: the speed may have changed by up to ``travel_accel_mps2`` in between
    (at most ``a * dt**2 / 4``) and each reported speed is off by up to
    ``travel_tolerance_mps`` (``* dt``). So the slack is small at 1 s (about 1 m a step) and
    grows quickly with sparse sampling, where speeds at the ends say little of the distance.
    ``None`` when ``use_travel`` is off or the trace has neither column.
    """
    if not config.use_travel or (trace.odometer_m is None and trace.speed_mps is None):
        return None
    speed_m = slack_m = unknown = None
    if trace.speed_mps is not None:
        v = trace.speed_mps
        step = 0.5 * (v[:-1] + v[1:]) * dt_s
        missing = ~np.isfinite(step)
        slack = config.travel_accel_mps2 * dt_s**2 / 4 + config.travel_tolerance_mps * dt_s
        speed_m = np.concatenate(([0.0], np.cumsum(np.where(missing, 0.0, step))))
        slack_m = np.concatenate(([0.0], np.cumsum(np.where(missing, 0.0, slack))))
        unknown = np.concatenate(([0], np.cumsum(missing))).astype(np.int64)
    return Travel(trace.odometer_m, speed_m, slack_m, unknown, unknown)


def _diagnostics(net: RoadNetwork, obs: Observations, solution: Solution) -> Diagnostics:
    """Every candidate of the model fixes with its scores."""
    cands, states = solution.cands, solution.states
    n = len(solution.used)
    point_of = np.repeat(np.arange(n), cands.counts)
    rank = np.arange(len(cands)) - cands.ptr[point_of]
    chosen = states[point_of] == rank
    prev = np.maximum(point_of - 1, 0)
    starts = np.zeros(n, dtype=bool)
    for start, _ in solution.pieces:
        starts[start] = True
    from_state = np.maximum(states[prev], 0)
    incoming = np.full(len(cands), np.nan)
    inner = (point_of > 0) & ~starts[point_of] & (states[prev] >= 0)
    incoming[inner] = solution.log_transition[prev[inner], from_state[inner], rank[inner]]
    u, v, key = net.edge_osm_ids(cands.edge)
    lon, lat = net.unproject(cands.x, cands.y)
    return Diagnostics(
        model_fixes=obs.rep[solution.used],
        fix=obs.rep[solution.used][point_of],
        edge=cands.edge,
        u=u,
        v=v,
        key=key.astype(np.int64),
        lon=lon,
        lat=lat,
        distance_m=cands.distance_m,
        log_emission=solution.log_emission[point_of, rank],
        log_transition=incoming,
        posterior=solution.post[point_of, rank],
        chosen=chosen,
    )


def _lap(timings: dict[str, float], name: str, since: float) -> float:
    now = time.perf_counter()
    timings[name] = now - since
    return now


def _speed_from_positions(step_m: FloatArray, dt_s: FloatArray) -> FloatArray:
    """Speed at each fix from the distance to its neighbours (NaN where times say nothing)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        v = np.where(dt_s > 0, step_m / dt_s, np.nan)
    if len(v) == 0:
        return np.full(1, np.nan)
    padded = np.concatenate(([v[0]], v, [v[-1]]))
    before, after = padded[:-1], padded[1:]
    known = np.isfinite(before).astype(np.float64) + np.isfinite(after)
    total = np.nan_to_num(before) + np.nan_to_num(after)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.asarray(np.where(known > 0, total / known, np.nan), dtype=np.float64)


def _isolated(flag: BoolArray) -> BoolArray:
    """Flagged entries whose neighbours are both unflagged (a lone stray fix)."""
    padded = np.concatenate(([False], flag, [False]))
    return np.asarray(flag & ~padded[:-2] & ~padded[2:], dtype=bool)


def _solve(
    net: RoadNetwork,
    fixes: Observations,
    all_cands: Candidates,
    used: IntArray,
    cut_after: BoolArray,
    config: MatchConfig,
) -> Solution:
    """Score the trellis over the ``used`` fixes and find the best sequence."""
    cands = all_cands.subset(used)
    n = len(used)
    point_of = np.repeat(np.arange(n), cands.counts)
    em = _emissions(fixes, cands, used[point_of], config)
    if config.candidate_margin > 0:
        best_em = np.full(n, -np.inf)
        np.maximum.at(best_em, point_of, em)
        keep = em >= best_em[point_of] - config.candidate_margin
        cands, em = cands.take(keep), em[keep]
        point_of = point_of[keep]

    step_m = np.hypot(np.diff(fixes.x[used]), np.diff(fixes.y[used]))
    pairs = candidate_pairs(cands.ptr)
    # every fix's candidates are sources: forward moves leave from them, and a fix that
    # scatters behind the previous one is found by routing from it to the previous candidate
    bounds = np.append(route_search_bounds(step_m, config), config.route_slack_m)
    table = net.shortest_paths(net.arrays.edge_v[cands.edge], bounds[point_of])
    lt, kind = _transitions(net, fixes, cands, pairs, table, used, step_m, config)
    lt[cut_after[pairs.step] | (lt < config.min_log_transition)] = -np.inf

    width = max(int(cands.counts.max()) if n else 1, 1)
    em_pad = np.full((n, width), -np.inf)
    em_pad[point_of, np.arange(len(cands)) - cands.ptr[point_of]] = em
    tr_pad = np.full((max(n - 1, 0), width, width), -np.inf)
    tr_pad[pairs.step, pairs.a_rank, pairs.b_rank] = lt
    kinds = np.full(tr_pad.shape, -1, dtype=np.int64)
    kinds[pairs.step, pairs.a_rank, pairs.b_rank] = kind
    best = viterbi(em_pad, tr_pad)
    post = posteriors(em_pad, tr_pad, best.pieces)
    return Solution(used, cands, best.states, best.pieces, post, kinds, table, em_pad, tr_pad)


def _distance_emission(
    distance_m: FloatArray, sigma_m: FloatArray, config: MatchConfig
) -> FloatArray:
    """Gaussian log emission of a distance to the road, floored at ``-max_emission_penalty``."""
    em = log_emission(distance_m, sigma_m=sigma_m)
    if config.max_emission_penalty > 0:
        em = np.logaddexp(em, -config.max_emission_penalty)
    return em


def _emissions(
    fixes: Observations, cands: Candidates, fix_of: IntArray, config: MatchConfig
) -> FloatArray:
    """Log emission of every candidate: distance to the road, and heading when known."""
    em = _distance_emission(cands.distance_m, fixes.sigma_m[fix_of], config)
    if fixes.heading_deg is not None:
        weight = heading_weight(fixes.speed_mps, config)
        em += log_heading(fixes.heading_deg[fix_of], cands.bearing_deg, weight[fix_of], config)
    return em


def _transitions(
    net: RoadNetwork,
    fixes: Observations,
    cands: Candidates,
    pairs: CandidatePairs,
    table: PathTable,
    used: IntArray,
    step_m: FloatArray,
    config: MatchConfig,
) -> tuple[FloatArray, IntArray]:
    """
    Log transition and route kind of every candidate pair: the best of its explanations.

    Driving forward (along the edge or through the graph) is scored for every pair; a U-turn
    in the middle of the road where ``b`` is on the reverse of ``a``'s edge; and holding still
    where ``b`` lies a little behind ``a``. A held car is where ``a`` is, so the standstill
    is also charged the emission ``b``'s fix has at ``a``'s place instead of its own.
    """
    arrays = net.arrays
    route, free_time, kind = routes_between(net, cands, pairs, table)
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
    back = standstill_distances(net, cands, pairs, table, tolerance)
    held = np.flatnonzero(np.isfinite(back))
    if len(held):
        fix_b = used[pairs.step[held] + 1]
        a_row, b_row = pairs.a[held], pairs.b[held]
        at_a = np.hypot(fixes.x[fix_b] - cands.x[a_row], fixes.y[fix_b] - cands.y[a_row])
        sigma_b = fixes.sigma_m[fix_b]
        # never better than b's own emission: holding is an explanation of b, not a bonus
        extra = np.minimum(
            _distance_emission(at_a, sigma_b, config)
            - _distance_emission(cands.distance_m[b_row], sigma_b, config),
            0.0,
        )
        zero = np.zeros(len(held))
        consider(held, zero, zero, ROUTE_STANDSTILL, extra)
    return lt, kind


def _cuts(used: IntArray, missing_before: IntArray) -> BoolArray:
    """Where a stretch of fixes with no road nearby, or a segment start, lies between them."""
    return np.asarray(missing_before[used[1:]] > missing_before[used[:-1]], dtype=bool)


def _repair_breaks(
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
    cut_after = _cuts(used, missing_before)
    drops: list[int] = []
    for start in solution.breaks[: config.max_break_repairs]:
        if cut_after[start - 1]:
            continue  # a stretch without roads: a real break
        for drop in (start, start - 1):
            if drop <= 0 or drop >= len(used) - 1 or drop in drops or drop - 1 in drops:
                continue
            pair = used[[drop - 1, drop + 1]]
            if not _solve(net, fixes, cands, pair, _cuts(pair, missing_before), config).breaks:
                drops.append(drop)
                break
    if not drops:
        return None
    kept = np.delete(used, drops)
    trial = _solve(net, fixes, cands, kept, _cuts(kept, missing_before), config)
    if len(trial.breaks) >= len(solution.breaks):
        return None
    return trial, len(drops)
