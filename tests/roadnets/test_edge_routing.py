"""The edge-based router on real extracts: against a node-based and a plain edge-based Dijkstra."""

from __future__ import annotations

import dataclasses
import heapq
import itertools
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import roadnets
from roadnets.route_search import _source_rank, gather, table_records, table_routes
from roadnets.routes import DEFAULT_UTURN_COST_M, route_pairs, route_table, scratch
from roadnets.routing import shortest_path_table
from roadnets.turns import build_turn_graph

if TYPE_CHECKING:
    from roadnets.arrays import NetworkArrays
    from roadnets.turns import TurnGraph

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data" / "osm"
#: An edge index drawn independently of the network (taken modulo its edge count), so that
#: one strategy serves every network the session-scoped fixture gives.
ANY_EDGE = st.integers(0, 2**31)
FIXTURE_OK = settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)


@pytest.fixture(scope="session")
def bayfront_net(data_dir: Path, cache_dir: Path) -> roadnets.RoadNetwork:
    """Marina Bay: 13 via-way restrictions (12 apply to the drivable graph)."""
    return roadnets.load(data_dir / "bayfront_singapore_2019.osm.pbf", cache_dir=cache_dir)


@pytest.fixture(scope="session")
def aguascalientes_net(data_dir: Path, cache_dir: Path) -> roadnets.RoadNetwork:
    return roadnets.load(data_dir / "aguascalientes_mx.osm.bz2", cache_dir=cache_dir)


@pytest.fixture(scope="session", params=["monaco", "bayfront", "aguascalientes", "andorra"])
def restricted_net(
    request: pytest.FixtureRequest, default_net: roadnets.RoadNetwork, cache_dir: Path
) -> roadnets.RoadNetwork:
    """Real networks with turn restrictions (Andorra only where ../shared is present)."""
    if request.param == "monaco":
        return default_net
    if request.param == "andorra":
        path = SHARED / "andorra_2020.osm.pbf"
        if not path.exists():
            pytest.skip("the shared extracts are not on this machine")
        return roadnets.load(path, cache_dir=cache_dir)
    net: roadnets.RoadNetwork = request.getfixturevalue(f"{request.param}_net")
    return net


def _unrestricted(arrays: NetworkArrays) -> NetworkArrays:
    return dataclasses.replace(
        arrays,
        banned_in=arrays.banned_in[:0],
        banned_out=arrays.banned_out[:0],
        banned_seq_ptr=np.zeros(1, dtype=np.int64),
        banned_seq_edge=arrays.banned_seq_edge[:0],
    )


def _reference(
    arrays: NetworkArrays,
    turns: TurnGraph,
    source: int,
    bound: float,
    uturn_cost: float,
    edge_cost: np.ndarray | None = None,
    turn_cost: np.ndarray | None = None,
) -> dict[int, float]:
    """Plain edge-based Dijkstra over the turn graph's states: lowest key per target edge."""
    edge_key = arrays.edge_length_m if edge_cost is None else edge_cost
    best: dict[int, float] = {}
    done: set[int] = set()

    def moves(s: int, arrive: float) -> list[tuple[float, int]]:
        out = []
        edge = int(turns.state_edge[s])
        for k in range(int(turns.trans_ptr[s]), int(turns.trans_ptr[s + 1])):
            t = int(turns.trans_to[k])
            key = arrive + (0.0 if turn_cost is None else float(turn_cost[k]))
            if turns.state_edge[t] == arrays.edge_twin[edge]:
                key += uturn_cost
            out.append((key, t))
        return out

    heap = moves(source, 0.0)
    heapq.heapify(heap)
    while heap:
        key, s = heapq.heappop(heap)
        if s in done or key > bound:
            continue
        done.add(s)
        best.setdefault(int(turns.state_edge[s]), key)
        for item in moves(s, key + float(edge_key[turns.state_edge[s]])):
            heapq.heappush(heap, item)
    return best


def _banned(arrays: NetworkArrays) -> tuple[set[tuple[int, int]], list[str]]:
    pairs = set(zip(arrays.banned_in.tolist(), arrays.banned_out.tolist(), strict=True))
    seqs = [
        "," + ",".join(map(str, arrays.banned_seq_edge[lo:hi].tolist())) + ","
        for lo, hi in itertools.pairwise(arrays.banned_seq_ptr.tolist())
    ]
    return pairs, seqs


