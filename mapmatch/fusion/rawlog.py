"""
Raw sensor logs: the validated input of the fusion front-end.

Layout (one row per sensor epoch, typically 10 Hz, sorted by time; column names are matched
case-insensitively; GNSS columns are empty on rows without a fix):

==================  ======================================================================
column              meaning
==================  ======================================================================
``time``            ISO-8601 or epoch seconds (aliases ``t``, ``timestamp``); strictly
                    increasing
``odo_speed_mps``   wheel-odometer speed over the interval since the previous row, m/s
``odo_count``       instead of ``odo_speed_mps``: cumulative odometer pulses (never
                    decreasing); needs ``pulses_per_m``
``gyro_z_dps``      yaw rate, deg/s, positive = turning left (counter-clockwise seen from
                    above), mean over the interval since the previous row
``lat``, ``lon``    GNSS fix, degrees; WGS84 unless ``crs`` says ``gcj02``/``bd09``
                    (aliases ``latitude``; ``lng``, ``longitude``)
``hdop``            horizontal dilution of precision of the fix (optional)
``sats``            satellites used in the fix (optional; alias ``num_sats``)
``gnss_speed_mps``  receiver speed over ground, m/s (optional)
``gnss_course_deg`` receiver course over ground, degrees clockwise from north (optional)
==================  ======================================================================

The sensor values on row ``k`` describe the interval ``(t[k-1], t[k]]``; a GNSS fix on row ``k``
is the position at ``t[k]``. Rows are numbered from 0 (the first data row) in error messages.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np
import pandas as pd

from mapmatch.fusion.errors import NoGnssFixError, RawLogError, RawLogNotFoundError
from mapmatch.trace.chinacrs import bd09_to_wgs84, gcj02_to_wgs84

if TYPE_CHECKING:
    import numpy.typing as npt

    FloatArray = npt.NDArray[np.float64]

__all__ = ["Crs", "RawLog"]

Crs = Literal["wgs84", "gcj02", "bd09"]

_ALIASES: dict[str, tuple[str, ...]] = {
    "time": ("time", "t", "timestamp"),
    "odo_speed_mps": ("odo_speed_mps",),
    "odo_count": ("odo_count",),
    "gyro_z_dps": ("gyro_z_dps",),
    "lat": ("lat", "latitude"),
    "lon": ("lon", "lng", "longitude"),
    "hdop": ("hdop",),
    "sats": ("sats", "num_sats"),
    "gnss_speed_mps": ("gnss_speed_mps",),
    "gnss_course_deg": ("gnss_course_deg",),
}


@dataclass(frozen=True, slots=True, eq=False)
class RawLog:
    """
    A validated raw sensor log; arrays of equal length ``n``, one entry per sensor epoch.

    Build it with :meth:`from_file` or :meth:`from_dataframe`, which check every field; the
    plain constructor trusts its arguments.

    Attributes
    ----------
    time_s
        Epoch seconds, strictly increasing.
    odo_speed_mps
        Odometer speed over the interval ending at each row (0.0 on row 0 for pulse counts).
    gyro_z_dps
        Yaw rate in deg/s, counter-clockwise positive.
    lon, lat
        GNSS fix in WGS84 degrees (already converted from GCJ-02/BD-09); NaN without a fix.
    hdop, sats
        Fix quality; NaN where unknown or without a fix.
    gnss_speed_mps, gnss_course_deg
        Receiver velocity (course clockwise from north); NaN where not given.
    source
        Name of the log in error messages (file name or ``"<dataframe>"``).
    source_crs
        The frame the fixes were given in before conversion.
    pulses_per_m
        Odometer pulses per metre when the speed came from ``odo_count`` (sets the
        quantisation noise the filter assumes), else None.
    """

    time_s: FloatArray
    odo_speed_mps: FloatArray
    gyro_z_dps: FloatArray
    lon: FloatArray
    lat: FloatArray
    hdop: FloatArray
    sats: FloatArray
    gnss_speed_mps: FloatArray
    gnss_course_deg: FloatArray
    source: str = "<arrays>"
    source_crs: Crs = "wgs84"
    pulses_per_m: float | None = None

    def __len__(self) -> int:
        return int(self.time_s.shape[0])

    @property
    def has_fix(self) -> npt.NDArray[np.bool_]:
        """Rows that carry a GNSS position."""
        return np.isfinite(self.lon) & np.isfinite(self.lat)

    @classmethod
    def from_file(
        cls, path: str | Path, *, crs: Crs = "wgs84", pulses_per_m: float | None = None
    ) -> RawLog:
        """
        Read and validate a raw log from CSV (``.csv``, ``.csv.gz``, ``-`` for stdin) or Parquet.

        Parameters
        ----------
        path
            File path; ``"-"`` reads CSV from standard input.
        crs
            Frame of the ``lat``/``lon`` columns: ``"wgs84"``, ``"gcj02"`` or ``"bd09"``.
        pulses_per_m
            Odometer pulses per metre, needed when the log has ``odo_count`` instead of
            ``odo_speed_mps``.

        Raises
        ------
        RawLogNotFoundError
            The file does not exist.
        RawLogError
            The content is invalid (see :meth:`from_dataframe`).
        """
        name = str(path)
        if name == "-":
            df = pd.read_csv(sys.stdin)
            return cls.from_dataframe(df, crs=crs, pulses_per_m=pulses_per_m, source="<stdin>")
        p = Path(path)
        if not p.exists():
            raise RawLogNotFoundError(name)
        suffixes = "".join(p.suffixes).lower()
        try:
            df = pd.read_parquet(p) if suffixes.endswith((".parquet", ".pq")) else pd.read_csv(p)
        except (ValueError, OSError, pd.errors.ParserError) as exc:
            raise RawLogError(
                name, f"cannot be read as CSV/Parquet ({exc})", "check the file format"
            ) from exc
        return cls.from_dataframe(df, crs=crs, pulses_per_m=pulses_per_m, source=p.name)

    @classmethod
    def from_dataframe(
        cls,
        df: pd.DataFrame,
        *,
        crs: Crs = "wgs84",
        pulses_per_m: float | None = None,
        source: str = "<dataframe>",
    ) -> RawLog:
        """
        Validate a raw log given as a DataFrame (layout in the module docstring).

        Parameters
        ----------
        df
            One row per sensor epoch.
        crs
            Frame of the ``lat``/``lon`` columns: ``"wgs84"``, ``"gcj02"`` or ``"bd09"``.
        pulses_per_m
            Odometer pulses per metre, for ``odo_count`` logs.
        source
            Name used in error messages.

        Raises
        ------
        RawLogError
            Missing column, unparsable or non-increasing time, non-finite sensor value,
            odometer count going backwards, coordinates out of range, half a fix.
        NoGnssFixError
            No row carries a GNSS fix.

        Examples
        --------
        >>> df = pd.DataFrame({"time": [0.0, 0.1], "odo_speed_mps": [0.0, 0.0],
        ...                    "gyro_z_dps": [0.0, 0.0], "lat": [39.9, None],
        ...                    "lon": [116.4, None], "hdop": [0.9, None], "sats": [9, None]})
        >>> len(RawLog.from_dataframe(df))
        2
        """
        if crs not in ("wgs84", "gcj02", "bd09"):
            raise RawLogError(source, f"unknown crs {crs!r}", "use 'wgs84', 'gcj02' or 'bd09'")
        cols = _resolve_columns(df, source)
        n = len(df)
        if n < 2:
            raise RawLogError(source, f"has {n} row(s)", "a raw log needs at least two epochs")
        time_s = _parse_time(df[cols["time"]], source, cols["time"])
        bad = np.flatnonzero(np.diff(time_s) <= 0.0)
        if bad.size:
            i = int(bad[0]) + 1
            raise RawLogError(
                source,
                f"time is not strictly increasing at row {i} (field {cols['time']!r}: "
                f"{float(time_s[i - 1])!r} then {float(time_s[i])!r})",
                "sort the log by time and drop duplicate epochs",
            )
        gyro = _numeric(df, cols["gyro_z_dps"], source, required=True)
        if "odo_speed_mps" in cols:
            odo = _numeric(df, cols["odo_speed_mps"], source, required=True)
        else:
            odo = _speed_from_counts(df, cols["odo_count"], time_s, source, pulses_per_m)
        lat = _numeric(df, cols["lat"], source, required=False)
        lon = _numeric(df, cols["lon"], source, required=False)
        half = np.flatnonzero(np.isfinite(lat) != np.isfinite(lon))
        if half.size:
            i = int(half[0])
            raise RawLogError(
                source,
                f"row {i} has only half a fix (lat={float(lat[i])!r}, lon={float(lon[i])!r})",
                "give both lat and lon or leave both empty",
            )
        fix = np.isfinite(lat)
        if not fix.any():
            raise NoGnssFixError(source, "every lat/lon cell is empty")
        out = np.flatnonzero(fix & ((np.abs(lat) > 90.0) | (np.abs(lon) > 180.0)))
        if out.size:
            i = int(out[0])
            raise RawLogError(
                source,
                f"row {i} has coordinates out of range "
                f"(lat={float(lat[i])!r}, lon={float(lon[i])!r})",
                "lat must be in [-90, 90] and lon in [-180, 180]; swapped columns?",
            )
        hdop = _optional(df, cols, "hdop", source, n)
        sats = _optional(df, cols, "sats", source, n)
        for name, arr in (("hdop", hdop), ("sats", sats)):
            neg = np.flatnonzero(arr < 0.0)
            if neg.size:
                i = int(neg[0])
                raise RawLogError(
                    source,
                    f"row {i} has a negative {name} ({float(arr[i])!r})",
                    f"{name} must be >= 0; leave it empty when unknown",
                )
        g_speed = _optional(df, cols, "gnss_speed_mps", source, n)
        g_course = _optional(df, cols, "gnss_course_deg", source, n)
        if crs == "gcj02":
            lon[fix], lat[fix] = gcj02_to_wgs84(lon[fix], lat[fix])
        elif crs == "bd09":
            lon[fix], lat[fix] = bd09_to_wgs84(lon[fix], lat[fix])
        return cls(
            time_s=time_s,
            odo_speed_mps=odo,
            gyro_z_dps=gyro,
            lon=lon,
            lat=lat,
            hdop=hdop,
            sats=sats,
            gnss_speed_mps=g_speed,
            gnss_course_deg=g_course,
            source=source,
            source_crs=crs,
            pulses_per_m=None if "odo_speed_mps" in cols else pulses_per_m,
        )


def _resolve_columns(df: pd.DataFrame, source: str) -> dict[str, str]:
    lower = {str(c).strip().lower(): str(c) for c in df.columns}
    found: dict[str, str] = {}
    for canonical, aliases in _ALIASES.items():
        for alias in aliases:
            if alias in lower:
                found[canonical] = lower[alias]
                break
    missing = [c for c in ("time", "gyro_z_dps", "lat", "lon") if c not in found]
    if "odo_speed_mps" not in found and "odo_count" not in found:
        missing.append("odo_speed_mps (or odo_count)")
    if missing:
        have = ", ".join(map(str, df.columns)) or "none"
        raise RawLogError(
            source,
            f"missing column(s) {', '.join(missing)} (columns present: {have})",
            "see mapmatch.fusion.rawlog for the raw log layout; names are case-insensitive",
        )
    return found


def _parse_time(col: pd.Series, source: str, name: str) -> FloatArray:
    numeric = pd.to_numeric(col, errors="coerce")
    parsed = pd.to_datetime(col.astype(str), errors="coerce", utc=True, format="ISO8601")
    is_num = numeric.notna().to_numpy()
    is_iso = parsed.notna().to_numpy() & ~is_num
    bad = np.flatnonzero(~(is_num | is_iso))
    if bad.size or (is_num.any() and is_iso.any()):
        i = int(bad[0]) if bad.size else int(np.flatnonzero(is_iso)[0])
        raise RawLogError(
            source,
            f"row {i}: field {name!r} value {col.iloc[i]!r} is not a time"
            + ("" if bad.size else " of the same kind as row 0"),
            "use ISO-8601 (2024-05-01T08:00:00.1Z) or epoch seconds, the same on every row",
        )
    if is_num.all():
        t = numeric.to_numpy(dtype=np.float64)
    else:
        ns = parsed.dt.tz_convert("UTC").dt.tz_localize(None).to_numpy(dtype="datetime64[ns]")
        t = ns.astype(np.int64).astype(np.float64) / 1e9
    bad_t = np.flatnonzero(~np.isfinite(t))
    if bad_t.size:
        i = int(bad_t[0])
        raise RawLogError(
            source, f"row {i}: field {name!r} is not finite ({float(t[i])!r})", "fill in every time"
        )
    return t


def _numeric(df: pd.DataFrame, name: str, source: str, *, required: bool) -> FloatArray:
    col = df[name]
    values = pd.to_numeric(col, errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan)
    garbage = np.flatnonzero(np.isnan(values) & col.notna().to_numpy())
    if garbage.size:
        i = int(garbage[0])
        raise RawLogError(
            source, f"row {i}: field {name!r} value {col.iloc[i]!r} is not a number", "fix it"
        )
    if required:
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            i = int(bad[0])
            raise RawLogError(
                source,
                f"row {i}: field {name!r} is empty or not finite ({float(values[i])!r})",
                "every sensor row needs odometer and gyro values; interpolate short gaps",
            )
    return values.copy()


def _optional(df: pd.DataFrame, cols: dict[str, str], key: str, source: str, n: int) -> FloatArray:
    if key not in cols:
        return np.full(n, np.nan)
    return _numeric(df, cols[key], source, required=False)


def _speed_from_counts(
    df: pd.DataFrame, name: str, time_s: FloatArray, source: str, pulses_per_m: float | None
) -> FloatArray:
    if pulses_per_m is None or not (np.isfinite(pulses_per_m) and pulses_per_m > 0.0):
        raise RawLogError(
            source,
            f"column {name!r} holds odometer pulses but pulses_per_m is {pulses_per_m!r}",
            "pass pulses_per_m=<pulses per metre> (CLI: --pulses-per-m)",
        )
    counts = _numeric(df, name, source, required=True)
    step = np.diff(counts)
    back = np.flatnonzero(step < 0.0)
    if back.size:
        i = int(back[0]) + 1
        raise RawLogError(
            source,
            f"odometer count goes backwards at row {i} (field {name!r}: "
            f"{float(counts[i - 1])!r} then {float(counts[i])!r})",
            "odo_count must be cumulative; unwrap counter roll-overs before fusing",
        )
    speed = np.zeros_like(counts)
    speed[1:] = step / pulses_per_m / np.diff(time_s)
    return speed
