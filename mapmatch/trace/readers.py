"""
Trace sources: files, request bodies and tables, read into unvalidated per-trace tables.

The formats: CSV (also gzipped), GPX, KML, NMEA, GeoJSON, Parquet, the JSON body of the API,
and tables (a pandas ``DataFrame`` or a GeoPandas ``GeoDataFrame`` of Points).

Each reader turns a source into :class:`RawTrace` tables: the columns as they appear in the
source, one row per fix, plus the 1-based line or record number of every row so that
:mod:`mapmatch.trace` can point at the offending place when it validates. Nothing is validated
here except the container itself; a file that cannot be read at all raises
:class:`~mapmatch.errors.TraceFileError`. Records a reader cannot use (an NMEA sentence with a
wrong checksum or without a fix) are skipped, counted in :attr:`RawTrace.dropped` and named in
:attr:`RawTrace.notes`, which the trace's report carries on; nothing is dropped silently.

Files in the wild
-----------------
- **CSV**: ``,``, ``;``, tab or ``|`` between fields (told from the header line, or from an
  Excel ``sep=;`` first line); with ``;``, tab or ``|``, a decimal comma (``43,73``) is read
  when the numbers use one; a UTF-8 byte-order mark is ignored, UTF-16 (Excel's "Unicode
  text") is converted, and a file that is not UTF-8 is read as Latin-1 (with a note).
- **GPX** 1.0 and 1.1: every ``<trk>`` is one trace, its ``<trkseg>`` kept as known gaps
  (:attr:`RawTrace.segment`); every ``<rte>`` (``<rtept>``) is one trace too. ``<time>``,
  ``<speed>``, ``<course>`` and ``<hdop>`` are read, also from ``<extensions>``.
- **KML**: every Placemark with a ``gx:Track`` (``<when>`` and ``<gx:coord>``; several in a
  ``gx:MultiTrack`` are segments) or a ``LineString`` (no times) is one trace.
- **NMEA 0183** logs (``$GPRMC`` / ``$GPGGA``, any talker: ``GN``, ``GL``, ``GA``, ``BD``):
  one trace per file. Every sentence's checksum is checked; a sentence with a wrong checksum,
  without a position, or reporting no fix (RMC status ``V``, GGA quality 0) is dropped and
  counted. RMC and GGA sentences of one epoch (same time of day, one after the other) make one
  fix: RMC gives the date, speed (knots, converted to m/s) and course; GGA the HDOP. GGA
  sentences take their date from the nearest RMC (rolling over at midnight); a log without any
  RMC has no date, and its times are seconds of day from 1970-01-01 (with a note).

Grouping into traces
--------------------
A table (CSV, Parquet, a DataFrame, GeoJSON Point features, JSON points) may hold several
traces. Its rows are grouped by an id column, found case-insensitively and ignoring ``_``,
``-``, spaces and dots (``VehicleID``, ``vehicle id`` and ``vehicle_id`` are one name):

1. ``id_column=`` (``--id-column``) names the column to group by; nothing else is used.
2. Otherwise the id columns present, from the most to the least specific, are
   :data:`ID_COLUMNS`: ``trace_id``, ``trip_id``, ``track_id``, ``vehicle_id`` (also
   ``vehicle``), ``device_id`` (also ``device``, ``imei``), and ``id``. Rows are grouped by all
   of them together, so a vehicle's trips stay apart even when trip numbers restart for each
   vehicle, and vehicles interleaved in time are split, never merged. A trace is named by its
   most specific id when that alone tells the traces apart, else by all its ids joined with
   ``/`` from the least specific (``bus-12/3``).
3. A plain ``id`` column is used only when no other id column is present, and not when it
   holds a different value in every row (then it numbers rows, not traces; a note says so).

Rows of one trace keep their file order. Groups keep the order of first appearance. Each GPX
``<trk>``/``<rte>``, KML Placemark and GeoJSON LineString is one trace, named by its
``<name>`` or ``trace_id`` property. A trace without an id is named after the file stem
(``trip.csv.gz`` -> ``"trip"``), or ``default_trace_id`` for a body or a table, or
``"trace"``; when several tracks of one file have no name, the ``k``-th (1-based) is called
``"<stem>-<k>"``.
"""

from __future__ import annotations

import gzip
import io
import json
import math
import os
import re
import sys
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Final

import numpy as np
import pandas as pd

from mapmatch.errors import InvalidTraceError, TraceFileError
from mapmatch.trace.columns import ID_COLUMNS, canonical, column, id_kind, normal_id_name

if TYPE_CHECKING:
    import numpy.typing as npt

    IntArray = npt.NDArray[np.int64]

__all__ = [
    "FORMATS",
    "ID_COLUMNS",
    "RawTrace",
    "group_rows",
    "id_columns",
    "infer_format",
    "read_raw_traces",
    "table_frame",
]

FORMATS = ("csv", "gpx", "kml", "nmea", "geojson", "parquet", "json")
"""Trace formats :func:`read_raw_traces` understands."""

_SUFFIXES = {
    ".csv": "csv",
    ".csv.gz": "csv",
    ".tsv": "csv",
    ".gpx": "gpx",
    ".kml": "kml",
    ".nmea": "nmea",
    ".nma": "nmea",
    ".geojson": "geojson",
    ".json": "json",
    ".parquet": "parquet",
    ".pq": "parquet",
}
_COORD_NAMES = frozenset(column("lat").names + column("lon").names)
_GPX_FIELDS = frozenset({"heading", "speed", "hdop"})  # read from a trkpt's child elements
_DOCTYPE = re.compile(rb"<!\s*(DOCTYPE|ENTITY)", re.IGNORECASE)
_SHOW = 5
_TABLE_ROW = "table row"


