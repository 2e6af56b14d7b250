from __future__ import annotations

import itertools
from typing import TYPE_CHECKING

import networkx as nx
import numpy as np
import pytest

if TYPE_CHECKING:
    import roadnets


def test_bounded_dijkstra_matches_networkx(default_net: roadnets.RoadNetwork) -> None:
    a = default_net.arrays
    G = nx.DiGraph()
    for e in range(a.n_edges):
        u, v, w = int(a.edge_u[e]), int(a.edge_v[e]), float(a.edge_length_m[e])
        if not G.has_edge(u, v) or G[u][v]["weight"] > w:
            G.add_edge(u, v, weight=w)
    sources = np.arange(0, a.n_nodes, 41)
    bound = 800.0
    table = default_net.shortest_paths(sources, bound)
    for s in sources.tolist():
        expected = nx.single_source_dijkstra_path_length(G, s, cutoff=bound, weight="weight")
        targets = np.array(sorted(expected), dtype=np.int64)
        dist, *_ = table.lookup(np.full(len(targets), s), targets)
        assert np.allclose(dist, [expected[t] for t in targets.tolist()])
        # nodes beyond the bound are not in the table
        far = np.setdiff1d(np.arange(a.n_nodes), targets)
        far_dist, *_ = table.lookup(np.full(len(far), s), far)
        assert np.isinf(far_dist).all()


def test_path_edges_connect_and_add_up(default_net: roadnets.RoadNetwork) -> None:
    a = default_net.arrays
    table = default_net.shortest_paths(np.array([5]), 1500.0)
    dist, *_ = table.lookup(np.full(a.n_nodes, 5), np.arange(a.n_nodes))
    reached = np.flatnonzero(np.isfinite(dist))
    assert len(reached) > 20
    for target in reached[::7].tolist():
        path = table.edges(5, target, a.edge_u)
        if target == 5:
            assert path == []
            continue
        assert int(a.edge_u[path[0]]) == 5
        assert int(a.edge_v[path[-1]]) == target
        for first, second in itertools.pairwise(path):
            assert a.edge_v[first] == a.edge_u[second]
        assert sum(a.edge_length_m[p] for p in path) == pytest.approx(dist[target])
        _, _, first, last = table.lookup(np.array([5]), np.array([target]))
        assert (first[0], last[0]) == (path[0], path[-1])


def test_a_path_the_table_does_not_hold_is_a_key_error(default_net: roadnets.RoadNetwork) -> None:
    table = default_net.shortest_paths(np.array([5]), 10.0)
    far = int(np.argmax(np.hypot(default_net.arrays.node_x - default_net.arrays.node_x[5], 0)))
    with pytest.raises(KeyError):
        table.edges(5, far, default_net.arrays.edge_u)


def test_free_flow_time_uses_the_speed_limits(oakland_net: roadnets.RoadNetwork) -> None:
    a = oakland_net.arrays
    e = 0
    table = oakland_net.shortest_paths(np.array([a.edge_u[e]]), 5000.0)
    dist, time, *_ = table.lookup(np.array([a.edge_u[e]]), np.array([a.edge_v[e]]))
    if dist[0] == pytest.approx(a.edge_length_m[e]):
        assert time[0] == pytest.approx(a.edge_length_m[e] / a.edge_speed_mps[e])
    assert np.all(time <= dist / a.edge_speed_mps.min() + 1e-9)


def test_a_precomputed_table_answers_when_the_bounds_fit(oakland_net: roadnets.RoadNetwork) -> None:
    a = oakland_net.arrays
    sources = np.arange(a.n_nodes)
    fresh = oakland_net.shortest_paths(sources, 300.0)
    try:
        table = oakland_net.precompute_paths(500.0)
        assert oakland_net.shortest_paths(sources[:3], 400.0) is table
        assert oakland_net.shortest_paths(sources[:3], 600.0) is not table
        targets = np.tile(sources, len(sources))
        repeated = np.repeat(sources, len(sources))
        d_fresh, *_ = fresh.lookup(repeated, targets)
        d_table, *_ = table.lookup(repeated, targets)
        near = np.isfinite(d_fresh)
        assert np.allclose(d_fresh[near], d_table[near])
    finally:
        oakland_net.precomputed = None
