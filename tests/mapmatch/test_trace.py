from __future__ import annotations

import contextlib
import math
import pickle
from types import MappingProxyType

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mapmatch.errors import (
    InvalidTraceError,
    MapMatchError,
    NoCandidatesError,
    TraceFileError,
)
from mapmatch.trace import UERE_M, Trace, TraceReport, chinacrs
from mapmatch.trace.frames import record_columns

LON = [7.4200, 7.4201, 7.4202, 7.4203]
LAT = [43.7300, 43.7301, 43.7302, 43.7303]


def make(**kwargs: object) -> Trace:
    base: dict[str, object] = {"time": [0, 1, 2, 3], "lon": LON, "lat": LAT}
    base.update(kwargs)
    return Trace(**base)  # type: ignore[arg-type]


# ------------------------------------------------------------------ errors


def test_errors_subclass_the_root_and_valueerror() -> None:
    for cls in (InvalidTraceError, TraceFileError, NoCandidatesError):
        assert issubclass(cls, MapMatchError)
        assert issubclass(cls, ValueError)


def test_no_candidates_error_message_and_pickle() -> None:
    err = NoCandidatesError("bus-3", 50.0)
    assert str(err) == "trace 'bus-3': no road within 50 m of any fix; swapped lon/lat?"
    back = pickle.loads(pickle.dumps(err))
    assert (back.trace_id, back.radius_m, str(back)) == ("bus-3", 50.0, str(err))


# ------------------------------------------------------------------ basics


def test_clean_trace_has_float_arrays_and_empty_report() -> None:
    tr = make(trace_id="t1")
    assert tr.trace_id == "t1"
    assert len(tr) == 4
    assert tr.time_s.dtype == np.float64
    assert tr.lon.tolist() == LON
    assert tr.lat.tolist() == LAT
    assert (tr.heading_deg, tr.speed_mps, tr.accuracy_m, tr.odometer_m) == (None,) * 4
    assert tr.report == TraceReport(
        input_rows=4,
        reordered_rows=0,
        merged_rows=(),
        shared_time_rows=0,
        dropped_rows=0,
        time_source="ok",
        time_unit="s",
        warnings=(),
    )
    assert tr.has_time
    assert tr.segment_starts.tolist() == []


def test_arrays_are_read_only() -> None:
    tr = make()
    with pytest.raises(ValueError, match="read-only"):
        tr.lat[0] = 0.0


def test_iso_epoch_datetime64_and_timestamps_agree() -> None:
    epoch = [1714550400, 1714550401.5, 1714550403]
    iso_utc = ["2024-05-01T08:00:00Z", "2024-05-01T08:00:01.5Z", "2024-05-01T08:00:03+00:00"]
    iso_naive = ["2024-05-01T08:00:00", "2024-05-01T08:00:01.500", "2024-05-01 08:00:03"]
    iso_zoned = [
        "2024-05-01T10:00:00+02:00",
        "2024-05-01T03:00:01.5-05:00",
        "2024-05-01T08:00:03Z",
    ]
    dt64 = np.array(
        ["2024-05-01T08:00:00", "2024-05-01T08:00:01.5", "2024-05-01T08:00:03"],
        dtype="datetime64[ms]",
    )
    stamps = [pd.Timestamp(s) for s in iso_zoned]
    lon, lat = LON[:3], LAT[:3]
    for time in (
        epoch,
        iso_utc,
        iso_naive,
        iso_zoned,
        dt64,
        stamps,
        pd.Series(epoch, index=[7, 8, 9]),
    ):
        tr = Trace(time=time, lon=lon, lat=lat)
        assert tr.time_s.tolist() == [1714550400.0, 1714550401.5, 1714550403.0], time


def test_epoch_as_numeric_strings_is_epoch_seconds() -> None:
    tr = make(time=["10", "11", "12.5", "13"])
    assert tr.time_s.tolist() == [10.0, 11.0, 12.5, 13.0]


def test_unparseable_time_names_row_and_raw_value() -> None:
    with pytest.raises(InvalidTraceError) as exc:
        make(time=["2024-05-01T08:00:00Z", "2024-05-01T08:00:01Z", "soon", None], trace_id="x")
    msg = str(exc.value)
    assert "trace 'x'" in msg
    assert "time is missing or not a time in 2 row(s)" in msg
    assert "row 2 = 'soon'" in msg
    assert "row 3 = missing" in msg
    assert "ISO-8601" in msg
    assert exc.value.rows == (2, 3)
    assert exc.value.field == "time"


def test_boolean_time_is_refused_with_plain_values() -> None:
    with pytest.raises(InvalidTraceError, match=r"time is missing or not a time .*row 0 = True"):
        make(time=np.array([True, False, True, False]))


def test_epoch_milliseconds_are_converted_and_reported() -> None:
    # documented change (issue 12): milliseconds are unambiguous by size, so they are read
    tr = make(time=[1714550400000, 1714550401000, 1714550402500, 1714550403000])
    assert tr.time_s.tolist() == [1714550400.0, 1714550401.0, 1714550402.5, 1714550403.0]
    assert tr.report.time_unit == "ms"
    assert tr.report.warnings == (
        "times are epoch milliseconds (e.g. 1714550400000) and were converted to seconds",
    )


# ------------------------------------------------------------------ coordinates


def test_lat_out_of_range_lists_rows_and_count() -> None:
    lat = [43.73] * 10
    for i in (1, 3, 4, 6, 7, 9):
        lat[i] = 91.0 + i
    with pytest.raises(InvalidTraceError) as exc:
        Trace(time=range(10), lon=[7.42] * 10, lat=lat, trace_id="far")
    msg = str(exc.value)
    assert "trace 'far'" in msg
    assert "lat is out of range [-90, 90] in 6 row(s)" in msg
    assert "row 1 = 92, row 3 = 94, row 4 = 95, row 6 = 97, row 7 = 98 and 1 more" in msg
    assert "row 9" not in msg
    assert exc.value.rows == (1, 3, 4, 6, 7, 9)


def test_lon_out_of_range() -> None:
    with pytest.raises(
        InvalidTraceError, match=r"lon is out of range \[-180, 180\] in 1 row\(s\): row 2 = 181"
    ):
        make(lon=[7.42, 7.42, 181.0, 7.42])


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), None, ""])
def test_non_finite_lat_is_an_error(bad: object) -> None:
    with pytest.raises(
        InvalidTraceError, match=r"lat is missing or not finite in 1 row\(s\): row 1"
    ) as exc:
        make(lat=[43.73, bad, 43.73, 43.73])
    assert exc.value.field == "lat"