@dataclass(frozen=True, slots=True)
class RawTrace:
    """
    One trace as read from its source, before validation.

    Attributes
    ----------
    trace_id
        Id of the trace (explicit in the source, else derived from the file stem).
    frame
        The columns as named in the source, one row per fix in source order.
    numbers
        ``label`` number of every row in the source (1-based CSV line, GPX trkpt, NMEA
        line ...; 0-based for a table's rows).
    label
        What ``numbers`` count: ``"line"``, ``"record"``, ``"trkpt"``, ``"rtept"``,
        ``"coord"``, ``"feature"``, ``"vertex"``, ``"point"`` or ``"table row"``.
    source
        Where the rows came from, for messages (``"trip.gpx trk 2"``, ``"<bytes>"``).
    segment
        Per-row segment number when the source splits the trace into known pieces (GPX
        ``<trkseg>``, KML ``gx:MultiTrack``, GeoJSON MultiLineString), else ``None``.
    dropped
        Source records skipped because they cannot be a fix (NMEA: wrong checksum, no fix).
    notes
        One sentence per thing the reader did that the trace's report must repeat.
    """

    trace_id: str
    frame: pd.DataFrame
    numbers: IntArray
    label: str
    source: str
    segment: IntArray | None = None
    dropped: int = 0
    notes: tuple[str, ...] = ()


def infer_format(path: str | os.PathLike[str]) -> str:
    """
    Trace format named by a file's suffix.

    Parameters
    ----------
    path
        File name; ``.csv``, ``.csv.gz``, ``.tsv``, ``.gpx``, ``.kml``, ``.nmea``, ``.nma``,
        ``.geojson``, ``.json``, ``.parquet`` and ``.pq`` are known (case-insensitive).

    Returns
    -------
    str
        One of :data:`FORMATS`.

    Raises
    ------
    TraceFileError
        For any other suffix.

    Examples
    --------
    >>> infer_format("trips/Day1.CSV.gz")
    'csv'
    >>> infer_format("box-17.nmea")
    'nmea'
    """
    name = Path(path).name.lower()
    for suffix in sorted(_SUFFIXES, key=len, reverse=True):
        if name.endswith(suffix):
            return _SUFFIXES[suffix]
    msg = (
        f"trace file {os.fspath(path)!r}: cannot tell the format from the suffix; "
        f"use one of {', '.join(sorted(_SUFFIXES))} or pass format= (one of {', '.join(FORMATS)})"
    )
    raise TraceFileError(msg, path=os.fspath(path))


def _stem(path: Path) -> str:
    name = path.name
    lower = name.lower()
    for suffix in sorted(_SUFFIXES, key=len, reverse=True):
        if lower.endswith(suffix):
            return name[: -len(suffix)] or name
    return path.stem or name


def read_raw_traces(
    source: str | os.PathLike[str] | bytes | pd.DataFrame,
    *,
    format: str | None = None,
    default_trace_id: str | None = None,
    id_column: str | None = None,
) -> list[RawTrace]:
    """
    Read every trace of a file, body or table into unvalidated tables.

    Parameters
    ----------
    source
        A file path, the raw bytes of a body (then ``format`` is required), or a table
        (pandas ``DataFrame``, or a GeoPandas ``GeoDataFrame`` of Points in any CRS).
    format
        One of :data:`FORMATS`; inferred from the file suffix when ``None``. ``"json"`` and
        ``"geojson"`` both accept either layout and tell them apart by content.
    default_trace_id
        Id of traces the source does not name; default: the file stem, or ``"trace"``.
    id_column
        Column whose values name the traces of a table; default: the rule of the module
        docstring.

    Returns
    -------
    list of RawTrace
        In order of first appearance in the source; never empty.

    Raises
    ------
    TraceFileError
        The file is missing, unreadable, of an unknown format, empty or malformed, or it has
        no column ``id_column``.
    InvalidTraceError
        Rows of a grouped table lack their id, or a GeoDataFrame row is not a Point.
    """
    if isinstance(source, pd.DataFrame):
        name = "<table>"
        ctx = _Context(name, None, "table", default_trace_id or "trace", id_column)
        frame = table_frame(source, source_name=name)
        numbers = np.arange(len(frame), dtype=np.int64)
        traces = group_rows(frame, numbers=numbers, label=_TABLE_ROW, ctx=ctx)
        if not traces:
            msg = "holds no rows"
            raise ctx.error(msg)
        return traces
    if isinstance(source, bytes | bytearray | memoryview):
        data = bytes(source)
        name = "<bytes>"
        path_str: str | None = None
        if format is None:
            msg = f"trace body {name}: format= is required for bytes (one of {', '.join(FORMATS)})"
            raise TraceFileError(msg)
        default_id = default_trace_id or "trace"
    else:
        path = Path(source)
        path_str = os.fspath(path)
        name = path.name
        fmt_from_suffix = infer_format(path) if format is None else None
        format = format or fmt_from_suffix
        try:
            data = path.read_bytes()
        except OSError as exc:
            msg = f"trace file {path_str!r} cannot be read: {exc.strerror or exc}; check the path"
            raise TraceFileError(msg, path=path_str, format=format) from exc
        default_id = default_trace_id or _stem(path) or "trace"
    fmt = str(format).lower()
    if fmt not in FORMATS:
        msg = f"trace file {name!r}: unknown format {format!r}; use one of {', '.join(FORMATS)}"
        raise TraceFileError(msg, path=path_str, format=str(format))
    ctx = _Context(name=name, path=path_str, fmt=fmt, default_id=default_id, id_column=id_column)
    readers = {
        "csv": _read_csv,
        "parquet": _read_parquet,
        "gpx": _read_gpx,
        "kml": _read_kml,
        "nmea": _read_nmea,
    }
    traces = readers.get(fmt, _read_json)(data, ctx)
    if not traces:
        msg = "holds no trace points"
        raise ctx.error(msg)
    return traces


