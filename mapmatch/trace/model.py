"""
The trace input stage: validate, sort and report one vehicle trace.

A :class:`Trace` holds the fused positions of one vehicle as float64 numpy arrays in WGS84,
in non-decreasing time order. It is built from arrays (``Trace(time=..., lon=..., lat=...)``),
a pandas DataFrame or GeoDataFrame, a list of point dicts (the HTTP JSON body) or a file;
:func:`read_traces` reads a source holding many traces. The sources live in
:mod:`mapmatch.trace.readers`.

Validation happens once, here. A row that breaks a rule raises
:class:`~mapmatch.errors.InvalidTraceError` naming the trace, the rows (0-based input row and,
for files, the 1-based line or record), the field and the value, and suggesting a fix.
Everything validation does to the rows is counted in :attr:`Trace.report` (and so in the
match's ``stats``), never silently:

Time
----
- **Optional.** Without a time column, or with every time blank, the trace is valid: its
  ``time_s`` is all NaN, ``report.time_source == "absent"`` and :attr:`Trace.has_time` is
  False, so the matcher uses distance-only transitions. Some times blank and others not is an
  error naming the blank rows.
- **Order.** Rows out of time order are stably sorted (``report.reordered_rows``); rows that
  share a time keep their file order and are all kept (``report.shared_time_rows`` counts the
  points whose time equals the previous point's; the matcher treats such a step by distance
  only).
- **True duplicates.** A row equal to an earlier row in time, position and every other field
  (an untimed trace: equal to the row before it) is the same fix sent twice; it is merged into
  the first (``report.merged_rows``). A trace is never merged below 2 points: two identical
  fixes stay a 2-point trace whose matched length is 0.
- **Units.** Numeric times are epoch seconds, milliseconds, microseconds or nanoseconds, told
  apart by size: magnitudes below 1e11 are seconds (up to the year 5138, or relative seconds),
  1e11..1e14 milliseconds, 1e14..1e17 microseconds, 1e17..1e20 nanoseconds (all of them
  1973..5138 in seconds). Milli-, micro- and nanoseconds are converted to seconds, with a
  warning (``report.time_unit``); a column mixing sizes is refused naming the rows and the
  unit they look like. float32 (and float16) times are refused when their resolution at the
  largest value is coarser than 0.01 s (any absolute epoch): float32 keeps 24 bits, so epoch
  seconds of today are 128 s apart and fixes would collapse into repeated times.
- **Times that cannot be right.** The steps between consecutive points that move at least
  :data:`MOVING_STEP_M` are checked: a step is impossible when its chord speed exceeds
  :data:`MAX_PLAUSIBLE_SPEED_MPS` (70 m/s, 252 km/h) or no time passes during it. When at
  least half of the moving steps (:data:`IMPLAUSIBLE_SHARE`) are impossible (times stamped
  1 s apart by a route planner, a burst logged under one second), the times are kept for the
  output but ``report.time_source == "implausible"``, ``has_time`` is False and the matcher
  uses distance-only transitions; a warning says so.

Segments
--------
A source that splits a trace into known pieces (GPX ``<trkseg>``, KML ``gx:MultiTrack``,
GeoJSON MultiLineString, or a ``segment`` column) gives :attr:`Trace.segment_starts`: the
indices of the points (after sorting) where a new piece starts, where the matcher breaks.

Input columns (case-insensitive; unknown columns are ignored)
-------------------------------------------------------------
``time`` (``t``, ``timestamp``, ``datetime``, ``ts``); ``lat`` (``latitude``); ``lon``
(``lng``, ``longitude``); optional ``heading`` (``bearing``, ``course``, ``heading_deg``),
``speed`` (``speed_mps``), ``accuracy`` (``accuracy_m``), ``hdop``, ``odometer``
(``odometer_m``), ``segment``. Tables are grouped into traces by their id columns
(``trace_id``, ``trip_id``, ``vehicle_id`` ...; see :mod:`mapmatch.trace.readers`).
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

from mapmatch.errors import InputTypeError, InvalidTraceError, TraceFileError
from mapmatch.trace import chinacrs
from mapmatch.trace.columns import FIELD_ALIASES, Column, canonical, column, input_columns
from mapmatch.trace.readers import RawTrace, id_columns, read_raw_traces

if TYPE_CHECKING:
    from collections.abc import Iterable
    from typing import Self

__all__ = [
    "FIELD_ALIASES",
    "IMPLAUSIBLE_SHARE",
    "MAX_PLAUSIBLE_SPEED_MPS",
    "MOVING_STEP_M",
    "SUPPORTED_CRS",
    "TIME_SOURCES",
    "UERE_M",
    "FloatArray",
    "Trace",
    "TraceReport",
    "check_match_inputs",
    "read_traces",
    "trace_from_raw",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

UERE_M: Final = 5.0
"""User-equivalent range error in metres: ``accuracy_m = hdop * UERE_M`` when only HDOP is known.

