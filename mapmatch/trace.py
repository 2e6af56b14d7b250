"""
The trace input stage: validate, sort and report one vehicle trace.

A :class:`Trace` holds the fused positions of one vehicle as float64 numpy arrays in WGS84,
sorted by strictly increasing time. It is built from arrays (``Trace(time=..., lon=..., lat=...)``),
a pandas DataFrame, a list of point dicts (the HTTP JSON body) or a file; :func:`read_traces`
reads a file holding many traces. The file formats live in :mod:`mapmatch.trace_readers`.

Validation happens once, here. A row that breaks a rule raises
:class:`~mapmatch.errors.InvalidTraceError` naming the trace, the rows (0-based input row and,
for files, the 1-based line or record), the field and the value, and suggesting a fix. Rows out
of time order are stably sorted and rows repeating an earlier time are collapsed (the first
kept); both are listed in :attr:`Trace.report`, never silently dropped and never an error.

Input columns (case-insensitive; unknown columns are ignored)
-------------------------------------------------------------
``trace_id``; ``time`` (``t``, ``timestamp``); ``lat`` (``latitude``); ``lon`` (``lng``,
``longitude``); optional ``heading`` (``bearing``, ``course``, ``heading_deg``), ``speed``
(``speed_mps``), ``accuracy`` (``accuracy_m``), ``hdop``, ``odometer`` (``odometer_m``).
"""

from __future__ import annotations

import logging
import os
from bisect import bisect_right
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final, cast

import numpy as np
import numpy.typing as npt
import pandas as pd

from mapmatch import chinacrs
from mapmatch.errors import InvalidTraceError, TraceFileError
from mapmatch.trace_readers import RawTrace, read_raw_traces

if TYPE_CHECKING:
    from collections.abc import Iterable
    from typing import Self

