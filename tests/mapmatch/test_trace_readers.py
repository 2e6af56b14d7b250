from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mapmatch.errors import InvalidTraceError, TraceFileError
from mapmatch.trace import Trace, read_traces
from mapmatch.trace_readers import infer_format

DATA = Path(__file__).resolve().parents[1] / "data" / "traces"
T0 = 1714550400.0  # 2024-05-01T08:00:00Z


# ------------------------------------------------------------------ CSV


def test_csv_aliases_mixed_case_blank_line_sort_and_dedupe() -> None:
    tr = Trace.from_file(DATA / "aliases_mixed_case.csv")
    assert tr.trace_id == "aliases_mixed_case"
    assert tr.time_s.tolist() == [T0, T0 + 1, T0 + 2, T0 + 3]
    assert tr.lon.tolist() == [7.4200, 7.4201, 7.4202, 7.4203]
    np.testing.assert_array_equal(tr.heading_deg, [90.0, 92.0, np.nan, 358.0])
    np.testing.assert_array_equal(tr.speed_mps, [10.0, 10.5, 10.8, 11.0])
    np.testing.assert_array_equal(tr.accuracy_m, [5.0, 6.0, 4.0, np.nan])  # hdop * 5 m
    assert tr.report.input_rows == 5
    assert tr.report.reordered_rows == 1
    assert tr.report.duplicate_time_rows == (4,)
    assert tr.report.warnings == (
        "1 row out of time order was sorted (first step back in time at row 3 (line 6))",
        "row 4 (line 7) repeats an earlier time and was collapsed "
        "(the first row with each time is kept)",
    )


def test_csv_with_two_trace_ids_groups_in_order() -> None:
    a, b = read_traces(DATA / "two_traces.csv")
    assert (a.trace_id, b.trace_id) == ("car-a", "car-b")
    assert a.time_s.tolist() == [T0, T0 + 1, T0 + 2]
    assert b.lat.tolist() == [43.7400, 43.7401]
    np.testing.assert_array_equal(a.odometer_m, [0.0, 12.5, 25.0])


def test_from_file_refuses_a_file_with_two_traces() -> None:
    with pytest.raises(TraceFileError, match=r"holds 2 traces \('car-a', 'car-b'\).*read_traces"):
        Trace.from_file(DATA / "two_traces.csv")


def test_csv_error_names_input_row_and_file_line() -> None:
    with pytest.raises(InvalidTraceError) as exc:
        Trace.from_file(DATA / "bad_lat.csv")
    msg = str(exc.value)
    assert "trace 'bad_lat' in bad_lat.csv" in msg
    assert "lat is out of range [-90, 90] in 2 row(s)" in msg
    assert "row 2 (line 4) = 94.5, row 4 (line 6) = -91" in msg
    assert exc.value.rows == (2, 4)


def test_csv_swapped_lon_lat_hint() -> None:
    with pytest.raises(InvalidTraceError, match="swapped lon/lat"):
        Trace.from_file(DATA / "swapped_lonlat.csv")


def test_csv_unparseable_time_names_line_and_raw_text() -> None:
    with pytest.raises(InvalidTraceError, match=r"row 2 \(line 4\) = 'yesterday noon'"):
        Trace.from_file(DATA / "bad_time.csv")


def test_csv_missing_trace_id_in_some_rows(tmp_path: Path) -> None:
    path = tmp_path / "ids.csv"
    path.write_text("trace_id,time,lat,lon\na,0,1,1\n,1,1,1\na,2,1,1\n")
    with pytest.raises(InvalidTraceError, match=r"1 rows have no trace_id \(line 3\)"):
        read_traces(path)