5 m is a typical 1-sigma UERE of a single-frequency automotive GNSS receiver."""

SUPPORTED_CRS: Final = ("wgs84", "gcj02", "bd09")
"""Coordinate frames a trace may arrive in; GCJ-02 and BD-09 are converted to WGS84."""

TIME_SOURCES: Final = ("ok", "absent", "implausible")
"""Values of :attr:`TraceReport.time_source`; only ``"ok"`` times enter the model."""

MAX_PLAUSIBLE_SPEED_MPS: Final = 70.0
"""Chord speed above which a step's times cannot be right: 70 m/s = 252 km/h, beyond any road
vehicle in ordinary traffic and well above what GNSS noise adds at 1 Hz."""

MOVING_STEP_M: Final = 1.0
"""Steps shorter than this (a stopped car, the same fix repeated) are not judged for speed."""

IMPLAUSIBLE_SHARE: Final = 0.5
"""Share of the moving steps that must be impossible for a trace's times to be set aside."""

_REQUIRED = tuple(c.name for c in input_columns(required_only=True))
_OPTIONAL = tuple(c for c in input_columns() if c.kind == "number" and not c.required)
_SHOW = 5  # offending rows quoted in a message
# Upper bounds of the magnitudes of epoch seconds, ms, us and ns (see the module docstring).
_UNIT_BOUNDS: Final = (1e11, 1e14, 1e17, 1e20)
_UNITS: Final = (("s", 1.0), ("ms", 1e3), ("us", 1e6), ("ns", 1e9))  # unit, per second
_UNIT_NAMES: Final = {
    "s": "seconds",
    "ms": "milliseconds",
    "us": "microseconds",
    "ns": "nanoseconds",
}
_FLOAT_TIME_RESOLUTION_S: Final = 0.01
_EARTH_RADIUS_M: Final = 6_371_008.8
_log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class TraceReport:
    """
    What validation did to a trace's input rows; nothing is changed silently.

    Attributes
    ----------
    input_rows
        Rows given to validation, before sorting and merging.
    reordered_rows
        Rows that were out of time order and had to move: the input length minus the longest
        run of rows already in (non-decreasing) time order. The sort is stable.
    merged_rows
        0-based input rows merged into an earlier row they repeat exactly (same time, position
        and every other field): the same fix sent twice.
    shared_time_rows
        Points kept whose time equals the previous point's (a burst stamped with one second);
        the number of steps with ``dt == 0``.
    dropped_rows
        Source records the reader skipped as unusable (an NMEA sentence with a wrong checksum
        or without a fix); not part of ``input_rows``. The warnings say which and why.
    time_source
        ``"ok"``, ``"absent"`` (no times: ``time_s`` is NaN) or ``"implausible"`` (times
        kept for the output, but they imply impossible speeds; see the module docstring).
    time_unit
        How numeric times were read: ``"s"``, ``"ms"``, ``"us"``, ``"ns"`` (converted to
        seconds); ``"iso"`` for text, ``"datetime"`` for datetime values, ``"mixed"`` for
        text and numbers, ``"none"`` without times.
    warnings
        One human-readable sentence per finding, empty for a clean trace.
    """

    input_rows: int
    reordered_rows: int = 0
    merged_rows: tuple[int, ...] = ()
    shared_time_rows: int = 0
    dropped_rows: int = 0
    time_source: str = "ok"
    time_unit: str = "s"
    warnings: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class _Origin:
    """Where input rows came from, to point at them in messages."""

    source: str | None = None  # file (and track) name
    label: str = "line"  # what ``numbers`` count
    numbers: IntArray | None = None  # number of each input row in the source
    segment: IntArray | None = None  # per-row segment of the source (GPX trkseg ...)
    dropped: int = 0  # source records the reader skipped
    notes: tuple[str, ...] = ()  # what the reader did, for the report


