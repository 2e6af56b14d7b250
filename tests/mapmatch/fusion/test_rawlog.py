from __future__ import annotations

from pathlib import Path  # noqa: TC003

import numpy as np
import pandas as pd
import pytest

from mapmatch import MapMatchError
from mapmatch.fusion import NoGnssFixError, RawLog, RawLogError, RawLogNotFoundError
from mapmatch.trace.chinacrs import wgs84_to_bd09, wgs84_to_gcj02


def _frame(n: int = 5) -> pd.DataFrame:
    lat = np.full(n, np.nan)
    lon = np.full(n, np.nan)
    lat[0], lon[0] = 39.9, 116.4
    lat[-1], lon[-1] = 39.9001, 116.4001
    return pd.DataFrame(
        {
            "time": 1_700_000_000.0 + 0.1 * np.arange(n),
            "odo_speed_mps": np.full(n, 10.0),
            "gyro_z_dps": np.zeros(n),
            "lat": lat,
            "lon": lon,
            "hdop": np.where(np.isfinite(lat), 0.9, np.nan),
            "sats": np.where(np.isfinite(lat), 9.0, np.nan),
        }
    )


def test_valid_frame_round_trip() -> None:
    raw = RawLog.from_dataframe(_frame())
    assert len(raw) == 5
    assert raw.has_fix.tolist() == [True, False, False, False, True]
    assert np.isnan(raw.gnss_course_deg).all()  # optional column absent


def test_column_names_case_insensitive_and_aliases() -> None:
    df = _frame().rename(
        columns={"time": "Timestamp", "lat": "Latitude", "lon": "LNG", "gyro_z_dps": "GYRO_Z_DPS"}
    )
    raw = RawLog.from_dataframe(df)
    assert raw.lat[0] == 39.9
    assert raw.lon[-1] == 116.4001


def test_iso_time_is_parsed_to_epoch_seconds() -> None:
    df = _frame(2)
    df["time"] = ["2024-05-01T08:00:00Z", "2024-05-01T08:00:00.100Z"]
    raw = RawLog.from_dataframe(df)
    assert raw.time_s[0] == pytest.approx(1714550400.0)
    assert raw.time_s[1] - raw.time_s[0] == pytest.approx(0.1)


def test_missing_columns_are_named() -> None:
    df = _frame().drop(columns=["gyro_z_dps", "odo_speed_mps"])
    with pytest.raises(RawLogError, match=r"gyro_z_dps.*odo_speed_mps \(or odo_count\)") as exc:
        RawLog.from_dataframe(df, source="trip.csv")
    assert isinstance(exc.value, MapMatchError)
    assert isinstance(exc.value, ValueError)
    assert "trip.csv" in str(exc.value)


def test_time_going_backwards_names_row_and_values() -> None:
    df = _frame()
    df.loc[3, "time"] = df.loc[1, "time"]
    with pytest.raises(RawLogError, match=r"not strictly increasing at row 3 .*'time'") as exc:
        RawLog.from_dataframe(df)
    assert "sort the log" in str(exc.value)


def test_unparsable_time_names_row() -> None:
    df = _frame()
    df["time"] = df["time"].astype(object)
    df.loc[2, "time"] = "yesterday"
    with pytest.raises(RawLogError, match=r"row 2: field 'time' value 'yesterday'"):
        RawLog.from_dataframe(df)


def test_no_gnss_fix_at_all() -> None:
    df = _frame()
    df["lat"] = np.nan
    df["lon"] = np.nan
    with pytest.raises(NoGnssFixError, match="no usable GNSS fix"):
        RawLog.from_dataframe(df)


def test_half_a_fix_is_an_error() -> None:
    df = _frame()
    df.loc[2, "lat"] = 39.9
    with pytest.raises(RawLogError, match="row 2 has only half a fix"):
        RawLog.from_dataframe(df)


def test_swapped_coordinates_out_of_range() -> None:
    df = _frame()
    df.loc[0, ["lat", "lon"]] = [116.4, 39.9]
    with pytest.raises(RawLogError, match=r"row 0 has coordinates out of range.*swapped"):
        RawLog.from_dataframe(df)


def test_missing_gyro_value_names_row() -> None:
    df = _frame()
    df.loc[4, "gyro_z_dps"] = np.nan
    with pytest.raises(RawLogError, match=r"row 4: field 'gyro_z_dps' is empty"):
        RawLog.from_dataframe(df)


def test_odometer_counts_to_speed() -> None:
    df = _frame().drop(columns=["odo_speed_mps"])
    df["odo_count"] = [0, 4, 8, 12, 16]  # 4 pulses per 0.1 s at 4 pulses/m = 10 m/s
    raw = RawLog.from_dataframe(df, pulses_per_m=4.0)
    np.testing.assert_allclose(raw.odo_speed_mps, [0.0, 10.0, 10.0, 10.0, 10.0], rtol=1e-5)
    assert raw.pulses_per_m == 4.0


def test_odometer_counts_going_backwards() -> None:
    df = _frame().drop(columns=["odo_speed_mps"])
    df["odo_count"] = [0, 4, 8, 7, 16]
    with pytest.raises(RawLogError, match=r"odometer count goes backwards at row 3.*8.* then 7"):
        RawLog.from_dataframe(df, pulses_per_m=4.0)


def test_odometer_counts_need_pulses_per_m() -> None:
    df = _frame().drop(columns=["odo_speed_mps"])
    df["odo_count"] = [0, 4, 8, 12, 16]
    with pytest.raises(RawLogError, match="pulses_per_m"):
        RawLog.from_dataframe(df)


@pytest.mark.parametrize(("crs", "forward"), [("gcj02", wgs84_to_gcj02), ("bd09", wgs84_to_bd09)])
def test_chinese_frames_are_converted_to_wgs84(crs, forward) -> None:
    df = _frame()
    fix = df["lat"].notna()
    df.loc[fix, "lon"], df.loc[fix, "lat"] = forward(df.loc[fix, "lon"], df.loc[fix, "lat"])
    assert abs(df.loc[0, "lon"] - 116.4) > 1e-3  # really shifted by hundreds of metres
    raw = RawLog.from_dataframe(df, crs=crs)
    assert raw.lon[0] == pytest.approx(116.4, abs=1e-8)
    assert raw.lat[-1] == pytest.approx(39.9001, abs=1e-8)
    assert raw.source_crs == crs


def test_unknown_crs() -> None:
    with pytest.raises(RawLogError, match="unknown crs 'utm'"):
        RawLog.from_dataframe(_frame(), crs="utm")  # type: ignore[arg-type]


def test_from_file_csv_and_parquet(tmp_path: Path) -> None:
    df = _frame()
    df.to_csv(tmp_path / "raw.csv", index=False)
    df.to_parquet(tmp_path / "raw.parquet")
    a = RawLog.from_file(tmp_path / "raw.csv")
    b = RawLog.from_file(tmp_path / "raw.parquet")
    np.testing.assert_array_equal(a.time_s, b.time_s)
    np.testing.assert_array_equal(a.lat, b.lat)
    assert a.source == "raw.csv"


def test_from_file_missing() -> None:
    with pytest.raises(RawLogNotFoundError, match="does not exist") as exc:
        RawLog.from_file("/no/such/raw.csv")
    assert isinstance(exc.value, FileNotFoundError)