@FIXTURE_OK
@given(data=st.data())
def test_without_restrictions_edge_routes_are_as_long_as_node_paths(
    default_net: roadnets.RoadNetwork, data: st.DataObject
) -> None:
    a = _unrestricted(default_net.arrays)
    turns = build_turn_graph(a)
    sources = np.array(
        data.draw(st.lists(st.integers(0, a.n_edges - 1), min_size=1, max_size=6, unique=True))
    )
    bound = data.draw(st.floats(0.0, 1500.0))
    table = route_table(a, turns, sources, bound, uturn_cost_m=0.0)
    nodes = shortest_path_table(a, a.edge_v[sources], bound)
    every = np.arange(a.n_edges)
    for s in sources.tolist():
        dist, _, _ = table.lookup(np.full(a.n_edges, s), every)
        node_dist, *_ = nodes.lookup(np.full(a.n_edges, a.edge_v[s]), a.edge_u[every])
        assert np.array_equal(np.isfinite(dist), np.isfinite(node_dist))
        near = np.isfinite(dist)
        assert np.allclose(dist[near], node_dist[near])


@FIXTURE_OK
@given(data=st.data())
def test_uturn_costs_only_lengthen_a_route_to_save_uturns(
    oakland_net: roadnets.RoadNetwork, data: st.DataObject
) -> None:
    a = oakland_net.arrays
    source = data.draw(st.integers(0, a.n_edges - 1))
    cost = data.draw(st.floats(1.0, 500.0))
    free = oakland_net.route_table(np.array([source]), 3000.0, uturn_cost_m=0.0)
    dear = oakland_net.route_table(np.array([source]), 3000.0, uturn_cost_m=cost)
    every = np.arange(a.n_edges)
    d0, _, u0 = free.lookup(np.full(a.n_edges, source), every)
    d1, _, u1 = dear.lookup(np.full(a.n_edges, source), every)
    both = np.isfinite(d0) & np.isfinite(d1)
    assert both.any()
    assert (d1[both] >= d0[both] - 1e-9).all()
    assert (u1[both] <= u0[both]).all()
    # the search key (length plus U-turn costs) is the lowest of both routes under that cost
    assert (d1[both] + cost * u1[both] <= d0[both] + cost * u0[both] + 1e-6).all()


@FIXTURE_OK
@given(data=st.data())
def test_the_pruned_search_finds_the_keys_of_a_plain_edge_dijkstra(
    restricted_net: roadnets.RoadNetwork, data: st.DataObject
) -> None:
    a, turns = restricted_net.arrays, restricted_net.turns
    source = data.draw(ANY_EDGE) % a.n_edges
    bound = data.draw(st.floats(0.0, 1200.0))
    cost = data.draw(st.sampled_from([0.0, 30.0, 300.0]))
    expected = _reference(a, turns, source, bound, cost)
    table = restricted_net.route_table(np.array([source]), bound, uturn_cost_m=cost)
    every = np.arange(a.n_edges)
    dist, _, uturns = table.lookup(np.full(a.n_edges, source), every)
    reached = np.flatnonzero(np.isfinite(dist))
    assert sorted(expected) == reached.tolist()
    keys = dist[reached] + cost * uturns[reached]
    assert np.allclose(keys, [expected[e] for e in reached.tolist()])


@FIXTURE_OK
@given(data=st.data())
def test_no_route_takes_a_banned_turn_or_drives_a_banned_sequence(
    restricted_net: roadnets.RoadNetwork, data: st.DataObject
) -> None:
    a = restricted_net.arrays
    pairs, seqs = _banned(a)
    assert pairs or seqs
    # half the sources enter a restriction, so that the bans are put to the test
    restricted = np.concatenate((a.banned_in, a.banned_seq_edge[a.banned_seq_ptr[:-1]]))
    entering = sorted(set(restricted.tolist()))
    pick = data.draw(ANY_EDGE)
    source = entering[pick % len(entering)] if data.draw(st.booleans()) else pick % a.n_edges
    cost = data.draw(st.sampled_from([0.0, 50.0]))
    table = restricted_net.route_table(np.array([source]), 1500.0, uturn_cost_m=cost)
    edge_time = a.edge_length_m / a.edge_speed_mps
    for rec in range(len(table.state)):
        target = int(table.turns.state_edge[table.state[rec]])
        drive = [source, *table.path(rec), target]
        moves = list(itertools.pairwise(drive))
        assert not set(moves) & pairs, drive
        text = "," + ",".join(map(str, drive)) + ","
        assert not any(seq in text for seq in seqs), drive
        # the route connects and its figures add up
        assert all(a.edge_v[x] == a.edge_u[y] for x, y in moves)
        between = drive[1:-1]
        assert table.distance_m[rec] == pytest.approx(a.edge_length_m[between].sum())
        assert table.time_s[rec] == pytest.approx(edge_time[between].sum())
        assert table.uturns[rec] == sum(a.edge_twin[x] == y for x, y in moves)