@dataclass(frozen=True, slots=True)
class _Context:
    name: str
    path: str | None
    fmt: str
    default_id: str
    id_column: str | None = None

    def error(self, problem: str) -> TraceFileError:
        msg = f"trace file {self.name!r} ({self.fmt}): {problem}"
        return TraceFileError(msg, path=self.path, format=self.fmt)

    def renamed(self, default_id: str) -> _Context:
        return _Context(self.name, self.path, self.fmt, default_id, self.id_column)


# --------------------------------------------------------------------------- tables


def _id_columns(columns: list[str], ctx: _Context) -> list[str]:
    """The id columns to group by, most specific first (the rule of the module docstring)."""
    if ctx.id_column is not None:
        want = normal_id_name(ctx.id_column)
        exact = [c for c in columns if str(c).strip().lower() == ctx.id_column.strip().lower()]
        found = exact or [c for c in columns if normal_id_name(c) == want]
        if not found:
            shown = ", ".join(repr(str(c)) for c in columns) or "none"
            msg = (
                f"has no column {ctx.id_column!r} to group traces by (id_column / "
                f"--id-column); found columns: {shown}"
            )
            raise ctx.error(msg)
        if len(found) > 1:
            msg = f"has {len(found)} columns named {ctx.id_column!r} ({found!r}); keep one"
            raise ctx.error(msg)
        return found
    by_kind: dict[str, list[str]] = {}
    for col in columns:
        kind = id_kind(col)
        if kind is not None:
            by_kind.setdefault(kind, []).append(col)
    for kind, cols in by_kind.items():
        if len(cols) > 1:
            shown = ", ".join(map(repr, cols))
            msg = f"has {len(cols)} {kind} columns ({shown}); keep one"
            raise ctx.error(msg)
    ordered = [by_kind[kind][0] for kind in ID_COLUMNS if kind in by_kind]
    if len(ordered) > 1 and "id" in by_kind:
        ordered.remove(by_kind["id"][0])
    return ordered


def id_columns(columns: list[str], *, id_column: str | None = None) -> list[str]:
    """
    The columns a table's rows are grouped by, most specific first (rule above).

    Examples
    --------
    >>> id_columns(["VehicleID", "timestamp", "lat", "lon", "trip_id", "id"])
    ['trip_id', 'VehicleID']
    """
    return _id_columns(columns, _Context("<table>", None, "table", "trace", id_column))


def group_rows(
    frame: pd.DataFrame,
    *,
    numbers: IntArray,
    label: str,
    ctx: _Context,
    source: str | None = None,
) -> list[RawTrace]:
    """
    Split a table into traces by its id columns, keeping first-appearance and row order.

    Parameters
    ----------
    frame
        The rows, as read.
    numbers
        The ``label`` number of every row in the source.
    label
        What ``numbers`` count.
    ctx
        The source (its name, default id and ``id_column``).
    source
        Name of the rows' source for messages; default the file name.

    Returns
    -------
    list of RawTrace
        One per id (or one for a table without ids); empty for an empty table.

    Raises
    ------
    InvalidTraceError
        Some rows have no id.
    """
    where = source or ctx.name
    if len(frame) == 0:
        return []
    frame = frame.reset_index(drop=True)
    cols = _id_columns([str(c) for c in frame.columns], ctx)
    notes: tuple[str, ...] = ()
    row_numbers = (
        ctx.id_column is None
        and cols
        and normal_id_name(cols[0]) == "id"
        and len(frame) > 2
        and frame[cols[0]].nunique(dropna=False) == len(frame)
    )
    if row_numbers:
        notes = (
            f"column {cols[0]!r} holds a different value in every row, so it numbers rows "
            "and does not name traces; the rows are one trace (pass id_column= to group by "
            "it anyway)",
        )
        cols = []
    if not cols:
        return [RawTrace(ctx.default_id, frame, numbers, label, where, notes=notes)]
    keys = pd.DataFrame({c: frame[c].astype("string").str.strip() for c in cols})
    missing = keys.isna().any(axis=1).to_numpy() | (keys == "").fillna(True).any(axis=1).to_numpy()
    if missing.any():
        bad = np.flatnonzero(missing)
        rows = ", ".join(f"{label} {numbers[i]}" for i in bad[:_SHOW])
        more = f" and {bad.size - _SHOW} more" if bad.size > _SHOW else ""
        named = " / ".join(str(c) for c in cols)
        msg = (
            f"trace file {ctx.name!r}: {bad.size} rows have no {named} ({rows}{more}); "
            f"fill the {named} column in every row or drop the column for a single-trace file"
        )
        raise InvalidTraceError(msg, field=str(cols[0]), rows=bad.tolist())
    codes = keys.groupby(cols, sort=False).ngroup().to_numpy()
    firsts = np.unique(codes, return_index=True)[1]
    primary = keys[cols[0]].to_numpy()[firsts]
    if len(set(primary.tolist())) == len(firsts):
        names = [str(v) for v in primary]
    else:
        names = ["/".join(str(keys[c].iat[i]) for c in reversed(cols)) for i in firsts]
    order = np.argsort(codes, kind="stable")
    bounds = np.cumsum(np.bincount(codes, minlength=len(firsts)))[:-1]
    traces = []
    for tid, idx in zip(names, np.split(order, bounds), strict=True):
        sub = frame.iloc[idx].reset_index(drop=True)
        traces.append(RawTrace(tid, sub, numbers[idx], label, where))
    return traces


