from __future__ import annotations

import dataclasses
import logging
import math

import numpy as np
import pytest

from mapmatch.distance import END_OUTLIERS, check_distance, chord_length_m, measured_span

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
