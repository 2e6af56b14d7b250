"""Turn restrictions on hand-made OSM networks: compiled, and obeyed by the edge-based router."""

from __future__ import annotations

import itertools
from typing import TYPE_CHECKING

import numpy as np
import pytest

import roadnets
from tests.roadnets.osm_relations import Restriction, write_osm

if TYPE_CHECKING:
    from pathlib import Path

    from tests.roadnets.osm_relations import Point

TWO_WAY = {"highway": "residential"}
ONEWAY = {"highway": "primary", "oneway": "yes"}


def metres(value: float) -> object:
    """A length as drawn (the tangent plane and the UTM projection differ by under 0.5 %)."""
    return pytest.approx(value, rel=5e-3)


class Toy:
    """A loaded hand-made network and its points' node ids."""

    def __init__(self, path: Path, ways: list, restrictions: list[Restriction]) -> None:  # type: ignore[type-arg]
        self.node_ids = write_osm(path, ways, restrictions)
        self.net = roadnets.load(path, use_cache=False)

    def edge(self, p: Point, q: Point) -> int:
        """The directed edge from point ``p`` to point ``q``."""
        a = self.net.arrays
        u = np.flatnonzero(a.node_osm_id == self.node_ids[p])
        v = np.flatnonzero(a.node_osm_id == self.node_ids[q])
        (found,) = np.flatnonzero((a.edge_u == u[0]) & (a.edge_v == v[0]))
        return int(found)

    def route(
        self, a: int, b: int, *, uturn_cost_m: float = roadnets.DEFAULT_UTURN_COST_M
    ) -> tuple[list[int], float, int]:
        """Edges strictly between ``a`` and ``b``, length and U-turns, checked both ways."""
        routes = self.net.edge_routes(
            np.array([a]), np.array([b]), 5000.0, uturn_cost_m=uturn_cost_m
        )
        path = routes.edges(a, b)
        table = self.net.route_table(np.array([a]), 5000.0, uturn_cost_m=uturn_cost_m)
        dist, _, turns = table.lookup(np.array([a]), np.array([b]))
        assert table.edges(a, b) == path
        assert (dist[0], turns[0]) == (routes.distance_m[0], routes.uturns[0])
        length = float(self.net.arrays.edge_length_m[path].sum())
        assert routes.distance_m[0] == metres(length)
        return path, float(routes.distance_m[0]), int(routes.uturns[0])


# ---- a banned left turn: the only legal way onto the side street is around the block ----
#
#   J''(100,200)
#    |
#   J'(100,100) ---- K'(200,100) ---- L'(300,100)
#    |                |                |
#   J(100,0) ------- K(200,0) ------- L(300,0)
#    |
#   P(0,0)   (way 1 runs P - J, P is a dead end)
P, J, K, L = (0.0, 0.0), (100.0, 0.0), (200.0, 0.0), (300.0, 0.0)
J1, J2, K1, L1 = (100.0, 100.0), (100.0, 200.0), (200.0, 100.0), (300.0, 100.0)
BLOCK = [
    (1, [P, J], TWO_WAY),
    (2, [J, K, L], TWO_WAY),
    (3, [J, J1, J2], TWO_WAY),
    (4, [K, K1], TWO_WAY),
    (5, [J1, K1, L1], TWO_WAY),
    (6, [L, L1], TWO_WAY),
]


@pytest.fixture(scope="module")
def block(tmp_path_factory: pytest.TempPathFactory) -> Toy:
    path = tmp_path_factory.mktemp("restrictions") / "block.osm"
    return Toy(path, BLOCK, [Restriction("no_left_turn", 1, J, 3)])


@pytest.fixture(scope="module")
def free_block(tmp_path_factory: pytest.TempPathFactory) -> Toy:
    return Toy(tmp_path_factory.mktemp("restrictions") / "free.osm", BLOCK, [])


def test_a_banned_left_turn_is_compiled_as_one_banned_pair(block: Toy) -> None:
    a = block.net.arrays
    assert list(zip(a.banned_in.tolist(), a.banned_out.tolist(), strict=True)) == [
        (block.edge(P, J), block.edge(J, J1))
    ]
    assert block.net.info().turn_restrictions == 1
    assert block.net.info().banned_sequences == 0


def test_a_banned_left_turn_sends_the_route_around_the_block(block: Toy, free_block: Toy) -> None:
    # without the restriction: straight up the side street
    a, b = free_block.edge(P, J), free_block.edge(J1, J2)
    assert free_block.route(a, b) == ([free_block.edge(J, J1)], metres(100.0), 0)
    # with it: east, north, west along the top, then onto the side street
    a, b = block.edge(P, J), block.edge(J1, J2)
    path, dist, turns = block.route(a, b)
    assert path == [block.edge(J, K), block.edge(K, K1), block.edge(K1, J1)]
    assert dist == metres(300.0)
    assert turns == 0


