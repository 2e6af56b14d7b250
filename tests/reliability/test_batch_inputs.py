"""
Batch inputs and names that used to break ``mapmatch match`` (issue 14 items 6, 7, 10, 11).

Each case runs the real command line on real files in a temporary folder and checks the
outcome: no output written over another, no traceback, every trace accounted for.
"""

from __future__ import annotations

import csv
import io
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import pandas as pd
import pytest

from mapmatch.batch.outputs import SUMMARY_COLUMNS, read_summary
from mapmatch.cli import main as cli_main
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trips
from mapmatch.trace.chinacrs import wgs84_to_gcj02

if TYPE_CHECKING:
    import roadnets

SIM = SimulationConfig(interval_s=2.0, route_length_m=600.0, noise_m=4.0)


def _frame(trace: object, trace_id: str) -> pd.DataFrame:
    frame = trace.to_dataframe()  # type: ignore[attr-defined]
    frame.insert(0, "trace_id", trace_id)
    return frame


@pytest.fixture(scope="module")
def traces(default_net: roadnets.RoadNetwork) -> list[object]:
    return [t.trace for t in simulate_trips(default_net, SIM, count=4, seed=41)]


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = cli_main(["match", *argv])
    out, err = capsys.readouterr()
    return code, out, err


def _rows(out: Path) -> list[dict[str, str]]:
    with (out / "summary.csv").open(newline="", encoding="utf-8") as handle:
        return list(csv.DictReader(handle))


