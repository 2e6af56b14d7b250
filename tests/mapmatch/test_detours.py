"""The detour search's scores (mapmatch.hmm.detours) on solved trellises of real trips."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pytest

import mapmatch
from mapmatch.evaluation.accuracy.conditions import condition_config
from mapmatch.evaluation.simulate import simulate_trips, strip_to_class
from mapmatch.hmm.detours import _best_paths, path_score
from mapmatch.hmm.fixes import fixes_of, observe
from mapmatch.hmm.selection import find_displaced
from mapmatch.hmm.trellis import model_fixes, solve

if TYPE_CHECKING:
    import roadnets
    from mapmatch.hmm.solution import Solution


def _solved(net: roadnets.RoadNetwork, trace: mapmatch.Trace) -> Solution:
    config = mapmatch.MatchConfig()
    x, y = net.project(trace.lon, trace.lat)
    fixes = fixes_of(trace, x, y, config)
    obs, cands = observe(net, fixes, config)
    outlier = find_displaced(fixes, obs, cands, config)
    used, _, cut_after = model_fixes(cands, outlier, fixes.segment_starts, obs.first)
    return solve(net, obs, cands, used, cut_after, config)


@pytest.mark.parametrize(
    ("condition", "input_class"), [("15s-10m", "positions"), ("30s-20m", "odometer")]
)
def test_the_best_paths_both_ways_agree_and_bound_the_chosen_path(
    melbourne_net: roadnets.RoadNetwork, condition: str, input_class: str
) -> None:
    for trip in simulate_trips(melbourne_net, condition_config(condition), count=3, seed=1000):
        solution = _solved(melbourne_net, strip_to_class(trip.trace, input_class))
        ahead, behind = _best_paths(solution)
        best = sum(float(ahead[stop - 1].max()) for _, stop in solution.pieces)
        # forwards and backwards give every piece the same best score
        backwards = sum(
            float((solution.log_emission[start] + behind[start]).max())
            for start, _ in solution.pieces
        )
        assert backwards == pytest.approx(best, abs=1e-9)
        # the chosen path is one of the paths max-product scores (the arrival rule can only
        # refuse some), so it scores no better
        assert path_score(solution) <= best + 1e-9
        assert np.isfinite(path_score(solution))
