"""
One vehicle trace: the :class:`Trace` value object, its constructors and views.

A :class:`Trace` holds the fused positions of one vehicle as read-only float64 numpy arrays
in WGS84, in non-decreasing time order. It is built from arrays (``Trace(time=..., lon=...,
lat=...)``), a pandas DataFrame or GeoDataFrame, a list of point dicts (the HTTP JSON body)
or a file; :func:`~mapmatch.trace.read_traces` reads a source holding many traces. The rules
it is validated by are those of :mod:`mapmatch.trace` (applied by
:func:`~mapmatch.trace.validation.validate`), the sources are in :mod:`mapmatch.trace.readers`.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Final

import numpy as np
import pandas as pd

from mapmatch.errors import InvalidTraceError, TraceFileError
from mapmatch.trace.checks import SHOW
from mapmatch.trace.frames import frame_columns, raw_origin, record_columns, single_raw
from mapmatch.trace.readers import RawTrace, read_raw_traces
from mapmatch.trace.report import Origin, TraceReport
from mapmatch.trace.validation import UERE_M, TraceFields, validate

if TYPE_CHECKING:
    from typing import Self

    from mapmatch.types import FloatArray

__all__ = ["UERE_M", "Trace"]

_NO_ORIGIN: Final = Origin()


class Trace(TraceFields):
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

    __slots__ = ()

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
        validate(self, columns, trace_id=trace_id, crs=crs, origin=_NO_ORIGIN)

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
        return cls._from_raw(single_raw(df, trace_id=trace_id, id_column=id_column), crs=crs)

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
        plain = all(type(rec) is dict for rec in records)  # the ABC check is slow
        bad = [] if plain else [i for i, r in enumerate(records) if not isinstance(r, Mapping)]
        if bad:
            msg = (
                f"trace {trace_id!r}: record {bad[0]} is a {type(records[bad[0]]).__name__}, "
                'not an object; send each point as {"time": ..., "lat": ..., "lon": ...}'
            )
            raise InvalidTraceError(msg, trace_id=trace_id, rows=bad)
        columns = record_columns(records)
        if columns is not None:  # numbers only: no table needed (the same result, faster)
            self = cls.__new__(cls)
            validate(self, columns, trace_id=trace_id or "trace", crs=crs, origin=_NO_ORIGIN)
            return self
        frame = pd.DataFrame.from_records(list(records))
        return cls._from_raw(single_raw(frame, trace_id=trace_id, id_column=None), crs=crs)

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
            ids = ", ".join(repr(r.trace_id) for r in raws[:SHOW])
            more = f" and {len(raws) - SHOW} more" if len(raws) > SHOW else ""
            msg = (
                f"trace file {os.fspath(path)!r} holds {len(raws)} traces ({ids}{more}); "
                "Trace.from_file reads exactly one, use mapmatch.read_traces for many"
            )
            raise TraceFileError(msg, path=os.fspath(path))
        return cls._from_raw(raws[0], crs=crs)

    @classmethod
    def _from_raw(cls, raw: RawTrace, *, crs: str) -> Self:
        tid, origin = raw.trace_id or "trace", raw_origin(raw)
        columns = frame_columns(raw.frame, trace_id=tid, origin=origin)
        self = cls.__new__(cls)
        validate(self, columns, trace_id=tid, crs=crs, origin=origin)
        return self

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