def table_frame(frame: pd.DataFrame, *, source_name: str = "<table>") -> pd.DataFrame:
    """
    A table with ``lon``/``lat`` columns: a GeoDataFrame's Points in WGS84, else as given.

    A GeoDataFrame's active geometry must be a Point in every row; it is converted to WGS84
    from its CRS (none = WGS84 assumed), and replaces any ``lon``/``lat`` columns of the table.

    Raises
    ------
    InvalidTraceError
        A row's geometry is missing, empty or not a Point.
    """
    gpd = sys.modules.get("geopandas")  # only a caller that has geopandas can pass a GeoDataFrame
    if gpd is None or not isinstance(frame, gpd.GeoDataFrame):
        return frame
    try:
        geom = frame.geometry
    except AttributeError:  # a GeoDataFrame without an active geometry column
        return pd.DataFrame(frame)
    missing = geom.isna().to_numpy(dtype=bool)
    kinds = [None if gone else str(k) for k, gone in zip(geom.geom_type, missing, strict=True)]
    empty = geom.is_empty.to_numpy(dtype=bool) & ~missing
    bad = np.flatnonzero(np.array([k != "Point" for k in kinds], dtype=bool) | empty)
    if bad.size:
        shown = ", ".join(
            f"row {i} is "
            + (
                "missing"
                if kinds[i] is None
                else f"an empty {kinds[i]}"
                if empty[i]
                else f"a {kinds[i]}"
            )
            for i in bad[:_SHOW]
        )
        more = f" and {bad.size - _SHOW} more" if bad.size > _SHOW else ""
        msg = (
            f"table {source_name}: the geometry must be a Point in every row ({shown}{more}); "
            "turn lines into their vertices first (gdf.get_coordinates() or gdf.explode())"
        )
        raise InvalidTraceError(msg, field="geometry", rows=bad.tolist())
    if frame.crs is not None:
        geom = geom.to_crs(4326)
    plain = pd.DataFrame(frame.drop(columns=[geom.name]))
    plain = plain.drop(columns=[c for c in plain.columns if str(c).strip().lower() in _COORD_NAMES])
    plain["lon"] = geom.x.to_numpy(dtype=np.float64)
    plain["lat"] = geom.y.to_numpy(dtype=np.float64)
    return plain


def _decode_text(data: bytes) -> bytes:
    """The bytes without a UTF-8 byte-order mark; UTF-16 (with its mark) converted to UTF-8."""
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        return data.decode("utf-16").encode("utf-8")
    if data.startswith(b"\xef\xbb\xbf"):
        return data[3:]
    return data


def _latin1_note(data: bytes) -> str:
    """Why a CSV is read as Latin-1: where it stops being UTF-8."""
    try:
        data.decode("utf-8")
    except UnicodeDecodeError as exc:
        where = f" (byte {exc.start + 1})"
    else:  # pragma: no cover - only called after pandas failed to decode
        where = ""
    return f"the file is not UTF-8{where}; it was read as Latin-1, so check accented text"


_COMMA_NUMBER = re.compile(r"^\s*\"?[-+]?\d+,\d+\"?\s*$")
_DOT_NUMBER = re.compile(r"^\s*\"?[-+]?\d+\.\d+\"?\s*$")


def _csv_dialect(data: bytes) -> tuple[str, str, int]:
    r"""
    ``(separator, decimal mark, lines to skip)`` told from the first lines of a CSV.

    Examples
    --------
    >>> _csv_dialect(b"time;lat;lon\n0;43,73;7,42\n")
    (';', ',', 0)
    >>> _csv_dialect(b"sep=|\ntime|lat|lon\n")
    ('|', '.', 1)
    """
    lines = data[:65536].decode("utf-8", errors="replace").splitlines()
    skip = 0
    head = next((line for line in lines if line.strip()), "")
    if head.lower().startswith("sep=") and len(head.strip()) == 5:
        sep, skip = head.strip()[4], lines.index(head) + 1
    else:
        counts = {s: head.count(s) for s in (",", ";", "\t", "|")}
        sep = max(counts, key=lambda s: counts[s]) if any(counts.values()) else ","
    decimal = "."
    if sep != ",":
        cells = [c for line in lines[skip + 1 : skip + 51] for c in line.split(sep)]
        commas = sum(1 for c in cells if _COMMA_NUMBER.match(c))
        dots = sum(1 for c in cells if _DOT_NUMBER.match(c))
        if commas > dots:
            decimal = ","
    return sep, decimal, skip


def _read_csv(data: bytes, ctx: _Context) -> list[RawTrace]:
    compressed = data[:2] == b"\x1f\x8b"
    if compressed:
        try:
            data = gzip.decompress(data)
        except (OSError, EOFError) as exc:
            msg = f"is not valid gzip: {exc}"
            raise ctx.error(msg) from exc
    data = _decode_text(data)
    sep, decimal, skip = _csv_dialect(data)
    notes: tuple[str, ...] = ()
    try:
        frame = _csv_frame(data, ctx, sep=sep, decimal=decimal, skip=skip, encoding="utf-8")
    except UnicodeDecodeError:
        notes = (_latin1_note(data),)
        frame = _csv_frame(data, ctx, sep=sep, decimal=decimal, skip=skip, encoding="latin-1")
    # Blank lines are not data: drop them but keep the line numbers of the others right
    # (header = line 1 + skip, first data row = line 2 + skip; one line per record assumed).
    keep = frame.notna().any(axis=1).to_numpy()
    numbers = np.flatnonzero(keep).astype(np.int64) + 2 + skip
    if not keep.all():
        frame = frame.loc[keep]
    traces = group_rows(frame.reset_index(drop=True), numbers=numbers, label="line", ctx=ctx)
    return [_with_notes(t, notes) for t in traces]