def test_text_coordinate_names_the_value() -> None:
    with pytest.raises(
        InvalidTraceError, match=r"lon is not a number in 1 row\(s\): row 3 = '7,42'"
    ):
        make(lon=["7.42", "7.42", "7.42", "7,42"])


def test_all_lat_beyond_90_hints_swapped_lon_lat() -> None:
    with pytest.raises(InvalidTraceError, match="swapped lon/lat") as exc:
        Trace(time=[0, 1, 2], lon=[35.68, 35.68, 35.69], lat=[139.70, 139.71, 139.72])
    assert "every lat looks like a longitude" in str(exc.value)


def test_mismatched_lengths() -> None:
    with pytest.raises(InvalidTraceError, match="'lat' has 3 values but 'time' has 4"):
        make(lat=LAT[:3])


def test_one_time_for_three_positions_keeps_them_all_and_sets_the_times_aside() -> None:
    # documented change (issue 12): repeated times no longer drop positions
    tr = Trace(time=[5, 5, 5], lon=LON[:3], lat=LAT[:3], trace_id="still")
    assert len(tr) == 3
    assert tr.lon.tolist() == LON[:3]
    assert tr.report.shared_time_rows == 2
    assert tr.report.merged_rows == ()
    assert tr.report.time_source == "implausible"
    assert not tr.has_time


def test_single_point_is_an_error() -> None:
    with pytest.raises(InvalidTraceError, match="at least 2 points"):
        Trace(time=[0], lon=[7.42], lat=[43.73])


def test_unknown_crs() -> None:
    with pytest.raises(InvalidTraceError, match=r"unknown crs 'utm'.*wgs84, gcj02, bd09"):
        make(crs="utm")


# ------------------------------------------------------------------ optional fields


def test_heading_normalised_and_non_finite_becomes_nan() -> None:
    tr = make(heading=[-90.0, 360.0, float("inf"), None])
    np.testing.assert_array_equal(tr.heading_deg, [270.0, 0.0, np.nan, np.nan])


def test_tiny_negative_heading_stays_below_360() -> None:
    tr = make(heading=[-1e-15, 725.0, 0.0, 359.5])
    np.testing.assert_array_equal(tr.heading_deg, [0.0, 5.0, 0.0, 359.5])


def test_negative_speed_names_row_and_value() -> None:
    with pytest.raises(InvalidTraceError) as exc:
        make(speed=[1.0, -2.5, float("nan"), 3.0], trace_id="s")
    msg = str(exc.value)
    assert "trace 's'" in msg
    assert "speed breaks the rule: must be >= 0 m/s in 1 row(s): row 1 = -2.5" in msg
    assert exc.value.field == "speed"


@pytest.mark.parametrize("bad", [0.0, -3.0])
def test_accuracy_must_be_positive(bad: float) -> None:
    with pytest.raises(
        InvalidTraceError, match=rf"accuracy breaks the rule: must be > 0 m .*row 2 = {bad:g}"
    ):
        make(accuracy=[3.0, 4.0, bad, float("nan")])


def test_hdop_only_gives_accuracy_via_uere() -> None:
    tr = make(hdop=[1.0, 2.0, float("nan"), 0.8])
    assert UERE_M == 5.0
    np.testing.assert_array_equal(tr.accuracy_m, [5.0, 10.0, np.nan, 4.0])


def test_accuracy_wins_over_hdop_where_known() -> None:
    tr = make(accuracy=[3.0, np.nan, 7.0, np.nan], hdop=[1.0, 2.0, 3.0, np.nan])
    np.testing.assert_array_equal(tr.accuracy_m, [3.0, 10.0, 7.0, np.nan])


def test_decreasing_odometer_names_both_rows() -> None:
    with pytest.raises(InvalidTraceError) as exc:
        make(odometer=[0.0, 10.0, np.nan, 8.0], trace_id="odo")
    msg = str(exc.value)
    assert "odometer decreases in time at 1 row(s): row 3 = 8 after row 1 = 10" in msg
    assert exc.value.rows == (3,)


def test_odometer_checked_in_time_order_not_input_order() -> None:
    tr = make(time=[3, 0, 1, 2], odometer=[30.0, 0.0, 10.0, 20.0])
    np.testing.assert_array_equal(tr.odometer_m, [0.0, 10.0, 20.0, 30.0])


# ------------------------------------------------------------------ sorting and collapsing


def test_out_of_order_rows_are_sorted_and_reported() -> None:
    tr = make(time=[0, 2, 1, 3], speed=[0.0, 2.0, 1.0, 3.0])
    assert tr.time_s.tolist() == [0.0, 1.0, 2.0, 3.0]
    assert tr.lon.tolist() == [LON[0], LON[2], LON[1], LON[3]]
    np.testing.assert_array_equal(tr.speed_mps, [0.0, 1.0, 2.0, 3.0])
    assert tr.report.reordered_rows == 1
    assert tr.report.warnings == (
        "1 row out of time order was sorted (first step back in time at row 2)",
    )


def test_one_late_first_row_counts_as_one_reordered_row() -> None:
    tr = Trace(time=[9, 1, 2, 3, 4], lon=[1.0, 2, 3, 4, 5], lat=[1.0, 2, 3, 4, 5])
    assert tr.report.reordered_rows == 1
    assert tr.lon.tolist() == [2.0, 3.0, 4.0, 5.0, 1.0]


def test_repeated_times_keep_every_position_and_merge_only_true_duplicates() -> None:
    lon = [7.4200, 7.4201, 7.4202, 7.4203, 7.4200, 7.4201]
    lat = [43.73] * 6
    tr = Trace(time=[0, 1, 1, 2, 0, 1], lon=lon, lat=lat)
    # rows 4 and 5 repeat rows 0 and 1 exactly; row 2 shares row 1's time at another place
    assert tr.time_s.tolist() == [0.0, 1.0, 1.0, 2.0]
    assert tr.lon.tolist() == [7.4200, 7.4201, 7.4202, 7.4203]
    assert tr.report.merged_rows == (4, 5)
    assert tr.report.shared_time_rows == 1
    assert tr.report.input_rows == 6
    assert tr.report.reordered_rows == 2
    assert tr.has_time  # one zero-time step of three moving steps is not "most"
    assert (
        "rows 4, 5 repeat an earlier row exactly (same time, position and other fields) "
        "and were merged into it" in tr.report.warnings
    )
    assert (
        "1 point shares the time of the point before (first at row 2); all are kept in file "
        "order and those steps are matched by distance only" in tr.report.warnings
    )