def test_csv_gz_and_bytes_give_the_same_trace(tmp_path: Path) -> None:
    raw = (DATA / "two_traces.csv").read_bytes()
    gz = tmp_path / "trips.csv.gz"
    gz.write_bytes(gzip.compress(raw))
    from_gz = read_traces(gz)
    from_bytes = read_traces(raw, format="csv")
    assert [t.trace_id for t in from_gz] == ["car-a", "car-b"]
    for x, y in zip(from_gz, from_bytes, strict=True):
        np.testing.assert_array_equal(x.time_s, y.time_s)
        np.testing.assert_array_equal(x.lon, y.lon)


def test_bytes_without_id_use_default_trace_id() -> None:
    body = b"time,lat,lon\n0,43.73,7.42\n1,43.74,7.42\n"
    assert read_traces(body, format="csv")[0].trace_id == "trace"
    assert read_traces(body, format="csv", default_trace_id="req-1")[0].trace_id == "req-1"


def test_bytes_need_a_format() -> None:
    with pytest.raises(TraceFileError, match="format= is required for bytes"):
        read_traces(b"time,lat,lon\n")


def test_unknown_suffix_and_missing_file(tmp_path: Path) -> None:
    with pytest.raises(TraceFileError, match=r"cannot tell the format.*\.csv\.gz"):
        read_traces(tmp_path / "trip.txt")
    with pytest.raises(TraceFileError, match="cannot be read"):
        read_traces(tmp_path / "nope.csv")


def test_empty_csv(tmp_path: Path) -> None:
    path = tmp_path / "empty.csv"
    path.write_text("")
    with pytest.raises(TraceFileError, match=r"'empty.csv' \(csv\): is empty"):
        read_traces(path)


@pytest.mark.parametrize(
    ("name", "fmt"),
    [
        ("a.csv", "csv"),
        ("A.CSV.GZ", "csv"),
        ("x.gpx", "gpx"),
        ("x.geojson", "geojson"),
        ("x.json", "json"),
        ("x.parquet", "parquet"),
        ("x.pq", "parquet"),
    ],
)
def test_infer_format(name: str, fmt: str) -> None:
    assert infer_format(name) == fmt


def test_large_csv_round_trip(tmp_path: Path) -> None:
    n = 100_000
    rng = np.random.default_rng(7)
    df = pd.DataFrame(
        {
            "time": T0 + np.arange(n, dtype=float),
            "lat": 43.73 + rng.uniform(-0.01, 0.01, n),
            "lon": 7.42 + rng.uniform(-0.01, 0.01, n),
            "speed": rng.uniform(0, 30, n),
        }
    )
    path = tmp_path / "big.csv"
    df.to_csv(path, index=False)
    tr = Trace.from_file(path)
    assert len(tr) == n
    np.testing.assert_allclose(tr.lat, df["lat"].to_numpy(), rtol=0, atol=1e-12)


# ------------------------------------------------------------------ Parquet


def test_parquet_with_trace_ids_and_timestamps(tmp_path: Path) -> None:
    df = pd.DataFrame(
        {
            "Trace_ID": ["p1", "p1", "p2", "p2", "p1"],
            "timestamp": pd.to_datetime([T0 + 2, T0, T0, T0 + 1, T0 + 1], unit="s", utc=True),
            "latitude": [43.7302, 43.7300, 43.74, 43.7401, 43.7301],
            "longitude": [7.4202, 7.4200, 7.43, 7.4301, 7.4201],
            "accuracy_m": [3.0, 4.0, 5.0, 6.0, 7.0],
        }
    )
    path = tmp_path / "fleet.parquet"
    df.to_parquet(path)
    p1, p2 = read_traces(path)
    assert (p1.trace_id, p2.trace_id) == ("p1", "p2")
    assert p1.time_s.tolist() == [T0, T0 + 1, T0 + 2]
    assert p1.lat.tolist() == [43.7300, 43.7301, 43.7302]
    np.testing.assert_array_equal(p1.accuracy_m, [4.0, 7.0, 3.0])
    assert p1.report.reordered_rows == 1


