"""Which candidates of a fix the trellis keeps: the road places with the best emission."""

from __future__ import annotations

import numpy as np

from mapmatch.hmm.trellis import _best_places


def _kept(em: list[float], places: list[int], most: int) -> list[int]:
    """The rows kept, for candidate rows whose projections are the given place numbers."""
    rows = np.arange(len(em), dtype=np.int64)
    x = np.asarray(places, dtype=np.float64)
    kept = _best_places(rows, np.asarray(em, dtype=np.float64), x, np.zeros_like(x), most)
    return rows[:kept].tolist()


def test_the_best_places_are_kept_nearest_first() -> None:
    # rows are nearest first; the farthest one agrees best with the heading
    assert _kept([-1.0, -6.0, -5.0, -0.5], [0, 1, 2, 3], most=2) == [0, 3]


def test_both_directions_of_a_road_are_one_place() -> None:
    # rows 0 and 1 are the two directions of one road (one projection): they stay together,
    # and still leave room for the next best place
    assert _kept([-1.0, -9.0, -2.0, -3.0], [0, 0, 1, 2], most=2) == [0, 1, 2]


def test_the_twin_of_a_kept_place_is_kept_even_when_its_emission_is_poor() -> None:
    assert _kept([-9.0, -1.0, -2.0], [0, 0, 1], most=1) == [0, 1]


def test_fewer_places_than_allowed_keep_every_row() -> None:
    assert _kept([-3.0, -1.0, -2.0], [0, 1, 1], most=5) == [0, 1, 2]


def test_a_twin_projected_a_few_ulps_apart_is_still_one_place() -> None:
    # a two-way road's two directions project a fix through their own (reversed) geometry,
    # which can land 1e-15 m apart: they are still one place, and leave room for the next
    rows = np.arange(4, dtype=np.int64)
    x = np.array([100.0, 100.0 + 1.4e-14, 200.0, 300.0])
    em = np.array([-1.0, -9.0, -2.0, -3.0])
    assert _best_places(rows, em, x, np.zeros(4), 2) == 3
    assert rows[:3].tolist() == [0, 1, 2]