@st.composite
def shuffled_traces(draw: st.DrawFn) -> tuple[dict[str, list[float]], list[int]]:
    n = draw(st.integers(min_value=2, max_value=30))
    times = draw(st.lists(st.integers(0, 10_000), min_size=n, max_size=n, unique=True).map(sorted))
    lon = draw(st.lists(st.floats(-180, 180), min_size=n, max_size=n))
    lat = draw(st.lists(st.floats(-89, 89), min_size=n, max_size=n))
    speed = draw(st.lists(st.floats(0, 60), min_size=n, max_size=n))
    perm = draw(st.permutations(list(range(n))))
    cols = {"time": [float(t) for t in times], "lon": lon, "lat": lat, "speed": speed}
    return cols, perm


@settings(derandomize=True, max_examples=60, deadline=None)
@given(data=shuffled_traces())
def test_any_permutation_gives_the_same_sorted_trace(
    data: tuple[dict[str, list[float]], list[int]],
) -> None:
    cols, perm = data
    ref = Trace(**cols)  # type: ignore[arg-type]
    shuffled = {k: [v[i] for i in perm] for k, v in cols.items()}
    tr = Trace(**shuffled)  # type: ignore[arg-type]
    for name in ("time_s", "lon", "lat", "speed_mps"):
        np.testing.assert_array_equal(getattr(tr, name), getattr(ref, name))
    assert tr.time_s.tolist() == cols["time"]
    assert tr.report.merged_rows == ()
    assert (tr.report.reordered_rows == 0) == (perm == sorted(perm))


# ------------------------------------------------------------------ tables and records


def test_from_dataframe_aliases_any_case_and_ignores_extras() -> None:
    df = pd.DataFrame(
        {
            "TimeStamp": [0, 1, 2],
            "Latitude": LAT[:3],
            "LNG": LON[:3],
            "course": [10.0, 20.0, 30.0],
            "Speed_mps": [1.0, 2.0, 3.0],
            "accuracy_m": [4.0, 5.0, 6.0],
            "Odometer_M": [0.0, 1.0, 2.0],
            "driver": ["a", "b", "c"],
        }
    )
    tr = Trace.from_dataframe(df, trace_id="df")
    assert tr.trace_id == "df"
    assert tr.lon.tolist() == LON[:3]
    np.testing.assert_array_equal(tr.heading_deg, [10.0, 20.0, 30.0])
    np.testing.assert_array_equal(tr.accuracy_m, [4.0, 5.0, 6.0])
    np.testing.assert_array_equal(tr.odometer_m, [0.0, 1.0, 2.0])


def test_two_columns_aliasing_one_field_names_both() -> None:
    df = pd.DataFrame(
        {"time": [0, 1], "lat": [1.0, 2.0], "lon": [1.0, 2.0], "Bearing": [1, 2], "course": [1, 2]}
    )
    with pytest.raises(
        InvalidTraceError, match="columns 'Bearing' and 'course' both give 'heading'"
    ):
        Trace.from_dataframe(df)


def test_missing_required_column_lists_found_columns() -> None:
    df = pd.DataFrame({"time": [0, 1], "y": [1.0, 2.0], "lon": [1.0, 2.0]})
    with pytest.raises(InvalidTraceError) as exc:
        Trace.from_dataframe(df, trace_id="m")
    msg = str(exc.value)
    assert "trace 'm'" in msg
    assert "missing required column(s) 'lat' (or latitude)" in msg
    assert "found columns: 'time', 'y', 'lon'" in msg
    assert exc.value.field == "lat"


def test_from_dataframe_takes_the_id_column_and_refuses_two_ids() -> None:
    df = pd.DataFrame({"trace_id": ["k9", "k9"], "t": [0, 1], "lat": [1.0, 2.0], "lon": [1.0, 2.0]})
    assert Trace.from_dataframe(df).trace_id == "k9"
    df.loc[1, "trace_id"] = "k10"
    with pytest.raises(
        InvalidTraceError, match=r"holds 2 ids \('k9', 'k10'\); use mapmatch.read_traces"
    ):
        Trace.from_dataframe(df)


def test_to_dataframe_round_trip() -> None:
    tr = make(time=[3, 1, 2, 0], heading=[1.0, 2.0, 3.0, 4.0], hdop=[1.0, 1.0, 2.0, 2.0])
    df = tr.to_dataframe()
    assert list(df.columns) == ["time", "lon", "lat", "heading", "accuracy"]
    assert df["time"].tolist() == [0.0, 1.0, 2.0, 3.0]
    back = Trace.from_dataframe(df, trace_id=tr.trace_id)
    for name in ("time_s", "lon", "lat", "heading_deg", "accuracy_m"):
        np.testing.assert_array_equal(getattr(back, name), getattr(tr, name))


def test_from_records_with_missing_optional_keys() -> None:
    recs = [
        {"time": "2024-05-01T08:00:00Z", "lat": 43.73, "lon": 7.42, "speed": 3.0},
        {"time": "2024-05-01T08:00:01Z", "lat": 43.74, "lon": 7.43},
    ]
    tr = Trace.from_records(recs, trace_id="rec")
    assert tr.time_s.tolist() == [1714550400.0, 1714550401.0]
    np.testing.assert_array_equal(tr.speed_mps, [3.0, np.nan])


def test_from_records_bad_row_named() -> None:
    recs = [
        {"time": 0, "lat": 43.73, "lon": 7.42},
        {"time": 1, "lat": 43.73, "lon": 7.42, "speed": -1},
    ]
    with pytest.raises(InvalidTraceError, match=r"trace 'body': speed .* row 1 = -1"):
        Trace.from_records(recs, trace_id="body")


def test_from_records_refuses_non_objects() -> None:
    with pytest.raises(InvalidTraceError, match="record 1 is a list, not an object"):
        Trace.from_records([{"time": 0, "lat": 1.0, "lon": 1.0}, [1, 1.0, 1.0]])  # type: ignore[list-item]


# ------------------------------------------------------------------ slice