def test_a_trace_named_like_a_sidecar_writes_over_nothing(
    traces: list[object], cache_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    source = tmp_path / "in.csv"
    pd.concat(
        [_frame(traces[0], "x"), _frame(traces[1], "x.edges"), _frame(traces[2], "X.Segments")]
    ).to_csv(source, index=False)
    for fmt, ext in (("csv", "csv"), ("geoparquet", "parquet")):
        out = tmp_path / fmt
        argv = [str(source), "--out", str(out), "--format", fmt, "--workers", "1"]
        code, _, _ = _run([*argv, "--cache-dir", str(cache_dir), "--quiet"], capsys)
        assert code == 0
        rows = {r["trace_id"]: r for r in _rows(out)}
        assert {r["status"] for r in rows.values()} == {"ok"}
        names = {tid: r["output"] for tid, r in rows.items()}
        assert names == {"x": "x", "x.edges": "x.edges~2", "X.Segments": "X.Segments~2"}
        read = pd.read_csv if ext == "csv" else pd.read_parquet
        for tid, name in names.items():
            points = read(out / f"{name}.{ext}")
            edges = read(out / f"{name}.edges.{ext}")
            assert set(points["trace_id"]) == {tid}  # each file holds its own trace
            assert set(edges["trace_id"]) == {tid}
            assert len(points) == int(rows[tid]["points"])
        # and --resume trusts exactly those files
        code, stdout, _ = _run([*argv, "--cache-dir", str(cache_dir), "--resume"], capsys)
        assert code == 0
        assert "(3 from an earlier run)" in stdout


def test_a_file_name_that_is_not_utf8_is_read_and_reported(
    traces: list[object], cache_dir: Path, tmp_path: Path
) -> None:
    folder = tmp_path / "in"
    folder.mkdir()
    _frame(traces[0], "plain").to_csv(folder / "plain.csv", index=False)
    odd = os.path.join(os.fsencode(folder), b"caf\xe9-\xff.csv")
    _frame(traces[1].slice(0, 12), "ignored").drop(columns=["trace_id"]).to_csv(  # type: ignore[attr-defined]
        os.fsdecode(odd), index=False
    )
    out = tmp_path / "out"
    argv = [sys.executable, "-m", "mapmatch", "match", str(folder), "--out", str(out)]
    proc = subprocess.run(
        [*argv, "--cache-dir", str(cache_dir), "--workers", "1"],
        capture_output=True,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr.decode()
    assert b"Traceback" not in proc.stderr
    rows = {r["trace_id"]: r for r in _rows(out)}
    assert set(rows) == {"plain", "caf\\xe9-\\xff"}  # the bytes spelled out, not lost
    odd_row = rows["caf\\xe9-\\xff"]
    assert odd_row["status"] == "ok"
    assert odd_row["source"].endswith("caf\\xe9-\\xff.csv")
    assert (out / f"{odd_row['output']}.geojson").is_file()
    assert "2 ok, 0 failed, from 2 file(s)" in proc.stdout.decode()  # the summary printed


def test_an_output_folder_inside_the_input_folder_is_not_read_back(
    traces: list[object], cache_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "traces"
    folder.mkdir()
    _frame(traces[0], "a").to_csv(folder / "a.csv", index=False)
    _frame(traces[1], "b").to_csv(folder / "b.csv", index=False)
    base = [str(folder), "--format", "csv", "--workers", "1", "--cache-dir", str(cache_dir)]
    for _ in range(2):  # the second run finds the first run's CSV outputs in the folder
        code, stdout, _ = _run([*base, "--out", str(folder / "matched")], capsys)
        assert code == 0
        assert sorted(r["trace_id"] for r in _rows(folder / "matched")) == ["a", "b"]
    assert "skipped   5 file(s) in output folders" in stdout
    # another output folder in there is left out too (it holds run.json and summary.csv)
    code, stdout, _ = _run([*base, "--out", str(tmp_path / "elsewhere")], capsys)
    assert code == 0
    assert sorted(r["trace_id"] for r in _rows(tmp_path / "elsewhere")) == ["a", "b"]
    assert "skipped   5 file(s) in output folders" in stdout


def test_formula_like_trace_ids_are_defused_in_summary_csv(
    traces: list[object], cache_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    ids = ['=HYPERLINK("http://x")', "+1+1", "-2+3", "@SUM(A1)", "'quoted", "fine-id"]
    frames = [_frame(traces[i % len(traces)].slice(0, 15), tid) for i, tid in enumerate(ids)]  # type: ignore[attr-defined]
    source = tmp_path / "ids.csv"
    pd.concat(frames).to_csv(source, index=False)
    out = tmp_path / "out"
    argv = [str(source), "--out", str(out), "--workers", "1", "--cache-dir", str(cache_dir)]
    assert _run([*argv, "--quiet"], capsys)[0] == 0
    with (out / "summary.csv").open(newline="", encoding="utf-8") as handle:
        cells = [row[0] for row in csv.reader(handle)][1:]
    assert cells == [
        '\'=HYPERLINK("http://x")',
        "'+1+1",
        "'-2+3",
        "'@SUM(A1)",
        "''quoted",
        "fine-id",
    ]
    assert not any(c[0] in "=+-@" for c in cells)  # no cell a spreadsheet would evaluate
    assert [r.trace_id for r in read_summary(out / "summary.csv")] == ids  # read back as given
    code, stdout, _ = _run([*argv, "--resume"], capsys)
    assert code == 0
    assert "(6 from an earlier run)" in stdout


def test_unusable_output_folder_is_one_line_and_exit_2(
    traces: list[object], cache_dir: Path, tmp_path: Path
) -> None:
    source = tmp_path / "a.csv"
    _frame(traces[0], "a").to_csv(source, index=False)
    a_file = tmp_path / "a-file"
    a_file.write_text("not a folder")
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    # root may write into a folder of mode 0500; nobody may write files into /proc/<pid>
    no_write = locked if os.geteuid() != 0 else Path("/proc/self")
    cases = [
        (a_file, "cannot create the output folder", str(a_file)),
        (a_file / "below", "cannot create the output folder", str(a_file / "below")),
        (
            no_write,
            "cannot write into the output folder",
            "/proc/" if no_write != locked else str(locked),
        ),
    ]
    try:
        for out, expected, shown in cases:
            argv = [sys.executable, "-m", "mapmatch", "match", str(source), "--out", str(out)]
            proc = subprocess.run(
                [*argv, "--cache-dir", str(cache_dir), "--workers", "1"],
                capture_output=True,
                timeout=120,
                check=False,
            )
            err = proc.stderr.decode()
            assert proc.returncode == 2, err
            assert err.startswith(f"mapmatch: error: {expected} '{shown}"), err
            assert len(err.strip().splitlines()) == 1
            assert "Traceback" not in err
    finally:
        locked.chmod(0o700)


def test_errors_name_the_files_own_line(
    traces: list[object], cache_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    good, bad = _frame(traces[0], "good"), _frame(traces[1], "bad")
    bad.loc[4, "lat"] = 95.0
    source = tmp_path / "mixed.csv"
    pd.concat([good, bad]).to_csv(source, index=False)
    line = len(good) + 1 + 4 + 1  # header, the good trace, then the bad trace's fifth row
    out = tmp_path / "out"
    argv = [str(source), "--out", str(out), "--workers", "1", "--cache-dir", str(cache_dir)]
    assert _run([*argv, "--quiet"], capsys)[0] == 1
    rows = {r["trace_id"]: r for r in _rows(out)}
    assert rows["good"]["status"] == "ok"
    error = rows["bad"]["error"]
    assert error.startswith("InvalidTraceError: ")
    assert f"line {line}" in error, error
    assert "lat" in error
    assert "95" in error


def test_crs_flag_reads_gcj02_traces(
    traces: list[object], cache_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    frame = _frame(traces[0], "shifted")
    frame["lon"], frame["lat"] = wgs84_to_gcj02(frame["lon"].to_numpy(), frame["lat"].to_numpy())
    source = tmp_path / "gcj.csv"
    frame.to_csv(source, index=False)
    base = [str(source), "--workers", "1", "--cache-dir", str(cache_dir), "--quiet"]
    assert _run([*base, "--out", str(tmp_path / "wgs")], capsys)[0] == 0
    assert _run([*base, "--out", str(tmp_path / "gcj"), "--crs", "gcj02"], capsys)[0] == 0
    as_wgs = json.loads((tmp_path / "wgs" / "shifted.geojson").read_text())
    as_gcj = json.loads((tmp_path / "gcj" / "shifted.geojson").read_text())
    # Monaco is outside China, where GCJ-02 is WGS84: the same match either way
    assert as_gcj["matched_length_m"] == as_wgs["matched_length_m"]
    manifest = json.loads((tmp_path / "gcj" / "run.json").read_text())
    assert manifest["fingerprint"]["crs"] == "gcj02"
    code, _, err = _run(
        [*base, "--out", str(tmp_path / "gcj"), "--resume"], capsys
    )  # resumed with another frame: refused
    assert code == 2
    assert "written with another crs" in err


def test_summary_header_is_unchanged() -> None:
    text = io.StringIO(",".join(SUMMARY_COLUMNS))
    assert next(csv.reader(text))[:5] == ["trace_id", "source", "index", "output", "status"]


def test_a_reader_that_leaves_early_gets_no_traceback(cache_dir: Path) -> None:
    # `mapmatch network info --json | head -c 1`: stdout's reader is gone before we write
    argv = [sys.executable, "-m", "mapmatch", "network", "info", "--cache-dir", str(cache_dir)]
    with subprocess.Popen(
        [*argv, "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE
    ) as proc:
        assert proc.stdout is not None
        assert proc.stderr is not None
        proc.stdout.close()
        err = proc.stderr.read().decode()
        assert proc.wait(timeout=120) == 141, err
    assert "Traceback" not in err, err
    assert "BrokenPipe" not in err, err
