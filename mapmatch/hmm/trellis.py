"""The HMM over a trace's observations: build the trellis, solve it, repair its breaks.

``solve`` scores the emissions and transitions of the observations in use, pads them into a
trellis and runs Viterbi and forward-backward (:mod:`mapmatch.hmm.viterbi`); where no
transition is possible the trace breaks. ``repair_breaks`` tries to join pieces by leaving out
the observation at a break (a two-observation trellis per try), then solves once more.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mapmatch.hmm.emission import emissions
from mapmatch.hmm.routes import candidate_pairs, route_search_bounds
from mapmatch.hmm.solution import Solution
from mapmatch.hmm.transition import transitions
from mapmatch.hmm.viterbi import posteriors, viterbi

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig
    from mapmatch.hmm.candidates import Candidates
    from mapmatch.hmm.observations import Observations
    from mapmatch.types import BoolArray, IntArray
    from roadnets import RoadNetwork

__all__ = ["cuts", "isolated", "repair_breaks", "solve"]


def solve(
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
    em = emissions(fixes, cands, used[point_of], config)
    if config.candidate_margin > 0:
        best_em = np.full(n, -np.inf)
        np.maximum.at(best_em, point_of, em)
        keep = em >= best_em[point_of] - config.candidate_margin
        cands, em = cands.take(keep), em[keep]
        point_of = point_of[keep]

    step_m = np.hypot(np.diff(fixes.x[used]), np.diff(fixes.y[used]))
    pairs = candidate_pairs(cands.ptr)
    dt = np.diff(fixes.time_s[used])
    bounds = route_search_bounds(step_m, dt, config)[pairs.step]
    lt, kind, routes = transitions(net, fixes, cands, pairs, bounds, used, step_m, config)
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
    return Solution(used, cands, best.states, best.pieces, post, kinds, routes, em_pad, tr_pad)


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