def test_slice_keeps_id_and_fields() -> None:
    tr = make(trace_id="s", speed=[0.0, 1.0, 2.0, 3.0])
    sub = tr.slice(1, 3)
    assert sub.trace_id == "s"
    assert sub.time_s.tolist() == [1.0, 2.0]
    np.testing.assert_array_equal(sub.speed_mps, [1.0, 2.0])
    assert sub.report.input_rows == 2
    assert tr.slice(-2, 4).lon.tolist() == LON[2:]


def test_slice_of_one_point_is_an_error() -> None:
    with pytest.raises(InvalidTraceError, match=r"slice\(2, 3\) of 4 points holds 1"):
        make().slice(2, 3)


# ------------------------------------------------------------------ Chinese frames


def test_gcj02_reference_point_converts_to_wgs84() -> None:
    # Tiananmen: WGS84 (116.404, 39.915) is GCJ-02 (116.410244, 39.916404) to 1e-6 deg.
    tr = Trace(time=[0, 1], lon=[116.410244, 116.410244], lat=[39.916404, 39.916404], crs="gcj02")
    assert tr.lon[0] == pytest.approx(116.404, abs=2e-6)
    assert tr.lat[0] == pytest.approx(39.915, abs=2e-6)


@pytest.mark.parametrize(
    ("crs", "forward"), [("gcj02", chinacrs.wgs84_to_gcj02), ("bd09", chinacrs.wgs84_to_bd09)]
)
def test_china_frames_round_trip(crs: str, forward: object) -> None:
    lon = np.array([116.404, 121.4737, 113.2644])
    lat = np.array([39.915, 31.2304, 23.1291])
    f_lon, f_lat = forward(lon, lat)  # type: ignore[operator]
    assert np.abs(f_lon - lon).max() > 1e-3  # the frames really differ here
    tr = Trace(time=[0, 1, 2], lon=f_lon, lat=f_lat, crs=crs)
    np.testing.assert_allclose(tr.lon, lon, atol=1e-7)
    np.testing.assert_allclose(tr.lat, lat, atol=1e-7)


def test_crs_outside_china_is_unchanged() -> None:
    tr = make(crs="gcj02")
    assert tr.lon.tolist() == LON
    assert tr.lat.tolist() == LAT


def test_time_is_non_decreasing_after_validation() -> None:
    tr = make(time=[2, 2, 1, 0])
    assert np.all(np.diff(tr.time_s) >= 0)
    assert tr.lon.tolist() == [LON[3], LON[2], LON[0], LON[1]]  # ties keep file order
    assert math.isclose(tr.time_s[-1], 2.0)


def test_issue_5_times_beyond_2262_parse_without_overflow() -> None:
    # pandas stores nanoseconds by default, which end in 2262; times must not crash validation
    trace = Trace(
        time=["2404-04-04T13:08:28Z", "2404-04-04T13:08:29Z"],
        lon=[7.42, 7.421],
        lat=[43.73, 43.731],
    )
    assert trace.time_s[0] == 13_703_864_908.0  # datetime(2404, 4, 4, 13, 8, 28, UTC)
    assert trace.time_s[1] - trace.time_s[0] == 1.0


def test_unparseable_time_names_its_row() -> None:
    with pytest.raises(InvalidTraceError) as caught:
        Trace(time=["2024-04-04T13:08:28Z", "yesterday"], lon=[7.42, 7.421], lat=[43.73, 43.731])
    assert caught.value.field == "time"
    assert caught.value.rows == (1,)


# ------------------------------------------------------------------ issue 12: time is optional


def test_issue_12_a_trace_without_times_is_valid_and_says_so() -> None:
    tr = Trace(lon=LON, lat=LAT, trace_id="plan")
    assert len(tr) == 4
    assert np.isnan(tr.time_s).all()
    assert tr.time_s.dtype == np.float64
    assert not tr.has_time
    assert tr.report.time_source == "absent"
    assert tr.report.time_unit == "none"
    assert tr.report.warnings == (
        "the trace has no times: it is matched by distance only (no speed, travel or time terms)",
    )
    assert repr(tr) == "Trace('plan', 4 points without times)"


@pytest.mark.parametrize("blank", [None, float("nan"), ""])
def test_issue_12_all_blank_times_are_no_times(blank: object) -> None:
    tr = make(time=[blank] * 4)
    assert tr.report.time_source == "absent"
    assert tr.lon.tolist() == LON  # file order kept


def test_issue_12_some_blank_times_are_an_error_naming_them() -> None:
    with pytest.raises(InvalidTraceError) as exc:
        make(time=[0, None, 2, float("nan")])
    assert exc.value.rows == (1, 3)
    assert "leave the time column out to match by distance only" in str(exc.value)


def test_issue_12_untimed_trace_merges_only_a_fix_repeated_in_a_row() -> None:
    lon = [7.4200, 7.4200, 7.4201, 7.4200]  # back at the start later: a loop, not a repeat
    tr = Trace(lon=lon, lat=[43.73] * 4)
    assert tr.lon.tolist() == [7.4200, 7.4201, 7.4200]
    assert tr.report.merged_rows == (1,)


def test_issue_12_two_identical_fixes_stay_a_two_point_trace() -> None:
    tr = Trace(time=[5, 5], lon=[7.42, 7.42], lat=[43.73, 43.73], trace_id="parked")
    assert len(tr) == 2
    assert tr.report.merged_rows == ()
    assert tr.report.shared_time_rows == 1
    assert tr.has_time  # nothing moved, so nothing moved impossibly fast
    assert tr.report.warnings[0] == (
        "all 2 rows are one fix repeated; 2 are kept so the trace stays a trace "
        "(its matched length is 0)"
    )
    untimed = Trace(lon=[7.42] * 3, lat=[43.73] * 3)
    assert len(untimed) == 2
    assert untimed.report.merged_rows == (2,)


def test_issue_12_rows_sharing_a_time_keep_their_file_order_when_sorted() -> None:
    tr = make(time=[3, 1, 1, 2], lon=[7.4204, 7.4201, 7.4202, 7.4203])
    assert tr.time_s.tolist() == [1.0, 1.0, 2.0, 3.0]
    assert tr.lon.tolist() == [7.4201, 7.4202, 7.4203, 7.4204]
    assert tr.report.reordered_rows == 1
    assert tr.report.shared_time_rows == 1


