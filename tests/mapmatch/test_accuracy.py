"""The accuracy matrix's parts: conditions, column specs, overrides, cells and the CLI."""

from __future__ import annotations

import csv
import json
import math
from typing import TYPE_CHECKING

import pytest

from mapmatch.cli import main
from mapmatch.config import MatchConfig
from mapmatch.errors import ConfigError
from mapmatch.evaluation.accuracy import (
    CONDITIONS,
    TRUTH_SUBSETS,
    CellTask,
    acceptance,
    cells,
    columns_of,
    condition_config,
    default_extracts,
    matrix_markdown,
    parse_overrides,
    run_cell,
    truth_tasks,
)
from mapmatch.evaluation.simulate import INPUT_CLASSES, SimulationConfig

if TYPE_CHECKING:
    from pathlib import Path


def test_conditions_and_column_specs() -> None:
    assert set(CONDITIONS) == {"1s-5m", "15s-10m", "30s-20m", "realistic-1s", "realistic-15s"}
    real = condition_config("realistic-15s")
    assert (real.interval_s, real.noise_correlation_per_s, real.odometer_bias) == (15.0, 0.95, 0.02)
    truth = condition_config("truth-0.1s")
    assert (truth.interval_s, truth.noise_m, truth.speed_noise_mps) == (0.1, 0.0, 0.0)
    with pytest.raises(ConfigError, match="unknown condition"):
        condition_config("rainy")
    assert columns_of("positions") == ()
    assert columns_of("odometer") == INPUT_CLASSES["odometer"]
    assert columns_of("heading+odometer") == ("heading", "odometer")
    with pytest.raises(ConfigError, match="unknown input class or column"):
        columns_of("speed+lidar")
    assert len(TRUTH_SUBSETS) == 8
    assert {columns_of(s) for s in TRUTH_SUBSETS} >= {(), ("heading", "speed", "odometer")}


def test_overrides_are_typed_and_checked() -> None:
    overrides = parse_overrides(
        ["uturn_penalty=20", "use_travel=no", "max_candidates=8", "distance_band=-0.05,0.02"],
        MatchConfig(),
    )
    assert overrides == {
        "uturn_penalty": 20.0,
        "use_travel": False,
        "max_candidates": 8,
        "distance_band": (-0.05, 0.02),
    }
    assert parse_overrides(["canyon_s=5,15"], SimulationConfig()) == {"canyon_s": (5.0, 15.0)}
    with pytest.raises(ConfigError, match="unknown field 'uturn'"):
        parse_overrides(["uturn=20"], MatchConfig())
    with pytest.raises(ConfigError, match="must be key=value"):
        parse_overrides(["uturn_penalty"], MatchConfig())
    with pytest.raises(ConfigError, match="max_candidates takes int"):
        parse_overrides(["max_candidates=many"], MatchConfig())


def test_truth_tasks_cover_every_interval_and_subset(data_dir: Path) -> None:
    extracts = [data_dir / "west-oakland_us.osm.bz2", data_dir / "melbourne-suburb_au.osm.pbf"]
    tasks = truth_tasks(extracts, trips=2)
    assert len(tasks) == 2 * 5
    assert {t.condition for t in tasks} == {f"truth-{s}s" for s in ("0.1", "1", "5", "15", "30")}
    assert all(t.specs == TRUTH_SUBSETS for t in tasks)
    assert tasks[0].condition == "truth-0.1s"  # the heaviest first
    assert len(default_extracts(quick=True)) == 2


def test_a_cell_matches_the_same_trips_in_every_class(data_dir: Path) -> None:
    task = CellTask(
        str(data_dir / "west-oakland_us.osm.bz2"), "realistic-15s", ("positions", "odometer"), 3
    )
    rows = run_cell(task)
    assert [(r.index, r.input_class) for r in rows] == [
        (i, c) for i in range(3) for c in ("positions", "odometer")
    ]
    assert rows[0].trip_id == "west-oakland_us:realistic-15s:0"
    assert rows[0].points == rows[1].points  # one trip, two column sets
    for row in rows:
        assert row.score is not None, row.error
        assert row.score.true_length_m > 0
    plain, metered = rows[0].score, rows[1].score
    assert plain is not None
    assert metered is not None
    assert plain.distance_source == "chord"
    assert metered.distance_source == "odometer"
    assert metered.true_verdict == "over"  # the realistic odometer reads 2 % high
    pooled = cells(rows, per_extract=False)
    assert [(c.extract, c.input_class, c.trips) for c in pooled] == [
        ("all", "positions", 3),
        ("all", "odometer", 3),
    ]
    odometer = pooled[1]
    assert math.isnan(pooled[0].verdict_accuracy)  # no odometer, nothing to judge
    assert 0 <= odometer.within_1pct <= odometer.within_2pct <= 1
    table = matrix_markdown(pooled)
    assert "| realistic-15s | odometer | 3 | 0 |" in table
    rules = acceptance(cells(rows, per_extract=True))
    assert rules[0].startswith("- within 1 % on >= 95 %: ")


def test_cli_matrix_writes_json_and_rows(
    data_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out_json, out_rows = tmp_path / "m.json", tmp_path / "rows.csv"
    argv = [
        "bench", "--matrix", "--extract", str(data_dir / "west-oakland_us.osm.bz2"),
        "--conditions", "30s-20m", "--classes", "positions,heading_speed", "--trips", "2",
        "--workers", "1", "--config", "uturn_penalty=7", "--json", str(out_json),
        "--rows", str(out_rows), "--worst", "2",
    ]  # fmt: skip
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "| 30s-20m | positions | 2 |" in text
    assert "uturn_penalty" in text
    assert "Worst 2 trips" in text
    report = json.loads(out_json.read_text())
    assert len(report["cells"]) == 2
    assert len(report["trips"]) == 4
    with out_rows.open() as handle:
        rows = list(csv.DictReader(handle))
    assert {r["trip_id"] for r in rows} == {
        "west-oakland_us:30s-20m:0",
        "west-oakland_us:30s-20m:1",
    }
    assert {"length_error", "uturns", "loops", "spurious_uturns", "verdict"} <= set(rows[0])
    # one of those trips again, by its id
    assert main(["bench", "--inspect", "west-oakland_us:30s-20m:1", "--classes", "positions"]) == 0
    assert "west-oakland_us:30s-20m:1 | positions |" in capsys.readouterr().out
    assert main(["bench", "--matrix", "--config", "uturn=1"]) != 0
    assert "unknown field 'uturn'" in capsys.readouterr().err