def test_a_banned_move_is_not_a_direct_follow(restricted_net: roadnets.RoadNetwork) -> None:
    a = restricted_net.arrays
    if not len(a.banned_in):
        pytest.skip("no via-node restriction here")
    routes = restricted_net.edge_routes(a.banned_in, a.banned_out, 2000.0)
    assert (routes.distance_m > 0).all()  # never "0 m, straight on" through the ban
    free = _unrestricted(a)
    unbanned = route_pairs(free, build_turn_graph(free), a.banned_in, a.banned_out, 2000.0)
    assert (unbanned.distance_m == 0).all()


@FIXTURE_OK
@given(data=st.data())
def test_pairs_get_the_routes_of_the_full_table(
    restricted_net: roadnets.RoadNetwork, data: st.DataObject
) -> None:
    a = restricted_net.arrays
    n = data.draw(st.integers(1, 60))
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    from_edges = rng.integers(0, a.n_edges, n)
    to_edges = rng.integers(0, a.n_edges, n)
    bounds = rng.uniform(0.0, 1500.0, n)
    routes = restricted_net.edge_routes(from_edges, to_edges, bounds)
    table = restricted_net.route_table(from_edges, bounds)
    dist, time, uturns = table.lookup(from_edges, to_edges)
    cost = roadnets.DEFAULT_UTURN_COST_M
    # every pair its table route has; a pair may get one beyond its own bound from a search
    # with a larger bound of the same source, never a worse one
    found = np.isfinite(dist)
    assert np.isfinite(routes.distance_m[found]).all()
    both = found & np.isfinite(routes.distance_m)
    assert np.allclose(
        (routes.distance_m + cost * routes.uturns)[both], (dist + cost * uturns)[both]
    )
    for i in np.flatnonzero(np.isfinite(routes.distance_m))[:20].tolist():
        path = routes.edges(int(from_edges[i]), int(to_edges[i]))
        assert routes.distance_m[i] == pytest.approx(a.edge_length_m[path].sum())
    assert np.allclose(routes.time_s[both], time[both])


def test_a_precomputed_route_table_answers_as_the_searches_when_bounds_and_cost_fit(
    oakland_net: roadnets.RoadNetwork,
) -> None:
    a = oakland_net.arrays
    from_edges = np.repeat(np.arange(a.n_edges), 5)
    to_edges = np.tile(np.arange(5), a.n_edges)
    bounds = np.random.default_rng(5).uniform(50.0, 400.0, len(from_edges))
    fresh = oakland_net.edge_routes(from_edges, to_edges, bounds)
    try:
        table = oakland_net.precompute_routes(500.0)
        assert table.complete
        answered = oakland_net.edge_routes(from_edges, to_edges, bounds)
        assert answered.table is table
        assert oakland_net.edge_routes(from_edges, to_edges, 600.0).table is not table
        other = oakland_net.edge_routes(from_edges, to_edges, 400.0, uturn_cost_m=10.0)
        assert other.table is not table
        # the same answers as the searches, routes beyond what they settle left out too
        near = np.isfinite(fresh.distance_m)
        assert np.array_equal(near, np.isfinite(answered.distance_m))
        assert np.allclose(fresh.distance_m[near], answered.distance_m[near])
        assert np.array_equal(fresh.uturns, answered.uturns)
        i = int(np.flatnonzero(near & (fresh.distance_m > 0))[0])
        pair = (int(from_edges[i]), int(to_edges[i]))
        assert answered.edges(*pair) == fresh.edges(*pair)
    finally:
        oakland_net.precomputed_routes = None