# ------------------------------------------------------------------ issue 12: implausible times


def _straight(n: int, step_deg: float) -> tuple[list[float], list[float]]:
    return [7.42 + i * step_deg for i in range(n)], [43.73] * n


def test_issue_12_planner_times_one_second_apart_are_set_aside() -> None:
    # 0.00125 deg of longitude at 43.73 N is 0.00125 * 111195 m * cos(43.73 deg) = 100.4 m
    lon, lat = _straight(12, 0.00125)
    tr = Trace(time=range(12), lon=lon, lat=lat)
    assert tr.report.time_source == "implausible"
    assert not tr.has_time
    assert tr.time_s.tolist() == [float(i) for i in range(12)]  # kept for the output
    assert tr.report.warnings == (
        "the times cannot be right: 11 of 11 moving steps imply more than 70 m/s (0 with no "
        "time between two positions; median 100 m/s); matched by distance only, the times "
        "are kept for the output",
    )


def test_issue_12_a_few_fast_or_untimed_steps_do_not_set_the_times_aside() -> None:
    lon, lat = _straight(12, 0.00025)  # 20 m apart
    times = [0, 2, 4, 5, 8, 10, 10, 14, 16, 18, 20, 22]  # one 20 m/s step, one with dt = 0
    tr = Trace(time=times, lon=lon, lat=lat)
    assert tr.has_time
    assert tr.report.shared_time_rows == 1
    # half the moving steps impossible is "most": the rule is >= IMPLAUSIBLE_SHARE
    half = [0, 0, 0, 0, 0, 0, 0, 14, 16, 18, 20, 22][:12]
    assert not Trace(time=half, lon=lon, lat=lat).has_time


def test_issue_12_the_plausibility_rule_uses_the_documented_constants() -> None:
    from mapmatch.trace import IMPLAUSIBLE_SHARE, MAX_PLAUSIBLE_SPEED_MPS, MOVING_STEP_M

    assert (MAX_PLAUSIBLE_SPEED_MPS, IMPLAUSIBLE_SHARE, MOVING_STEP_M) == (70.0, 0.5, 1.0)
    lon, lat = _straight(3, 0.0007)  # about 56 m apart
    assert Trace(time=[0, 0.81, 1.62], lon=lon, lat=lat).has_time  # 69 m/s
    assert not Trace(time=[0, 0.79, 1.58], lon=lon, lat=lat).has_time  # 71 m/s


# ------------------------------------------------------------------ issue 12: units


@pytest.mark.parametrize(
    ("scale", "unit"), [(1, "s"), (1_000, "ms"), (1_000_000, "us"), (1_000_000_000, "ns")]
)
def test_issue_12_epoch_units_are_told_apart_by_size(scale: int, unit: str) -> None:
    seconds = [1714550400, 1714550401, 1714550403, 1714550404]
    tr = make(time=np.array([s * scale for s in seconds], dtype=np.int64))
    assert tr.time_s.tolist() == [float(s) for s in seconds]
    assert tr.report.time_unit == unit
    assert tr.has_time
    assert len(tr.report.warnings) == (0 if unit == "s" else 1)


def test_issue_12_microsecond_text_epochs_are_converted() -> None:
    tr = make(time=["1714550400000000", "1714550400500000", "1714550401000000", "1714550402e6"])
    assert tr.time_s.tolist() == [1714550400.0, 1714550400.5, 1714550401.0, 1714550402.0]
    assert tr.report.time_unit == "us"


def test_issue_12_a_time_column_mixing_units_is_refused_naming_the_odd_rows() -> None:
    with pytest.raises(InvalidTraceError) as exc:
        make(time=[1714550400, 1714550401, 1714550402000, 1714550403])
    msg = str(exc.value)
    assert (
        "time mixes units: these rows look like epoch milliseconds while the others are "
        "epoch seconds in 1 row(s): row 2 = 1.71455e+12" in msg
    )
    assert exc.value.rows == (2,)


def test_issue_12_times_beyond_nanosecond_epochs_are_refused() -> None:
    with pytest.raises(InvalidTraceError, match="too large for epoch seconds, milliseconds"):
        make(time=[1e21, 1e21 + 1, 1e21 + 2, 1e21 + 3])


def test_issue_12_float32_epoch_times_are_refused_saying_why() -> None:
    times = np.array([1714550400, 1714550401, 1714550402, 1714550403], dtype=np.float32)
    with pytest.raises(InvalidTraceError) as exc:
        make(time=times, trace_id="f32")
    assert str(exc.value) == (
        "trace 'f32': time is stored as float32, which keeps 24 bits: near 1.71455e+09 its "
        "values can only be 128 s apart, so fixes seconds apart would collapse into repeated "
        "times; store times as float64 or int64 epoch seconds, or as ISO-8601 text"
    )
    assert exc.value.field == "time"
    frame = pd.DataFrame({"time": times, "lat": LAT, "lon": LON})
    with pytest.raises(InvalidTraceError, match="float32"):
        Trace.from_dataframe(frame)


def test_issue_12_float32_relative_seconds_are_fine() -> None:
    tr = make(time=np.array([0.0, 0.5, 1.0, 1.5], dtype=np.float32))
    assert tr.time_s.tolist() == [0.0, 0.5, 1.0, 1.5]


# ------------------------------------------------------------------ issue 12: segments, tables


def test_issue_12_segment_labels_give_segment_starts_after_sorting() -> None:
    tr = make(time=[0, 1, 3, 2], segment=[0, 0, 1, 1])
    assert tr.segment_starts.tolist() == [2]
    back = Trace.from_dataframe(tr.to_dataframe())
    assert back.segment_starts.tolist() == [2]
    assert tr.slice(1, 4).segment_starts.tolist() == [1]
    assert tr.slice(2, 4).segment_starts.tolist() == []
    with pytest.raises(ValueError, match="read-only"):
        tr.segment_starts[0] = 1


def test_issue_12_from_dataframe_with_a_fleet_refuses_naming_the_id_column() -> None:
    df = pd.DataFrame(
        {"VehicleID": ["a", "b", "a"], "t": [0, 0, 1], "lat": LAT[:3], "lon": LON[:3]}
    )
    with pytest.raises(InvalidTraceError, match=r"the VehicleID column holds 2 ids \('a', 'b'\)"):
        Trace.from_dataframe(df)
    assert Trace.from_dataframe(df[df["VehicleID"] == "a"]).trace_id == "a"


