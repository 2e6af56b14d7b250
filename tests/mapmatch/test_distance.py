from __future__ import annotations

import dataclasses
import logging
import math

import numpy as np
import pytest

from mapmatch.distance import (
    END_OUTLIERS,
    check_distance,
    chord_length_m,
    measured_chord,
    measured_span,
)

BAND = (-0.04, 0.01)


def _check(**kw: object) -> object:
    base: dict[str, object] = {
        "trace_id": "t",
        "matched_length_m": 1000.0,
        "complete": True,
        "band": BAND,
        "odometer_m": None,
        "fused_distance_m": None,
        "chord_m": 950.0,
    }
    base.update(kw)
    return check_distance(**base)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("fused", "verdict"),
    [(1000.0, "pass"), (1009.9, "pass"), (960.1, "pass"), (1010.5, "over"), (959.0, "under")],
)
def test_verdict_follows_the_metering_band(fused: float, verdict: str) -> None:
    c = _check(fused_distance_m=fused)
    assert c.source == "caller"  # type: ignore[attr-defined]
    assert c.verdict == verdict  # type: ignore[attr-defined]
    assert c.relative_error == pytest.approx((fused - 1000.0) / 1000.0)  # type: ignore[attr-defined]


def test_odometer_is_preferred_and_uses_last_minus_first_known() -> None:
    odo = np.array([np.nan, 100.0, 600.0, 1105.0, np.nan])
    c = _check(odometer_m=odo, fused_distance_m=2000.0)
    assert c.source == "odometer"  # type: ignore[attr-defined]
    assert c.fused_length_m == pytest.approx(1005.0)  # type: ignore[attr-defined]


def test_chord_sum_is_the_last_resort() -> None:
    c = _check()
    assert (c.source, c.fused_length_m, c.verdict) == ("chord", 950.0, "under")  # type: ignore[attr-defined]


def test_breaks_make_the_check_incomplete() -> None:
    c = _check(complete=False, fused_distance_m=1000.0)
    assert c.verdict == "incomplete"  # type: ignore[attr-defined]


def test_zero_matched_length_gives_no_ratio() -> None:
    c = _check(matched_length_m=0.0, fused_distance_m=5.0)
    assert math.isnan(c.relative_error)  # type: ignore[attr-defined]
    assert c.to_dict()["relative_error"] is None  # type: ignore[attr-defined]


def test_chord_length_sums_straight_lines() -> None:
    assert chord_length_m(np.array([0.0, 3.0, 3.0]), np.array([0.0, 4.0, 10.0])) == 11.0


def test_a_reported_distance_out_of_band_is_logged_a_chord_sum_is_not(
    caplog: pytest.LogCaptureFixture,
) -> None:
    with caplog.at_level(logging.WARNING, logger="mapmatch"):
        assert _check().verdict == "under"  # type: ignore[attr-defined]
        assert not caplog.records  # the chord cuts the curves: no meter to suspect
        assert _check(fused_distance_m=950.0).verdict == "under"  # type: ignore[attr-defined]
        assert _check(odometer_m=np.array([0.0, 1100.0])).verdict == "over"  # type: ignore[attr-defined]
    assert [r.getMessage().split(":")[0] for r in caplog.records] == ["trace 't'"] * 2
    assert "(caller)" in caplog.records[0].getMessage()
    assert "(odometer)" in caplog.records[1].getMessage()


def test_the_check_as_a_dict_has_every_member() -> None:
    c = _check(fused_distance_m=990.0)
    assert c.to_dict() == {  # type: ignore[attr-defined]
        **{f.name: getattr(c, f.name) for f in dataclasses.fields(c)},  # type: ignore[arg-type]
        "band": list(BAND),
    }


def test_an_outlier_at_an_end_leaves_the_span_complete_a_stretch_off_road_does_not() -> None:
    matched = np.array([False, True, True, True, False])
    outlier = np.array([True, False, False, False, True])
    odometer = np.arange(5) * 10.0
    span, complete, readings = measured_span(matched, outlier, 1, odometer)
    assert (span, complete, readings.tolist()) == (slice(1, 4), True, [10.0, 20.0, 30.0])
    assert measured_span(matched, outlier, 1, None)[:2] == (slice(None), False)  # caller's
    off_road = np.array([False, False, False, False, True])
    assert measured_span(matched, off_road, 1, odometer)[:2] == (slice(None), False)
    assert measured_span(matched, outlier, 2, odometer)[:2] == (slice(None), False)  # a break
    many = np.array([False] * (END_OUTLIERS + 1) + [True, True])
    assert measured_span(many, ~many, 1, np.arange(5.0))[:2] == (slice(None), False)
    whole = measured_span(np.ones(3, dtype=bool), np.zeros(3, dtype=bool), 1, None)
    assert whole == (slice(None), True, None)


def _span_as_numpy_finds_it(
    matched: np.ndarray, outlier: np.ndarray, segments: int, odometer: np.ndarray | None
) -> tuple[slice, bool]:
    """The span of the fixes the check compares, written with numpy (what the kernel must do)."""
    at = np.flatnonzero(matched)
    if segments != 1 or not len(at):
        return slice(None), False
    first, last = int(at[0]), int(at[-1])
    if first == 0 and last == len(matched) - 1:
        return slice(None), True
    head, tail = outlier[:first], outlier[last + 1 :]
    few = len(head) <= END_OUTLIERS and len(tail) <= END_OUTLIERS
    if few and head.all() and tail.all() and odometer is not None:
        return slice(first, last + 1), True
    return slice(None), False


def test_the_compiled_span_and_chord_agree_with_numpy_to_the_bit() -> None:
    rng = np.random.default_rng(51)
    for trial in range(400):
        n = int(rng.integers(0, 300)) if trial % 4 else int(rng.integers(0, 9))
        x, y = rng.normal(0, 500, n), rng.normal(0, 500, n)
        # chord: np.sum adds pairwise, so a plain running sum would differ in the last bit
        assert chord_length_m(x, y) == float(np.hypot(np.diff(x), np.diff(y)).sum())
        matched = rng.random(n) < rng.choice([0.5, 0.95, 1.0])
        outlier = ~matched & (rng.random(n) < 0.9)
        odometer = None if trial % 3 == 0 else np.arange(n) * 10.0
        segments = int(rng.choice([1, 1, 1, 2]))
        span, complete = _span_as_numpy_finds_it(matched, outlier, segments, odometer)
        got = measured_span(matched, outlier, segments, odometer)
        assert got[:2] == (span, complete)
        assert (got[2] is None) == (odometer is None)
        if odometer is not None:
            assert np.array_equal(got[2], odometer[span])
        together = measured_chord(matched, outlier, segments, odometer, x, y)
        chord = float(np.hypot(np.diff(x[span]), np.diff(y[span])).sum())
        assert together[0] == complete
        assert together[2] == chord
        assert (together[1] is None) == (odometer is None)
        if odometer is not None:
            assert np.array_equal(together[1], odometer[span])