@pytest.mark.parametrize("runs", [True, False], ids=["runs of one source", "any order"])
def test_the_staged_table_look_up_answers_as_its_steps_and_the_searches(
    restricted_net: roadnets.RoadNetwork, runs: bool
) -> None:
    net = restricted_net
    a, turns = net.arrays, net.turns
    rng = np.random.default_rng(11)
    from_edges = rng.integers(0, a.n_edges, 400)
    if runs:  # as the matcher asks: each source's targets together
        from_edges = np.repeat(from_edges[:50], 8)
    to_edges = rng.integers(0, a.n_edges, len(from_edges))
    near = rng.random(len(from_edges)) < 0.5  # half of them close by, so that routes exist
    to_edges[near] = a.edge_twin[from_edges[near]].clip(0)
    to_edges[::7] = from_edges[::7]
    bounds = rng.uniform(0.0, 600.0, len(from_edges))
    previous = net.precomputed_routes
    try:
        net.precomputed_routes = None
        routes = net.edge_routes(from_edges, to_edges, bounds)  # searched
        assert routes.targets is not None
        table = net.precompute_routes(600.0)
        slot = scratch(a, turns)[1][0]
        index = table.index()
        rec, dist, time, uturns, arrival = table_routes(
            table.lookup_columns(),
            turns.state_edge,
            from_edges,
            to_edges,
            bounds,
            DEFAULT_UTURN_COST_M,
            slot,
        )
        assert (slot == -1).all()  # the scratch is left clean for the next caller
        four = table_records(table.sources, table.ptr, table.state, index, turns.copy_ptr,
                             turns.copy_state, from_edges, to_edges)  # fmt: skip
        # a record counts within the largest bound of its source's pairs (one search each)
        largest = {int(e): float(bounds[from_edges == e].max()) for e in np.unique(from_edges)}
        key = table.distance_m[four] + DEFAULT_UTURN_COST_M * table.uturns[four]
        beyond = key > np.array([largest[int(e)] for e in from_edges])
        four[(four >= 0) & beyond] = -1
        assert np.array_equal(rec, four)
        gathered = gather(four, table.distance_m, table.time_s, table.uturns)
        for got, want in zip((dist, time, uturns), gathered, strict=True):
            assert np.array_equal(got, want)
        # as the searches with these bounds find them, and each arrives on its target from
        # the route's last edge before it (its source when the target follows at once)
        assert np.array_equal(np.isfinite(dist), np.isfinite(routes.distance_m))
        found = np.flatnonzero(rec >= 0)
        assert len(found) > 50
        assert np.allclose(dist[found], routes.distance_m[found])
        for i in found.tolist():
            path = routes.edges(int(from_edges[i]), int(to_edges[i]))
            assert arrival[i] == (path[-1] if path else from_edges[i])
        assert (arrival[rec < 0] == -1).all()
        # and what the network answers from the table is the same
        answered = net.edge_routes(from_edges, to_edges, bounds)
        assert answered.table is table
        assert np.array_equal(answered.distance_m, dist)
        assert np.array_equal(answered.uturns, uturns)
    finally:
        net.precomputed_routes = previous


def test_a_source_is_found_at_its_place_and_any_other_edge_is_no_source() -> None:
    rng = np.random.default_rng(5)
    for size in (0, 1, 2, 3, 120):
        sources = np.unique(rng.integers(0, 400, 4 * size))[:size]
        for edge in range(-2, 405):
            place = int(np.searchsorted(sources, edge))
            known = place < len(sources) and sources[place] == edge
            assert _source_rank(sources, edge) == (place if known else -1)


def test_bad_arguments_are_named(oakland_net: roadnets.RoadNetwork) -> None:
    n = oakland_net.arrays.n_edges
    with pytest.raises(ValueError, match=r"to_edges\[1\] = 99999 is not an edge"):
        oakland_net.edge_routes(np.array([0, 1]), np.array([0, 99999]), 100.0)
    with pytest.raises(ValueError, match="from_edges has 2 entries but to_edges 1"):
        oakland_net.edge_routes(np.array([0, 1]), np.array([0]), 100.0)
    with pytest.raises(ValueError, match=r"sources\[0\] = -1"):
        oakland_net.route_table(np.array([-1]), 100.0)
    with pytest.raises(ValueError, match="uturn_cost_m"):
        oakland_net.route_table(np.array([n - 1]), 100.0, uturn_cost_m=-1.0)
    with pytest.raises(KeyError):
        oakland_net.edge_routes(np.array([0]), np.array([1]), 100.0).edges(1, 0)


