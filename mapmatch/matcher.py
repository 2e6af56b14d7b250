"""``mapmatch.match``: a trace and a road network in, the roads driven out.

The stages, each vectorised over the whole trace: project the fixes and find their candidates
(one R-tree query), leave out outliers and the near-duplicate fixes of a stopped car, score
emissions, build every candidate pair of consecutive fixes, route them (one bounded
many-source Dijkstra), score transitions, run Viterbi and forward-backward on the padded
trellis, try to join pieces by leaving out the fix at a break, and assemble segments. Fixes
left out of the model get their position on the matched path interpolated by time.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from mapmatch.assemble import assemble
from mapmatch.candidates import Candidates, find_candidates, search_radii
from mapmatch.config import MatchConfig
from mapmatch.distance import check_distance, chord_length_m
from mapmatch.errors import NoCandidatesError
from mapmatch.models import (
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
from mapmatch.result import Diagnostics, MatchResult, MatchStats
from mapmatch.selection import find_outliers, thin_fixes
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
    """A trace's fixes in metres with the per-fix model inputs."""

    x: FloatArray
    y: FloatArray
    time_s: FloatArray
    sigma_m: FloatArray
    speed_mps: FloatArray
    heading_deg: FloatArray | None
    odometer_m: FloatArray | None
    reported_speed_mps: FloatArray | None


@dataclass(frozen=True, slots=True)
class Solution:
    """
    The HMM solved over a subset of fixes (``used``, indices into the trace).

    ``states`` is the chosen candidate rank of each used fix (-1: none); ``pieces`` are
    ``(start, stop)`` ranges of *used* positions; ``kinds`` the route kind of every padded
    transition; ``table`` the shortest paths the transitions were routed on.
    """

    used: IntArray
    cands: Candidates
    states: IntArray
    pieces: list[tuple[int, int]]
    post: FloatArray
    kinds: IntArray
    table: PathTable
    log_emission: FloatArray
    log_transition: FloatArray

    @property
    def breaks(self) -> list[int]:
        """Used positions where a new piece starts."""
        return [start for start, _ in self.pieces[1:]]


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
    radius = search_radii(trace.accuracy_m, n, config)
    sigma = np.full(n, config.sigma_m)
    if trace.accuracy_m is not None:
        sigma = np.fmax(sigma, trace.accuracy_m)
    # the near-repeats of a stopped or crawling car add nothing but noise: no candidates
    queried = thin_fixes(x, y, sigma, np.ones(n, dtype=bool), config)
    q = np.flatnonzero(queried)
    cands = find_candidates(net, x[q], y[q], radius[q], config).spread(q, n)
    if len(cands) == 0:
        raise NoCandidatesError(trace.trace_id, float(radius.max()))
    dt = np.diff(trace.time_s)
    speed = trace.speed_mps
    if speed is None:
        speed = _speed_from_positions(np.hypot(np.diff(x), np.diff(y)), dt)
    fixes = Fixes(
        x, y, trace.time_s, sigma, speed, trace.heading_deg, trace.odometer_m, trace.speed_mps
    )
    clock = _lap(timings, "candidates", clock)

    has_cands = cands.counts > 0
    near = np.flatnonzero(has_cands)  # outliers are judged among fixes near a road
    outlier = np.zeros(n, dtype=bool)
    travel = _travel_between(fixes, near, config)
    outlier[near] = find_outliers(x[near], y[near], trace.time_s[near], sigma[near], config, travel)
    lonely = np.zeros(n, dtype=bool)
    lonely[q] = _isolated(~has_cands[q])
    used = np.flatnonzero(has_cands & ~outlier)
    # a stretch of fixes with no road nearby (not a lone stray fix) splits the trace
    missing_before = np.cumsum(queried & ~has_cands & ~lonely, dtype=np.int64)
    cut_after = _cuts(used, missing_before)
    clock = _lap(timings, "selection", clock)

    solution = _solve(net, fixes, cands, used, cut_after, config)
    repairs = 0
    if solution.breaks and config.max_break_repairs:
        repaired = _repair_breaks(net, fixes, cands, solution, missing_before, config)
        if repaired is not None:
            solution, repairs = repaired
    clock = _lap(timings, "hmm", clock)

    assembled = assemble(net, trace, fixes.x, fixes.y, solution, outlier)
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
        diagnostics=_diagnostics(net, solution) if diagnostics else None,
    )


def _diagnostics(net: RoadNetwork, solution: Solution) -> Diagnostics:
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
        model_fixes=solution.used,
        fix=solution.used[point_of],
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
    """Speed at each fix from the distance to its neighbours (when the trace has none)."""
    v = step_m / dt_s
    padded = np.concatenate(([v[0]], v, [v[-1]]))
    return np.asarray(0.5 * (padded[:-1] + padded[1:]), dtype=np.float64)


