"""
Validation of one trace's columns: the rules of :mod:`mapmatch.trace`, in order.

:func:`validate` takes the columns by canonical name (arrays, lists or pandas Series, as
:class:`~mapmatch.trace.Trace` was given them) and returns the validated, sorted and merged
arrays with their :class:`~mapmatch.trace.TraceReport`. The steps: lengths; times
(:mod:`~mapmatch.trace.times`); coordinates and the declared rules of every optional column
(:mod:`~mapmatch.trace.checks`, bounds from :mod:`~mapmatch.trace.columns`); the frame
conversion (:mod:`~mapmatch.trace.chinacrs`); then the order of the rows
(:mod:`~mapmatch.trace.ordering`): time sort, true duplicates, shared times, the odometer,
and whether the times can be right.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Final

import numpy as np

from mapmatch.errors import InvalidTraceError
from mapmatch.trace import chinacrs
from mapmatch.trace.checks import Checker, check_lengths, check_odometer, checked_column
from mapmatch.trace.columns import input_columns
from mapmatch.trace.ordering import implausible_times, merge_duplicates, shared_times, time_order
from mapmatch.trace.report import TraceReport
from mapmatch.trace.times import parse_time, unit_note

if TYPE_CHECKING:
    from collections.abc import Mapping

    from mapmatch.trace.report import Origin
    from mapmatch.types import FloatArray, IntArray

__all__ = ["SUPPORTED_CRS", "UERE_M", "TraceFields", "validate"]

UERE_M: Final = 5.0
"""User-equivalent range error in metres: ``accuracy_m = hdop * UERE_M`` when only HDOP is known.

5 m is a typical 1-sigma UERE of a single-frequency automotive GNSS receiver."""

SUPPORTED_CRS: Final = ("wgs84", "gcj02", "bd09")
"""Coordinate frames a trace may arrive in; GCJ-02 and BD-09 are converted to WGS84."""

_OPTIONAL: Final = tuple(c for c in input_columns() if c.kind == "number" and not c.required)
_log = logging.getLogger("mapmatch.trace")


class TraceFields:
    """
    The validated columns of a trace, filled by :func:`validate`.

    :class:`~mapmatch.trace.Trace` is this layout plus its constructors and views; its
    docstring describes the attributes.
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


def validate(
    out: TraceFields, columns: Mapping[str, object], *, trace_id: str, crs: str, origin: Origin
) -> None:
    """
    Validate, sort and merge one trace's columns into ``out``.

    ``columns`` maps canonical names to the values given (``None``: not given).

    Raises
    ------
    InvalidTraceError
        A rule is broken; the message names the rows, the field, the value and a fix.
    """
    tid = str(trace_id)
    crs_key = str(crs).strip().lower()
    if crs_key not in SUPPORTED_CRS:
        msg = f"trace {tid!r}: unknown crs {crs!r}; use one of {', '.join(SUPPORTED_CRS)}"
        raise InvalidTraceError(msg, trace_id=tid, field="crs")
    given = {f: v for f, v in columns.items() if v is not None}
    n = check_lengths(given, tid)
    chk = Checker(tid, origin)

    time_s, unit = parse_time(given.get("time"), n, chk)
    timed = unit != "none"
    lat = chk.numeric(given["lat"], "lat")
    lon = chk.numeric(given["lon"], "lon")
    chk.coordinates(lon, lat)
    opt = {c.name: checked_column(chk, c, given[c.name]) for c in _OPTIONAL if c.name in given}
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
    note = unit_note(time_s, unit)
    if note is not None:
        warnings.append(note)
    order, reordered = time_order(time_s, timed, chk, warnings)

    # True duplicates: the same fix twice (same time, position and fields) is merged.
    fields = [time_s, lon, lat, heading, speed, accuracy, odometer, segment]
    present = [f for f in fields if f is not None]
    kept, merged = merge_duplicates(present, order, timed=timed, chk=chk, warnings=warnings)
    shared = shared_times(time_s, kept, chk, warnings) if timed else 0

    if odometer is not None:
        check_odometer(odometer, kept, chk, origin)

    time_source = "ok" if timed else "absent"
    if timed:
        verdict = implausible_times(time_s[kept], lon[kept], lat[kept])
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
    starts = np.zeros(0, dtype=np.int64)
    if segment is not None:
        seg = segment[kept]
        starts = (np.flatnonzero(seg[1:] != seg[:-1]) + 1).astype(np.int64)
    starts.flags.writeable = False
    out.trace_id = tid
    out.time_s = _picked(time_s, kept)
    out.lon = _picked(lon, kept)
    out.lat = _picked(lat, kept)
    out.heading_deg = None if heading is None else _picked(heading, kept)
    out.speed_mps = None if speed is None else _picked(speed, kept)
    out.accuracy_m = None if accuracy is None else _picked(accuracy, kept)
    out.odometer_m = None if odometer is None else _picked(odometer, kept)
    out.segment_starts = starts
    out.report = TraceReport(
        input_rows=n,
        reordered_rows=int(reordered),
        merged_rows=tuple(int(r) for r in merged),
        shared_time_rows=shared,
        dropped_rows=int(origin.dropped),
        time_source=time_source,
        time_unit=unit,
        warnings=tuple(warnings),
    )


def _picked(values: FloatArray, kept: IntArray) -> FloatArray:
    """The ``kept`` rows of ``values`` (a fresh float64 array), read-only."""
    out = values[kept]
    out.flags.writeable = False
    return out