def test_the_banned_edge_itself_is_reached_by_a_uturn_down_the_road(block: Toy) -> None:
    # onto J -> J' from the west is banned; a U-turn at K and a right turn at J is the
    # shortest legal way (200 m, one U-turn)
    a, b = block.edge(P, J), block.edge(J, J1)
    assert block.route(a, b) == ([block.edge(J, K), block.edge(K, J)], metres(200.0), 1)
    # when a U-turn costs more than 400 m, round the right-hand block and back (600 m, none)
    # (either way round: the two are equally long)
    loops = [
        [J, K, L, L1, K1, K, J],
        [J, K, K1, L1, L, K, J],
    ]
    path, dist, turns = block.route(a, b, uturn_cost_m=1000.0)
    assert path in [[block.edge(p, q) for p, q in itertools.pairwise(loop)] for loop in loops]
    assert (dist, turns) == (metres(600.0), 0)


def test_a_turn_straight_onto_the_next_edge_is_length_zero(block: Toy) -> None:
    a, b = block.edge(P, J), block.edge(J, K)
    assert block.route(a, b) == ([], 0.0, 0)


def test_the_uturn_cost_orders_the_search_but_is_not_in_the_length(free_block: Toy) -> None:
    t = free_block
    a, back = t.edge(J, K), t.edge(K, J)
    # turning straight back: nothing in between, one U-turn
    assert t.route(a, back, uturn_cost_m=50.0) == ([], 0.0, 1)
    assert t.route(a, back, uturn_cost_m=390.0) == ([], 0.0, 1)
    # when a U-turn costs more than the 400 m round the right-hand block, the block wins
    # (either way round)
    loops = [[K, L, L1, K1, K], [K, K1, L1, L, K]]
    path, dist, turns = t.route(a, back, uturn_cost_m=410.0)
    assert path in [[t.edge(p, q) for p, q in itertools.pairwise(loop)] for loop in loops]
    assert (dist, turns) == (metres(400.0), 0)


def test_a_dead_end_needs_its_uturn_however_dear(free_block: Toy) -> None:
    t = free_block
    into_dead_end, out_of_it = t.edge(J, P), t.edge(P, J)
    assert t.route(into_dead_end, out_of_it, uturn_cost_m=2000.0) == ([], 0.0, 1)
    path, dist, turns = t.route(into_dead_end, t.edge(J, K), uturn_cost_m=2000.0)
    assert (path, dist, turns) == ([out_of_it], metres(100.0), 1)


def test_a_route_from_an_edge_to_itself_is_a_loop_back_to_its_start(free_block: Toy) -> None:
    t = free_block
    a = t.edge(J, K)
    # cheap U-turns: back along the road and turn again at J (100 m, two U-turns)
    assert t.route(a, a, uturn_cost_m=50.0) == ([t.edge(K, J)], metres(100.0), 2)
    # dear U-turns: round the left-hand block (300 m, none)
    around = [t.edge(K, K1), t.edge(K1, J1), t.edge(J1, J)]
    assert t.route(a, a, uturn_cost_m=200.0) == (around, metres(300.0), 0)


# ---- only_straight_on: from the west arm, only east is allowed ----
#
#          N(100,100)
#           |
#  W(0,0) - X(100,0) - E(200,0)
#           |            |
#          S(100,-100) - SE(200,-100)
#           |
#          S2(100,-200)
W, X, E, N = (0.0, 0.0), (100.0, 0.0), (200.0, 0.0), (100.0, 100.0)
S, SE, S2 = (100.0, -100.0), (200.0, -100.0), (100.0, -200.0)


@pytest.fixture(scope="module")
def straight_on(tmp_path_factory: pytest.TempPathFactory) -> Toy:
    ways = [
        (11, [W, X], TWO_WAY),
        (12, [X, E], TWO_WAY),
        (13, [X, N], TWO_WAY),
        (14, [X, S, S2], TWO_WAY),
        (15, [E, SE, S], TWO_WAY),
    ]
    path = tmp_path_factory.mktemp("restrictions") / "straight.osm"
    return Toy(path, ways, [Restriction("only_straight_on", 11, X, 12)])


def test_only_straight_on_bans_every_other_move_at_the_node(straight_on: Toy) -> None:
    t = straight_on
    a = t.net.arrays
    banned = set(zip(a.banned_in.tolist(), a.banned_out.tolist(), strict=True))
    came = t.edge(W, X)
    assert banned == {(came, t.edge(X, N)), (came, t.edge(X, S)), (came, t.edge(X, W))}


def test_only_straight_on_routes_the_right_turn_around(straight_on: Toy) -> None:
    t = straight_on
    path, dist, turns = t.route(t.edge(W, X), t.edge(S, S2))
    assert path == [t.edge(X, E), t.edge(E, S)]  # E -> S bends at SE (no junction there)
    assert (dist, turns) == (metres(300.0), 0)
    # the U-turn at X is banned too: back west takes a U-turn at E (200 m) ...
    a, b = t.edge(W, X), t.edge(X, W)
    assert t.route(a, b) == ([t.edge(X, E), t.edge(E, X)], metres(200.0), 1)
    # ... or, when U-turns are dear, the way round the block
    path, dist, turns = t.route(a, b, uturn_cost_m=500.0)
    assert (path, turns) == ([t.edge(X, E), t.edge(E, S), t.edge(S, X)], 0)


