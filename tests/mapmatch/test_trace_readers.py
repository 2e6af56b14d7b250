from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mapmatch.errors import InvalidTraceError, TraceFileError
from mapmatch.trace import Trace, read_traces
from mapmatch.trace.readers import infer_format

DATA = Path(__file__).resolve().parents[1] / "data" / "traces"
T0 = 1714550400.0  # 2024-05-01T08:00:00Z


# ------------------------------------------------------------------ CSV


def test_csv_aliases_mixed_case_blank_line_sort_and_shared_time() -> None:
    tr = Trace.from_file(DATA / "aliases_mixed_case.csv")
    assert tr.trace_id == "aliases_mixed_case"
    # line 7 shares line 5's time at another position: both kept, in file order
    assert tr.time_s.tolist() == [T0, T0 + 1, T0 + 2, T0 + 3, T0 + 3]
    assert tr.lon.tolist() == [7.4200, 7.4201, 7.4202, 7.4203, 7.4204]
    np.testing.assert_array_equal(tr.heading_deg, [90.0, 92.0, np.nan, 358.0, 95.0])
    np.testing.assert_array_equal(tr.speed_mps, [10.0, 10.5, 10.8, 11.0, 11.0])
    np.testing.assert_array_equal(tr.accuracy_m, [5.0, 6.0, 4.0, np.nan, 10.0])  # hdop * 5 m
    assert tr.report.input_rows == 5
    assert tr.report.reordered_rows == 1
    assert tr.report.merged_rows == ()
    assert tr.report.shared_time_rows == 1
    assert tr.report.warnings == (
        "1 row out of time order was sorted (first step back in time at row 3 (line 6))",
        "1 point shares the time of the point before (first at row 4 (line 7)); all are kept "
        "in file order and those steps are matched by distance only",
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


# ------------------------------------------------------------------ issue 12: files in the wild


def _nmea(body: str) -> str:
    """A sentence with its checksum: XOR of the characters between $ and *."""
    check = 0
    for ch in body:
        check ^= ord(ch)
    return f"${body}*{check:02X}"


def test_issue_12_gpx_without_times_is_a_trace_without_times() -> None:
    tr = Trace.from_file(DATA / "no_time.gpx")
    assert tr.trace_id == "8th Street, no times"
    assert len(tr) == 21
    assert tr.report.time_source == "absent"
    assert (tr.lon[0], tr.lat[0]) == (-122.291725, 37.805714)  # the file's first trkpt
    assert (tr.lon[-1], tr.lat[-1]) == (-122.298280, 37.807194)


def test_issue_12_gpx_burst_keeps_all_29_positions() -> None:
    tr = Trace.from_file(DATA / "burst_one_second.gpx")
    assert len(tr) == 29
    assert set(tr.time_s.tolist()) == {T0 + 60}
    assert tr.report.shared_time_rows == 28
    assert tr.report.merged_rows == ()
    assert tr.report.time_source == "implausible"
    assert not tr.has_time


def test_issue_12_gpx_of_two_identical_points_is_a_trace() -> None:
    tr = Trace.from_file(DATA / "two_identical.gpx")
    assert len(tr) == 2
    assert tr.lon.tolist() == [-122.294561, -122.294561]


def test_issue_12_gpx_segments_are_kept_as_known_gaps() -> None:
    gap, campbell = read_traces(DATA / "two_segments.gpx")
    assert (gap.trace_id, campbell.trace_id) == ("8th Street with a gap", "Campbell Street")
    assert len(gap) == 20
    assert gap.segment_starts.tolist() == [10]
    assert gap.time_s[10] - gap.time_s[9] == 123.0
    assert campbell.segment_starts.tolist() == []
    # the old two-track file: 2 segments in "morning"
    morning, _ = read_traces(DATA / "two_tracks.gpx")
    assert morning.segment_starts.tolist() == [2]


def test_issue_12_gpx_1_0_track_fields_and_a_route() -> None:
    track, route = read_traces(DATA / "gpx10_track_and_route.gpx")
    assert (track.trace_id, route.trace_id) == ("9th Street 1.0", "Campbell plan")
    np.testing.assert_array_equal(track.speed_mps, [10.0] * 6)
    np.testing.assert_array_equal(track.heading_deg, [302.0] * 6)
    assert track.time_s.tolist() == [T0 + 4 * k for k in range(6)]
    assert len(route) == 7
    assert route.report.time_source == "absent"


def test_issue_12_gpx_only_waypoints_is_still_refused() -> None:
    with pytest.raises(TraceFileError, match="waypoints alone are not a trace"):
        read_traces(b'<gpx><wpt lat="1" lon="2"/></gpx>', format="gpx")


def test_issue_12_kml_track_and_linestring() -> None:
    track, line = read_traces(DATA / "track.kml")
    assert (track.trace_id, line.trace_id) == ("8th Street track", "9th Street line")
    assert track.time_s.tolist() == [T0 + 4 * k for k in range(10)]
    assert (track.lon[0], track.lat[0]) == (-122.292380, 37.805864)
    assert line.report.time_source == "absent"
    assert len(line) == 7


def test_issue_12_kml_track_with_fewer_times_than_positions() -> None:
    body = (
        b'<kml xmlns:gx="http://www.google.com/kml/ext/2.2"><Placemark><gx:Track>'
        b"<when>2024-05-01T08:00:00Z</when><gx:coord>7.42 43.73 0</gx:coord>"
        b"<gx:coord>7.43 43.73 0</gx:coord></gx:Track></Placemark></kml>"
    )
    with pytest.raises(TraceFileError, match="gx:Track has 1 <when> for 2 <gx:coord>"):
        read_traces(body, format="kml")


def test_issue_12_nmea_log_checksums_fixes_and_midnight() -> None:
    tr = Trace.from_file(DATA / "box.nmea")
    assert tr.trace_id == "box"
    # 30 epochs of RMC + GGA; the epoch at line 37/38 has no fix; line 21 (an RMC) is corrupt
    assert len(tr) == 29
    assert tr.report.dropped_rows == 3
    assert tr.report.warnings == (
        "1 NMEA sentence with a wrong checksum was dropped (line 21)",
        "1 NMEA sentence (RMC) reporting no fix (status V) was dropped (line 37)",
        "1 NMEA sentence (GGA) reporting no fix (fix quality 0) was dropped (line 38)",
        "3 source records could not be used and were dropped in all",
    )
    # 2024-05-01 23:59:45 UTC .. 2024-05-02 00:00:14, one second apart, across midnight
    start = T0 + 16 * 3600 - 15
    expected = [start + k for k in range(30) if k != 17]
    assert tr.time_s.tolist() == expected
    assert tr.has_time
    # the RMC of line 21 was corrupt: its epoch has the GGA's position and HDOP, no speed
    assert tr.speed_mps is not None
    assert np.isnan(tr.speed_mps[9])
    np.testing.assert_allclose(np.delete(tr.speed_mps, 9), 21.4 * 1852 / 3600)
    np.testing.assert_array_equal(tr.accuracy_m, [1.2 * 5.0] * 29)
    # line 3: $GPRMC,235945.00,A,3748.4554,N,12217.9257,W,...
    assert tr.lat[0] == pytest.approx(37 + 48.4554 / 60, abs=1e-9)
    assert tr.lon[0] == pytest.approx(-(122 + 17.9257 / 60), abs=1e-9)


def test_issue_12_nmea_gga_only_has_no_date_and_says_so(tmp_path: Path) -> None:
    path = tmp_path / "gga.nmea"
    lines = [
        _nmea("GPGGA,235959.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"),
        "$GNGGA,000000.00,4807.040,N,01131.002,E,1,08,0.9,545.4,M,46.9,M,,",  # no checksum
    ]
    path.write_text("\n".join(lines) + "\n")
    tr = Trace.from_file(path)
    assert tr.time_s.tolist() == [86399.0, 86400.0]  # seconds of day, rolled over midnight
    assert tr.report.warnings[:2] == (
        "1 NMEA sentence(s) carry no checksum (*hh) and were used unchecked",
        "no RMC sentence gives a date: times are seconds of day counted from 1970-01-01 (the "
        "order and the intervals are right, the date is not)",
    )


def test_issue_12_nmea_without_any_fix_is_refused() -> None:
    with pytest.raises(TraceFileError, match=r"holds no fix with a position; 1 NMEA sentence"):
        read_traces(b"$GPRMC,120000.00,V,,,,,,,010524,,,N*71\n$GPGSV,1,1,00*79\n", format="nmea")
    with pytest.raises(TraceFileError, match=r"holds no \$..RMC or \$..GGA sentence"):
        read_traces(b"hello\n", format="nmea")


def test_issue_12_excel_csv_with_bom_semicolons_and_decimal_commas() -> None:
    (tr,) = read_traces(DATA / "excel_semicolon.csv")
    assert tr.trace_id == "7"  # grouped by VehicleID
    assert tr.lat[0] == 37.809022
    assert tr.lon[0] == -122.299706
    np.testing.assert_array_equal(tr.speed_mps, [10.0] * 10)
    assert tr.time_s[1] - tr.time_s[0] == 3.0


@pytest.mark.parametrize(
    ("text", "encoding"),
    [
        ("time\tlat\tlon\n0\t43.73\t7.42\n1\t43.74\t7.42\n", "utf-8"),
        ("sep=;\ntime;lat;lon\n0;43,73;7,42\n1;43,74;7,42\n", "utf-8"),
        ("time|lat|lon\n0|43.73|7.42\n1|43.74|7.42\n", "utf-8"),
        ("time\tlat\tlon\n0\t43.73\t7.42\n1\t43.74\t7.42\n", "utf-16"),
    ],
)
def test_issue_12_csv_dialects(text: str, encoding: str) -> None:
    tr = read_traces(text.encode(encoding), format="csv")[0]
    assert tr.lat.tolist() == [43.73, 43.74]
    assert tr.lon.tolist() == [7.42, 7.42]


def test_issue_12_csv_sep_line_keeps_line_numbers_right() -> None:
    body = b"sep=;\ntime;lat;lon\n0;43,73;7,42\n1;95,0;7,42\n"
    with pytest.raises(InvalidTraceError, match=r"row 1 \(line 4\) = 95"):
        read_traces(body, format="csv")


def test_issue_12_latin1_csv_is_read_with_a_note() -> None:
    body = "time,lat,lon,driver\n0,43.73,7.42,Jos\xe9\n1,43.7301,7.42,Jos\xe9\n".encode("latin-1")
    tr = read_traces(body, format="csv")[0]
    assert tr.report.warnings == (
        "the file is not UTF-8 (byte 37); it was read as Latin-1, so check accented text",
    )


# ------------------------------------------------------------------ issue 12: fleets


def test_issue_12_fleet_csv_interleaved_in_time_is_split_by_vehicle() -> None:
    bus, van = read_traces(DATA / "fleet_interleaved.csv")
    assert (bus.trace_id, van.trace_id) == ("bus-12", "van-7")
    assert (len(bus), len(van)) == (60, 60)
    assert bus.time_s.tolist() == [T0 + k for k in range(60)]
    assert van.time_s.tolist() == [T0 + k + 0.5 for k in range(60)]
    for tr in (bus, van):
        assert tr.report.merged_rows == ()
        assert tr.report.reordered_rows == 0
        assert tr.report.warnings == ()
    with pytest.raises(TraceFileError, match="holds 2 traces"):
        Trace.from_file(DATA / "fleet_interleaved.csv")


def test_issue_12_id_column_override_and_its_error(tmp_path: Path) -> None:
    path = tmp_path / "drivers.csv"
    path.write_text(
        "driver,time,lat,lon\nana,0,43.73,7.42\nbo,0,43.74,7.43\nana,1,43.73,7.4201\n"
        "bo,2,43.74,7.4301\n"
    )
    (both,) = read_traces(path)  # 'driver' is no id column by default
    assert len(both) == 4
    ana, bo = read_traces(path, id_column="Driver")
    assert (ana.trace_id, len(ana), bo.trace_id, len(bo)) == ("ana", 2, "bo", 2)
    with pytest.raises(TraceFileError, match=r"has no column 'vehicle' to group traces by"):
        read_traces(path, id_column="vehicle")


def test_issue_12_trips_restarting_per_vehicle_stay_apart() -> None:
    df = pd.DataFrame(
        {
            "vehicle": ["a", "b", "a", "b", "a", "a"],
            "trip_id": [1, 1, 1, 1, 2, 2],
            "time": [0, 0, 1, 1, 50, 51],
            "lat": [43.73, 43.74, 43.7301, 43.7401, 43.75, 43.7501],
            "lon": [7.42] * 6,
        }
    )
    traces = read_traces(df)
    assert [t.trace_id for t in traces] == ["a/1", "b/1", "a/2"]
    assert [len(t) for t in traces] == [2, 2, 2]
    unique = df.assign(trip_id=["t1", "t2", "t1", "t2", "t3", "t3"])
    assert [t.trace_id for t in read_traces(unique)] == ["t1", "t2", "t3"]


def test_issue_12_an_id_column_numbering_rows_is_not_a_trace_id() -> None:
    df = pd.DataFrame({"id": [10, 11, 12], "time": [0, 1, 2], "lat": [43.73] * 3, "lon": LON3})
    (tr,) = read_traces(df, default_trace_id="rows")
    assert tr.trace_id == "rows"
    assert tr.report.warnings[0].startswith("column 'id' holds a different value in every row")
    two = pd.DataFrame({"ID": ["x", "x", "y", "y"], "t": [0, 1, 0, 1], "lat": [43.73] * 4})
    assert [t.trace_id for t in read_traces(two.assign(lon=[*LON3, 7.43]))] == ["x", "y"]


LON3 = [7.42, 7.421, 7.422]


def test_issue_12_read_traces_of_a_geodataframe_groups_and_converts() -> None:
    gpd = pytest.importorskip("geopandas")
    frame = pd.read_csv(DATA / "fleet_interleaved.csv")
    gdf = gpd.GeoDataFrame(
        frame.drop(columns=["latitude", "longitude"]),
        geometry=gpd.points_from_xy(frame["longitude"], frame["latitude"]),
        crs="EPSG:4326",
    ).to_crs("EPSG:32610")
    bus, van = read_traces(gdf)
    assert (bus.trace_id, len(bus), van.trace_id, len(van)) == ("bus-12", 60, "van-7", 60)
    expected = frame[frame["vehicle_id"] == "bus-12"]
    np.testing.assert_allclose(bus.lon, expected["longitude"], atol=1e-8)
    np.testing.assert_allclose(bus.lat, expected["latitude"], atol=1e-8)
