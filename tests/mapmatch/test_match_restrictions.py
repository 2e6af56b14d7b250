"""The matcher's paths obey turn restrictions (issue 13: one routing engine for everyone).

Hand-made networks with ``no_left_turn``, ``only_straight_on`` and a via-way ``no_u_turn``
(tests/roadnets/test_turn_restrictions.py draws them), matched from sparse 30 s traces whose
only legal explanation drives round: the path must be the legal one, never the banned turn.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pytest

import mapmatch
from tests.mapmatch.toy import trace_of
from tests.roadnets.osm_relations import Restriction
from tests.roadnets.test_turn_restrictions import (
    BLOCK,
    J1,
    K1,
    NB0,
    NB1,
    NB2,
    NB3,
    ONEWAY,
    S2,
    SB0,
    SB1,
    SB2,
    SB3,
    SE,
    TWO_WAY,
    E,
    J,
    K,
    N,
    S,
    Toy,
    W,
    X,
)

if TYPE_CHECKING:
    from pathlib import Path


# way 1 eastbound towards J, then (30 s later) northbound on way 3 above J1
APPROACH = [(20.0, 1.0, 0.0), (50.0, 1.0, 3.0), (80.0, 1.0, 6.0)]
NORTH = [(101.0, 125.0, 36.0), (101.0, 160.0, 39.0), (101.0, 195.0, 42.0)]


def _path(result: mapmatch.MatchResult) -> list[int]:
    assert len(result.segments) == 1
    return [e.edge for e in result.segments[0].edges]


def _match(toy: Toy, fixes: list[tuple[float, float, float]]) -> list[int]:
    """Match fixes ``(x, y, t)`` and check that no move on the path is banned."""
    x, y, t = (np.array([f[i] for f in fixes]) for i in range(3))
    result = mapmatch.match(trace_of(x, y, time_s=t), toy.net)
    path = _path(result)
    assert toy.net.turns.first_banned(path) == -1  # no banned turn or sequence anywhere
    return path


def test_a_banned_left_turn_is_driven_round_the_block(tmp_path: Path) -> None:
    toy = Toy(tmp_path / "block.osm", BLOCK, [Restriction("no_left_turn", 1, J, 3)])
    # east along way 1 towards J, 30 s without fixes, then north on way 3 above J1: the
    # left turn at J is banned, so the car went round J-K-K1-J1
    path = _match(toy, APPROACH + NORTH)
    around = [toy.edge(J, K), toy.edge(K, K1), toy.edge(K1, J1)]
    assert all(edge in path for edge in around)
    assert toy.edge(J, J1) not in path
    # without the restriction the same fixes turn left at J
    free = Toy(tmp_path / "free.osm", BLOCK, [])
    free_path = _match(free, APPROACH + NORTH)
    assert free.edge(J, J1) in free_path


def test_only_straight_on_sends_the_right_turn_round(tmp_path: Path) -> None:
    ways = [
        (11, [W, X], TWO_WAY),
        (12, [X, E], TWO_WAY),
        (13, [X, N], TWO_WAY),
        (14, [X, S, S2], TWO_WAY),
        (15, [E, SE, S], TWO_WAY),
    ]
    toy = Toy(tmp_path / "straight.osm", ways, [Restriction("only_straight_on", 11, X, 12)])
    # from the west arm, then south of S: the right turn at X is not allowed
    fixes = [(20.0, 1.0, 0.0), (50.0, 1.0, 3.0), (80.0, 1.0, 6.0)]
    fixes += [(101.0, -130.0, 36.0), (101.0, -160.0, 39.0), (101.0, -190.0, 42.0)]
    path = _match(toy, fixes)
    assert toy.edge(X, E) in path
    assert toy.edge(E, S) in path
    assert toy.edge(X, S) not in path


def test_a_via_way_no_u_turn_takes_the_next_crossing(tmp_path: Path) -> None:
    ways = [
        (21, [NB0, NB1], ONEWAY),
        (22, [NB1, NB2], ONEWAY),
        (23, [NB2, NB3], ONEWAY),
        (24, [SB3, SB2], ONEWAY),
        (25, [SB2, SB1], ONEWAY),
        (26, [SB1, SB0], ONEWAY),
        (31, [NB1, SB1], ONEWAY),
        (32, [NB2, SB2], ONEWAY),
    ]
    toy = Toy(tmp_path / "dual.osm", ways, [Restriction("no_u_turn", 21, [31], 26)])
    # northbound below the first crossing, then southbound below it: the U-turn through the
    # first crossing is banned for traffic coming from way 21
    fixes = [(-1.0, 60.0, 0.0), (-1.0, 100.0, 3.0), (-1.0, 140.0, 6.0)]
    fixes += [(21.0, 150.0, 66.0), (21.0, 110.0, 69.0), (21.0, 70.0, 72.0)]
    path = _match(toy, fixes)
    assert toy.edge(NB2, SB2) in path  # round by the second crossing
    assert toy.edge(NB1, SB1) not in path


@pytest.mark.parametrize("seed", [1, 2])
def test_noisy_sparse_fixes_keep_to_the_rules(tmp_path: Path, seed: int) -> None:
    toy = Toy(tmp_path / "block.osm", BLOCK, [Restriction("no_left_turn", 1, J, 3)])
    rng = np.random.default_rng(seed)
    noisy = [(x + rng.normal(0, 5), y + rng.normal(0, 5), t) for x, y, t in APPROACH + NORTH]
    path = _match(toy, noisy)  # _match checks that no move on the path is banned
    assert toy.edge(K, K1) in path