def test_via_way_restrictions_of_a_real_extract_compile_and_survive_the_cache(
    data_dir: Path, tmp_path: Path
) -> None:
    source = data_dir / "bayfront_singapore_2019.osm.pbf"
    compiled = roadnets.load(source, cache_dir=tmp_path)
    cached = roadnets.load(source, cache_dir=tmp_path)
    assert cached.from_cache
    a = cached.arrays
    assert np.array_equal(a.banned_seq_ptr, compiled.arrays.banned_seq_ptr)
    assert np.array_equal(a.banned_seq_edge, compiled.arrays.banned_seq_edge)
    assert cached.info().banned_sequences == 12
    for lo, hi in itertools.pairwise(a.banned_seq_ptr.tolist()):
        seq = a.banned_seq_edge[lo:hi].tolist()
        assert len(seq) >= 3
        assert all(a.edge_v[x] == a.edge_u[y] for x, y in itertools.pairwise(seq))
        assert cached.turns.first_banned(seq) == len(seq) - 1
    assert cached.turns.n_states > a.n_edges  # restricted copies of the via edges


def test_repeated_pairs_share_one_search_and_no_pairs_is_no_work(cache_dir: Path) -> None:
    default_net = roadnets.load(cache_dir=cache_dir)  # its own: no route table attached
    a = default_net.arrays
    source = int(a.banned_in[0])
    targets = np.arange(a.n_edges)
    full = default_net.route_table(np.array([source]), 900.0)
    dist, _, uturns = full.lookup(np.full(a.n_edges, source), targets)
    far = int(np.flatnonzero(np.isfinite(dist) & (dist > 500.0))[0])
    # the same pair twice, with a small and a large bound: both get the large bound's route
    routes = default_net.edge_routes(
        np.array([source, source]), np.array([far, far]), np.array([10.0, 900.0])
    )
    assert routes.distance_m.tolist() == [dist[far], dist[far]]
    assert routes.uturns.tolist() == [uturns[far], uturns[far]]
    assert len(routes.table.sources) == 1
    empty = default_net.edge_routes(np.zeros(0, int), np.zeros(0, int), 300.0)
    assert len(empty.distance_m) == 0
    assert len(empty.table.state) == 0


@FIXTURE_OK
@given(data=st.data())
def test_custom_costs_find_the_keys_of_a_plain_edge_dijkstra(
    restricted_net: roadnets.RoadNetwork, data: st.DataObject
) -> None:
    # a fastest route with a penalty on some turns, as the simulator wants one
    a, turns = restricted_net.arrays, restricted_net.turns
    source = data.draw(ANY_EDGE) % a.n_edges
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    edge_cost = a.edge_length_m / a.edge_speed_mps
    turn_cost = rng.choice([0.0, 0.0, 5.0], size=len(turns.trans_to))
    expected = _reference(a, turns, source, 120.0, 30.0, edge_cost, turn_cost)
    table = restricted_net.route_table(
        np.array([source]), 120.0, uturn_cost_m=30.0, edge_cost=edge_cost, turn_cost=turn_cost
    )
    assert table.weighted
    got: dict[int, float] = {}
    for rec in range(len(table.state)):
        chain = [rec]
        while table.pred[chain[-1]] >= 0:
            chain.append(int(table.pred[chain[-1]]))
        states = [source, *(int(table.state[r]) for r in reversed(chain))]
        key = 0.0
        for s, t in itertools.pairwise(states):
            lo, hi = int(turns.trans_ptr[s]), int(turns.trans_ptr[s + 1])
            k = lo + int(np.flatnonzero(turns.trans_to[lo:hi] == t)[0])
            key += turn_cost[k] + (
                30.0 if a.edge_twin[turns.state_edge[s]] == turns.state_edge[t] else 0.0
            )
        key += float(edge_cost[turns.state_edge[states[1:-1]]].sum())
        got.setdefault(int(turns.state_edge[table.state[rec]]), key)
    assert sorted(got) == sorted(expected)
    assert np.allclose([got[e] for e in sorted(got)], [expected[e] for e in sorted(got)])


def test_bad_costs_are_named(oakland_net: roadnets.RoadNetwork) -> None:
    n = oakland_net.arrays.n_edges
    with pytest.raises(ValueError, match=rf"edge_cost has shape \(3,\); .* shape \({n},\)"):
        oakland_net.route_table(np.array([0]), 100.0, edge_cost=np.ones(3))
    bad = np.ones(len(oakland_net.turns.trans_to))
    bad[4] = np.nan
    with pytest.raises(ValueError, match=r"turn_cost\[4\] = nan"):
        oakland_net.route_table(np.array([0]), 100.0, turn_cost=bad)