# ---- a via-way restriction: no U-turn through the median crossing of a dual carriageway ----
#
#  x=0 northbound (ways 21, 22, 23), x=20 southbound (ways 26, 25, 24), crossings M1 at
#  y=200 (way 31) and M2 at y=600 (way 32), both from west to east; a side road (way 33) goes
#  east from the crossing M1 lands on.
NB0, NB1, NB2, NB3 = (0.0, 0.0), (0.0, 200.0), (0.0, 600.0), (0.0, 800.0)
SB0, SB1, SB2, SB3 = (20.0, 0.0), (20.0, 200.0), (20.0, 600.0), (20.0, 800.0)
SIDE = (120.0, 200.0)


@pytest.fixture(scope="module")
def dual(tmp_path_factory: pytest.TempPathFactory) -> Toy:
    ways = [
        (21, [NB0, NB1], ONEWAY),
        (22, [NB1, NB2], ONEWAY),
        (23, [NB2, NB3], ONEWAY),
        (24, [SB3, SB2], ONEWAY),
        (25, [SB2, SB1], ONEWAY),
        (26, [SB1, SB0], ONEWAY),
        (31, [NB1, SB1], ONEWAY),
        (32, [NB2, SB2], ONEWAY),
        (33, [SB1, SIDE], TWO_WAY),
    ]
    path = tmp_path_factory.mktemp("restrictions") / "dual.osm"
    return Toy(path, ways, [Restriction("no_u_turn", 21, [31], 26)])


def test_a_via_way_restriction_is_compiled_as_a_banned_sequence(dual: Toy) -> None:
    a = dual.net.arrays
    assert len(a.banned_in) == 0
    assert a.banned_seq_ptr.tolist() == [0, 3]
    expected = [dual.edge(NB0, NB1), dual.edge(NB1, SB1), dual.edge(SB1, SB0)]
    assert a.banned_seq_edge.tolist() == expected
    assert dual.net.info().banned_sequences == 1
    # one restricted copy of the crossing, entered from the northbound carriageway only
    turns = dual.net.turns
    assert turns.n_states == a.n_edges + 1
    assert turns.state_edge[-1] == dual.edge(NB1, SB1)
    assert turns.first_banned(expected) == 2
    assert turns.first_banned([*expected[:2], dual.edge(SB1, SIDE)]) == -1


def test_the_banned_uturn_goes_to_the_next_crossing(dual: Toy) -> None:
    t = dual
    a, b = t.edge(NB0, NB1), t.edge(SB1, SB0)
    # the U-turn through the crossing is banned as a sequence: driving on to the next
    # crossing is 820 m ...
    path, dist, turns = t.route(a, b, uturn_cost_m=1000.0)
    assert path == [t.edge(NB1, NB2), t.edge(NB2, SB2), t.edge(SB2, SB1)]
    assert (dist, turns) == (metres(820.0), 0)
    # ... but through the crossing, a U-turn at the end of the side road and back is not
    # the banned sequence (220 m and a U-turn)
    path, dist, turns = t.route(a, b, uturn_cost_m=50.0)
    assert path == [t.edge(NB1, SB1), t.edge(SB1, SIDE), t.edge(SIDE, SB1)]
    assert (dist, turns) == (metres(220.0), 1)


def test_the_crossing_stays_open_for_other_moves(dual: Toy) -> None:
    t = dual
    # from the northbound carriageway through the crossing onto the side road
    assert t.route(t.edge(NB0, NB1), t.edge(SB1, SIDE)) == (
        [t.edge(NB1, SB1)],
        metres(20.0),
        0,
    )
    # from the side road back through nothing: onto the southbound carriageway directly
    assert t.route(t.edge(SIDE, SB1), t.edge(SB1, SB0)) == ([], 0.0, 0)


def test_restrictions_for_other_vehicles_or_unusable_ones_are_counted_not_applied(
    tmp_path: Path,
) -> None:
    from roadnets.osm_reader import read_osm

    path = tmp_path / "except.osm"
    write_osm(
        path,
        BLOCK,
        [
            Restriction("no_left_turn", 1, J, 3, (("except", "motorcar"),)),
            Restriction("no_right_turn_on_red", 1, J, 3),
        ],
    )
    extract = read_osm(path)
    assert extract.restrictions == []
    assert extract.skipped_restrictions == {
        "cars exempt (except=...)": 1,
        "not a no_* / only_* turn restriction": 1,
    }
    assert len(roadnets.load(path, use_cache=False).arrays.banned_in) == 0