def test_parquet_error_names_record(tmp_path: Path) -> None:
    df = pd.DataFrame({"time": [0, 1, 2], "lat": [43.73, 43.73, 43.73], "lon": [7.42, 200.0, 7.42]})
    path = tmp_path / "bad.pq"
    df.to_parquet(path)
    with pytest.raises(InvalidTraceError, match=r"in bad.pq: lon .*row 1 \(record 2\) = 200"):
        read_traces(path)


def test_corrupt_parquet(tmp_path: Path) -> None:
    path = tmp_path / "junk.parquet"
    path.write_bytes(b"not parquet at all")
    with pytest.raises(TraceFileError, match=r"'junk.parquet' \(parquet\): is not readable"):
        read_traces(path)


# ------------------------------------------------------------------ GPX


def test_gpx_two_tracks_with_extensions_and_hdop() -> None:
    morning, evening = read_traces(DATA / "two_tracks.gpx")
    assert (morning.trace_id, evening.trace_id) == ("morning", "evening")
    assert morning.time_s.tolist() == [T0, T0 + 1, T0 + 2]  # across two <trkseg>
    assert morning.lat.tolist() == [43.7300, 43.7301, 43.7302]
    np.testing.assert_array_equal(morning.speed_mps, [8.5, 9.0, np.nan])
    np.testing.assert_array_equal(morning.heading_deg, [45.0, 46.0, np.nan])
    np.testing.assert_array_equal(morning.accuracy_m, [7.5, 5.0, np.nan])
    assert evening.time_s.tolist() == [T0 + 8 * 3600, T0 + 8 * 3600 + 5]  # 18:00+02:00


def test_gpx_with_doctype_is_refused() -> None:
    with pytest.raises(TraceFileError, match="DOCTYPE/ENTITY declaration, which is refused"):
        read_traces(DATA / "entity_bomb.gpx")


def test_gpx_utf16_doctype_is_refused_too() -> None:
    data = (DATA / "entity_bomb.gpx").read_text().encode("utf-16")
    with pytest.raises(TraceFileError, match="DOCTYPE"):
        read_traces(data, format="gpx")


def test_gpx_unnamed_tracks_get_stem_numbers(tmp_path: Path) -> None:
    pts = (
        '<trkseg><trkpt lat="43.73" lon="7.42"><time>2024-05-01T08:00:00Z</time></trkpt>'
        '<trkpt lat="43.73" lon="7.43"><time>2024-05-01T08:00:01Z</time></trkpt></trkseg>'
    )
    path = tmp_path / "ride.gpx"
    path.write_text(f'<gpx version="1.0"><trk>{pts}</trk><trk>{pts}</trk></gpx>')
    assert [t.trace_id for t in read_traces(path)] == ["ride-1", "ride-2"]
    path.write_text(f'<gpx version="1.0"><trk>{pts}</trk></gpx>')
    assert Trace.from_file(path).trace_id == "ride"


def test_gpx_bad_point_names_track_and_trkpt() -> None:
    body = (DATA / "two_tracks.gpx").read_bytes().replace(b'lat="43.7401"', b'lat="143.7401"')
    with pytest.raises(InvalidTraceError) as exc:
        read_traces(body, format="gpx")
    msg = str(exc.value)
    assert "trace 'evening' in <bytes> trk 2" in msg
    assert "row 1 (trkpt 2) = 143.74" in msg


def test_gpx_malformed_and_without_points() -> None:
    with pytest.raises(TraceFileError, match="not well-formed XML"):
        read_traces(b"<gpx><trk>", format="gpx")
    with pytest.raises(TraceFileError, match="no <trk>/<trkseg>/<trkpt> points"):
        read_traces(b'<gpx><wpt lat="1" lon="2"/></gpx>', format="gpx")


# ------------------------------------------------------------------ GeoJSON / JSON


def test_geojson_point_features_grouped_by_trace_id() -> None:
    with pytest.raises(InvalidTraceError) as exc:
        read_traces(DATA / "points.geojson")
    # van-2's second feature (feature 4 of the file) has accuracy 0.
    msg = str(exc.value)
    assert "trace 'van-2' in points.geojson: accuracy breaks the rule: must be > 0 m" in msg
    assert "row 1 (feature 4) = 0" in msg