def _csv_frame(
    data: bytes, ctx: _Context, *, sep: str, decimal: str, skip: int, encoding: str
) -> pd.DataFrame:
    """The CSV's table, id columns read as text; UnicodeDecodeError passes through."""
    try:
        header = pd.read_csv(io.BytesIO(data), nrows=0, sep=sep, skiprows=skip, encoding=encoding)
        id_cols = _id_columns([str(c) for c in header.columns], ctx)
        return pd.read_csv(
            io.BytesIO(data),
            sep=sep,
            decimal=decimal,
            skiprows=skip,
            skip_blank_lines=False,
            encoding=encoding,
            dtype=dict.fromkeys(id_cols, str) if id_cols else None,
        )
    except pd.errors.EmptyDataError as exc:
        msg = "is empty; expected a header line and rows"
        raise ctx.error(msg) from exc
    except UnicodeDecodeError:
        raise
    except TraceFileError:
        raise
    except (pd.errors.ParserError, ValueError) as exc:
        msg = f"is not readable as CSV: {exc}"
        raise ctx.error(msg) from exc


def _with_notes(raw: RawTrace, notes: tuple[str, ...], dropped: int = 0) -> RawTrace:
    if not notes and not dropped:
        return raw
    return RawTrace(
        raw.trace_id,
        raw.frame,
        raw.numbers,
        raw.label,
        raw.source,
        raw.segment,
        raw.dropped + dropped,
        (*raw.notes, *notes),
    )


def _read_parquet(data: bytes, ctx: _Context) -> list[RawTrace]:
    try:
        frame = pd.read_parquet(io.BytesIO(data))
    except (OSError, ValueError, ImportError) as exc:
        msg = f"is not readable as Parquet: {exc}"
        raise ctx.error(msg) from exc
    numbers = np.arange(1, len(frame) + 1, dtype=np.int64)
    return group_rows(frame.reset_index(drop=True), numbers=numbers, label="record", ctx=ctx)


# --------------------------------------------------------------------------- XML: GPX, KML


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1].lower()


def _check_no_dtd(data: bytes, ctx: _Context) -> bytes:
    """Reject DTDs (no entity expansion, no external entities); normalise UTF-16/32 to UTF-8."""
    head = data[:4]
    if head.startswith((b"\xff\xfe", b"\xfe\xff")) or b"\x00" in head:
        for codec in ("utf-32", "utf-16"):
            try:
                text = data.decode(codec)
            except UnicodeDecodeError:
                continue
            data = re.sub(r"^\s*<\?xml[^>]*\?>", "", text).encode("utf-8")
            break
        else:
            msg = "has an unknown text encoding; save it as UTF-8"
            raise ctx.error(msg)
    if _DOCTYPE.search(data):
        msg = (
            "contains a DOCTYPE/ENTITY declaration, which is refused for safety; "
            "remove the <!DOCTYPE ...> line"
        )
        raise ctx.error(msg)
    return data


def _xml_root(data: bytes, ctx: _Context, expected: str) -> ET.Element:
    data = _check_no_dtd(data, ctx)
    try:
        root = ET.fromstring(data)
    except ET.ParseError as exc:
        msg = f"is not well-formed XML: {exc}"
        raise ctx.error(msg) from exc
    if _local(root.tag) != expected:
        msg = f"root element is <{_local(root.tag)}>, expected <{expected}>"
        raise ctx.error(msg)
    return root


@dataclass(slots=True)
class _Piece:
    """One trace of an XML or GeoJSON file before it is named."""

    what: str  # "trk", "rte", "Placemark", "LineString"
    k: int  # 1-based number among its kind
    name: str | None
    label: str
    records: list[dict[str, object]] = field(default_factory=list)
    segment: list[int] = field(default_factory=list)


def _child_name(el: ET.Element) -> str | None:
    for child in el:
        if _local(child.tag) == "name" and child.text and child.text.strip():
            return child.text.strip()
    return None


def _read_gpx(data: bytes, ctx: _Context) -> list[RawTrace]:
    root = _xml_root(data, ctx, "gpx")
    pieces: list[_Piece] = []
    for k, trk in enumerate((el for el in root if _local(el.tag) == "trk"), start=1):
        piece = _Piece("trk", k, _child_name(trk), "trkpt")
        for child in trk:
            if _local(child.tag) != "trkseg":
                continue
            points = [_gpx_point(pt) for pt in child if _local(pt.tag) == "trkpt"]
            if points:
                number = piece.segment[-1] + 1 if piece.segment else 0
                piece.records.extend(points)
                piece.segment.extend([number] * len(points))
        pieces.append(piece)
    for k, rte in enumerate((el for el in root if _local(el.tag) == "rte"), start=1):
        piece = _Piece("rte", k, _child_name(rte), "rtept")
        piece.records = [_gpx_point(pt) for pt in rte if _local(pt.tag) == "rtept"]
        pieces.append(piece)
    if not any(p.records for p in pieces):
        msg = (
            "has no <trk>/<trkseg>/<trkpt> points and no <rte>/<rtept> points "
            "(waypoints alone are not a trace)"
        )
        raise ctx.error(msg)
    return _pieces_to_traces(pieces, ctx)


def _pieces_to_traces(pieces: list[_Piece], ctx: _Context) -> list[RawTrace]:
    traces = []
    for tid, piece in _name_pieces(pieces, ctx):
        numbers = np.arange(1, len(piece.records) + 1, dtype=np.int64)
        frame = pd.DataFrame.from_records(piece.records)
        segment = None
        if piece.segment and piece.segment[-1] > 0:
            segment = np.asarray(piece.segment, dtype=np.int64)
        source = f"{ctx.name} {piece.what} {piece.k}"
        traces.append(RawTrace(tid, frame, numbers, piece.label, source, segment))
    return traces


def _gpx_point(pt: ET.Element) -> dict[str, object]:
    rec: dict[str, object] = {"lat": pt.get("lat"), "lon": pt.get("lon"), "time": None}
    for el in pt.iter():
        if el is pt or el.text is None:
            continue
        tag = _local(el.tag)
        if tag == "time":
            rec["time"] = el.text.strip()
        elif canonical(tag) in _GPX_FIELDS:
            rec[str(canonical(tag))] = el.text.strip()
    return rec