def test_issue_12_a_geodataframe_in_a_projected_crs_is_read_in_wgs84() -> None:
    gpd = pytest.importorskip("geopandas")
    lon = np.array([-122.2920, -122.2930, -122.2940])
    lat = np.array([37.8058, 37.8060, 37.8063])
    gdf = gpd.GeoDataFrame(
        {"time": [0, 5, 10], "speed": [8.0, 9.0, 10.0]},
        geometry=gpd.points_from_xy(lon, lat),
        crs="EPSG:4326",
    ).to_crs("EPSG:26910")  # NAD83 / UTM 10N, metres
    assert float(gdf.geometry.x.iloc[0]) > 500_000  # really projected
    tr = Trace.from_dataframe(gdf, trace_id="gdf")
    np.testing.assert_allclose(tr.lon, lon, atol=1e-8)
    np.testing.assert_allclose(tr.lat, lat, atol=1e-8)
    np.testing.assert_array_equal(tr.speed_mps, [8.0, 9.0, 10.0])


def test_issue_12_a_geodataframe_of_lines_is_refused_naming_the_rows() -> None:
    gpd = pytest.importorskip("geopandas")
    from shapely.geometry import LineString, Point

    gdf = gpd.GeoDataFrame(
        {"time": [0, 1, 2]},
        geometry=[Point(7.42, 43.73), LineString([(7.42, 43.73), (7.43, 43.73)]), None],
        crs="EPSG:4326",
    )
    with pytest.raises(InvalidTraceError) as exc:
        Trace.from_dataframe(gdf)
    assert "row 1 is a LineString, row 2 is missing" in str(exc.value)
    assert exc.value.rows == (1, 2)


# ------------------------------------------------------------------ issue 12: match() inputs


def test_issue_12_match_inputs_must_be_a_trace_and_a_network() -> None:
    import networkx as nx

    from mapmatch.errors import InputTypeError
    from mapmatch.trace import check_match_inputs

    tr = make()
    with pytest.raises(InputTypeError) as exc:
        check_match_inputs(tr, nx.MultiDiGraph())
    assert str(exc.value) == (
        "match(trace, net): net must be a roadnets.RoadNetwork, not a networkx MultiDiGraph; "
        "convert the graph with roadnets.from_graph(G), or load an extract with "
        "roadnets.load(path)"
    )
    assert isinstance(exc.value, TypeError)
    with pytest.raises(InputTypeError, match=r"not None; load one with roadnets.load\(path\)"):
        check_match_inputs(tr, None)
    with pytest.raises(
        InputTypeError, match=r"not a pandas DataFrame; build one with .*from_dataframe"
    ):
        check_match_inputs(tr.to_dataframe(), None)


# ------------------------------------------------- numpy arrays without pandas (issue 15)

_T0 = 1_714_550_400.0
_EQUIVALENCE_CASES: dict[str, dict[str, object]] = {
    "clean": {"time": [0.0, 5.0, 10.0, 15.0]},
    "epoch int64": {"time": np.array([0, 5, 10, 15], dtype=np.int64) + int(_T0)},
    "epoch ms": {"time": (np.array([0.0, 5.0, 10.0, 15.0]) + _T0) * 1e3},
    "epoch ns uint": {"time": (np.array([0, 5, 10, 15], dtype=np.uint64) + int(_T0)) * 10**9},
    "unsorted with a true duplicate": {"time": [5.0, 0.0, 5.0, 10.0], "lon": LON[:2] * 2},
    "shared time": {"time": [0.0, 5.0, 5.0, 10.0]},
    "no times": {"time": [np.nan] * 4},
    "implausible times": {"time": [0.0, 0.0, 0.0, 0.0], "lon": [7.42, 7.43, 7.44, 7.45]},
    "optional fields": {
        "time": [0.0, 5.0, 10.0, 15.0],
        "heading": [-90.0, 370.0, np.inf, np.nan],
        "speed": [0.0, 5.5, np.nan, 7.0],
        "accuracy": [np.nan, 3.0, 4.0, 5.0],
        "hdop": [1.2, np.nan, 0.8, 0.9],
        "odometer": [0.0, 10.0, np.nan, 30.0],
        "segment": [0, 0, 1, 1],
    },
    "float32 relative seconds": {"time": np.array([0.0, 1.0, 2.0, 3.0], dtype=np.float32)},
    "gcj02": {"time": [0.0, 5.0, 10.0, 15.0], "crs": "gcj02"},
    # each of the following is refused; the message must be the same on both paths
    "bool time": {"time": [True, False, True, True]},
    "bool speed": {"time": [0.0, 1.0, 2.0, 3.0], "speed": [True, False, True, True]},
    "partly blank time": {"time": [0.0, np.nan, 2.0, 3.0]},
    "infinite time": {"time": [0.0, np.inf, 2.0, 3.0]},
    "mixed units": {"time": [_T0, _T0 + 1, (_T0 + 2) * 1e3, _T0 + 3]},
    "too large": {"time": [1e21, 1e21, 1e21, 1e21]},
    "float32 epoch": {"time": np.array([_T0, _T0 + 1, _T0 + 2, _T0 + 3], dtype=np.float32)},
    "lat out of range": {"time": [0.0, 1.0, 2.0, 3.0], "lat": [43.73, 91.0, 43.73, -95.0]},
    "lat NaN": {"time": [0.0, 1.0, 2.0, 3.0], "lat": [43.73, np.nan, 43.73, 43.74]},
    "swapped": {"time": [0.0, 1.0, 2.0, 3.0], "lon": LAT, "lat": [107.0, 107.1, 107.2, 107.3]},
    "negative speed": {"time": [0.0, 1.0, 2.0, 3.0], "speed": [1.0, -2.5, 1.0, 1.0]},
    "infinite speed": {"time": [0.0, 1.0, 2.0, 3.0], "speed": [1.0, np.inf, 1.0, 1.0]},
    "zero accuracy": {"time": [0.0, 1.0, 2.0, 3.0], "accuracy": [1.0, 0.0, 1.0, 1.0]},
    "odometer back": {"time": [0.0, 1.0, 2.0, 3.0], "odometer": [0.0, 10.0, 5.0, 20.0]},
    "segment NaN": {"time": [0.0, 1.0, 2.0, 3.0], "segment": [0.0, np.nan, 1.0, 1.0]},
}


