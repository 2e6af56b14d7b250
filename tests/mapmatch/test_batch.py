"""Batch matching end to end: real trace files in, real output files and summary.csv out."""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import signal
import subprocess
import sys
import time
from datetime import UTC, datetime
from typing import TYPE_CHECKING

import pandas as pd
import pytest

from mapmatch.batch.outputs import SUMMARY_COLUMNS, read_summary
from mapmatch.cli import main as cli_main
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trips

if TYPE_CHECKING:
    from pathlib import Path

    import roadnets
    from mapmatch import Trace

SIM = SimulationConfig(interval_s=2.0, route_length_m=700.0, noise_m=4.0)
OK_TRACES = {"csv-a", "csv-b", "gpx-trip", "geo-trip", "pq-trip", "good-after-bad"}


def _frame(trace: Trace, trace_id: str) -> pd.DataFrame:
    frame = trace.to_dataframe()
    frame.insert(0, "trace_id", trace_id)
    return frame


def _iso(t_s: float) -> str:
    return datetime.fromtimestamp(t_s, tz=UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def _write_gpx(path: Path, trace: Trace, name: str) -> None:
    pts = "\n".join(
        f'<trkpt lat="{lat:.7f}" lon="{lon:.7f}"><time>{_iso(t)}</time></trkpt>'
        for t, lon, lat in zip(trace.time_s, trace.lon, trace.lat, strict=True)
    )
    path.write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        '<gpx version="1.1" creator="test" xmlns="http://www.topografix.com/GPX/1/1">\n'
        f"<trk><name>{name}</name><trkseg>\n{pts}\n</trkseg></trk></gpx>\n",
        encoding="utf-8",
    )


def _write_geojson(path: Path, trace: Trace, trace_id: str) -> None:
    features = [
        {
            "type": "Feature",
            "geometry": {"type": "Point", "coordinates": [float(lon), float(lat)]},
            "properties": {"trace_id": trace_id, "time": _iso(t)},
        }
        for t, lon, lat in zip(trace.time_s, trace.lon, trace.lat, strict=True)
    ]
    path.write_text(json.dumps({"type": "FeatureCollection", "features": features}))


@pytest.fixture(scope="module")
def mixed_folder(
    tmp_path_factory: pytest.TempPathFactory, default_net: roadnets.RoadNetwork
) -> Path:
    """CSV with two traces, GPX, GeoJSON, Parquet, a corrupt GPX, an off-map and a bad trace."""
    folder = tmp_path_factory.mktemp("mixed")
    trips = [t.trace for t in simulate_trips(default_net, SIM, count=6, seed=11)]
    pd.concat([_frame(trips[0], "csv-a"), _frame(trips[1], "csv-b")]).to_csv(
        folder / "a_two.csv", index=False
    )
    (folder / "sub").mkdir()
    _write_gpx(folder / "sub" / "b.gpx", trips[2], "gpx-trip")
    _write_geojson(folder / "c.geojson", trips[3], "geo-trip")
    _frame(trips[4], "pq-trip").to_parquet(folder / "d.parquet", index=False)
    (folder / "broken.gpx").write_text('<?xml version="1.0"?><gpx><trk><trkseg><trkpt lat="43')
    paris = _frame(trips[5], "offmap")
    paris["lon"] += 2.35 - 7.42  # the same drive, shifted to Paris: no road of Monaco near
    paris["lat"] += 48.85 - 43.73
    paris.to_csv(folder / "offmap.csv", index=False)
    bad = _frame(trips[0], "bad-lat")
    bad.loc[3, "lat"] = 95.0
    pd.concat([bad, _frame(trips[1], "good-after-bad")]).to_csv(
        folder / "e_bad_then_good.csv", index=False
    )
    (folder / "notes.txt").write_text("not a trace; folders only pick trace suffixes")
    return folder


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = cli_main(["match", *argv])
    out, err = capsys.readouterr()
    return code, out, err