def _name_pieces(pieces: list[_Piece], ctx: _Context) -> list[tuple[str, _Piece]]:
    """Give every non-empty piece an id: its own name, the stem, or ``<stem>-<k>``."""
    full = [p for p in pieces if p.records]
    unnamed = sum(1 for p in full if p.name is None)
    seen: dict[str, _Piece] = {}
    out = []
    for position, piece in enumerate(full, start=1):
        k = piece.k if len({p.what for p in full}) == 1 else position
        tid = (
            piece.name
            if piece.name is not None
            else (ctx.default_id if unnamed == 1 else f"{ctx.default_id}-{k}")
        )
        if tid in seen:
            first = seen[tid]
            msg = (
                f"{first.what} {first.k} and {piece.what} {piece.k} are both named {tid!r}; "
                "give each trace its own name (or merge them)"
            )
            raise ctx.error(msg)
        seen[tid] = piece
        out.append((tid, piece))
    return out


def _read_kml(data: bytes, ctx: _Context) -> list[RawTrace]:
    root = _xml_root(data, ctx, "kml")
    pieces: list[_Piece] = []
    marks = [el for el in root.iter() if _local(el.tag) == "placemark"]
    for k, mark in enumerate(marks, start=1):
        piece = _Piece("Placemark", k, _child_name(mark), "coord")
        for el in mark.iter():
            tag = _local(el.tag)
            if tag == "track":
                whens = [w.text for w in el if _local(w.tag) == "when"]
                coords = [c.text or "" for c in el if _local(c.tag) == "coord"]
                if whens and len(whens) != len(coords):
                    msg = (
                        f"Placemark {k}: a gx:Track has {len(whens)} <when> for "
                        f"{len(coords)} <gx:coord>; give one time per position"
                    )
                    raise ctx.error(msg)
                parts = [c.split() for c in coords]
                times = [w.strip() if w else None for w in whens] or [None] * len(coords)
                _add_segment(piece, parts, times)
            elif tag == "linestring":
                text = next((c.text or "" for c in el if _local(c.tag) == "coordinates"), "")
                parts = [t.split(",") for t in text.split()]
                _add_segment(piece, parts, [None] * len(parts))
        pieces.append(piece)
    if not any(p.records for p in pieces):
        msg = "has no Placemark with a gx:Track or a LineString (points alone are not a trace)"
        raise ctx.error(msg)
    return _pieces_to_traces(pieces, ctx)


def _add_segment(piece: _Piece, parts: list[list[str]], times: list[str | None]) -> None:
    if not parts:
        return
    number = piece.segment[-1] + 1 if piece.segment else 0
    for p, t in zip(parts, times, strict=True):
        lon, lat = (p[0], p[1]) if len(p) >= 2 else (None, None)
        piece.records.append({"time": t, "lon": lon, "lat": lat})
    piece.segment.extend([number] * len(parts))


# --------------------------------------------------------------------------- NMEA 0183

_KNOT_MPS: Final = 1852.0 / 3600.0
_NMEA_TIME = re.compile(r"^(\d{2})(\d{2})(\d{2}(?:\.\d+)?)$")
_DAY_S: Final = 86400.0


@dataclass(slots=True)
class _Fix:
    line: int
    tod: str  # time of day as written (hhmmss.ss): sentences of one epoch share it
    tod_s: float
    date_s: float | None  # epoch seconds of the date's midnight (RMC only)
    lat: float
    lon: float
    speed: float = math.nan
    course: float = math.nan
    hdop: float = math.nan


def _nmea_checksum(body: str) -> int:
    """
    XOR of the characters between ``$`` and ``*``.

    Examples
    --------
    >>> f"{_nmea_checksum('GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,'):02X}"
    '47'
    """
    value = 0
    for ch in body.encode("ascii", errors="replace"):
        value ^= ch
    return value


def _nmea_degrees(value: str, hemi: str, width: int) -> float:
    """``ddmm.mmmm`` (``dddmm.mmmm`` for longitude) and N/S/E/W to signed degrees (NaN if bad)."""
    value, hemi = value.strip(), hemi.strip().upper()
    if len(value) < width + 2 or hemi not in ("N", "S", "E", "W"):
        return math.nan
    try:
        deg = int(value[:width]) + float(value[width:]) / 60.0
    except ValueError:
        return math.nan
    return -deg if hemi in ("S", "W") else deg


