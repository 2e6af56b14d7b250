"""Without a reported heading, the course between a fix's neighbours drops the wrong way."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

import mapmatch
from mapmatch.evaluation.accuracy.conditions import condition_config
from mapmatch.evaluation.simulate import simulate_trips, strip_to_class
from mapmatch.hmm.trellis import solve
from tests.mapmatch.solving import solved

if TYPE_CHECKING:
    import roadnets


def _trips(net: roadnets.RoadNetwork, count: int = 3) -> list[mapmatch.Trace]:
    trips = simulate_trips(net, condition_config("1s-5m"), count=count, seed=1000)
    return [strip_to_class(trip.trace, "positions") for trip in trips]


def test_no_kept_candidate_runs_against_the_course(default_net: roadnets.RoadNetwork) -> None:
    config = mapmatch.MatchConfig()
    pruned = 0
    for trace in _trips(default_net):
        _, _, solution = solved(default_net, trace, config)
        course = solution.course_deg[solution.used]
        assert np.isfinite(course).mean() > 0.5  # a drive at 1 s has a course nearly throughout
        c = solution.cands
        for t in np.flatnonzero(np.isfinite(course)):
            bearings = c.bearing_deg[c.ptr[t] : c.ptr[t + 1]]
            off = np.abs((bearings - course[t] + 180.0) % 360.0 - 180.0)
            assert (off <= config.course_prune_deg).all()
        _, _, unpruned = solved(default_net, trace, config.replace({"course_prune_deg": 0.0}))
        pruned += len(unpruned.cands) - len(c)
    assert pruned > 0  # the two-way roads' wrong directions were there to drop


def test_dropping_the_wrong_way_changes_no_match(default_net: roadnets.RoadNetwork) -> None:
    # the wrong way of a road the car is clearly driving along is reached only by a U-turn,
    # which the transitions rule out: dropping it saves its routes and changes nothing
    off = mapmatch.MatchConfig(course_prune_deg=0.0)
    for trace in _trips(default_net, count=4):
        with_course = mapmatch.match(trace, default_net)
        without = mapmatch.match(trace, default_net, off)
        assert with_course.matched_length_m == without.matched_length_m
        assert [s.edge.tolist() for s in with_course.segments] == [
            s.edge.tolist() for s in without.segments
        ]


def test_a_heading_column_of_nans_is_no_heading(default_net: roadnets.RoadNetwork) -> None:
    # a file of several traces has a heading column even where one trace has no headings:
    # its NaNs say as little as no column, so the course stands in for them alike
    trace = _trips(default_net, count=1)[0]
    nans = mapmatch.Trace(
        time=trace.time_s,
        lon=trace.lon,
        lat=trace.lat,
        heading=np.full(len(trace), np.nan),
        trace_id=trace.trace_id,
    )
    plain, blank = mapmatch.match(trace, default_net), mapmatch.match(nans, default_net)
    np.testing.assert_array_equal(blank.points.confidence, plain.points.confidence)


def test_a_trellis_over_some_observations_keeps_their_candidates(
    default_net: roadnets.RoadNetwork,
) -> None:
    # the detour search bridges two observations of a solution with a trellis of their own
    # and reads its scores by the solution's candidate ranks: given the solution's courses
    # and paces, the bridge's observations keep the candidates they had (in a trellis of
    # their own both are ends, with no course)
    config = mapmatch.MatchConfig()
    obs, all_cands, solution = solved(default_net, _trips(default_net, count=1)[0], config)
    c, used = solution.cands, solution.used
    never = np.zeros(2, dtype=bool)
    differs = 0
    for t in range(1, len(used) - 1, 5):
        pair = used[[t - 1, t + 1]]
        bridge = solve(
            default_net, obs, all_cands, pair, never, config, solution.course_deg, solution.pace_mps
        )
        for k, at in enumerate((t - 1, t + 1)):
            kept = c.edge[c.ptr[at] : c.ptr[at + 1]].tolist()
            assert bridge.cands.edge[bridge.cands.ptr[k] : bridge.cands.ptr[k + 1]].tolist() == kept
        own = solve(default_net, obs, all_cands, pair, never, config)
        differs += len(own.cands) != len(bridge.cands)
    assert differs > 0  # without the solution's courses the bridge's candidates differ
