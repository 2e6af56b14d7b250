"""Beyond a fix's core radius only its nearest few candidates enter the model."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

import mapmatch
from mapmatch.evaluation.accuracy.conditions import condition_config
from mapmatch.evaluation.simulate import simulate_trips, strip_to_class
from tests.mapmatch.solving import solved

if TYPE_CHECKING:
    import roadnets

#: A noise that widens the search radius past the core: 80 m searched, a 50 m core.
NOISY = mapmatch.MatchConfig(sigma_m=20.0)


def _trips(net: roadnets.RoadNetwork, count: int = 4) -> list[mapmatch.Trace]:
    trips = simulate_trips(net, condition_config("30s-20m"), count=count, seed=2000)
    return [strip_to_class(trip.trace, "positions") for trip in trips]


def test_only_the_nearest_candidates_beyond_the_core_enter(
    default_net: roadnets.RoadNetwork,
) -> None:
    far = NOISY.far_candidates
    left_out = 0
    for trace in _trips(default_net):
        obs, cands, solution = solved(default_net, trace, NOISY)
        model = solution.cands
        for i, u in enumerate(solution.used):
            found = cands.distance_m[cands.ptr[u] : cands.ptr[u + 1]]
            assert (np.diff(found) >= 0).all()  # nearest first, as the reach assumes
            core_m = max(NOISY.search_radius_m, NOISY.core_radius_sigmas * obs.sigma_m[u])
            kept = model.distance_m[model.ptr[i] : model.ptr[i + 1]]
            n_core = int(np.count_nonzero(found <= core_m))
            if n_core == 0:  # nothing in the core: every candidate may enter
                continue
            reach = found[: n_core + far]
            assert np.count_nonzero(kept > core_m) <= far
            assert (kept <= reach.max()).all()
            left_out += len(found) - len(reach)
    assert left_out > 0  # the noise searched past the core, and the rule left roads out


def test_a_core_as_wide_as_the_search_lets_every_candidate_in(
    default_net: roadnets.RoadNetwork,
) -> None:
    whole = mapmatch.MatchConfig(sigma_m=20.0, core_radius_sigmas=NOISY.radius_accuracy_factor)
    fewer = more = 0
    for trace in _trips(default_net):
        fewer += len(solved(default_net, trace, NOISY)[2].cands)
        more += len(solved(default_net, trace, whole)[2].cands)
    assert fewer < more


def test_a_fix_with_no_road_in_its_core_keeps_its_candidates(
    default_net: roadnets.RoadNetwork,
) -> None:
    # no far candidate at all: only fixes with nothing in their core have any beyond it
    none_far = mapmatch.MatchConfig(sigma_m=20.0, far_candidates=0)
    for trace in _trips(default_net):
        obs, cands, solution = solved(default_net, trace, none_far)
        model = solution.cands
        for i, u in enumerate(solution.used):
            core_m = max(NOISY.search_radius_m, NOISY.core_radius_sigmas * obs.sigma_m[u])
            found = cands.distance_m[cands.ptr[u] : cands.ptr[u + 1]]
            kept = model.distance_m[model.ptr[i] : model.ptr[i + 1]]
            if (found <= core_m).any():
                assert (kept <= core_m).all()
            else:
                assert len(kept) > 0