def _nmea_float(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        return math.nan


def _nmea_tod(text: str) -> float | None:
    m = _NMEA_TIME.match(text.strip())
    if m is None:
        return None
    h, mi, s = int(m.group(1)), int(m.group(2)), float(m.group(3))
    if h > 23 or mi > 59 or s >= 61:
        return None
    return h * 3600.0 + mi * 60.0 + s


def _nmea_date_s(text: str) -> float | None:
    text = text.strip()
    if len(text) != 6 or not text.isdigit():
        return None
    day, month, yy = int(text[:2]), int(text[2:4]), int(text[4:])
    year = 2000 + yy if yy < 80 else 1900 + yy
    try:
        stamp = np.datetime64(f"{year:04d}-{month:02d}-{day:02d}", "D")
    except ValueError:
        return None
    return float(stamp.astype("datetime64[s]").astype(np.int64))


class _NmeaTally:
    """Lines of an NMEA log that did not become fixes, by reason."""

    def __init__(self) -> None:
        self.reasons: dict[str, list[int]] = {}
        self.unchecked = 0

    def drop(self, reason: str, line: int) -> None:
        self.reasons.setdefault(reason, []).append(line)

    @property
    def dropped(self) -> int:
        return sum(len(v) for v in self.reasons.values())

    def notes(self) -> tuple[str, ...]:
        out = []
        for reason, lines in self.reasons.items():
            shown = ", ".join(str(n) for n in lines[:_SHOW])
            more = f" and {len(lines) - _SHOW} more" if len(lines) > _SHOW else ""
            many = len(lines) != 1
            out.append(
                f"{len(lines)} NMEA sentence{'s' if many else ''} {reason} "
                f"{'were' if many else 'was'} dropped (line{'s' if many else ''} {shown}{more})"
            )
        if self.unchecked:
            out.append(
                f"{self.unchecked} NMEA sentence(s) carry no checksum (*hh) and were used unchecked"
            )
        return tuple(out)


def _nmea_sentence(line: str, number: int, tally: _NmeaTally) -> list[str] | None:
    """The fields of one RMC or GGA sentence with a valid checksum, else ``None``."""
    start = line.find("$")
    if start < 0:
        return None
    text = line[start + 1 :].strip()
    body, star, check = text.partition("*")
    kind = body.split(",", 1)[0]
    if len(kind) != 5 or kind[2:] not in ("RMC", "GGA"):
        return None  # other sentences (GSV, GSA, VTG, proprietary) carry no fix
    if star:
        given = check[:2]
        try:
            ok = int(given, 16) == _nmea_checksum(body)
        except ValueError:
            ok = False
        if not ok:
            tally.drop("with a wrong checksum", number)
            return None
    else:
        tally.unchecked += 1
    return body.split(",")


def _nmea_fix(fields: list[str], number: int, tally: _NmeaTally) -> _Fix | None:
    kind = fields[0][2:]
    need = 10 if kind == "RMC" else 9
    if len(fields) < need:
        tally.drop(f"({kind}) with too few fields", number)
        return None
    tod_s = _nmea_tod(fields[1])
    if kind == "RMC":
        valid = fields[2].strip().upper() == "A"
        lat = _nmea_degrees(fields[3], fields[4], 2)
        lon = _nmea_degrees(fields[5], fields[6], 3)
    else:
        valid = fields[6].strip() not in ("", "0")
        lat = _nmea_degrees(fields[2], fields[3], 2)
        lon = _nmea_degrees(fields[4], fields[5], 3)
    if not valid:
        status = "status V" if kind == "RMC" else "fix quality 0"
        tally.drop(f"({kind}) reporting no fix ({status})", number)
        return None
    if tod_s is None or math.isnan(lat) or math.isnan(lon):
        tally.drop(f"({kind}) without a readable time or position", number)
        return None
    fix = _Fix(number, fields[1].strip(), tod_s, None, lat, lon)
    if kind == "RMC":
        fix.date_s = _nmea_date_s(fields[9])
        fix.speed = _nmea_float(fields[7]) * _KNOT_MPS
        fix.course = _nmea_float(fields[8])
    else:
        fix.hdop = _nmea_float(fields[8])
    return fix


def _read_nmea(data: bytes, ctx: _Context) -> list[RawTrace]:
    text = data.decode("ascii", errors="replace")
    tally = _NmeaTally()
    fixes: list[_Fix] = []
    sentences = 0
    for number, line in enumerate(text.splitlines(), start=1):
        fields = _nmea_sentence(line, number, tally)
        if fields is None:
            continue
        sentences += 1
        fix = _nmea_fix(fields, number, tally)
        if fix is None:
            continue
        last = fixes[-1] if fixes else None
        if last is not None and last.tod == fix.tod:  # RMC + GGA of one epoch
            last.date_s = last.date_s if last.date_s is not None else fix.date_s
            for name in ("speed", "course", "hdop"):
                if math.isnan(getattr(last, name)):
                    setattr(last, name, getattr(fix, name))
            continue
        fixes.append(fix)
    if not fixes:
        what = "no $..RMC or $..GGA sentence" if sentences == 0 and not tally.dropped else "no fix"
        dropped = f"; {'; '.join(tally.notes())}" if tally.notes() else ""
        msg = f"holds {what} with a position{dropped}"
        raise ctx.error(msg)
    notes = list(tally.notes())
    time_s = _nmea_times(fixes, notes)
    frame = pd.DataFrame(
        {
            "time": time_s,
            "lat": [f.lat for f in fixes],
            "lon": [f.lon for f in fixes],
            "speed": [f.speed for f in fixes],
            "course": [f.course for f in fixes],
            "hdop": [f.hdop for f in fixes],
        }
    )
    for name in ("speed", "course", "hdop"):
        if frame[name].isna().all():
            frame = frame.drop(columns=name)
    numbers = np.array([f.line for f in fixes], dtype=np.int64)
    raw = RawTrace(ctx.default_id, frame, numbers, "line", ctx.name)
    return [_with_notes(raw, tuple(notes), tally.dropped)]


def _nmea_times(fixes: list[_Fix], notes: list[str]) -> list[float]:
    """Epoch seconds of every fix: its RMC date, else the nearest RMC's, rolling at midnight."""
    dated = [i for i, f in enumerate(fixes) if f.date_s is not None]
    if not dated:
        notes.append(
            "no RMC sentence gives a date: times are seconds of day counted from 1970-01-01 "
            "(the order and the intervals are right, the date is not)"
        )
    first_date = fixes[dated[0]].date_s if dated else None
    day = 0.0 if first_date is None else first_date
    # Walk back from the first dated fix so that leading GGA fixes get its date (or the day
    # before when they are before midnight), then forward.
    out = [math.nan] * len(fixes)
    first = dated[0] if dated else 0
    current, prev_tod = day, fixes[first].tod_s
    for i in range(first, -1, -1):
        tod = fixes[i].tod_s
        if tod > prev_tod + _DAY_S / 2:
            current -= _DAY_S
        prev_tod = tod
        out[i] = current + tod
    current, prev_tod = day, fixes[first].tod_s
    for i in range(first + 1, len(fixes)):
        fix = fixes[i]
        if fix.date_s is not None:
            current = fix.date_s
        elif fix.tod_s < prev_tod - _DAY_S / 2:
            current += _DAY_S
        prev_tod = fix.tod_s
        out[i] = current + fix.tod_s
    return out


# --------------------------------------------------------------------------- JSON / GeoJSON


def _read_json(data: bytes, ctx: _Context) -> list[RawTrace]:
    try:
        doc = json.loads(data)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        msg = f"is not valid JSON: {exc}"
        raise ctx.error(msg) from exc
    if isinstance(doc, Mapping) and doc.get("type") in ("FeatureCollection", "Feature"):
        return _read_geojson(doc, ctx)
    if ctx.fmt == "geojson":
        msg = "is not a GeoJSON Feature or FeatureCollection (no 'type' member)"
        raise ctx.error(msg)
    if isinstance(doc, Mapping) and isinstance(doc.get("points"), list):
        points = doc["points"]
        tid = doc.get("trace_id")
    elif isinstance(doc, list):
        points, tid = doc, None
    else:
        msg = 'expected {"points": [...], "trace_id": ...} or a list of point objects'
        raise ctx.error(msg)
    bad = [i for i, p in enumerate(points) if not isinstance(p, Mapping)]
    if bad:
        msg = f"point {bad[0] + 1} is {type(points[bad[0]]).__name__}, not an object"
        raise ctx.error(msg)
    frame = pd.DataFrame.from_records(points)
    numbers = np.arange(1, len(points) + 1, dtype=np.int64)
    if tid is not None:
        drop = [c for c in frame.columns if id_kind(c) == "trace_id"]
        frame = frame.drop(columns=drop)
        ctx = ctx.renamed(str(tid))
    return group_rows(frame, numbers=numbers, label="point", ctx=ctx)


def _read_geojson(doc: Mapping[str, object], ctx: _Context) -> list[RawTrace]:
    features = doc.get("features") if doc.get("type") == "FeatureCollection" else [doc]
    if not isinstance(features, list):
        msg = "'features' is not a list"
        raise ctx.error(msg)
    point_records: list[dict[str, object]] = []
    point_numbers: list[int] = []
    lines: list[_Piece] = []
    for k, feat in enumerate(features, start=1):
        if not isinstance(feat, Mapping) or feat.get("type") != "Feature":
            msg = f"feature {k} is not a GeoJSON Feature object"
            raise ctx.error(msg)
        props = feat.get("properties") or {}
        geom = feat.get("geometry")
        if not isinstance(props, Mapping):
            msg = f"feature {k}: 'properties' is not an object"
            raise ctx.error(msg)
        gtype = geom.get("type") if isinstance(geom, Mapping) else None
        coords = geom.get("coordinates") if isinstance(geom, Mapping) else None
        if gtype in ("LineString", "MultiLineString") and isinstance(coords, list):
            parts = [coords] if gtype == "LineString" else coords
            lines.append(_linestring_piece(k, props, parts, ctx))
            continue
        if gtype not in ("Point", None):
            msg = f"feature {k} is a {gtype}; use Point features or one LineString per trace"
            raise ctx.error(msg)
        rec = {key: v for key, v in props.items() if str(key).strip().lower() not in _COORD_NAMES}
        lon, lat = _lonlat(coords)
        rec["lon"], rec["lat"] = lon, lat
        point_records.append(rec)
        point_numbers.append(k)
    traces: list[RawTrace] = []
    if point_records:
        frame = pd.DataFrame.from_records(point_records)
        numbers = np.asarray(point_numbers, dtype=np.int64)
        traces.extend(group_rows(frame, numbers=numbers, label="feature", ctx=ctx))
    if lines:
        taken = {t.trace_id for t in traces}
        for raw in _pieces_to_traces(lines, ctx):
            if raw.trace_id in taken:
                msg = f"trace_id {raw.trace_id!r} is used by Point features and a LineString"
                raise ctx.error(msg)
            traces.append(raw)
    return traces


def _lonlat(coords: object) -> tuple[object, object]:
    if isinstance(coords, list | tuple) and len(coords) >= 2:
        return coords[0], coords[1]
    return None, None


def _linestring_piece(
    k: int, props: Mapping[str, object], parts: list[object], ctx: _Context
) -> _Piece:
    """
    Vertices of a (Multi)LineString feature with per-vertex list properties as columns.

    A MultiLineString's lines are segments; its per-vertex properties are lists of lists
    (one per line, as ``coordTimes`` of togeojson) or one flat list over all vertices.
    """
    lines = [p if isinstance(p, list) else [] for p in parts]
    coords = [c for line in lines for c in line]
    n = len(coords)
    columns: dict[str, list[object]] = {}
    per_vertex: dict[str, object] = dict(props)
    nested = props.get("coordinateProperties")
    if isinstance(nested, Mapping):
        per_vertex.update(nested)
    for key, value in per_vertex.items():
        name = str(key)
        if name.strip().lower() in ("times", "coordtimes"):
            name = "time"
        if not isinstance(value, list):
            continue
        if len(lines) > 1 and len(value) == len(lines) and all(isinstance(v, list) for v in value):
            value = [v for sub in value for v in sub]
        if len(value) != n:
            msg = (
                f"feature {k}: property {key!r} has {len(value)} values for {n} coordinates; "
                "give one value per vertex"
            )
            raise ctx.error(msg)
        if name.strip().lower() not in _COORD_NAMES:
            columns[name] = value
    tid = props.get("trace_id")
    piece = _Piece("LineString", k, None if tid is None else str(tid), "vertex")
    for i, c in enumerate(coords):
        lon, lat = _lonlat(c)
        rec: dict[str, object] = {key: vals[i] for key, vals in columns.items()}
        rec["lon"], rec["lat"] = lon, lat
        piece.records.append(rec)
    piece.segment = [s for s, line in enumerate(lines) for _ in line]
    return piece
