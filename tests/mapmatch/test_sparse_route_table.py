"""Sparse traces start the network's route table and match the same with it as without."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

import roadnets
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trip
from mapmatch.matcher import match

OAKLAND = Path(__file__).parents[1] / "data" / "west-oakland_us.osm.bz2"
MONACO = Path(roadnets.__file__).parent / "data" / "monaco_2020.osm.pbf"


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


def _route_edges(
    rec: int, source: str, searched: tuple[Any, ...], table: tuple[Any, ...], graph: tuple[Any, ...]
) -> list[int]:
    """The edges of a pair's route, read back from the records it names."""
    if source == "table":
        state, pred = table[3], table[10]
    else:
        state, pred = searched[3], searched[7]
    edges = []
    while rec >= 0:
        edges.append(int(graph[2][state[rec]]))
        rec = int(pred[rec])
    return edges


def test_pairs_some_of_whose_searches_fit_the_table_get_the_searches_routes() -> None:
    from mapmatch.hmm.transition import (
        ROUTES_MIXED,
        ROUTES_SEARCHED,
        _pair_routes,
        route_inputs,
        table_record,
    )

    net = roadnets.load(MONACO, use_cache=False)
    searching = route_inputs(net)  # no table yet
    net.precompute_routes(800.0)
    with_table = route_inputs(net)
    rng = np.random.default_rng(7)
    sources = rng.integers(0, net.arrays.n_edges, 60)
    from_edge = np.repeat(sources, 8)  # in runs of one from edge, as a trellis's pairs are
    to_edge = rng.integers(0, net.arrays.n_edges, len(from_edge))
    bounds = np.repeat(rng.uniform(300.0, 1500.0, len(sources)), 8)
    bounds[::5] = 700.0  # a source whose pairs' bounds differ: its largest decides
    mixed = _pair_routes(*with_table, from_edge, to_edge, bounds)
    alone = _pair_routes(*searching, from_edge, to_edge, bounds)
    assert mixed[0] == ROUTES_MIXED
    assert alone[0] == ROUTES_SEARCHED
    for ours, theirs in zip(mixed[3:], alone[3:], strict=True):  # length, time, U-turns, arrival
        assert np.array_equal(ours, theirs)
    graph, table = with_table[0], with_table[4]
    kinds = set()
    for k in range(len(from_edge)):
        r = int(mixed[2][k])
        if table_record(r) >= 0:
            kinds.add("table")
            got = _route_edges(table_record(r), "table", mixed[1], table, graph)
        else:
            kinds.add("search" if r >= 0 else "none")
            got = _route_edges(r, "search", mixed[1], table, graph)
        assert got == _route_edges(int(alone[2][k]), "search", alone[1], table, graph)
    assert kinds == {"table", "search", "none"}
