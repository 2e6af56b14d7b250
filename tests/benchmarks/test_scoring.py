"""Tests of the geometric route-mismatch scoring used by the peer benchmark."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.benchmarks.scripts import load_script

scoring = load_script("scoring.py")

LON0, LAT0 = 7.42, 43.73
PROJ = scoring.LocalProjection(LON0, LAT0)


def lonlat(xy: list[tuple[float, float]] | np.ndarray) -> list[list[float]]:
    """Metric points around (LON0, LAT0) as [[lon, lat], ...]."""
    return PROJ.to_lonlat(np.asarray(xy, dtype=float)).tolist()


# an L-shaped route: 500 m east, then 300 m north
ROUTE = [(0.0, 0.0), (250.0, 0.0), (500.0, 0.0), (500.0, 300.0)]
ROUTE_LEN = 800.0


def test_identical_geometry_has_no_mismatch() -> None:
    s = scoring.score_route(lonlat(ROUTE), [lonlat(ROUTE)])
    assert s.true_length_m == pytest.approx(ROUTE_LEN, rel=2e-3)
    assert s.mismatch == pytest.approx(0.0, abs=1e-9)
    assert s.precision == pytest.approx(1.0)
    assert s.recall == pytest.approx(1.0)


def test_identical_geometry_with_different_vertices_has_no_mismatch() -> None:
    dense = [(float(x), 0.0) for x in np.arange(0.0, 500.0, 7.3)] + [(500.0, 0.0), (500.0, 300.0)]
    s = scoring.score_route(lonlat(ROUTE), [lonlat(dense)])
    assert s.mismatch < 0.005


def test_detour_adds_its_length() -> None:
    # at x=250 the match turns into a side street 100 m north and comes back
    detour = [(0.0, 0.0), (250.0, 0.0), (250.0, 100.0), (250.0, 0.0), (500.0, 0.0), (500.0, 300.0)]
    s = scoring.score_route(lonlat(ROUTE), [lonlat(detour)])
    assert s.added_m == pytest.approx(200.0, abs=3.0)
    assert s.missed_m == pytest.approx(0.0, abs=3.0)
    assert s.mismatch == pytest.approx(200.0 / ROUTE_LEN, abs=0.01)
    assert s.precision == pytest.approx(800.0 / 1000.0, abs=0.01)


def test_missing_stretch_counts_as_missed() -> None:
    # the match has a break: nothing between x=100 and x=400
    pieces = [
        lonlat([(0.0, 0.0), (100.0, 0.0)]),
        lonlat([(400.0, 0.0), (500.0, 0.0), (500.0, 300.0)]),
    ]
    s = scoring.score_route(lonlat(ROUTE), pieces)
    assert s.missed_m == pytest.approx(300.0, abs=2.0)
    assert s.added_m == pytest.approx(0.0, abs=2.0)
    assert s.recall == pytest.approx(500.0 / ROUTE_LEN, abs=0.005)
    assert s.precision == pytest.approx(1.0, abs=0.005)


def test_reversed_direction_counts_as_wrong() -> None:
    s = scoring.score_route(lonlat(ROUTE), [lonlat(ROUTE[::-1])])
    assert s.correct_m == pytest.approx(0.0, abs=1e-9)
    assert s.covered_m == pytest.approx(0.0, abs=1e-9)
    assert s.mismatch == pytest.approx(2.0, abs=0.01)


def test_offset_by_two_metres_still_matches() -> None:
    shifted = [(x + 1.2, y - 1.6) for x, y in ROUTE]  # 2 m off, diagonally
    s = scoring.score_route(lonlat(ROUTE), [lonlat(shifted)])
    assert s.mismatch < 0.01


def test_offset_beyond_tolerance_does_not_match() -> None:
    # a parallel road 12 m away
    parallel = [(x, y - 12.0) for x, y in ROUTE[:3]]
    s = scoring.score_route(lonlat(ROUTE[:3]), [lonlat(parallel)])
    assert s.correct_m == pytest.approx(0.0, abs=1e-9)


def test_perpendicular_crossing_road_is_not_correct() -> None:
    truth = [(0.0, 0.0), (200.0, 0.0)]
    crossing = [(100.0, -50.0), (100.0, 50.0)]
    s = scoring.score_route(lonlat(truth), [lonlat(crossing)])
    assert s.correct_m == pytest.approx(0.0, abs=1e-9)
    assert s.added_m == pytest.approx(100.0, abs=1.0)


BLOCK = [(0.0, 0.0), (200.0, 0.0), (200.0, 200.0), (0.0, 200.0), (0.0, 0.0)]


def test_truth_loop_needs_two_matched_passes() -> None:
    twice = BLOCK + BLOCK[1:]
    s = scoring.score_route(lonlat(twice), [lonlat(BLOCK)])
    assert s.true_length_m == pytest.approx(1600.0, rel=2e-3)
    assert s.recall == pytest.approx(0.5, abs=0.01)
    assert s.precision == pytest.approx(1.0, abs=0.01)


def test_matched_extra_loop_is_added() -> None:
    twice = BLOCK + BLOCK[1:]
    s = scoring.score_route(lonlat(BLOCK), [lonlat(twice)])
    # the second pass may re-use a couple of metres (the chain's back-step allowance)
    assert s.added_m == pytest.approx(800.0, abs=4.0)
    assert s.recall == pytest.approx(1.0, abs=0.01)


def test_empty_match_misses_everything() -> None:
    s = scoring.score_route(lonlat(ROUTE), [])
    assert s.mismatch == pytest.approx(1.0)
    assert math.isnan(s.precision)
    assert s.recall == 0.0


def test_summary_weights_precision_by_length() -> None:
    a = scoring.RouteScore(
        true_length_m=100.0, matched_length_m=100.0, correct_m=100.0, covered_m=100.0
    )
    b = scoring.RouteScore(
        true_length_m=300.0, matched_length_m=100.0, correct_m=50.0, covered_m=50.0
    )
    summary = scoring.summarize([a, b])
    assert summary.traces == 2
    assert summary.precision == pytest.approx(150.0 / 200.0)
    assert summary.recall == pytest.approx(150.0 / 400.0)
    assert summary.mismatch_mean == pytest.approx((0.0 + (50.0 + 250.0) / 300.0) / 2)
    assert summary.mismatch_median == pytest.approx(summary.mismatch_mean)


def test_empty_truth_is_rejected() -> None:
    with pytest.raises(ValueError, match="truth geometry is empty"):
        scoring.score_route([], [lonlat(ROUTE)])
