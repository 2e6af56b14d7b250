"""``mapmatch.match``: a trace and a road network in, the roads driven out.

The facade over the stages of :mod:`mapmatch.hmm` (docs/DESIGN.md shows the data flow):
the fixes in metres with their model inputs, merged into observations with their candidates
(one R-tree query); displaced observations left out; the trellis scored and solved, breaks
repaired; the solution assembled into driven edges and per-fix positions, the path's ends
placed by the odometer; the matched length held against the fused trip distance.
"""

from __future__ import annotations

import logging
import time
import weakref
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mapmatch.config import MatchConfig
from mapmatch.distance import Evidence, check_distance, chord_of_span, measured_chord
from mapmatch.errors import DeadlineExceededError, NoCandidatesError
from mapmatch.hmm.assemble import assemble, path_uturns
from mapmatch.hmm.detours import drop_detour_fixes
from mapmatch.hmm.ends import moves_ends, odometer_ends
from mapmatch.hmm.fixes import (
    Fixes,
    estimated_sigma_m,
    fixes_of,
    hold_limit_m,
    observe,
    with_sigma,
)
from mapmatch.hmm.selection import find_displaced
from mapmatch.hmm.trellis import model_fixes, repair_breaks, solve
from mapmatch.result import Diagnostics, MatchResult, MatchStats, Segment
from mapmatch.trace import check_match_inputs

if TYPE_CHECKING:
    from mapmatch.hmm.observations import Observations
    from mapmatch.hmm.solution import Solution
    from mapmatch.trace import Trace
    from roadnets import RoadNetwork

__all__ = ["match"]

#: The configuration of a match called without one (frozen: shared).
_DEFAULT = MatchConfig()
_log = logging.getLogger(__name__)
#: Whether this process has looked for the compiled kernels yet (see :func:`_announce_compile`).
_LOOKED = False


def _announce_compile() -> None:
    """Say so, once per process, when the first match is about to compile every kernel."""
    global _LOOKED  # one look per process
    if _LOOKED:
        return
    _LOOKED = True
    from mapmatch.hmm.kernels import kernels_on_disk

    if not kernels_on_disk():
        _log.warning(
            "compiling the matcher's kernels for this install: about a minute, once "
            "(`mapmatch network build` does it ahead)"
        )