def _summary(out_dir: Path) -> dict[str, dict[str, str]]:
    with (out_dir / "summary.csv").open(newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    return {r["trace_id"] or r["source"]: r for r in rows}


def _normalised(path: Path) -> object:
    """An output's content without wall-clock timings (the only part that may differ)."""
    if path.suffix == ".geojson":
        data = json.loads(path.read_text())
        data["stats"].pop("timings_s")
        return data
    return path.read_bytes()


def _outputs(out_dir: Path) -> dict[str, object]:
    return {
        p.name: _normalised(p)
        for p in sorted(out_dir.iterdir())
        if p.is_file() and p.name not in {"summary.csv", "run.json"}
    }


def _summary_without_seconds(out_dir: Path) -> list[dict[str, str]]:
    with (out_dir / "summary.csv").open(newline="", encoding="utf-8") as handle:
        return [{k: v for k, v in r.items() if k != "seconds"} for r in csv.DictReader(handle)]


@pytest.fixture(scope="module")
def geojson_run(
    mixed_folder: Path,
    cache_dir: Path,
    tmp_path_factory: pytest.TempPathFactory,
) -> tuple[Path, int, str]:
    out = tmp_path_factory.mktemp("geojson-out")
    argv = [str(mixed_folder), "--out", str(out), "--cache-dir", str(cache_dir), "--workers", "1"]
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = cli_main(["match", *argv])
    return out, code, buf.getvalue()


def test_mixed_folder_records_each_trace_and_goes_on_past_failures(
    geojson_run: tuple[Path, int, str], mixed_folder: Path
) -> None:
    out, code, stdout = geojson_run
    assert code == 1  # some traces failed
    rows = _summary(out)
    assert {k for k, r in rows.items() if r["status"] == "ok"} == OK_TRACES
    order = list(rows)
    broken_source = next(k for k in order if k.endswith("broken.gpx"))
    assert order == [  # input order: files of the folder sorted by path, traces as in the file
        "csv-a",
        "csv-b",
        broken_source,
        "geo-trip",
        "pq-trip",
        "bad-lat",
        "good-after-bad",
        "offmap",
        "gpx-trip",
    ]
    broken = next(r for r in rows.values() if r["source"].endswith("broken.gpx"))
    assert broken["status"] == "failed"
    assert broken["trace_id"] == ""
    assert broken["error"].startswith("TraceFileError: ")
    assert "broken.gpx" in broken["error"]
    assert rows["offmap"]["error"] == (
        "NoCandidatesError: trace 'offmap': no road within 50 m of any fix; swapped lon/lat?"
    )
    assert int(rows["offmap"]["points"]) == len(pd.read_csv(mixed_folder / "offmap.csv"))
    assert rows["bad-lat"]["error"].startswith("InvalidTraceError: ")
    assert "95" in rows["bad-lat"]["error"]
    assert "lat" in rows["bad-lat"]["error"]
    for tid in OK_TRACES:
        assert rows[tid]["error"] == ""
        assert rows[tid]["verdict"] in {"pass", "over", "under", "incomplete"}
        assert int(rows[tid]["matched_points"]) > 0.9 * int(rows[tid]["points"])
        assert 300 < float(rows[tid]["matched_length_m"]) < 1500
    produced = {p.name for p in out.iterdir()}
    assert produced == {f"{t}.geojson" for t in OK_TRACES} | {"summary.csv", "run.json"}
    assert "6 ok, 3 failed, from 7 file(s)" in stdout
    assert "offmap" in stdout
    assert f"output    {out}" in stdout


def test_summary_columns_and_sources(
    geojson_run: tuple[Path, int, str], mixed_folder: Path
) -> None:
    out, _, _ = geojson_run
    with (out / "summary.csv").open(newline="") as handle:
        header = next(csv.reader(handle))
    assert tuple(header) == SUMMARY_COLUMNS
    rows = _summary(out)
    assert rows["gpx-trip"]["source"] == str(mixed_folder / "sub" / "b.gpx")
    assert rows["csv-b"]["index"] == "1"
    assert rows["good-after-bad"]["source"].endswith("e_bad_then_good.csv")


def test_geojson_outputs_follow_the_design_schema(geojson_run: tuple[Path, int, str]) -> None:
    out, _, _ = geojson_run
    rows = _summary(out)
    doc = json.loads((out / "gpx-trip.geojson").read_text())
    assert doc["type"] == "FeatureCollection"
    assert {"trace_id", "network", "matched_length_m", "distance_check", "breaks", "stats"} <= set(
        doc
    )
    assert doc["trace_id"] == "gpx-trip"
    assert doc["network"]["id"] == "monaco_2020"
    assert doc["matched_length_m"] == pytest.approx(float(rows["gpx-trip"]["matched_length_m"]))
    assert doc["distance_check"]["verdict"] == rows["gpx-trip"]["verdict"]
    kinds = [f["properties"]["kind"] for f in doc["features"]]
    assert kinds.count("point") == int(rows["gpx-trip"]["points"])
    segment = next(f for f in doc["features"] if f["properties"]["kind"] == "segment")
    assert segment["geometry"]["type"] == "LineString"
    assert {"segment", "point_range", "length_m", "edges"} <= set(segment["properties"])
    assert {
        "u",
        "v",
        "key",
        "osm_way_ids",
        "length_m",
        "start_offset_m",
        "end_offset_m",
        "name",
        "road_class",
        "speed_limit_kph",
        "entry_time",
        "exit_time",
        "duration_s",
        "mean_speed_kph",
    } == set(segment["properties"]["edges"][0])
    point = next(f for f in doc["features"] if f["properties"]["kind"] == "point")
    assert {
        "index",
        "time",
        "matched",
        "u",
        "v",
        "key",
        "offset_m",
        "distance_m",
        "confidence",
        "segment",
        "edge_index",
        "along_m",
    } <= (set(point["properties"]))


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_tables_with_edge_sidecar(
    fmt: str,
    mixed_folder: Path,
    cache_dir: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    source = mixed_folder / "a_two.csv"
    code, _, _ = _run(
        [
            str(source),
            "--out",
            str(tmp_path),
            "--format",
            fmt,
            "--cache-dir",
            str(cache_dir),
            "--workers",
            "1",
            "--sigma-m",
            "6",
            "--beta-m",
            "4",
            "--search-radius-m",
            "60",
        ],
        capsys,
    )
    assert code == 0
    read = pd.read_csv if fmt == "csv" else pd.read_parquet
    rows = _summary(tmp_path)
    for tid in ("csv-a", "csv-b"):
        points = read(tmp_path / f"{tid}.{fmt}")
        edges = read(tmp_path / f"{tid}.edges.{fmt}")
        assert list(points.columns[:4]) == ["trace_id", "index", "time", "raw_lon"]
        assert len(points) == int(rows[tid]["points"])
        assert int(points["matched"].sum()) == int(rows[tid]["matched_points"])
        assert set(edges["trace_id"]) == {tid}
        driven = (edges["end_offset_m"] - edges["start_offset_m"]).sum()
        assert driven == pytest.approx(float(rows[tid]["matched_length_m"]), rel=1e-6)
    run = json.loads((tmp_path / "run.json").read_text())
    assert run["fingerprint"]["config"]["sigma_m"] == 6.0
    assert run["fingerprint"]["config"]["beta_m"] == 4.0
    assert run["fingerprint"]["config"]["search_radius_m"] == 60.0


def test_stdin_pipe_names_outputs_by_trace_id(
    mixed_folder: Path, cache_dir: Path, tmp_path: Path
) -> None:
    data = (mixed_folder / "a_two.csv").read_bytes()
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "mapmatch",
            "match",
            "-",
            "--out",
            str(tmp_path),
            "--cache-dir",
            str(cache_dir),
            "--workers",
            "1",
            "--format",
            "geojson",
        ],
        input=data,
        capture_output=True,
        timeout=60,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr.decode()
    assert proc.stderr == b""  # no progress bar when stderr is not a terminal
    rows = _summary(tmp_path)
    assert {r["source"] for r in rows.values()} == {"-"}
    assert (tmp_path / "csv-a.geojson").is_file()
    assert (tmp_path / "csv-b.geojson").is_file()


def test_usage_errors_exit_2(
    cache_dir: Path, tmp_path: Path, mixed_folder: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, _, err = _run([str(tmp_path / "nope.csv"), "--out", str(tmp_path / "o")], capsys)
    assert code == 2
    assert "nope.csv' does not exist" in err
    code, _, err = _run(
        [
            str(mixed_folder / "a_two.csv"),
            "--out",
            str(tmp_path / "o"),
            "--sigma-m",
            "-1",
            "--cache-dir",
            str(cache_dir),
        ],
        capsys,
    )
    assert code == 2
    assert "sigma_m must be > 0 (got -1)" in err
    with pytest.raises(SystemExit) as exc:
        cli_main(["match", str(mixed_folder), "--out", str(tmp_path), "--workers", "0"])
    assert exc.value.code == 2
    assert "--workers: must be a whole number >= 1" in capsys.readouterr().err


def test_resume_skips_complete_traces_and_redoes_missing_ones(
    mixed_folder: Path, cache_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [str(mixed_folder / "a_two.csv"), str(mixed_folder / "offmap.csv"), "--out"]
    argv += [str(tmp_path), "--cache-dir", str(cache_dir), "--workers", "1", "--format", "csv"]
    assert _run(argv, capsys)[0] == 1
    kept = (tmp_path / "csv-a.csv").stat().st_mtime_ns
    (tmp_path / "csv-b.csv").unlink()  # as if the run had died before writing it
    code, out, _ = _run([*argv, "--resume"], capsys)
    assert code == 1  # the off-map trace is tried again and fails again
    assert "(1 from an earlier run)" in out
    assert (tmp_path / "csv-a.csv").stat().st_mtime_ns == kept
    assert (tmp_path / "csv-b.csv").is_file()
    rows = _summary(tmp_path)
    assert [rows[t]["status"] for t in ("csv-a", "csv-b", "offmap")] == ["ok", "ok", "failed"]

    code, _, err = _run([*argv, "--resume", "--sigma-m", "9"], capsys)
    assert code == 2
    assert "written with another config" in err


def test_read_summary_drops_a_torn_last_line(tmp_path: Path) -> None:
    path = tmp_path / "summary.csv"
    header = ",".join(SUMMARY_COLUMNS)
    whole = "t1,a.csv,0,t1,ok,10,10,0,100.5,101,0.00497,pass,ok,10,0,0,0,0,,0.1,"
    path.write_text(f"{header}\n{whole}\n{whole.replace('t1', 't2')[:20]}")
    rows = read_summary(path)
    assert [r.trace_id for r in rows] == ["t1"]
    assert rows[0].matched_length_m == 100.5


@pytest.fixture(scope="module")
def many_traces(
    tmp_path_factory: pytest.TempPathFactory, default_net: roadnets.RoadNetwork
) -> Path:
    folder = tmp_path_factory.mktemp("many")
    cfg = SimulationConfig(interval_s=1.0, route_length_m=1500.0, noise_m=4.0)
    trips = simulate_trips(default_net, cfg, count=120, seed=5)
    frames = [_frame(t.trace, t.trace.trace_id) for t in trips]
    pd.concat(frames[:60]).to_csv(folder / "first.csv", index=False)
    pd.concat(frames[60:]).to_csv(folder / "second.csv", index=False)
    return folder


@pytest.fixture(scope="module")
def reference_run(
    many_traces: Path, cache_dir: Path, tmp_path_factory: pytest.TempPathFactory
) -> Path:
    """An uninterrupted in-process run that the other executors must reproduce."""
    out = tmp_path_factory.mktemp("reference")
    argv = [str(many_traces), "--out", str(out), "--format", "csv", "--workers", "1"]
    assert cli_main(["match", *argv, "--cache-dir", str(cache_dir), "--quiet"]) == 0
    return out


def test_sigkill_then_resume_gives_the_uninterrupted_outputs(
    many_traces: Path, cache_dir: Path, reference_run: Path, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    argv = [sys.executable, "-m", "mapmatch", "match", str(many_traces), "--out", str(out)]
    argv += ["--format", "csv", "--cache-dir", str(cache_dir), "--quiet"]
    proc = subprocess.Popen(
        [*argv, "--workers", "2", "--chunk-traces", "2"],
        start_new_session=True,  # its own process group: the kill takes its workers too
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 60
    try:
        while time.monotonic() < deadline and proc.poll() is None:
            if out.is_dir() and len(list(out.glob("trip-*.edges.csv"))) >= 4:
                break
            time.sleep(0.005)
        still_running = proc.poll() is None
        os.killpg(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    assert still_running, "the run finished before it could be killed; give it more traces"
    finished = [p for p in out.glob("trip-*.csv") if not p.name.endswith(".edges.csv")]
    assert 0 < len(finished) < 120

    resumed = subprocess.run([*argv, "--resume"], capture_output=True, timeout=120, check=False)
    assert resumed.returncode == 0, resumed.stderr.decode()
    assert not list(out.glob(".tmp-*"))
    assert _outputs(out) == _outputs(reference_run)
    assert _summary_without_seconds(out) == _summary_without_seconds(reference_run)


def test_dask_cluster_gives_the_local_outputs(
    many_traces: Path,
    cache_dir: Path,
    reference_run: Path,
    dask_cluster: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    argv = [str(many_traces), "--out", str(tmp_path), "--format", "csv"]
    code, out, _ = _run([*argv, "--cache-dir", str(cache_dir), "--scheduler", dask_cluster], capsys)
    assert code == 0
    assert f"dask {dask_cluster} (2 workers, 2 threads)" in out
    assert _outputs(tmp_path) == _outputs(reference_run)
    assert _summary_without_seconds(tmp_path) == _summary_without_seconds(reference_run)


def test_unreachable_scheduler_is_a_usage_error(
    many_traces: Path, cache_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [str(many_traces), "--out", str(tmp_path), "--cache-dir", str(cache_dir)]
    code, _, err = _run(
        [*argv, "--scheduler", "tcp://127.0.0.1:9", "--scheduler-timeout-s", "1"], capsys
    )
    assert code == 2
    assert "cannot reach the Dask scheduler at 'tcp://127.0.0.1:9'" in err


# --------------------------------------------------------------------------- issue 12


def test_issue_12_fleet_file_is_split_and_every_count_reaches_summary_csv(
    data_dir: Path, cache_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "in"
    folder.mkdir()
    traces = data_dir / "traces"
    for name in ("fleet_interleaved.csv", "box.nmea", "no_time.gpx"):
        (folder / name).write_bytes((traces / name).read_bytes())
    out = tmp_path / "out"
    network = str(data_dir / "west-oakland_us.osm.bz2")
    argv = [str(folder), "--out", str(out), "--network", network, "--cache-dir", str(cache_dir)]
    code, stdout, _ = _run([*argv, "--workers", "1"], capsys)
    rows = _summary(out)
    assert set(rows) == {"bus-12", "van-7", "box", "8th Street, no times"}, rows
    assert code == 0, [r["error"] for r in rows.values()]
    bus, van, box, plan = rows["bus-12"], rows["van-7"], rows["box"], rows["8th Street, no times"]
    assert (bus["points"], bus["input_rows"], van["points"]) == ("60", "60", "60")
    assert (bus["index"], van["index"]) == ("0", "1")
    for row in (bus, van):
        assert (row["reordered_rows"], row["merged_rows"], row["dropped_rows"]) == ("0", "0", "0")
        assert (row["time"], row["warnings"]) == ("ok", "")
    assert (box["dropped_rows"], box["input_rows"], box["time"]) == ("3", "29", "ok")
    assert box["warnings"].split(" | ")[0] == (
        "1 NMEA sentence with a wrong checksum was dropped (line 21)"
    )
    assert (plan["time"], plan["points"]) == ("absent", "21")
    assert plan["warnings"].startswith("the trace has no times")
    assert "rows      170 read: 0 reordered, 0 merged (true duplicates), 3 dropped;" in stdout
    assert "times     ok 3, absent 1 (1 matched by distance only)" in stdout
    assert "warnings  2 trace(s) with warnings (see summary.csv)" in stdout


def test_issue_12_id_column_flag_groups_by_another_column(
    data_dir: Path, cache_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    frame = pd.read_csv(data_dir / "traces" / "fleet_interleaved.csv")
    frame["driver"] = frame["vehicle_id"].map({"bus-12": "ana", "van-7": "bo"})
    source = tmp_path / "drivers.csv"
    frame.drop(columns=["vehicle_id"]).to_csv(source, index=False)
    network = str(data_dir / "west-oakland_us.osm.bz2")
    base = [str(source), "--network", network, "--cache-dir", str(cache_dir), "--workers", "1"]
    _run([*base, "--out", str(tmp_path / "one"), "--quiet"], capsys)
    (alone,) = _summary(tmp_path / "one").values()
    assert (alone["trace_id"], alone["points"]) == ("drivers", "120")  # one trace, both cars
    code, _, _ = _run([*base, "--out", str(tmp_path / "two"), "--id-column", "driver"], capsys)
    rows = _summary(tmp_path / "two")
    assert code == 0
    assert {k: r["points"] for k, r in rows.items()} == {"ana": "60", "bo": "60"}
    run = json.loads((tmp_path / "two" / "run.json").read_text())
    assert run["fingerprint"]["id_column"] == "driver"


def test_a_batch_makes_the_route_table_once_before_its_workers_start(
    mixed_folder: Path, tmp_path: Path
) -> None:
    cache = tmp_path / "cache"
    argv = [str(mixed_folder), "--out", str(tmp_path / "out"), "--cache-dir", str(cache)]
    cli_main(["match", *argv, "--workers", "1", "--quiet"])  # the folder holds bad files too
    assert [p.parent.name for p in cache.glob("*/*/meta.json")] == ["routes"]


def test_batch_options_take_path_objects_and_one_input(
    mixed_folder: Path, cache_dir: Path, tmp_path: Path
) -> None:
    # the Python API as a user writes it: pathlib paths, one input rather than a tuple
    from mapmatch.batch import BatchOptions, run_batch
    from mapmatch.batch.run import BatchError

    options = BatchOptions(
        inputs=mixed_folder / "a_two.csv",  # type: ignore[arg-type]
        out_dir=tmp_path / "out",
        cache_dir=cache_dir,  # type: ignore[arg-type]
        workers=1,
    )
    assert options.inputs == (str(mixed_folder / "a_two.csv"),)
    assert options.cache_dir == str(cache_dir)
    report = run_batch(options)
    assert (report.traces_ok, report.traces_failed) == (2, 0)
    assert set(_summary(tmp_path / "out")) == {"csv-a", "csv-b"}
    with pytest.raises(BatchError, match="inputs must be paths"):
        BatchOptions(inputs=(mixed_folder, 3), out_dir=tmp_path / "x")  # type: ignore[arg-type]
