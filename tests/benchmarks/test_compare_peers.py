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


_FAKE_RUNNER = """
import sys, time
sys.path.insert(0, {peers!r})
from common import run_peer

NAME = {name!r}
SEEN = []


def load(job):
    return {{"log": job["params"]["log"]}}


def match(ctx, trace):
    if trace.trace_id == "t1":  # once a pass (and at the warm-up): which runner
        with open(ctx["log"], "a") as log:
            log.write(NAME + "\\n")
        SEEN.append(NAME)
        if NAME == "broken" and len(SEEN) == 3:  # dies in its second timed pass
            raise SystemExit(3)
    return trace


def geometry(ctx, trace, raw):
    return [[[lon, lat] for lon, lat in zip(raw.lon, raw.lat)]]


raise SystemExit(run_peer(NAME, load, match, geometry))
"""


def _fake_jobs(tmp_path: Path, names: list[str], repeats: int) -> tuple[list[object], Path]:
    """Jobs of runners that note each pass in one shared log, on a two-trace file."""
    import sys

    traces = tmp_path / "traces.csv"
    traces.write_text(
        "trace_id,time,lon,lat\nt1,0,7.0,43.0\nt1,1,7.001,43.0\nt2,0,7.0,43.1\nt2,1,7.0,43.101\n"
    )
    log = tmp_path / "passes.log"
    jobs = []
    for name in names:
        script = tmp_path / f"run_{name}.py"
        script.write_text(_FAKE_RUNNER.format(peers=str(cp.PEERS_DIR), name=name))
        peer = cp.Peer(name, name, cp.Path(sys.executable), script, False)
        work = tmp_path / "runs" / name
        jobs.append(cp.Job(peer, tmp_path, traces, {"log": str(log)}, repeats, 0.0, work))
    return jobs, log


def test_peers_in_turns_take_one_pass_each_round(tmp_path: Path) -> None:
    jobs, log = _fake_jobs(tmp_path, ["a", "b"], repeats=3)
    outcomes = cp.run_jobs_in_turns(jobs, 60.0)
    # the warm-up trace (t1 of each, alone after its load), then the passes alternating
    assert log.read_text().split() == ["a", "b"] + ["a", "b"] * 3
    for (res, err, _), name in zip(outcomes, ["a", "b"], strict=True):
        assert err is None
        assert res is not None
        assert res["peer"] == name
        assert len(res["match_s_runs"]) == 3
        assert [r["trace_id"] for r in res["results"]] == ["t1", "t2"]


def test_peers_back_to_back_run_their_passes_in_one_block(tmp_path: Path) -> None:
    jobs, log = _fake_jobs(tmp_path, ["a", "b"], repeats=2)
    outcomes = [cp.run_job(job, 60.0) for job in jobs]
    assert log.read_text().split() == ["a"] * 3 + ["b"] * 3
    assert all(err is None for _, err, _ in outcomes)


def test_a_runner_that_dies_in_turns_fails_alone(tmp_path: Path) -> None:
    jobs, log = _fake_jobs(tmp_path, ["a", "broken"], repeats=2)
    (res_a, err_a, _), (res_b, err_b, _) = cp.run_jobs_in_turns(jobs, 60.0)
    assert err_a is None
    assert res_a is not None
    assert len(res_a["match_s_runs"]) == 2
    assert res_b is None
    assert err_b is not None
    assert "no answer to pass 2" in err_b
    assert log.read_text().split() == ["a", "broken", "a", "broken", "a", "broken"]