__all__ = [
    "FIELD_ALIASES",
    "SUPPORTED_CRS",
    "UERE_M",
    "FloatArray",
    "Trace",
    "TraceReport",
    "read_traces",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

UERE_M: Final = 5.0
"""User-equivalent range error in metres: ``accuracy_m = hdop * UERE_M`` when only HDOP is known.

5 m is a typical 1-sigma UERE of a single-frequency automotive GNSS receiver."""

SUPPORTED_CRS: Final = ("wgs84", "gcj02", "bd09")
"""Coordinate frames a trace may arrive in; GCJ-02 and BD-09 are converted to WGS84."""

FIELD_ALIASES: Final[Mapping[str, tuple[str, ...]]] = {
    "trace_id": ("trace_id",),
    "time": ("time", "t", "timestamp"),
    "lat": ("lat", "latitude"),
    "lon": ("lon", "lng", "longitude"),
    "heading": ("heading", "bearing", "course", "heading_deg"),
    "speed": ("speed", "speed_mps"),
    "accuracy": ("accuracy", "accuracy_m"),
    "hdop": ("hdop",),
    "odometer": ("odometer", "odometer_m"),
}
"""Canonical field -> accepted column names (matched case-insensitively)."""

_ALIAS_TO_FIELD = {alias: field for field, aliases in FIELD_ALIASES.items() for alias in aliases}
_REQUIRED = ("time", "lat", "lon")
_OPTIONAL = ("heading", "speed", "accuracy", "hdop", "odometer")
_SHOW = 5  # offending rows quoted in a message
_EPOCH_MS_LIMIT = 1e11  # epoch seconds beyond year 5000 are almost surely milliseconds
_log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class TraceReport:
    """
    What validation did to a trace's input rows; nothing is changed silently.

    Attributes
    ----------
    input_rows
        Rows given, before sorting and collapsing.
    reordered_rows
        Rows that were out of time order and had to move: the input length minus the longest
        run of rows already in (non-decreasing) time order. The sort is stable.
    duplicate_time_rows
        0-based input rows dropped because their time equals an earlier row's time; the first
        input row with each time is kept.
    warnings
        One human-readable sentence per finding, empty for a clean trace.
    """

    input_rows: int
    reordered_rows: int
    duplicate_time_rows: tuple[int, ...]
    warnings: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class _Origin:
    """Where input rows came from, to point at them in messages."""

    source: str | None = None  # file (and track) name
    label: str = "line"  # what ``numbers`` count
    numbers: IntArray | None = None  # 1-based number of each input row in the source


class Trace:
    """
    One vehicle trace, validated, sorted by time, in WGS84.

    Parameters
    ----------
    time
        Epoch seconds (int/float), ISO-8601 strings (with or without zone; naive = UTC), or
        numpy ``datetime64`` / pandas Timestamps.
    lon, lat
        Position in degrees, in the frame named by ``crs``.
    heading
        Degrees clockwise from north; normalised to ``[0, 360)``; non-finite = unknown (NaN).
    speed
        Metres per second, ``>= 0``; NaN = unknown.
    accuracy
        1-sigma horizontal position error in metres, ``> 0``; NaN = unknown.
    hdop
        Horizontal dilution of precision, ``> 0``; fills unknown accuracy as
        ``hdop * UERE_M`` (:data:`UERE_M` = 5 m).
    odometer
        Cumulative fused distance in metres, must not decrease in time; NaN = unknown.
    trace_id
        Name of the trace, used in every message and output.
    crs
        ``"wgs84"`` (default), ``"gcj02"`` or ``"bd09"``; the latter two are converted to WGS84.

    Attributes
    ----------
    trace_id : str
    time_s, lon, lat : FloatArray
        Epoch seconds (strictly increasing) and WGS84 degrees.
    heading_deg, speed_mps, accuracy_m, odometer_m : FloatArray or None
        ``None`` when not given; NaN marks an unknown value in a row.
    report : TraceReport
        Rows sorted or collapsed, with warnings.

    Raises
    ------
    InvalidTraceError
        A rule is broken; the message names the rows, the field, the value and a fix.

    Examples
    --------
    >>> tr = Trace(time=[0, 2, 1, 2], lon=[7.42, 7.44, 7.43, 7.45], lat=[43.73] * 4, trace_id="a")
    >>> tr.time_s.tolist(), tr.lon.tolist()
    ([0.0, 1.0, 2.0], [7.42, 7.43, 7.44])
    >>> tr.report.duplicate_time_rows
    (3,)
    """

    __slots__ = (
        "accuracy_m",
        "heading_deg",
        "lat",
        "lon",
        "odometer_m",
        "report",
        "speed_mps",
        "time_s",
        "trace_id",
    )

    trace_id: str
    time_s: FloatArray
    lon: FloatArray
    lat: FloatArray
    heading_deg: FloatArray | None
    speed_mps: FloatArray | None
    accuracy_m: FloatArray | None
    odometer_m: FloatArray | None
    report: TraceReport

    def __init__(
        self,
        *,
        time: object,
        lon: object,
        lat: object,
        heading: object = None,
        speed: object = None,
        accuracy: object = None,
        hdop: object = None,
        odometer: object = None,
        trace_id: str = "trace",
        crs: str = "wgs84",
    ) -> None:
        columns = {
            "time": time,
            "lon": lon,
            "lat": lat,
            "heading": heading,
            "speed": speed,
            "accuracy": accuracy,
            "hdop": hdop,
            "odometer": odometer,
        }
        self._validate(columns, trace_id=trace_id, crs=crs, origin=_Origin())

    # ------------------------------------------------------------------ constructors

    @classmethod
    def from_dataframe(
        cls, df: pd.DataFrame, *, trace_id: str | None = None, crs: str = "wgs84"
    ) -> Self:
        """
        Build one trace from a table with the input columns (aliases, any case).

        Parameters
        ----------
        df
            One row per fix. A ``trace_id`` column, if present, must hold a single id.
        trace_id
            Name of the trace; default: the ``trace_id`` column's value, else ``"trace"``.
        crs
            Frame of ``lon``/``lat``: ``"wgs84"``, ``"gcj02"`` or ``"bd09"``.

        Returns
        -------
        Trace

        Raises
        ------
        InvalidTraceError
            A required column is missing, two columns alias one field, the ``trace_id``
            column holds several ids, or a row breaks a rule.
        """
        return cls._from_frame(df, trace_id=trace_id, crs=crs, origin=_Origin())

    @classmethod
    def from_records(
        cls,
        records: Sequence[Mapping[str, object]],
        *,
        trace_id: str = "trace",
        crs: str = "wgs84",
    ) -> Self:
        """
        Build one trace from point objects, as in the JSON body of ``POST /v1/match``.

        Parameters
        ----------
        records
            One mapping per fix with the input fields as keys (aliases, any case); missing
            optional keys mean unknown.
        trace_id
            Name of the trace.
        crs
            Frame of ``lon``/``lat``: ``"wgs84"``, ``"gcj02"`` or ``"bd09"``.

        Returns
        -------
        Trace

        Examples
        --------
        >>> pts = [{"t": 0, "lat": 43.73, "lng": 7.42}, {"t": 5, "lat": 43.74, "lng": 7.42}]
        >>> Trace.from_records(pts, trace_id="bus").time_s.tolist()
        [0.0, 5.0]
        """
        bad = [i for i, rec in enumerate(records) if not isinstance(rec, Mapping)]
        if bad:
            msg = (
                f"trace {trace_id!r}: record {bad[0]} is a {type(records[bad[0]]).__name__}, "
                'not an object; send each point as {"time": ..., "lat": ..., "lon": ...}'
            )
            raise InvalidTraceError(msg, trace_id=trace_id, rows=bad)
        frame = pd.DataFrame.from_records(list(records))
        return cls._from_frame(frame, trace_id=trace_id, crs=crs, origin=_Origin(label="record"))

    @classmethod
    def from_file(cls, path: str | os.PathLike[str], *, crs: str = "wgs84") -> Self:
        """
        Read the one trace of a file (CSV, GPX, GeoJSON, Parquet or JSON).

        Parameters
        ----------
        path
            The file; its suffix names the format (see :func:`read_traces`).
        crs
            Frame of the coordinates in the file.

        Returns
        -------
        Trace

        Raises
        ------
        TraceFileError
            The file cannot be read, or holds more than one trace (use :func:`read_traces`).
        InvalidTraceError
            A row breaks a rule.
        """
        raws = read_raw_traces(path)
        if len(raws) != 1:
            ids = ", ".join(repr(r.trace_id) for r in raws[:_SHOW])
            more = f" and {len(raws) - _SHOW} more" if len(raws) > _SHOW else ""
            msg = (
                f"trace file {os.fspath(path)!r} holds {len(raws)} traces ({ids}{more}); "
                "Trace.from_file reads exactly one, use mapmatch.read_traces for many"
            )
            raise TraceFileError(msg, path=os.fspath(path))
        return cls._from_raw(raws[0], crs=crs)

    @classmethod
    def _from_raw(cls, raw: RawTrace, *, crs: str) -> Self:
        origin = _Origin(source=raw.source, label=raw.label, numbers=raw.numbers)
        return cls._from_frame(raw.frame, trace_id=raw.trace_id, crs=crs, origin=origin)

    @classmethod
    def _from_frame(
        cls, df: pd.DataFrame, *, trace_id: str | None, crs: str, origin: _Origin
    ) -> Self:
        names = _resolve_columns(df.columns, trace_id=trace_id or "trace", origin=origin)
        if "trace_id" in names:
            trace_id = _single_trace_id(df[names["trace_id"]], trace_id, origin)
        tid = trace_id or "trace"
        missing = [f for f in _REQUIRED if f not in names]
        if missing:
            found = ", ".join(repr(str(c)) for c in df.columns) or "none"
            need = "; ".join(f"{f!r} (or {', '.join(FIELD_ALIASES[f][1:])})" for f in missing)
            msg = (
                f"trace {tid!r}{_in(origin)}: missing required column(s) {need}; "
                f"found columns: {found}; rename the columns (names are case-insensitive)"
            )
            raise InvalidTraceError(msg, trace_id=tid, field=missing[0])
        columns: dict[str, object] = {f: df[col] for f, col in names.items() if f != "trace_id"}
        self = cls.__new__(cls)
        self._validate(columns, trace_id=tid, crs=crs, origin=origin)
        return self

    # ------------------------------------------------------------------ validation

    def _validate(
        self, columns: Mapping[str, object], *, trace_id: str, crs: str, origin: _Origin
    ) -> None:
        tid = str(trace_id)
        crs_key = str(crs).strip().lower()
        if crs_key not in SUPPORTED_CRS:
            msg = f"trace {tid!r}: unknown crs {crs!r}; use one of {', '.join(SUPPORTED_CRS)}"
            raise InvalidTraceError(msg, trace_id=tid, field="crs")
        given = {f: v for f, v in columns.items() if v is not None}
        n = _check_lengths(given, tid)
        chk = _Checker(tid, origin)

        time_s = _parse_time(given["time"], chk)
        lat = chk.numeric(given["lat"], "lat")
        lon = chk.numeric(given["lon"], "lon")
        chk.coordinates(lon, lat)
        opt = {f: chk.numeric(given[f], f) for f in _OPTIONAL if f in given}

        heading = opt.get("heading")
        if heading is not None:
            finite = np.isfinite(heading)
            heading = np.where(finite, np.mod(np.where(finite, heading, 0.0), 360.0), np.nan)
            heading[heading >= 360.0] = 0.0  # np.mod(-1e-15, 360) rounds to 360.0
        speed = opt.get("speed")
        if speed is not None:
            chk.rule(speed, "speed", (speed < 0) | np.isinf(speed), "must be >= 0 m/s")
        accuracy = opt.get("accuracy")
        if accuracy is not None:
            chk.rule(accuracy, "accuracy", ~(accuracy > 0) & ~np.isnan(accuracy), "must be > 0 m")
            chk.rule(accuracy, "accuracy", np.isinf(accuracy), "must be finite")
        hdop = opt.get("hdop")
        if hdop is not None:
            chk.rule(hdop, "hdop", ~(hdop > 0) & ~np.isnan(hdop), "must be > 0")
            chk.rule(hdop, "hdop", np.isinf(hdop), "must be finite")
            from_hdop = hdop * UERE_M
            accuracy = (
                from_hdop if accuracy is None else np.where(np.isnan(accuracy), from_hdop, accuracy)
            )
        odometer = opt.get("odometer")
        if odometer is not None:
            chk.rule(odometer, "odometer", np.isinf(odometer), "must be finite (NaN = unknown)")

        if crs_key == "gcj02":
            lon, lat = chinacrs.gcj02_to_wgs84(lon, lat)
        elif crs_key == "bd09":
            lon, lat = chinacrs.bd09_to_wgs84(lon, lat)

        # Sort (stable) and collapse repeated times, keeping the first input row of each time.
        warnings: list[str] = []
        steps = np.diff(time_s)
        if np.all(steps >= 0):
            order = np.arange(n, dtype=np.int64)
            reordered = 0
        else:
            order = np.argsort(time_s, kind="stable").astype(np.int64)
            reordered = n - _longest_nondecreasing(time_s)
            first_back = int(np.flatnonzero(steps < 0)[0]) + 1
            warnings.append(
                f"{reordered} row{'s' if reordered != 1 else ''} out of time order "
                f"{'were' if reordered != 1 else 'was'} sorted (first step back in time at "
                f"{chk.where(first_back)})"
            )
        t_sorted = time_s[order]
        keep = np.ones(n, dtype=bool)
        keep[1:] = t_sorted[1:] != t_sorted[:-1]
        dup_rows = np.sort(order[~keep])
        if dup_rows.size:
            warnings.append(
                f"{chk.rows_phrase(dup_rows)} repeat{'s' if dup_rows.size == 1 else ''} an "
                "earlier time and " + ("was" if dup_rows.size == 1 else "were") + " collapsed "
                "(the first row with each time is kept)"
            )
        kept = order[keep]
        if kept.size < 2:
            extra = f" after collapsing {dup_rows.size} repeated time(s)" if dup_rows.size else ""
            msg = (
                f"trace {tid!r}{_in(origin)}: {kept.size} point(s){extra} from {n} input row(s); "
                "a trace needs at least 2 points with distinct times"
            )
            raise InvalidTraceError(msg, trace_id=tid, field="time", rows=dup_rows.tolist())

        if odometer is not None:
            odo = odometer[kept]
            known = np.flatnonzero(~np.isnan(odo))
            back = np.flatnonzero(np.diff(odo[known]) < 0)
            if back.size:
                later, earlier = kept[known[back + 1]], kept[known[back]]
                shown = ", ".join(
                    f"{chk.where(int(b))} = {odometer[b]:g} after {chk.where(int(a))} = "
                    f"{odometer[a]:g}"
                    for a, b in zip(earlier[:_SHOW], later[:_SHOW], strict=True)
                )
                more = f" and {later.size - _SHOW} more" if later.size > _SHOW else ""
                msg = (
                    f"trace {tid!r}{_in(origin)}: odometer decreases in time at {later.size} "
                    f"row(s): {shown}{more}; the odometer must be cumulative distance in metres "
                    "(fix or blank those values, NaN = unknown)"
                )
                raise InvalidTraceError(msg, trace_id=tid, field="odometer", rows=later.tolist())

        for text in warnings:
            _log.info("trace %r: %s", tid, text)
        self.trace_id = tid
        self.time_s = _frozen(time_s[kept])
        self.lon = _frozen(lon[kept])
        self.lat = _frozen(lat[kept])
        self.heading_deg = None if heading is None else _frozen(heading[kept])
        self.speed_mps = None if speed is None else _frozen(speed[kept])
        self.accuracy_m = None if accuracy is None else _frozen(accuracy[kept])
        self.odometer_m = None if odometer is None else _frozen(odometer[kept])
        self.report = TraceReport(
            input_rows=n,
            reordered_rows=int(reordered),
            duplicate_time_rows=tuple(int(r) for r in dup_rows),
            warnings=tuple(warnings),
        )

    # ------------------------------------------------------------------ views

    def __len__(self) -> int:
        """Return the number of points (after collapsing repeated times)."""
        return int(self.time_s.size)

    def __repr__(self) -> str:
        """Short summary: id, points and time span."""
        span = self.time_s[-1] - self.time_s[0]
        return f"Trace({self.trace_id!r}, {len(self)} points over {span:g} s)"

    def to_dataframe(self) -> pd.DataFrame:
        """
        Return the trace as a table.

        Returns
        -------
        pandas.DataFrame
            Columns ``time`` (float epoch seconds), ``lon``, ``lat`` (WGS84 degrees) and, where
            present, ``heading``, ``speed``, ``accuracy``, ``odometer``. ``Trace.from_dataframe``
            reads it back.
        """
        data: dict[str, FloatArray] = {"time": self.time_s, "lon": self.lon, "lat": self.lat}
        for name, values in (
            ("heading", self.heading_deg),
            ("speed", self.speed_mps),
            ("accuracy", self.accuracy_m),
            ("odometer", self.odometer_m),
        ):
            if values is not None:
                data[name] = values
        return pd.DataFrame({k: v.copy() for k, v in data.items()})

    def slice(self, start: int, stop: int) -> Trace:
        """
        Points ``start`` up to (not including) ``stop`` as a trace with the same id.

        Indices follow Python slicing (negative counts from the end). The new trace's report
        describes the slice only (no reordering, no repeated times).

        Raises
        ------
        InvalidTraceError
            The slice holds fewer than 2 points.

        Examples
        --------
        >>> tr = Trace(time=[0, 1, 2, 3], lon=[7.42, 7.43, 7.44, 7.45], lat=[43.73] * 4)
        >>> tr.slice(1, 3).time_s.tolist()
        [1.0, 2.0]
        """
        sel = slice(start, stop)
        count = len(range(len(self))[sel])
        if count < 2:
            msg = (
                f"trace {self.trace_id!r}: slice({start}, {stop}) of {len(self)} points holds "
                f"{count}; a trace needs at least 2 points"
            )
            raise InvalidTraceError(msg, trace_id=self.trace_id)
        out = Trace.__new__(Trace)
        out.trace_id = self.trace_id
        out.time_s = self.time_s[sel]
        out.lon = self.lon[sel]
        out.lat = self.lat[sel]
        out.heading_deg = None if self.heading_deg is None else self.heading_deg[sel]
        out.speed_mps = None if self.speed_mps is None else self.speed_mps[sel]
        out.accuracy_m = None if self.accuracy_m is None else self.accuracy_m[sel]
        out.odometer_m = None if self.odometer_m is None else self.odometer_m[sel]
        out.report = TraceReport(
            input_rows=count, reordered_rows=0, duplicate_time_rows=(), warnings=()
        )
        return out


def read_traces(
    source: str | os.PathLike[str] | bytes,
    *,
    format: str | None = None,
    default_trace_id: str | None = None,
    crs: str = "wgs84",
) -> list[Trace]:
    """
    Read every trace of a file or request body.

    Parameters
    ----------
    source
        A file path, or the raw bytes of a body (then ``format`` is required).
    format
        ``"csv"``, ``"gpx"``, ``"geojson"``, ``"parquet"`` or ``"json"``; inferred from the
        suffix (``.csv``, ``.csv.gz``, ``.gpx``, ``.geojson``, ``.json``, ``.parquet``, ``.pq``)
        when ``None``.
    default_trace_id
        Id of traces the source does not name; default: the file stem, or ``"trace"``.
    crs
        Frame of the coordinates: ``"wgs84"``, ``"gcj02"`` or ``"bd09"``.

    Returns
    -------
    list of Trace
        In order of first appearance. CSV/Parquet rows are grouped by a ``trace_id`` column,
        GeoJSON Point features by their ``trace_id`` property; each GPX ``<trk>`` (named by its
        ``<name>``) and each GeoJSON LineString (``properties.times`` or ``coordTimes``) is one
        trace. JSON is ``{"points": [...], "trace_id": ...}`` or a list of point objects.

    Raises
    ------
    TraceFileError
        The file cannot be read or is not in the format.
    InvalidTraceError
        A trace breaks a rule; the message names the file, the line or record and the field.
    """
    raws = read_raw_traces(source, format=format, default_trace_id=default_trace_id)
    return [Trace._from_raw(raw, crs=crs) for raw in raws]


# ---------------------------------------------------------------------- helpers


def _frozen(values: FloatArray) -> FloatArray:
    out = np.ascontiguousarray(values, dtype=np.float64)
    out.flags.writeable = False
    return out


def _in(origin: _Origin) -> str:
    return f" in {origin.source}" if origin.source else ""


def _resolve_columns(columns: pd.Index, *, trace_id: str, origin: _Origin) -> dict[str, str]:
    """Canonical field -> the column naming it; two columns for one field is an error."""
    found: dict[str, list[str]] = {}
    for col in columns:
        field = _ALIAS_TO_FIELD.get(str(col).strip().lower())
        if field is not None:
            found.setdefault(field, []).append(col)
    for field, cols in found.items():
        if len(cols) > 1:
            both = " and ".join(repr(str(c)) for c in cols)
            msg = (
                f"trace {trace_id!r}{_in(origin)}: columns {both} both give {field!r}; "
                "drop or rename all but one"
            )
            raise InvalidTraceError(msg, trace_id=trace_id, field=field)
    return {field: cols[0] for field, cols in found.items()}


def _single_trace_id(ids: pd.Series[Any], given: str | None, origin: _Origin) -> str | None:
    values = [str(v) for v in pd.unique(ids.dropna().astype(str).str.strip()) if v]
    if len(values) > 1:
        shown = ", ".join(repr(v) for v in values[:_SHOW])
        more = f" and {len(values) - _SHOW} more" if len(values) > _SHOW else ""
        name = given or values[0]
        msg = (
            f"trace {name!r}{_in(origin)}: the trace_id column holds {len(values)} ids "
            f"({shown}{more}); use mapmatch.read_traces or split the table by trace_id"
        )
        raise InvalidTraceError(msg, trace_id=name, field="trace_id")
    if given is not None:
        return given
    return str(values[0]) if values else None


def _check_lengths(given: Mapping[str, object], tid: str) -> int:
    lengths: dict[str, int] = {}
    for field, values in given.items():
        if isinstance(values, str | bytes) or np.ndim(values) != 1:  # type: ignore[arg-type]
            msg = (
                f"trace {tid!r}: {field!r} must be a 1-D sequence with one value per point "
                f"(got {type(values).__name__})"
            )
            raise InvalidTraceError(msg, trace_id=tid, field=field)
        lengths[field] = len(values)  # type: ignore[arg-type]
    n = lengths["time"]
    for field, size in lengths.items():
        if size != n:
            msg = (
                f"trace {tid!r}: {field!r} has {size} values but 'time' has {n}; "
                "give every field one value per point"
            )
            raise InvalidTraceError(msg, trace_id=tid, field=field)
    if n < 2:
        msg = f"trace {tid!r}: {n} point(s); a trace needs at least 2 points with distinct times"
        raise InvalidTraceError(msg, trace_id=tid, field="time")
    return n


def _series(values: object) -> pd.Series[Any]:
    if isinstance(values, pd.Series):
        return values.reset_index(drop=True)
    if isinstance(values, pd.Index):
        return values.to_series().reset_index(drop=True)
    if isinstance(values, np.ndarray):
        return pd.Series(values)
    return pd.Series(list(cast("Iterable[Any]", values)))


def _longest_nondecreasing(values: FloatArray) -> int:
    """Length of the longest non-decreasing subsequence (patience sorting, O(n log n))."""
    tails: list[float] = []
    for x in values.tolist():
        i = bisect_right(tails, x)
        if i == len(tails):
            tails.append(x)
        else:
            tails[i] = x
    return len(tails)


class _Checker:
    """Builds the row-pointing messages of one trace's validation."""

    def __init__(self, trace_id: str, origin: _Origin) -> None:
        self.tid = trace_id
        self.origin = origin

    def where(self, row: int) -> str:
        nums = self.origin.numbers
        if nums is None:
            return f"row {row}"
        return f"row {row} ({self.origin.label} {int(nums[row])})"

    def rows_phrase(self, rows: IntArray) -> str:
        shown = ", ".join(self.where(int(r)).removeprefix("row ") for r in rows[:_SHOW])
        more = f" and {rows.size - _SHOW} more ({rows.size} in all)" if rows.size > _SHOW else ""
        return f"row{'s' if rows.size > 1 else ''} {shown}{more}"

    def fail(
        self,
        field: str,
        problem: str,
        rows: IntArray,
        raw: pd.Series[Any] | FloatArray,
        fix: str,
    ) -> InvalidTraceError:
        shown = ", ".join(f"{self.where(int(r))} = {_fmt(raw[int(r)])}" for r in rows[:_SHOW])
        more = f" and {rows.size - _SHOW} more" if rows.size > _SHOW else ""
        msg = (
            f"trace {self.tid!r}{_in(self.origin)}: {field} {problem} in {rows.size} row(s): "
            f"{shown}{more}; {fix}"
        )
        return InvalidTraceError(msg, trace_id=self.tid, field=field, rows=rows.tolist())

    def numeric(self, values: object, field: str) -> FloatArray:
        """Float64 values; blanks become NaN, text that is not a number is an error."""
        s = _series(values)
        if pd.api.types.is_bool_dtype(s.dtype):
            bad = np.arange(len(s), dtype=np.int64)
            raise self.fail(field, "is boolean, not a number", bad, s, "give numbers")
        if pd.api.types.is_numeric_dtype(s.dtype):
            return np.asarray(s.to_numpy(dtype=np.float64, na_value=np.nan), dtype=np.float64)
        text = s.astype("string").str.strip()
        blank = s.isna().to_numpy() | (text == "").fillna(True).to_numpy()
        num = pd.to_numeric(s.where(~blank, None), errors="coerce")
        out = np.asarray(num.to_numpy(dtype=np.float64, na_value=np.nan), dtype=np.float64)
        bad = np.flatnonzero(np.isnan(out) & ~blank)
        if bad.size:
            raise self.fail(
                field, "is not a number", bad, s, "give decimal numbers (or leave blank)"
            )
        return out

    def rule(
        self, values: FloatArray, field: str, broken: npt.NDArray[np.bool_], rule: str
    ) -> None:
        bad = np.flatnonzero(broken)
        if bad.size:
            raise self.fail(
                field,
                f"breaks the rule: {rule}",
                bad,
                values,
                "fix the values or leave them blank (NaN = unknown)",
            )

    def coordinates(self, lon: FloatArray, lat: FloatArray) -> None:
        for field, values in (("lat", lat), ("lon", lon)):
            bad = np.flatnonzero(~np.isfinite(values))
            if bad.size:
                raise self.fail(
                    field,
                    "is missing or not finite",
                    bad,
                    values,
                    f"every row needs a {field} in degrees; fix or drop those rows",
                )
        if np.all(np.abs(lat) > 90.0) and np.all(np.abs(lon) <= 90.0):
            bad = np.flatnonzero(np.abs(lat) > 90.0)
            raise self.fail(
                field="lat",
                problem="is out of range [-90, 90]",
                rows=bad,
                raw=lat,
                fix="every lat looks like a longitude: swapped lon/lat? swap the two columns",
            )
        for field, values, limit in (("lat", lat, 90.0), ("lon", lon, 180.0)):
            bad = np.flatnonzero(np.abs(values) > limit)
            if bad.size:
                raise self.fail(
                    field,
                    f"is out of range [-{limit:g}, {limit:g}]",
                    bad,
                    values,
                    "give WGS84 degrees (not metres or projected coordinates); swapped lon/lat?",
                )


def _fmt(value: object) -> str:
    if isinstance(value, np.generic):
        value = value.item()
    if value is None or value is pd.NA or value is pd.NaT:
        return "missing"
    if isinstance(value, float | np.floating):
        if np.isnan(value):
            return "missing"
        return f"{float(value):g}"
    return repr(value)


def _parse_time(values: object, chk: _Checker) -> FloatArray:
    """Epoch seconds from numbers, ISO-8601 text, datetime64 or Timestamps (naive = UTC)."""
    s = _series(values)
    epoch = pd.Timestamp(0, tz="UTC")
    one_s = pd.Timedelta(1, "s")
    if pd.api.types.is_datetime64_any_dtype(s.dtype):
        dti = pd.DatetimeIndex(s)
        dti = dti.tz_localize("UTC") if dti.tz is None else dti.tz_convert("UTC")
        out = np.asarray(((dti - epoch) / one_s).to_numpy(na_value=np.nan), dtype=np.float64)
        raw: pd.Series[Any] | FloatArray = s
    elif pd.api.types.is_bool_dtype(s.dtype):
        out = np.full(len(s), np.nan)
        raw = s
    elif pd.api.types.is_numeric_dtype(s.dtype):
        out = np.asarray(s.to_numpy(dtype=np.float64, na_value=np.nan), dtype=np.float64)
        raw = s
        _check_not_ms(out, chk)
    else:
        text = s.where(s.isna(), s.astype("string").str.strip())
        num = np.asarray(
            pd.to_numeric(text, errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan),
            dtype=np.float64,
        )
        todo = np.isnan(num) & s.notna().to_numpy()
        out = num
        if todo.any():
            out = num.copy()
            out[todo] = _iso_to_epoch_s(s[todo])
        _check_not_ms(np.where(todo, np.nan, num), chk)
        raw = s
    bad = np.flatnonzero(~np.isfinite(out))
    if bad.size:
        raise chk.fail(
            field="time",
            problem="is missing or not a time",
            rows=bad,
            raw=raw,
            fix="give ISO-8601 text (2024-05-01T08:00:00Z; no zone = UTC) or epoch seconds",
        )
    return out


def _iso_to_epoch_s(text: pd.Series[Any]) -> FloatArray:
    """
    ISO-8601 text to epoch seconds (NaN for text that is no time).

    Works at microsecond resolution, so times outside pandas' nanosecond range (1677-2262)
    neither overflow nor crash.
    """
    try:
        dt = pd.to_datetime(text, utc=True, format="ISO8601", errors="coerce")
        stamps = dt.dt.tz_localize(None).to_numpy(dtype="datetime64[us]")
    except (pd.errors.OutOfBoundsDatetime, OverflowError, ValueError):
        stamps = np.array([_one_iso(value) for value in text], dtype="datetime64[us]")
    out = stamps.astype(np.int64) / 1e6
    out[np.isnat(stamps)] = np.nan
    return np.asarray(out, dtype=np.float64)


def _one_iso(value: object) -> str:
    """One ISO-8601 time as naive UTC text numpy can read, or ``"NaT"``."""
    try:
        stamp = pd.Timestamp(str(value))
    except (ValueError, OverflowError, pd.errors.OutOfBoundsDatetime):
        return "NaT"
    if stamp.tzinfo is not None:
        stamp = stamp.tz_convert("UTC").tz_localize(None)
    return str(stamp.isoformat())


def _check_not_ms(epoch_s: FloatArray, chk: _Checker) -> None:
    bad = np.flatnonzero(np.abs(epoch_s) > _EPOCH_MS_LIMIT)
    if bad.size:
        raise chk.fail(
            field="time",
            problem="is too large for epoch seconds",
            rows=bad,
            raw=epoch_s,
            fix="these look like epoch milliseconds; divide by 1000",
        )