def match(
    trace: Trace,
    net: RoadNetwork,
    config: MatchConfig | None = None,
    *,
    fused_distance_m: float | None = None,
    diagnostics: bool = False,
    deadline: float | None = None,
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
    deadline
        A :func:`time.monotonic` time past which the match gives up: checked between its
        stages (candidates, selection, Viterbi, detours, break repair, assembly), so a caller with a
        time budget (the HTTP service) gets its thread back soon after the budget is spent.

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
    DeadlineExceededError
        ``deadline`` passed before the match was done.
    """
    check_match_inputs(trace, net)
    _announce_compile()
    config = config or _DEFAULT
    timings: dict[str, float] = {}
    clock = time.perf_counter()

    x, y = net.project(trace.lon, trace.lat)
    n = len(x)
    fixes = fixes_of(trace, x, y, config)
    obs, cands = observe(net, fixes, config)
    if trace.accuracy_m is None and config.estimate_sigma:
        sigma = estimated_sigma_m(obs, cands)
        if sigma > 1.25 * config.sigma_m:  # noisier than assumed: look again, wider
            fixes = with_sigma(fixes, sigma, config)
            obs, cands = observe(net, fixes, config, previous=(obs, cands))
    if len(cands) == 0:
        raise NoCandidatesError(trace.trace_id, float(fixes.radius_m.max()))
    clock = _lap(timings, "candidates", clock)
    _check_deadline(deadline, trace, "candidates")

    outlier = find_displaced(fixes, obs, cands, config)
    # a stretch of fixes with no road nearby (not a lone stray fix), and the start of a new
    # segment of the trace file (a GPX trkseg), split the trace
    used, missing_before, cut_after = model_fixes(cands, outlier, fixes.segment_starts, obs.first)
    clock = _lap(timings, "selection", clock)
    _check_deadline(deadline, trace, "selection")

    solution = solve(net, obs, cands, used, cut_after, config)
    repairs = 0
    _check_deadline(deadline, trace, "viterbi")
    detoured = drop_detour_fixes(net, obs, cands, solution, missing_before, config)
    if detoured is not None:
        # a fix only a detour explained is a displaced one, and says so in the output
        solution, left_out = detoured
        outlier[left_out] = True
        _check_deadline(deadline, trace, "detours")
    if solution.breaks and config.max_break_repairs:
        repaired = repair_breaks(net, obs, cands, solution, missing_before, config)
        if repaired is not None:
            solution, repairs = repaired
    clock = _lap(timings, "hmm", clock)
    _check_deadline(deadline, trace, "break repair")

    assembled = assemble(
        net,
        trace,
        x,
        y,
        obs,
        solution,
        outlier[obs.of_fix],
        fixes.radius_m,
        fixes.time_s,
        hold_limit_m(fixes, config),
        config,
    )
    _check_deadline(deadline, trace, "assembly")
    placed = assembled.placed
    if moves_ends(trace.odometer_m, config) and len(placed.lengths):
        segments, points = odometer_ends(
            net,
            placed.segments(),
            assembled.points,
            trace.odometer_m,
            config,
            fixes.radius_m,
            (x, y),
        )
        matched_length = float(sum(s.length_m for s in segments))
        complete, odometer, chord = measured_chord(
            points.matched, points.outlier, len(segments), trace.odometer_m, x, y
        )
        matched_points = int(np.count_nonzero(points.matched))
        outliers = int(np.count_nonzero(points.outlier))
        breaks = [s.first for s in segments[1:]]
        deferred = None
    else:  # the assembly's arrays are the result, its numbers from the assembly's call
        segments, points, deferred = [], assembled.points, placed
        matched_length = float(sum(placed.lengths.tolist()))
        complete, odometer, chord = chord_of_span(assembled.span, n, trace.odometer_m)
        matched_points, outliers = assembled.matched_points, assembled.outliers
        breaks = placed.paths.first[1:].tolist()
    check = check_distance(
        trace_id=trace.trace_id,
        matched_length_m=matched_length,
        complete=complete,
        band=config.distance_band,
        odometer_m=odometer,
        fused_distance_m=fused_distance_m,
        chord_m=chord,
        evidence=_evidence(trace, fixes, config),
        uturns=assembled.uturns,  # moving the ends by the odometer keeps every edge
    )
    _lap(timings, "result", clock)
    timings["total"] = sum(timings.values())
    stats = MatchStats(
        points=n,
        matched_points=matched_points,
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
        outliers=outliers,
        break_repairs=repairs,
    )
    result = MatchResult(
        trace_id=trace.trace_id,
        network=_network_ids(net),
        segments=segments,
        points=points,
        breaks=breaks,
        matched_length_m=matched_length,
        distance_check=check,
        stats=stats,
        diagnostics=_diagnostics(net, obs, solution) if diagnostics else None,
        config=config,
    )
    if deferred is not None:
        result.defer_segments(deferred)  # made when read: the document needs none
    return result


#: ``MatchResult.network`` of each network matched on (its id, file name and CRS), made once.
_NETWORK_IDS: weakref.WeakKeyDictionary[RoadNetwork, dict[str, str]] = weakref.WeakKeyDictionary()


def _network_ids(net: RoadNetwork) -> dict[str, str]:
    """The network's id, source file name and CRS, for the result (a new dict each time)."""
    ids = _NETWORK_IDS.get(net)
    if ids is None:
        ids = _NETWORK_IDS[net] = {
            "id": net.network_id,
            "source": Path(net.source).name,
            "crs": net.crs,
        }
    return dict(ids)


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
    return sum(int(path_uturns(twin, s.edge, 0, len(s.edge))) for s in segments)


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


def _check_deadline(deadline: float | None, trace: Trace, stage: str) -> None:
    if deadline is not None and time.monotonic() > deadline:
        raise DeadlineExceededError(trace.trace_id, stage)


def _lap(timings: dict[str, float], name: str, since: float) -> float:
    now = time.perf_counter()
    timings[name] = now - since
    return now
