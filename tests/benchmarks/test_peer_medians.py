"""The per-row medians of several peer runs (benchmarks/peer_medians.py), on rows made here."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

from tests.benchmarks.scripts import load_script

if TYPE_CHECKING:
    from pathlib import Path

pm = load_script("peer_medians.py")


def row(
    peer: str, ratio: float | None, mismatch: float = 0.01, interval: float = 15.0
) -> dict[str, Any]:
    return {
        "extract": "krems",
        "interval_s": interval,
        "input": "positions",
        "peer": peer,
        "ours_cpu_ratio": ratio,
        "mismatch_mean": mismatch,
        "length_err_mean": 0.0,
        "within_1pct": 1.0,
        "failed": 0,
    }


def run(tmp_path: Path, name: str, rows: list[dict[str, Any]]) -> Path:
    folder = tmp_path / name
    folder.mkdir()
    (folder / "peers.json").write_text(json.dumps({"rows": rows}))
    return folder


def test_median_of_the_runs_marks_rows_below_the_target(tmp_path: Path, capsys: Any) -> None:
    runs = [
        run(tmp_path, "a", [row("ours", 1.0), row("fmm", 1.2), row("valhalla", 2.5)]),
        run(tmp_path, "b", [row("ours", 1.0), row("fmm", 1.7), row("valhalla", 1.9)]),
        run(tmp_path, "c", [row("ours", 1.0), row("fmm", 1.4), row("valhalla", 2.1)]),
    ]
    assert pm.main([str(r) for r in runs]) == 0
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if x.startswith("| krems"))
    assert "| 1.20 / 1.70 / 1.40 | 1.40 * |" in line  # median 1.40 < 1.5
    assert "| 2.50 / 1.90 / 2.10 | 2.10 |" in line  # median 2.10 >= 2
    assert "the same in every run" in out


def test_a_missing_row_and_a_changed_accuracy_are_shown(tmp_path: Path) -> None:
    first = [row("ours", 1.0), row("fmm", 1.6)]
    second = [row("ours", 1.0, mismatch=0.02)]  # FMM missing, our mismatch changed
    table = pm.ratios([first, second], ["fmm"])
    assert table[("krems", 15.0, "positions")]["fmm"] == [1.6, None]
    text = pm.median_table(table, {"fmm": 1.5}, ["a", "b"])
    assert "| 1.60 / - | 1.60 |" in text
    assert pm.accuracy_changes([first, second]) == ["krems 15 s positions mismatch_mean"]


def test_a_target_is_peer_equals_ratio() -> None:
    assert pm.parse_target("fmm=1.5") == ("fmm", 1.5)