class Trace:
    """
    One vehicle trace, validated, in non-decreasing time order, in WGS84.

    Parameters
    ----------
    lon, lat
        Position in degrees, in the frame named by ``crs``.
    time
        Epoch seconds (int/float; ms, us and ns epochs are recognised and converted), ISO-8601
        strings (with or without zone; naive = UTC), or numpy ``datetime64`` / pandas
        Timestamps. ``None`` (or all blank): a trace without times, matched by distance only.
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
    segment
        Per-point label of known pieces of the trace (a GPX ``<trkseg>`` ...); the matcher
        breaks where the label changes (:attr:`segment_starts`).
    trace_id
        Name of the trace, used in every message and output.
    crs
        ``"wgs84"`` (default), ``"gcj02"`` or ``"bd09"``; the latter two are converted to WGS84.

    Attributes
    ----------
    trace_id : str
    time_s, lon, lat : FloatArray
        Epoch seconds (non-decreasing; all NaN without times) and WGS84 degrees.
    heading_deg, speed_mps, accuracy_m, odometer_m : FloatArray or None
        ``None`` when not given; NaN marks an unknown value in a row.
    segment_starts : IntArray
        Indices (ascending, in ``1 .. len - 1``) of the points that start a known piece of
        the trace; empty for a trace in one piece.
    report : TraceReport
        Rows sorted, merged or dropped, what the times are, with warnings.

    Raises
    ------
    InvalidTraceError
        A rule is broken; the message names the rows, the field, the value and a fix.

    Examples
    --------
    >>> lon = [7.4200, 7.4202, 7.4201, 7.4202]
    >>> tr = Trace(time=[0, 2, 1, 2], lon=lon, lat=[43.73] * 4, trace_id="a")
    >>> tr.time_s.tolist(), tr.lon.tolist()
    ([0.0, 1.0, 2.0], [7.42, 7.4201, 7.4202])
    >>> tr.report.reordered_rows, tr.report.merged_rows, tr.has_time
    (1, (3,), True)
    >>> Trace(lon=[7.42, 7.43], lat=[43.73, 43.73]).has_time
    False
    """

    __slots__ = (
        "accuracy_m",
        "heading_deg",
        "lat",
        "lon",
        "odometer_m",
        "report",
        "segment_starts",
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
    segment_starts: IntArray
    report: TraceReport

    def __init__(
        self,
        *,
        lon: object,
        lat: object,
        time: object = None,
        heading: object = None,
        speed: object = None,
        accuracy: object = None,
        hdop: object = None,
        odometer: object = None,
        segment: object = None,
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
            "segment": segment,
        }
        self._validate(columns, trace_id=trace_id, crs=crs, origin=_Origin())

    # ------------------------------------------------------------------ constructors

    @classmethod
    def from_dataframe(
        cls,
        df: pd.DataFrame,
        *,
        trace_id: str | None = None,
        crs: str = "wgs84",
        id_column: str | None = None,
    ) -> Self:
        """
        Build one trace from a table with the input columns (aliases, any case).

        Parameters
        ----------
        df
            One row per fix; a pandas DataFrame, or a GeoPandas GeoDataFrame of Points in any
            CRS (converted to WGS84; its geometry replaces ``lon``/``lat`` columns). Id
            columns (``trace_id``, ``vehicle_id`` ...), if present, must hold a single trace.
        trace_id
            Name of the trace; default: the id column's value, else ``"trace"``.
        crs
            Frame of ``lon``/``lat``: ``"wgs84"``, ``"gcj02"`` or ``"bd09"`` (a GeoDataFrame
            is converted to WGS84 first).
        id_column
            The column naming the trace, instead of the usual id columns.

        Returns
        -------
        Trace

        Raises
        ------
        InvalidTraceError
            A required column is missing, two columns alias one field, the id columns hold
            several traces, or a row breaks a rule.
        """
        return cls._from_table(df, trace_id=trace_id, crs=crs, id_column=id_column)

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
        return cls._from_table(frame, trace_id=trace_id, crs=crs, id_column=None)

    @classmethod
    def from_file(
        cls, path: str | os.PathLike[str], *, crs: str = "wgs84", format: str | None = None
    ) -> Self:
        """
        Read the one trace of a file (CSV, GPX, KML, NMEA, GeoJSON, Parquet or JSON).

        Parameters
        ----------
        path
            The file; its suffix names the format (see :func:`read_traces`).
        crs
            Frame of the coordinates in the file.
        format
            The format, when the suffix does not name it (``"nmea"`` for a ``.log``).

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
        raws = read_raw_traces(path, format=format)
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
    def _from_table(
        cls, df: pd.DataFrame, *, trace_id: str | None, crs: str, id_column: str | None
    ) -> Self:
        raws = read_raw_traces(df, default_trace_id=trace_id or "trace", id_column=id_column)
        if len(raws) > 1:
            cols = " / ".join(id_columns([str(c) for c in df.columns], id_column=id_column))
            shown = ", ".join(repr(r.trace_id) for r in raws[:_SHOW])
            more = f" and {len(raws) - _SHOW} more" if len(raws) > _SHOW else ""
            name = trace_id or raws[0].trace_id
            msg = (
                f"trace {name!r}: the {cols} column holds {len(raws)} ids ({shown}{more}); "
                f"use mapmatch.read_traces or split the table by {cols}"
            )
            raise InvalidTraceError(msg, trace_id=name, field="trace_id")
        raw = raws[0]
        if trace_id is not None:
            raw = RawTrace(
                trace_id,
                raw.frame,
                raw.numbers,
                raw.label,
                raw.source,
                raw.segment,
                raw.dropped,
                raw.notes,
            )
        return cls._from_raw(raw, crs=crs)

    @classmethod
    def _from_raw(cls, raw: RawTrace, *, crs: str) -> Self:
        numbers: IntArray | None = raw.numbers
        source: str | None = raw.source
        if raw.label == "table row":
            source = None
            if np.array_equal(raw.numbers, np.arange(len(raw.numbers))):
                numbers = None  # the whole table in order: "row 5" says it all
        origin = _Origin(
            source=source,
            label=raw.label,
            numbers=numbers,
            segment=raw.segment,
            dropped=raw.dropped,
            notes=raw.notes,
        )
        return cls._from_frame(raw.frame, trace_id=raw.trace_id, crs=crs, origin=origin)

    @classmethod
    def _from_frame(
        cls, df: pd.DataFrame, *, trace_id: str | None, crs: str, origin: _Origin
    ) -> Self:
        tid = trace_id or "trace"
        names = _resolve_columns(df.columns, trace_id=tid, origin=origin)
        missing = [f for f in _REQUIRED if f not in names]
        if missing:
            found = ", ".join(repr(str(c)) for c in df.columns) or "none"
            need = "; ".join(f"{f!r} (or {', '.join(FIELD_ALIASES[f][1:])})" for f in missing)
            msg = (
                f"trace {tid!r}{_in(origin)}: missing required column(s) {need}; "
                f"found columns: {found}; rename the columns (names are case-insensitive)"
            )
            raise InvalidTraceError(msg, trace_id=tid, field=missing[0])
        columns: dict[str, object] = {f: df[col] for f, col in names.items()}
        if origin.segment is not None and "segment" not in columns:
            columns["segment"] = origin.segment
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

        time_s, unit = _parse_time(given.get("time"), n, chk)
        timed = unit != "none"
        lat = chk.numeric(given["lat"], "lat")
        lon = chk.numeric(given["lon"], "lon")
        chk.coordinates(lon, lat)
        opt = {c.name: _checked(chk, c, given[c.name]) for c in _OPTIONAL if c.name in given}
        heading = opt.get("heading")
        speed = opt.get("speed")
        accuracy = opt.get("accuracy")
        hdop = opt.get("hdop")
        if hdop is not None:
            from_hdop = hdop * UERE_M
            accuracy = (
                from_hdop if accuracy is None else np.where(np.isnan(accuracy), from_hdop, accuracy)
            )
        odometer = opt.get("odometer")
        segment = None
        if "segment" in given:
            segment = chk.numeric(given["segment"], "segment")
            chk.rule(segment, "segment", ~np.isfinite(segment), "must be a number in every row")

        if crs_key == "gcj02":
            lon, lat = chinacrs.gcj02_to_wgs84(lon, lat)
        elif crs_key == "bd09":
            lon, lat = chinacrs.bd09_to_wgs84(lon, lat)

        warnings: list[str] = list(origin.notes)
        if unit in _UNIT_NAMES and unit != "s":
            first = float(time_s[np.flatnonzero(np.isfinite(time_s))[0]]) * _per_s(unit)
            shown = f"{first:.0f}" if abs(first - round(first)) < 0.5 else f"{first:.17g}"
            warnings.append(
                f"times are epoch {_UNIT_NAMES[unit]} (e.g. {shown}) and were converted to seconds"
            )
        order, reordered = _time_order(time_s, timed, chk, warnings)

        # True duplicates: the same fix twice (same time, position and fields) is merged.
        fields = [time_s, lon, lat, heading, speed, accuracy, odometer, segment]
        matrix = np.column_stack([f[order] for f in fields if f is not None])
        dup = _true_duplicates(matrix, timed=timed)
        if dup.sum() > n - 2:  # never below 2 points: two identical fixes stay a trace
            dup[np.flatnonzero(dup)[0]] = False
            warnings.append(
                f"all {n} rows are one fix repeated; 2 are kept so the trace stays a trace "
                "(its matched length is 0)"
            )
        merged = np.sort(order[dup])
        if merged.size:
            many = merged.size != 1
            warnings.append(
                f"{chk.rows_phrase(merged)} repeat{'' if many else 's'} an earlier row exactly "
                f"(same time, position and other fields) and {'were' if many else 'was'} "
                "merged into it"
            )
        kept = order[~dup]

        shared = 0
        if timed:
            zero = np.flatnonzero(np.diff(time_s[kept]) == 0) + 1
            shared = int(zero.size)
            if shared:
                warnings.append(
                    f"{shared} point{'s' if shared != 1 else ''} share{'' if shared != 1 else 's'}"
                    f" the time of the point before (first at {chk.where(int(kept[zero[0]]))}); "
                    "all are kept in file order and those steps are matched by distance only"
                )

        if odometer is not None:
            _check_odometer(odometer, kept, chk, origin)

        time_source = "ok" if timed else "absent"
        if timed:
            verdict = _implausible_times(time_s[kept], lon[kept], lat[kept])
            if verdict is not None:
                time_source = "implausible"
                warnings.append(verdict)
        else:
            warnings.append(
                "the trace has no times: it is matched by distance only (no speed, travel or "
                "time terms)"
            )
        if origin.dropped:
            many = origin.dropped != 1
            warnings.append(
                f"{origin.dropped} source record{'s' if many else ''} could not be used and "
                f"{'were' if many else 'was'} dropped in all"
            )

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
        starts = np.zeros(0, dtype=np.int64)
        if segment is not None:
            seg = segment[kept]
            starts = (np.flatnonzero(seg[1:] != seg[:-1]) + 1).astype(np.int64)
        starts.flags.writeable = False
        self.segment_starts = starts
        self.report = TraceReport(
            input_rows=n,
            reordered_rows=int(reordered),
            merged_rows=tuple(int(r) for r in merged),
            shared_time_rows=shared,
            dropped_rows=int(origin.dropped),
            time_source=time_source,
            time_unit=unit,
            warnings=tuple(warnings),
        )

    # ------------------------------------------------------------------ views

    @property
    def has_time(self) -> bool:
        """
        Whether the times are present and plausible, so the model may use them.

        False for a trace without times (``time_s`` all NaN) and for one whose times imply
        impossible speeds between most fixes (``report.time_source``); the matcher then uses
        distance-only transitions.
        """
        return self.report.time_source == "ok"

    def __len__(self) -> int:
        """Return the number of points (after merging true duplicates)."""
        return int(self.time_s.size)

    def __repr__(self) -> str:
        """Short summary: id, points and time span."""
        if self.report.time_source == "absent":
            return f"Trace({self.trace_id!r}, {len(self)} points without times)"
        span = self.time_s[-1] - self.time_s[0]
        odd = ", times implausible" if self.report.time_source == "implausible" else ""
        return f"Trace({self.trace_id!r}, {len(self)} points over {span:g} s{odd})"

    def to_dataframe(self) -> pd.DataFrame:
        """
        Return the trace as a table.

        Returns
        -------
        pandas.DataFrame
            Columns ``time`` (float epoch seconds, NaN without times), ``lon``, ``lat`` (WGS84
            degrees) and, where present, ``heading``, ``speed``, ``accuracy``, ``odometer``,
            ``segment`` (0-based piece number, when the trace has several).
            ``Trace.from_dataframe`` reads it back.
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
        out = pd.DataFrame({k: v.copy() for k, v in data.items()})
        if self.segment_starts.size:
            marks = np.zeros(len(self), dtype=np.int64)
            marks[self.segment_starts] = 1
            out["segment"] = np.cumsum(marks)
        return out

    def slice(self, start: int, stop: int) -> Trace:
        """
        Points ``start`` up to (not including) ``stop`` as a trace with the same id.

        Indices follow Python slicing (negative counts from the end). The new trace's report
        describes the slice only (no reordering, merging or dropping), with the parent's
        judgement of its times; segment starts inside the slice are kept.

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
        picked = range(len(self))[sel]
        count = len(picked)
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
        first = picked[0]
        inside = self.segment_starts[
            (self.segment_starts > first) & (self.segment_starts < first + count)
        ]
        starts = (inside - first).astype(np.int64) if picked.step == 1 else np.zeros(0, np.int64)
        starts.flags.writeable = False
        out.segment_starts = starts
        shared = int(np.sum(np.diff(out.time_s) == 0))
        out.report = TraceReport(
            input_rows=count,
            shared_time_rows=shared,
            time_source=self.report.time_source,
            time_unit=self.report.time_unit,
        )
        return out


def read_traces(
    source: str | os.PathLike[str] | bytes | pd.DataFrame,
    *,
    format: str | None = None,
    default_trace_id: str | None = None,
    crs: str = "wgs84",
    id_column: str | None = None,
) -> list[Trace]:
    """
    Read every trace of a file, request body or table.

    Parameters
    ----------
    source
        A file path; the raw bytes of a body (then ``format`` is required); or a table: a
        pandas DataFrame, or a GeoPandas GeoDataFrame of Points in any CRS (converted to
        WGS84).
    format
        ``"csv"``, ``"gpx"``, ``"kml"``, ``"nmea"``, ``"geojson"``, ``"parquet"`` or
        ``"json"``; inferred from the suffix (``.csv``, ``.csv.gz``, ``.tsv``, ``.gpx``,
        ``.kml``, ``.nmea``, ``.nma``, ``.geojson``, ``.json``, ``.parquet``, ``.pq``) when
        ``None``.
    default_trace_id
        Id of traces the source does not name; default: the file stem, or ``"trace"``.
    crs
        Frame of the coordinates: ``"wgs84"``, ``"gcj02"`` or ``"bd09"``.
    id_column
        The column whose values name the traces of a table; default: the usual id columns
        (``trace_id``, ``trip_id``, ``track_id``, ``vehicle_id``, ``device_id``, ``id``; see
        :mod:`mapmatch.trace.readers` for the rule).

    Returns
    -------
    list of Trace
        In order of first appearance. Table rows are grouped by their id columns (vehicles
        interleaved in time are split), GeoJSON Point features by their id properties; each
        GPX ``<trk>`` or ``<rte>`` (named by its ``<name>``, segments kept), KML Placemark,
        GeoJSON LineString (``properties.times`` or ``coordTimes``) and NMEA log is one
        trace. JSON is ``{"points": [...], "trace_id": ...}`` or a list of point objects.

    Raises
    ------
    TraceFileError
        The file cannot be read or is not in the format.
    InvalidTraceError
        A trace breaks a rule; the message names the file, the line or record and the field.
    """
    raws = read_raw_traces(
        source, format=format, default_trace_id=default_trace_id, id_column=id_column
    )
    return [trace_from_raw(raw, crs=crs) for raw in raws]


def trace_from_raw(raw: RawTrace, *, crs: str = "wgs84") -> Trace:
    """
    Validate one trace a reader of :mod:`mapmatch.trace.readers` returned.

    Keeps what the reader knew: the source's line or record numbers for messages, its
    segments, and the records it dropped (in the report).
    """
    return Trace._from_raw(raw, crs=crs)


def check_match_inputs(trace: object, net: object) -> None:
    """
    Refuse, with a message that says what to pass, a ``match()`` call on the wrong objects.

    Parameters
    ----------
    trace
        Must be a :class:`Trace`.
    net
        Must be a :class:`roadnets.RoadNetwork`.

    Raises
    ------
    InputTypeError
        (also a ``TypeError``) naming the argument, what it got and how to make the right one.

    Examples
    --------
    >>> check_match_inputs([(7.42, 43.73)], None)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    mapmatch.errors.InputTypeError: match(trace, net): trace must be a mapmatch.Trace, not a ...
    """
    from roadnets import RoadNetwork

    if isinstance(trace, RoadNetwork) and isinstance(net, Trace):
        msg = "match(trace, net): the arguments are swapped; call match(trace, net)"
        raise InputTypeError(msg)
    if not isinstance(trace, Trace):
        msg = f"match(trace, net): trace must be a mapmatch.Trace, not {_kind(trace)}; " + (
            _how_to_trace(trace)
        )
        raise InputTypeError(msg)
    if not isinstance(net, RoadNetwork):
        msg = (
            f"match(trace, net): net must be a roadnets.RoadNetwork, not {_kind(net)}; "
            + _how_to_network(net)
        )
        raise InputTypeError(msg)


def _kind(value: object) -> str:
    if value is None:
        return "None"
    cls = type(value)
    module = cls.__module__.split(".")[0]
    name = cls.__name__ if module in ("builtins", "") else f"{module} {cls.__name__}"
    return f"an {name}" if name[:1].lower() in "aeiou" else f"a {name}"


def _how_to_trace(value: object) -> str:
    if isinstance(value, pd.DataFrame):
        return "build one with mapmatch.Trace.from_dataframe(df) (or mapmatch.read_traces(df))"
    if isinstance(value, str | os.PathLike):
        return "read the file with mapmatch.Trace.from_file(path) (or mapmatch.read_traces(path))"
    if isinstance(value, list | tuple):
        return (
            "build one with mapmatch.Trace.from_records(points) (or Trace(lon=..., lat=..., "
            "time=...))"
        )
    return "build one with mapmatch.Trace(lon=..., lat=..., time=...) or Trace.from_file(path)"


def _how_to_network(value: object) -> str:
    module = type(value).__module__.split(".")[0]
    if module in ("networkx", "osmnx"):
        return (
            "convert the graph with roadnets.from_graph(G), or load an extract with "
            "roadnets.load(path)"
        )
    if isinstance(value, str | os.PathLike):
        return "load the extract first: net = roadnets.load(path)"
    return (
        "load one with roadnets.load(path) (roadnets.load() is the embedded default network) "
        "or convert an osmnx graph with roadnets.from_graph(G)"
    )


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
        field = canonical(col)
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
    ref = "time" if "time" in lengths else "lat"
    n = lengths[ref]
    for field, size in lengths.items():
        if size != n:
            msg = (
                f"trace {tid!r}: {field!r} has {size} values but {ref!r} has {n}; "
                "give every field one value per point"
            )
            raise InvalidTraceError(msg, trace_id=tid, field=field)
    if n < 2:
        msg = f"trace {tid!r}: {n} point(s); a trace needs at least 2 points"
        raise InvalidTraceError(msg, trace_id=tid, field="lat")
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


def _time_order(
    time_s: FloatArray, timed: bool, chk: _Checker, warnings: list[str]
) -> tuple[IntArray, int]:
    """The stable time order of the rows (file order without times) and how many moved."""
    n = time_s.size
    steps = np.diff(time_s)
    if not timed or np.all(steps >= 0):
        return np.arange(n, dtype=np.int64), 0
    order = np.argsort(time_s, kind="stable").astype(np.int64)
    reordered = n - _longest_nondecreasing(time_s)
    first_back = int(np.flatnonzero(steps < 0)[0]) + 1
    warnings.append(
        f"{reordered} row{'s' if reordered != 1 else ''} out of time order "
        f"{'were' if reordered != 1 else 'was'} sorted (first step back in time at "
        f"{chk.where(first_back)})"
    )
    return order, reordered


def _true_duplicates(matrix: FloatArray, *, timed: bool) -> BoolArray:
    """
    Rows (in time order) that repeat an earlier row in every column (NaN equals NaN).

    With times (column 0, sorted), any earlier row of the same time counts; without, only
    the row before.

    Examples
    --------
    >>> m = np.array([[0.0, 1.0], [0.0, 2.0], [0.0, 1.0], [1.0, np.nan], [1.0, np.nan]])
    >>> _true_duplicates(m, timed=True).tolist()
    [False, False, True, False, True]
    >>> _true_duplicates(m[:, 1:], timed=False).tolist()
    [False, False, False, False, True]
    """
    if timed:  # only rows of one time can repeat each other: look at shared times only
        t = matrix[:, 0]
        shared = np.zeros(len(t), dtype=bool)
        shared[1:] = t[1:] == t[:-1]
        shared[:-1] |= shared[1:]
        dup = np.zeros(len(t), dtype=bool)
        rows = np.flatnonzero(shared)
        if rows.size:
            dup[rows] = pd.DataFrame(matrix[rows]).duplicated(keep="first").to_numpy()
        return dup
    a, b = matrix[1:], matrix[:-1]
    same = ((a == b) | (np.isnan(a) & np.isnan(b))).all(axis=1)
    return np.concatenate(([False], same))


def _check_odometer(odometer: FloatArray, kept: IntArray, chk: _Checker, origin: _Origin) -> None:
    odo = odometer[kept]
    known = np.flatnonzero(~np.isnan(odo))
    back = np.flatnonzero(np.diff(odo[known]) < 0)
    if not back.size:
        return
    later, earlier = kept[known[back + 1]], kept[known[back]]
    shown = ", ".join(
        f"{chk.where(int(b))} = {odometer[b]:g} after {chk.where(int(a))} = {odometer[a]:g}"
        for a, b in zip(earlier[:_SHOW], later[:_SHOW], strict=True)
    )
    more = f" and {later.size - _SHOW} more" if later.size > _SHOW else ""
    msg = (
        f"trace {chk.tid!r}{_in(origin)}: odometer decreases in time at {later.size} "
        f"row(s): {shown}{more}; the odometer must be cumulative distance in metres "
        "(fix or blank those values, NaN = unknown)"
    )
    raise InvalidTraceError(msg, trace_id=chk.tid, field="odometer", rows=later.tolist())


def _step_m(lon: FloatArray, lat: FloatArray) -> FloatArray:
    """
    Distance between consecutive positions, metres (equirectangular at the step's latitude).

    Within 0.1 % of the great circle for steps under 100 km away from the poles, which is
    all a speed check needs.

    Examples
    --------
    >>> round(float(_step_m(np.array([7.42, 7.43]), np.array([43.73, 43.73]))[0]), 1)
    803.5
    """
    rad = np.pi / 180.0
    dlon = (np.diff(lon) + 180.0) % 360.0 - 180.0  # the short way across the antimeridian
    mid = (lat[1:] + lat[:-1]) * (0.5 * rad)
    return np.asarray(
        _EARTH_RADIUS_M * rad * np.hypot(dlon * np.cos(mid), np.diff(lat)), dtype=np.float64
    )


def _implausible_times(time_s: FloatArray, lon: FloatArray, lat: FloatArray) -> str | None:
    """
    The warning when the times cannot be right (the rule of the module docstring), else None.

    Examples
    --------
    >>> lon = 7.42 + np.arange(5) * 0.0013  # about 100 m apart
    >>> _implausible_times(np.arange(5.0), lon, np.full(5, 43.73))[:46]
    'the times cannot be right: 4 of 4 moving steps'
    >>> _implausible_times(np.arange(5.0) * 10, lon, np.full(5, 43.73)) is None
    True
    """
    step = _step_m(lon, lat)
    dt = np.diff(time_s)
    moving = step >= MOVING_STEP_M
    with np.errstate(divide="ignore", invalid="ignore"):
        speed = np.where(dt > 0, step / np.where(dt > 0, dt, 1.0), np.inf)
    impossible = moving & (speed > MAX_PLAUSIBLE_SPEED_MPS)
    n_moving, n_bad = int(moving.sum()), int(impossible.sum())
    if n_moving == 0 or n_bad < IMPLAUSIBLE_SHARE * n_moving:
        return None
    timed_speeds = speed[moving & np.isfinite(speed)]
    median = f"; median {np.median(timed_speeds):.3g} m/s" if timed_speeds.size else ""
    no_time = int((moving & ~(dt > 0)).sum())
    return (
        f"the times cannot be right: {n_bad} of {n_moving} moving steps imply more than "
        f"{MAX_PLAUSIBLE_SPEED_MPS:g} m/s ({no_time} with no time between two positions"
        f"{median}); matched by distance only, the times are kept for the output"
    )


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
        lat_col = column("lat")
        outside = ~_within(lat, lat_col)
        if np.all(outside) and np.all(_within(lon, lat_col)):
            bad = np.flatnonzero(outside)
            raise self.fail(
                field="lat",
                problem=f"is out of range [{lat_col.ge:g}, {lat_col.le:g}]",
                rows=bad,
                raw=lat,
                fix="every lat looks like a longitude: swapped lon/lat? swap the two columns",
            )
        for values, col in ((lat, column("lat")), (lon, column("lon"))):
            bad = np.flatnonzero(~_within(values, col))
            if bad.size:
                raise self.fail(
                    col.name,
                    f"is out of range [{col.ge:g}, {col.le:g}]",
                    bad,
                    values,
                    "give WGS84 degrees (not metres or projected coordinates); swapped lon/lat?",
                )


def _checked(chk: _Checker, col: Column, values: object) -> FloatArray:
    """
    An optional number column as float64, its declared rules applied (:mod:`.columns`).

    A wrapping column (heading) is taken modulo its period, a non-finite value being
    unknown (NaN); any other value must keep its bounds and be finite (NaN = unknown).
    """
    out = chk.numeric(values, col.name)
    if col.wraps is not None:
        finite = np.isfinite(out)
        out = np.where(finite, np.mod(np.where(finite, out, 0.0), col.wraps), np.nan)
        out[out >= col.wraps] = 0.0  # np.mod(-1e-15, 360) rounds to 360.0
        return out
    if col.bounded:
        unit = f" {col.unit}" if col.unit else ""
        broken = ~_within(out, col) & ~np.isnan(out)
        chk.rule(out, col.name, broken, f"must be {col.rule()}{unit}")
    chk.rule(out, col.name, np.isinf(out), "must be finite (NaN = unknown)")
    return out


def _within(values: FloatArray, col: Column) -> BoolArray:
    """Whether each value keeps the column's bounds (NaN keeps none)."""
    ok = np.ones(values.shape, dtype=bool)
    with np.errstate(invalid="ignore"):
        if col.gt is not None:
            ok &= values > col.gt
        if col.ge is not None:
            ok &= values >= col.ge
        if col.le is not None:
            ok &= values <= col.le
    return ok


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


_TIME: Final = "time"
_TIME_FIX: Final = (
    "give ISO-8601 text (2024-05-01T08:00:00Z; no zone = UTC) or epoch seconds in every row, "
    "or leave the time column out to match by distance only"
)


def _parse_time(values: object, n: int, chk: _Checker) -> tuple[FloatArray, str]:
    """
    Epoch seconds and how they were read (``TraceReport.time_unit``); NaN without times.

    Numbers are epoch seconds, ms, us or ns by size; text is ISO-8601 or numbers;
    ``datetime64`` and Timestamps are converted (naive = UTC).
    """
    if values is None:
        return np.full(n, np.nan), "none"
    s = _series(values)
    epoch = pd.Timestamp(0, tz="UTC")
    one_s = pd.Timedelta(1, "s")
    raw: pd.Series[Any] | FloatArray = s
    if pd.api.types.is_bool_dtype(s.dtype):
        rows = np.arange(n, dtype=np.int64)
        raise chk.fail(_TIME, "is missing or not a time", rows, s, _TIME_FIX)
    if pd.api.types.is_datetime64_any_dtype(s.dtype):
        dti = pd.DatetimeIndex(s)
        dti = dti.tz_localize("UTC") if dti.tz is None else dti.tz_convert("UTC")
        out = np.asarray(((dti - epoch) / one_s).to_numpy(na_value=np.nan), dtype=np.float64)
        blank = np.isnan(out)
        unit = "datetime"
    elif pd.api.types.is_numeric_dtype(s.dtype):
        out = np.asarray(s.to_numpy(dtype=np.float64, na_value=np.nan), dtype=np.float64)
        blank = np.isnan(out)
        out, unit = _epoch_seconds(out, chk)
        _check_float_precision(s, out, unit, chk)
    else:
        text = s.where(s.isna(), s.astype("string").str.strip())
        blank = s.isna().to_numpy() | (text == "").fillna(True).to_numpy()
        num = np.asarray(
            pd.to_numeric(text, errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan),
            dtype=np.float64,
        )
        iso = np.isnan(num) & ~blank
        out, unit = _epoch_seconds(num, chk)
        if iso.any():
            out = out.copy()
            out[iso] = _iso_to_epoch_s(s[iso])
            unit = "iso" if np.isnan(num).all() else "mixed"
    if blank.all():
        return np.full(n, np.nan), "none"
    bad = np.flatnonzero(~np.isfinite(out))
    if bad.size:
        raise chk.fail(_TIME, "is missing or not a time", bad, raw, _TIME_FIX)
    return out, unit


def _per_s(unit: str) -> float:
    return dict(_UNITS).get(unit, 1.0)


def _epoch_seconds(values: FloatArray, chk: _Checker) -> tuple[FloatArray, str]:
    """
    Numeric times in seconds, their unit told by size; a column mixing sizes is refused.

    Examples
    --------
    >>> chk = _Checker("t", _Origin())
    >>> seconds, unit = _epoch_seconds(np.array([1714550400123.0, 1714550401123.0]), chk)
    >>> seconds.tolist(), unit
    ([1714550400.123, 1714550401.123], 'ms')
    >>> _epoch_seconds(np.array([0.0, 1.5]), chk)
    (array([0. , 1.5]), 's')
    """
    finite = np.isfinite(values)
    band = np.searchsorted(np.asarray(_UNIT_BOUNDS), np.abs(values), side="right")
    band[~finite] = -1
    present = np.unique(band[finite]).tolist()
    if not present:
        return values, "s"
    if present[-1] >= len(_UNITS):
        bad = np.flatnonzero(band >= len(_UNITS))
        raise chk.fail(
            _TIME,
            "is too large for epoch seconds, milliseconds, microseconds or nanoseconds",
            bad,
            values,
            "give epoch seconds or ISO-8601 text",
        )
    if len(present) > 1:
        counts = {b: int((band == b).sum()) for b in present}
        main = max(present, key=lambda b: counts[b])
        bad = np.flatnonzero(finite & (band != main))
        odd = ", ".join(_UNIT_NAMES[_UNITS[b][0]] for b in present if b != main)
        raise chk.fail(
            _TIME,
            f"mixes units: these rows look like epoch {odd} while the others are epoch "
            f"{_UNIT_NAMES[_UNITS[main][0]]}",
            bad,
            values,
            "give every time in one unit (epoch seconds, or ISO-8601 text)",
        )
    unit, per_s = _UNITS[present[0]]
    out = values if per_s == 1.0 else values / per_s
    return np.asarray(out, dtype=np.float64), unit


def _check_float_precision(s: pd.Series[Any], time_s: FloatArray, unit: str, chk: _Checker) -> None:
    """Refuse float32/float16 times too coarse to tell fixes apart."""
    kind = str(s.dtype).lower()
    if kind not in ("float32", "float16"):
        return
    finite = time_s[np.isfinite(time_s)]
    if not finite.size:
        return
    raw_max = float(np.max(np.abs(finite))) * _per_s(unit)
    ftype = np.float32 if kind == "float32" else np.float16
    step_s = float(np.spacing(ftype(raw_max))) / _per_s(unit)
    if step_s <= _FLOAT_TIME_RESOLUTION_S:
        return
    bits = 24 if kind == "float32" else 11
    msg = (
        f"trace {chk.tid!r}{_in(chk.origin)}: time is stored as {kind}, which keeps {bits} bits: "
        f"near {raw_max:.6g} its values can only be {step_s:g} s apart, so fixes seconds apart "
        "would collapse into repeated times; store times as float64 or int64 epoch seconds, "
        "or as ISO-8601 text"
    )
    raise InvalidTraceError(msg, trace_id=chk.tid, field="time")


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