def _isolated(flag: BoolArray) -> BoolArray:
    """Flagged entries whose neighbours are both unflagged (a lone stray fix)."""
    padded = np.concatenate(([False], flag, [False]))
    return np.asarray(flag & ~padded[:-2] & ~padded[2:], dtype=bool)


def _solve(
    net: RoadNetwork,
    fixes: Fixes,
    all_cands: Candidates,
    used: IntArray,
    cut_after: BoolArray,
    config: MatchConfig,
) -> Solution:
    """Score the trellis over the ``used`` fixes and find the best sequence."""
    cands = all_cands.subset(used)
    n = len(used)
    point_of = np.repeat(np.arange(n), cands.counts)
    fix_of = used[point_of]
    em = log_emission(cands.distance_m, sigma_m=fixes.sigma_m[fix_of])
    if config.max_emission_penalty > 0:
        em = np.logaddexp(em, -config.max_emission_penalty)
    if fixes.heading_deg is not None:
        weight = heading_weight(fixes.speed_mps, config)
        em += log_heading(fixes.heading_deg[fix_of], cands.bearing_deg, weight[fix_of], config)
    if config.candidate_margin > 0:
        best_em = np.full(n, -np.inf)
        np.maximum.at(best_em, point_of, em)
        keep = em >= best_em[point_of] - config.candidate_margin
        cands, em = cands.take(keep), em[keep]
        point_of = point_of[keep]
        fix_of = used[point_of]

    x, y = fixes.x[used], fixes.y[used]
    step_m = np.hypot(np.diff(x), np.diff(y))
    dt = np.diff(fixes.time_s[used])
    pairs = candidate_pairs(cands.ptr)
    bounds = route_search_bounds(step_m, config)
    leaving = point_of < n - 1
    table = net.shortest_paths(net.arrays.edge_v[cands.edge[leaving]], bounds[point_of[leaving]])
    route, free_time, kind = routes_between(net, cands, pairs, table, config, fixes.sigma_m[fix_of])
    gc, step_dt = step_m[pairs.step], dt[pairs.step]
    sigma = fixes.sigma_m[used]
    step_sigma = np.maximum(sigma[pairs.step], sigma[pairs.step + 1])
    travel = _travel_between(fixes, used, config)
    step_travel = None if travel is None else (travel[0][pairs.step], travel[1][pairs.step])
    lt = log_transition(gc, route, free_time, kind, step_dt, step_sigma, config, step_travel)
    u_route = uturn_routes(net, cands, pairs)
    twins = np.flatnonzero(np.isfinite(u_route))  # a U-turn in place is possible
    if len(twins):
        u_route = u_route[twins]
        u_time = u_route / net.arrays.edge_speed_mps[cands.edge[pairs.a[twins]]]
        u_travel = None if step_travel is None else (step_travel[0][twins], step_travel[1][twins])
        lu = log_transition(
            gc[twins],
            u_route,
            u_time,
            np.full(len(twins), ROUTE_UTURN),
            step_dt[twins],
            step_sigma[twins],
            config,
            u_travel,
        )
        better = lu > lt[twins]
        lt[twins[better]] = lu[better]
        kind[twins[better]] = ROUTE_UTURN
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


def _travel_between(
    fixes: Fixes, used: IntArray, config: MatchConfig
) -> tuple[FloatArray, FloatArray] | None:
    """
    Distance the trace says the car travelled between consecutive used fixes, and its slack.

    Odometer increments where both ends have one (no extra), else the
    mean reported speed times dt (``travel_tolerance_mps * dt`` extra, as the speed may
    change in between); NaN where neither is known; ``None`` when the trace has neither
    column or ``use_travel`` is off.
    """
    if not config.use_travel or (fixes.odometer_m is None and fixes.reported_speed_mps is None):
        return None
    dt = np.diff(fixes.time_s[used])
    travel = np.full(len(used) - 1, np.nan)
    slack = np.zeros(len(used) - 1)
    if fixes.reported_speed_mps is not None:
        v = fixes.reported_speed_mps[used]
        travel = 0.5 * (v[:-1] + v[1:]) * dt
        slack = config.travel_tolerance_mps * dt  # speed may change between the fixes
    if fixes.odometer_m is not None:
        odo = np.diff(fixes.odometer_m[used])
        exact = np.isfinite(odo) & (odo >= 0)
        travel = np.where(exact, odo, travel)
        slack = np.where(exact, 0.0, slack)
    return travel, slack


def _cuts(used: IntArray, missing_before: IntArray) -> BoolArray:
    """Where a stretch of fixes with no road nearby lies between consecutive used fixes."""
    return np.asarray(missing_before[used[1:]] > missing_before[used[:-1]], dtype=bool)


def _repair_breaks(
    net: RoadNetwork,
    fixes: Fixes,
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
