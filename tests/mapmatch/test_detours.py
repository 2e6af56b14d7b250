"""The detour search (mapmatch.hmm.detours) on solved trellises of real trips."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pytest

import mapmatch
from mapmatch.evaluation.accuracy.conditions import condition_config
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trips, strip_to_class
from mapmatch.hmm.detours import _best_paths, drop_detour_fixes, path_score
from mapmatch.hmm.fixes import fixes_of, observe
from mapmatch.hmm.selection import find_displaced
from mapmatch.hmm.transition import log_transition
from mapmatch.hmm.trellis import cuts, model_fixes, solve

if TYPE_CHECKING:
    import roadnets
    from mapmatch.hmm.candidates import Candidates
    from mapmatch.hmm.observations import Observations
    from mapmatch.hmm.solution import Solution
    from mapmatch.types import IntArray


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


def _reference_search(
    net: roadnets.RoadNetwork,
    obs: Observations,
    cands: Candidates,
    solution: Solution,
    missing_before: IntArray,
    config: mapmatch.MatchConfig,
) -> tuple[Solution, IntArray] | None:
    """The detour search as it was before its tries were bounded: every try bridged."""
    nats, tries = config.detour_outlier_nats, config.max_detour_tries
    left_out: list[int] = []
    while tries > 0:
        used, states, tr = solution.used, solution.states, solution.log_transition
        inside = np.ones(max(len(used) - 1, 0), dtype=bool)
        for start, _ in solution.pieces[1:]:
            inside[start - 1] = False
        steps = np.arange(1, len(used))
        scores = tr[steps - 1, states[steps - 1], states[steps]]
        costly = steps[inside & (scores < -nats)]
        if not len(costly):
            break
        piece = np.empty(len(used), dtype=np.int64)
        inner = np.ones(len(used), dtype=bool)
        for k, (start, stop) in enumerate(solution.pieces):
            piece[start:stop] = k
            inner[[start, stop - 1]] = False
        positions = np.flatnonzero(inner)
        if not len(positions):
            break
        reach = np.abs(positions[:, None] - costly[None, :]).min(axis=1)
        positions = positions[reach <= 8]
        xs, ys = obs.x[used], obs.y[used]
        mid_x = 0.5 * (xs[positions - 1] + xs[positions + 1])
        mid_y = 0.5 * (ys[positions - 1] + ys[positions + 1])
        sticks_out = np.hypot(xs[positions] - mid_x, ys[positions] - mid_y)
        order = positions[np.argsort(-sticks_out, kind="stable")][:tries]
        em = solution.log_emission
        ahead, behind = np.full(em.shape, -np.inf), np.full(em.shape, -np.inf)
        for start, stop in solution.pieces:
            ahead[start] = em[start]
            for t in range(start + 1, stop):
                ahead[t] = em[t] + (ahead[t - 1][:, None] + tr[t - 1]).max(axis=0)
            behind[stop - 1] = 0.0
            for t in range(stop - 2, start - 1, -1):
                behind[t] = (tr[t] + (em[t + 1] + behind[t + 1])[None, :]).max(axis=1)
        estimates: list[tuple[float, int]] = []
        for drop in order:
            tries -= 1
            pair = used[[drop - 1, drop + 1]]
            bridge = solve(
                net, obs, cands, pair, cuts(pair, missing_before), config, solution.course_deg
            )
            width = bridge.log_transition.shape[-1]
            through = (
                ahead[drop - 1, :width, None]
                + bridge.log_transition[0]
                + (em[drop + 1, :width] + behind[drop + 1, :width])[None, :]
            )
            _, stop = solution.pieces[piece[drop]]
            gain = float(through.max()) - float(ahead[stop - 1].max())
            if gain > nats:
                estimates.append((gain, int(drop)))
        if not estimates:
            break
        _, drop = max(estimates)
        kept = np.delete(used, drop)
        trial = solve(net, obs, cands, kept, cuts(kept, missing_before), config)
        if path_score(trial) - path_score(solution) <= nats or len(trial.pieces) > len(
            solution.pieces
        ):
            break
        chosen = em[np.arange(len(used)), states]
        after = trial.log_emission[np.arange(len(kept)), trial.states]
        if np.delete(chosen, drop).sum() - after.sum() > config.detour_max_emission_loss:
            break
        left_out.append(int(used[drop]))
        solution = trial
    return (solution, np.asarray(left_out, dtype=np.int64)) if left_out else None


@pytest.mark.parametrize(("interval_s", "input_class"), [(15.0, "positions"), (30.0, "odometer")])
def test_bounded_tries_leave_out_what_bridging_every_try_does(
    default_net: roadnets.RoadNetwork, interval_s: float, input_class: str
) -> None:
    # a low detour_outlier_nats makes many transitions costly: many tries, most of them
    # bounded away, some fixes left out and some refused
    sim = SimulationConfig(
        interval_s=interval_s, noise_m=20.0, outlier_rate=0.05, route_length_m=3000.0
    )
    left = 0
    for nats in (20.0, 6.0, 3.0):
        config = mapmatch.MatchConfig(detour_outlier_nats=nats)
        for trip in simulate_trips(default_net, sim, count=4, seed=77):
            trace = strip_to_class(trip.trace, input_class)
            x, y = default_net.project(trace.lon, trace.lat)
            fixes = fixes_of(trace, x, y, config)
            obs, cands = observe(default_net, fixes, config)
            outlier = find_displaced(fixes, obs, cands, config)
            used, missing_before, cut_after = model_fixes(
                cands, outlier, fixes.segment_starts, obs.first
            )
            solution = solve(default_net, obs, cands, used, cut_after, config)
            args = (default_net, obs, cands, solution, missing_before, config)
            found, expected = drop_detour_fixes(*args), _reference_search(*args)
            assert (found is None) == (expected is None)
            if found is not None and expected is not None:
                np.testing.assert_array_equal(found[1], expected[1])
                np.testing.assert_array_equal(found[0].states, expected[0].states)
                np.testing.assert_array_equal(found[0].used, expected[0].used)
                left += len(found[1])
    assert left > 0  # the comparison saw fixes left out


def test_no_transition_scores_above_zero(melbourne_net: roadnets.RoadNetwork) -> None:
    # what bounds the detour search's tries: a transition scores at most 0
    for input_class in ("positions", "heading_speed", "odometer"):
        for trip in simulate_trips(melbourne_net, condition_config("15s-10m"), count=3, seed=1000):
            tr = _solved(melbourne_net, strip_to_class(trip.trace, input_class)).log_transition
            assert np.all(tr[np.isfinite(tr)] <= 0.0)
    rng = np.random.default_rng(5)
    n = 2000
    gc, route = rng.uniform(0, 3000, n), rng.uniform(0, 6000, n)
    scores = log_transition(
        gc,
        route,
        route / rng.uniform(1, 40, n),
        rng.integers(0, 6, n),
        rng.choice([np.nan, 0.0, 1.0, 15.0, 60.0], n),
        rng.uniform(0, 50, n),
        mapmatch.MatchConfig(),
        travel=(rng.choice([np.nan, 100.0, 2000.0], n), rng.uniform(0, 300, n)),
        uturn_penalty=rng.uniform(0, 30, n),
    )
    assert np.all(scores[~np.isnan(scores)] <= 0.0)
