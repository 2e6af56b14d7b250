"""Tests of the peer benchmark's pieces that need no peer: inputs, scoring of results, tables."""

from __future__ import annotations

import csv
import math
from typing import TYPE_CHECKING

import numpy as np
import pytest

from tests.benchmarks.scripts import load_script

if TYPE_CHECKING:
    from pathlib import Path

cp = load_script("compare_peers.py")

PROJ = cp.scoring.LocalProjection(7.42, 43.73)


def lonlat(xy: list[tuple[float, float]]) -> list[list[float]]:
    out: list[list[float]] = PROJ.to_lonlat(np.asarray(xy, dtype=float)).tolist()
    return out


ROUTE = [(0.0, 0.0), (500.0, 0.0), (500.0, 300.0)]  # 800 m


def test_positions_only_copy_keeps_rows_and_drops_the_other_columns(tmp_path: Path) -> None:
    full = tmp_path / "traces.csv"
    full.write_text(
        "trace_id,time,lon,lat,heading,speed,accuracy,odometer\n"
        "a,0,7.42,43.73,90,10,5,0\n"
        "a,1,7.4201,43.73,91,10,5,10\n"
        "b,0,7.43,43.74,,,,\n"
    )
    out = tmp_path / "positions.csv"
    rows, columns = cp.write_positions_only(full, out)
    assert rows == 3
    assert columns == ["trace_id", "time", "lon", "lat", "heading", "speed", "accuracy", "odometer"]
    with out.open(newline="") as f:
        got = list(csv.reader(f))
    assert got == [
        ["trace_id", "time", "lon", "lat"],
        ["a", "0", "7.42", "43.73"],
        ["a", "1", "7.4201", "43.73"],
        ["b", "0", "7.43", "43.74"],
    ]


def test_positions_only_copy_names_a_missing_column(tmp_path: Path) -> None:
    full = tmp_path / "traces.csv"
    full.write_text("trace_id,time,x,y\na,0,1,2\n")
    with pytest.raises(SystemExit, match="no column 'lon'"):
        cp.write_positions_only(full, tmp_path / "positions.csv")


def test_length_error_and_failures_are_scored() -> None:
    truth = {"exact": lonlat(ROUTE), "long": lonlat(ROUTE), "failed": lonlat(ROUTE)}
    longer = [*ROUTE, (500.0, 320.0)]  # 20 m past the end: +2.5 %
    result = {
        "results": [
            {"trace_id": "exact", "geometry": [lonlat(ROUTE)], "error": None},
            {"trace_id": "long", "geometry": [lonlat(longer)], "error": None},
            {"trace_id": "failed", "geometry": [], "error": "RuntimeError: no candidates"},
        ]
    }
    acc = cp.score_result(truth, result)
    assert acc.failed == 1
    errs = {t["trace_id"]: t["length_err"] for t in acc.per_trace}
    assert errs["exact"] == pytest.approx(0.0, abs=1e-3)
    assert errs["long"] == pytest.approx(0.025, abs=2e-3)
    assert errs["failed"] == pytest.approx(-1.0)
    assert acc.within_1pct == pytest.approx(1 / 3)
    assert acc.length_err_mean == pytest.approx((0.025 - 1.0) / 3, abs=2e-3)
    assert acc.length_abs_err_mean == pytest.approx((0.025 + 1.0) / 3, abs=2e-3)


def test_a_trace_missing_from_the_result_counts_as_failed() -> None:
    acc = cp.score_result({"x": lonlat(ROUTE)}, {"results": []})
    assert acc.failed == 1
    assert acc.per_trace[0]["error"] == "missing"
    assert acc.summary.mismatch_mean == pytest.approx(1.0)


def _row(
    peer: str, pps: float, ratio: float, mismatch: float, lerr: float, within: float
) -> object:
    return cp.Row(
        "monaco_2020",
        peer,
        15.0,
        10.0,
        "positions",
        20,
        points=500,
        points_per_s=pps,
        cpu_points_per_s=pps,
        ours_ratio=ratio,
        ours_cpu_ratio=ratio * 1.1,
        mismatch_mean=mismatch,
        length_err_mean=lerr,
        within_1pct=within,
    )


def test_summary_puts_ratios_and_every_peers_accuracy_on_one_line() -> None:
    rows = [
        _row("ours", 2000.0, 1.0, 0.01, 0.002, 0.95),
        _row("fmm", 4000.0, 0.5, 0.25, 0.2, 0.0),
        cp.Row("monaco_2020", "fmm-drop", 15.0, 10.0, "positions", 20, error="exit 1: boom"),
        _row("valhalla", 1000.0, 2.0, 0.02, -0.01, 0.8),
    ]
    table = cp.summary_markdown(rows, ["fmm", "fmm-drop", "valhalla"])
    line = table.strip().splitlines()[-1]
    assert line.startswith(
        "| monaco_2020 | 15 s / 10 m | positions | 2,000 | 0.50 (0.55) | - | 2.00 (2.20) |"
    )
    assert "| 1.0 / 25.0 / - / 2.0 |" in line
    assert "| +0.2 / +20.0 / - / -1.0 |" in line
    assert "| 95 / 0 / - / 80 |" in line
    detail = cp.detail_markdown(rows)
    assert "(failed: exit 1: boom)" in detail


def test_quick_fills_only_what_was_not_given() -> None:
    a = cp.parse_args(["--quick", "--traces", "3"])
    assert a.traces == 3
    assert a.sets == cp.QUICK["sets"]
    assert a.extract == cp.QUICK["extract"]
    b = cp.parse_args([])
    assert b.extract == list(cp.DEFAULT_EXTRACTS)
    assert (b.repeats, b.min_time, b.traces, b.sets) == (3, 1.0, 20, cp.DEFAULT_SETS)
    assert a.min_time == 0.0


def test_json_is_strict() -> None:
    cleaned = cp._json_clean({"a": math.nan, "b": [1.0, math.inf], "c": "x"})
    assert cleaned == {"a": None, "b": [1.0, None], "c": "x"}
