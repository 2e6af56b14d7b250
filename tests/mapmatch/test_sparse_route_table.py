"""Sparse traces start the network's route table and match the same with it as without."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import roadnets
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trip
from mapmatch.matcher import match

OAKLAND = Path(__file__).parents[1] / "data" / "west-oakland_us.osm.bz2"


def test_a_sparse_trace_starts_the_table_and_matches_the_same_with_it(tmp_path: Path) -> None:
    net = roadnets.load(OAKLAND, cache_dir=tmp_path)
    dense = simulate_trip(net, SimulationConfig(interval_s=1.0, noise_m=5.0), seed=4).trace
    match(dense, net)
    assert not net.route_table_requested  # 1 s: the searches are faster
    config = SimulationConfig(interval_s=15.0, noise_m=10.0)
    trips = [simulate_trip(net, config, seed=seed).trace for seed in range(8)]
    searched = [match(trip, net) for trip in trips]
    assert net.route_table_requested  # in the background, from the first sparse trace
    assert net.sparse_route_table() is not None  # waits for it
    answered = [match(trip, net) for trip in trips]
    for one, other in zip(searched, answered, strict=True):
        assert one.matched_length_m == other.matched_length_m
        assert [s.edge.tolist() for s in one.segments] == [s.edge.tolist() for s in other.segments]
        assert np.array_equal(one.points.edge, other.points.edge)