def _outcome(kwargs: dict[str, object]) -> object:
    try:
        tr = Trace(**kwargs)  # type: ignore[arg-type]
    except InvalidTraceError as exc:
        return ("error", str(exc), exc.field, exc.rows)
    fields = ("time_s", "lon", "lat", "heading_deg", "speed_mps", "accuracy_m", "odometer_m")
    arrays = {f: getattr(tr, f) for f in fields}
    for name, values in arrays.items():
        assert values is None or (values.dtype == np.float64 and not values.flags.writeable), name
    return (
        {f: None if v is None else v.tobytes() for f, v in arrays.items()},
        tr.segment_starts.tolist(),
        tr.report,
    )


@pytest.mark.parametrize("case", list(_EQUIVALENCE_CASES), ids=list(_EQUIVALENCE_CASES))
def test_numpy_arrays_are_validated_without_pandas_to_the_same_result(
    case: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    given = {"lon": LON, "lat": LAT, "trace_id": case, **_EQUIVALENCE_CASES[case]}
    as_arrays, as_series = {}, {}
    for key, value in given.items():
        if key in ("trace_id", "crs"):
            as_arrays[key] = as_series[key] = value
            continue
        arr = np.asarray(value)
        as_arrays[key] = arr
        as_series[key] = pd.Series(arr)
    reference = _outcome(as_series)
    with monkeypatch.context() as patched:  # the arrays path must not build a pandas Series
        for module in ("checks", "times"):
            patched.setattr(f"mapmatch.trace.{module}.as_series", _no_pandas)
        fast = _outcome(as_arrays)
    assert fast == reference


@pytest.mark.parametrize("case", list(_EQUIVALENCE_CASES), ids=list(_EQUIVALENCE_CASES))
def test_lists_of_numbers_give_what_pandas_gives(case: str) -> None:
    given = {"lon": LON, "lat": LAT, "trace_id": case, **_EQUIVALENCE_CASES[case]}
    as_lists, as_series = {}, {}
    for key, value in given.items():
        if key in ("trace_id", "crs"):
            as_lists[key] = as_series[key] = value
            continue
        items = np.asarray(value).tolist()  # Python floats, ints or bools
        as_lists[key] = items
        as_series[key] = pd.Series(items)
    assert _outcome(as_lists) == _outcome(as_series)


def _no_pandas(values: object) -> object:
    msg = "a numpy array went through pandas"
    raise AssertionError(msg)


def test_datetime64_arrays_give_the_times_pandas_gives() -> None:
    stamps = np.array(
        ["2024-05-01T08:00:00", "2024-05-01T08:00:01.250", "NaT", "2262-04-12T00:00:00"],
        dtype="datetime64[ms]",
    )
    lon, lat = np.array(LON[:3]), np.array(LAT[:3])
    for unit in ("s", "ms", "us", "ns"):
        # the year 2262 is beyond nanosecond epochs: numpy itself cannot hold it in ns
        values = stamps[[0, 1, 3] if unit != "ns" else [0, 1, 1]].astype(f"datetime64[{unit}]")
        fast = Trace(time=values, lon=lon, lat=lat, trace_id=unit)
        reference = Trace(time=pd.Series(values), lon=lon, lat=lat, trace_id=unit)
        assert fast.time_s.tobytes() == reference.time_s.tobytes(), unit
        assert fast.report == reference.report
        assert fast.report.time_unit == "datetime"
        step = fast.time_s[1] - fast.time_s[0]
        assert step == pytest.approx(1.0 if unit == "s" else 1.25, abs=1e-6)
    lon4, lat4 = np.array(LON), np.array(LAT)
    with pytest.raises(InvalidTraceError, match=r"time is missing or not a time.*row 2") as err:
        Trace(time=stamps, lon=lon4, lat=lat4)
    with pytest.raises(InvalidTraceError) as ref:
        Trace(time=pd.Series(stamps), lon=lon4, lat=lat4)
    assert str(err.value) == str(ref.value)


def test_validation_never_writes_into_the_callers_arrays() -> None:
    time = np.array([5.0, 0.0, 5.0, 10.0])
    heading = np.array([-90.0, 370.0, np.inf, 10.0])
    lon, lat = np.array(LON), np.array(LAT)
    before = [a.copy() for a in (time, heading, lon, lat)]
    tr = Trace(time=time, lon=lon, lat=lat, heading=heading, crs="gcj02")
    for a, b in zip((time, heading, lon, lat), before, strict=True):
        np.testing.assert_array_equal(a, b)
    assert not np.shares_memory(tr.time_s, time)
    assert not np.shares_memory(tr.lon, lon)


def _record(**fields: object) -> dict[str, object]:
    return fields


_P = [(7.4200, 43.7300), (7.4206, 43.7304), (7.4212, 43.7308), (7.4218, 43.7312)]
_TEXT_TIMES: dict[str, list[object]] = {
    "UTC": [f"2024-05-01T08:00:0{i}.25Z" for i in range(4)],
    "naive, space, unsorted": ["2024-05-01 08:00:09", "2024-05-01 08:00:01"],
    "offsets": ["2024-05-01T10:00:00+02:00", "2024-05-01T08:00:05Z"],
    "a day that does not exist": ["2024-02-30T08:00:00Z", "2024-02-28T08:00:00Z"],
    "leap second": ["2016-12-31T23:59:60Z", "2017-01-01T00:00:01Z"],
    "blank and missing": ["2024-05-01T08:00:00Z", "", None, "2024-05-01T08:00:03Z"],
    "numbers as text": ["1714550400", "1714550405"],
    "text and numbers": ["2024-05-01T08:00:00Z", 1714550405],
    "beyond 2262": ["2300-01-01T00:00:00Z", "2300-01-01T00:00:05Z"],
    "not a time": ["2024-05-01T08:00:00Z", "soon"],
}
_RECORD_CASES: dict[str, list[dict[str, object]]] = {
    "numbers": [{"time": 5 * i, "lon": x, "lat": y} for i, (x, y) in enumerate(_P)],
    "aliases any case, extra keys": [
        {"T": 5.0 * i, "LNG": x, "Latitude": y, "note": "x"} for i, (x, y) in enumerate(_P)
    ],
    "optional fields with gaps": [
        _record(time=5 * i, lon=x, lat=y, speed=None if i == 1 else 3.0, heading=-90)
        for i, (x, y) in enumerate(_P)
    ]
    + [{"time": 99, "lon": 7.43, "lat": 43.74, "accuracy": 4}],
    "a key missing in some points": [
        {"time": 5 * i, "lon": x, "lat": y, **({"odometer": 10.0 * i} if i % 2 else {})}
        for i, (x, y) in enumerate(_P)
    ],
    "ns epochs as ints": [
        {"time": (1_714_550_400 + i) * 10**9 + 7, "lon": x, "lat": y} for i, (x, y) in enumerate(_P)
    ],
    "no times": [_record(time=None, lon=x, lat=y) for x, y in _P],
    "unsorted and repeated": [
        {"time": t, "lon": 7.42, "lat": 43.73 + t * 1e-4} for t in (5, 0, 5, 5)
    ],
    "some times blank": [
        {"time": None if i == 2 else i, "lon": x, "lat": y} for i, (x, y) in enumerate(_P)
    ],
    "lat out of range": [{"time": i, "lon": x, "lat": 95.0} for i, (x, _) in enumerate(_P)],
    "infinite speed": [
        {"time": i, "lon": x, "lat": y, "speed": math.inf} for i, (x, y) in enumerate(_P)
    ],
    **{
        f"text times: {name}": [
            _record(time=stamps[i % len(stamps)], lon=x, lat=y) for i, (x, y) in enumerate(_P)
        ]
        for name, stamps in _TEXT_TIMES.items()
    },
    # these take the table path: ids, booleans, numpy scalars, two keys for one field, no
    # lon, one point
    "an id key": [{"trace_id": "a", "time": i, "lon": x, "lat": y} for i, (x, y) in enumerate(_P)],
    "boolean speed": [
        {"time": i, "lon": x, "lat": y, "speed": True} for i, (x, y) in enumerate(_P)
    ],
    "numpy scalars": [{"time": np.float64(i), "lon": x, "lat": y} for i, (x, y) in enumerate(_P)],
    "two keys for lon": [{"time": i, "lon": x, "lng": x, "lat": y} for i, (x, y) in enumerate(_P)],
    "no lon": [{"time": i, "lat": y} for i, (_, y) in enumerate(_P)],
    "one point": [{"time": 0, "lon": 7.42, "lat": 43.73}],
}


_TABLE_CASES = list(_RECORD_CASES)[list(_RECORD_CASES).index("an id key") :]


@pytest.mark.parametrize("case", list(_RECORD_CASES), ids=list(_RECORD_CASES))
def test_point_records_give_what_the_table_path_gives(case: str) -> None:
    records = _RECORD_CASES[case]
    # numbers only are validated from arrays, the rest through a table
    assert (record_columns(records) is None) == (case in _TABLE_CASES)

    def outcome(build: object) -> object:
        try:
            tr = build()  # type: ignore[operator]
        except MapMatchError as exc:
            return (type(exc), str(exc), getattr(exc, "field", None), getattr(exc, "rows", None))
        fields = ("time_s", "lon", "lat", "heading_deg", "speed_mps", "accuracy_m", "odometer_m")
        values = [None if (v := getattr(tr, f)) is None else v.tobytes() for f in fields]
        return (tr.trace_id, values, tr.segment_starts.tolist(), tr.report)

    fast = outcome(lambda: Trace.from_records(records, trace_id="bus", crs="gcj02"))
    table = pd.DataFrame.from_records(records)
    reference = outcome(lambda: Trace.from_dataframe(table, trace_id="bus", crs="gcj02"))
    assert fast == reference


@pytest.mark.parametrize("case", list(_RECORD_CASES), ids=list(_RECORD_CASES))
def test_points_read_by_column_give_what_the_point_by_point_walk_gives(case: str) -> None:
    records = _RECORD_CASES[case]
    walked = record_columns([MappingProxyType(r) for r in records])  # not dicts: the walk
    by_column = record_columns(records)
    assert (by_column is None) == (walked is None)
    if by_column is not None and walked is not None:
        assert list(by_column) == list(walked)
        for field, values in by_column.items():
            other = walked[field]
            if isinstance(values, np.ndarray):
                assert isinstance(other, np.ndarray)
                assert values.tobytes() == other.tobytes(), field
            else:
                assert values == other, field


def test_plain_utc_text_times_and_numbers_need_no_pandas(monkeypatch: pytest.MonkeyPatch) -> None:
    for module, name in (("checks", "as_series"), ("times", "_parse_with_pandas")):
        monkeypatch.setattr(f"mapmatch.trace.{module}.{name}", _no_pandas)
    monkeypatch.setattr(pd.DataFrame, "from_records", _no_pandas)
    for case in ("numbers", "optional fields with gaps", "text times: UTC"):
        tr = Trace.from_records(_RECORD_CASES[case])
        assert len(tr) >= 4
    tr = Trace.from_records(_RECORD_CASES["text times: naive, space, unsorted"])
    assert tr.report.time_unit == "iso"
    assert tr.report.reordered_rows == 2
    assert np.diff(tr.time_s).tolist() == [0.0, 8.0, 0.0]


def test_a_trace_shares_no_memory_with_the_frame_it_was_read_from() -> None:
    # number columns are read without pandas' checks, but copied: changing the caller's
    # frame afterwards (in place, numpy-style) leaves the trace as it was read
    df = pd.DataFrame(
        {
            "time": np.arange(5, dtype=np.int64) + 1_700_000_000,
            "lat": np.linspace(43.73, 43.74, 5),
            "lon": np.full(5, 7.42),
            "speed": np.full(5, 3.0, dtype=np.float32),
        },
        index=[10, 11, 12, 13, 14],
    )
    trace = Trace.from_dataframe(df)
    assert trace.speed_mps is not None
    speed = trace.speed_mps
    before = (trace.time_s.copy(), trace.lat.copy(), trace.lon.copy(), speed.copy())
    for column in df.columns:
        with contextlib.suppress(ValueError):  # pandas >= 3 hands out read-only buffers
            df[column].to_numpy()[:] = 0  # writes through where pandas hands out its buffer
        df.loc[12, column] = 1
    assert [a.tolist() for a in before] == [
        trace.time_s.tolist(),
        trace.lat.tolist(),
        trace.lon.tolist(),
        trace.speed_mps.tolist(),
    ]
    assert trace.time_s.tolist() == [1_700_000_000.0 + i for i in range(5)]