def test_geojson_point_features_fields(tmp_path: Path) -> None:
    doc = json.loads((DATA / "points.geojson").read_text())
    doc["features"][3]["properties"]["accuracy"] = 2.0
    path = tmp_path / "fixed.geojson"
    path.write_text(json.dumps(doc))
    van1, van2 = read_traces(path)
    assert (van1.trace_id, van2.trace_id) == ("van-1", "van-2")
    assert van1.time_s.tolist() == [T0, T0 + 2, T0 + 4]
    assert van1.lon.tolist() == [7.4200, 7.4201, 7.4202]
    np.testing.assert_array_equal(van1.odometer_m, [1000.0, 1011.0, 1023.0])
    np.testing.assert_array_equal(van2.accuracy_m, [np.nan, 2.0])


def test_geojson_linestring_with_coord_times() -> None:
    tr = Trace.from_file(DATA / "linestring.geojson")
    assert tr.trace_id == "linestring"
    assert tr.time_s.tolist() == [T0, T0 + 1, T0 + 2]
    assert tr.lat.tolist() == [43.7300, 43.7301, 43.7302]
    np.testing.assert_array_equal(tr.speed_mps, [3.0, 4.0, 5.0])


def test_geojson_linestring_times_length_mismatch() -> None:
    doc = {
        "type": "Feature",
        "geometry": {"type": "LineString", "coordinates": [[7.42, 43.73], [7.43, 43.73]]},
        "properties": {"times": [0]},
    }
    with pytest.raises(TraceFileError, match="feature 1: property 'times' has 1 values for 2"):
        read_traces(json.dumps(doc).encode(), format="geojson")


def test_geojson_polygon_is_refused() -> None:
    doc = {
        "type": "FeatureCollection",
        "features": [
            {
                "type": "Feature",
                "properties": {},
                "geometry": {"type": "Polygon", "coordinates": []},
            }
        ],
    }
    with pytest.raises(TraceFileError, match="feature 1 is a Polygon"):
        read_traces(json.dumps(doc).encode(), format="geojson")


def test_json_body_with_points_and_trace_id() -> None:
    tr = Trace.from_file(DATA / "body.json")
    assert tr.trace_id == "api-7"
    assert tr.time_s.tolist() == [T0, T0 + 1.5, T0 + 3]
    np.testing.assert_array_equal(tr.accuracy_m, [6.0, np.nan, 5.0])


def test_json_bare_list_of_points_and_bad_point_number() -> None:
    pts = [{"t": 0, "lat": 43.73, "lon": 7.42}, {"t": 1, "lat": 43.73, "lon": 7.42, "speed": -3}]
    with pytest.raises(InvalidTraceError, match=r"trace 'r9'.*row 1 \(point 2\) = -3"):
        read_traces(json.dumps(pts).encode(), format="json", default_trace_id="r9")


def test_invalid_json() -> None:
    with pytest.raises(TraceFileError, match=r"'<bytes>' \(json\): is not valid JSON"):
        read_traces(b"{points: }", format="json")


def test_iso_and_epoch_files_agree(tmp_path: Path) -> None:
    iso = tmp_path / "iso.csv"
    iso.write_text(
        "time,lat,lon\n2024-05-01T10:00:00+02:00,43.73,7.42\n2024-05-01T08:00:02,43.74,7.42\n"
    )
    epoch = tmp_path / "epoch.csv"
    epoch.write_text(f"time,lat,lon\n{T0:.0f},43.73,7.42\n{T0 + 2:.0f},43.74,7.42\n")
    assert Trace.from_file(iso).time_s.tolist() == Trace.from_file(epoch).time_s.tolist()
    assert Trace.from_file(iso).time_s.tolist() == [T0, T0 + 2]
