"""
Trace file formats: CSV (also gzipped), GPX, GeoJSON, Parquet and the JSON body of the API.

Each reader turns a file (or an in-memory body) into :class:`RawTrace` tables: the columns as
they appear in the source, one row per fix, plus the 1-based line or record number of every row
so that :mod:`mapmatch.trace` can point at the offending place when it validates. Nothing is
validated here except the container itself; a file that cannot be read at all raises
:class:`~mapmatch.errors.TraceFileError`.

Grouping into traces
--------------------
A file may hold several traces. CSV and Parquet rows are grouped by a ``trace_id`` column,
GeoJSON Point features by their ``trace_id`` property, JSON points by their ``trace_id`` member;
each GPX ``<trk>`` and each GeoJSON LineString feature is one trace, named by its ``<name>`` or
``trace_id`` property. Groups keep the order of first appearance. A trace without an id is
named after the file stem (``trip.csv.gz`` -> ``"trip"``), or ``default_trace_id`` for a body,
or ``"trace"``; when several tracks or LineStrings of one file have no name, the ``k``-th
(1-based) is called ``"<stem>-<k>"``.
"""

from __future__ import annotations

import gzip
import io
import json
import os
import re
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from mapmatch.errors import InvalidTraceError, TraceFileError

if TYPE_CHECKING:
    import numpy.typing as npt

    IntArray = npt.NDArray[np.int64]

__all__ = ["FORMATS", "RawTrace", "infer_format", "read_raw_traces"]

FORMATS = ("csv", "gpx", "geojson", "parquet", "json")
"""Trace formats :func:`read_raw_traces` understands."""

_SUFFIXES = {
    ".csv": "csv",
    ".csv.gz": "csv",
    ".gpx": "gpx",
    ".geojson": "geojson",
    ".json": "json",
    ".parquet": "parquet",
    ".pq": "parquet",
}
_TRACE_ID_NAMES = frozenset({"trace_id"})
_COORD_NAMES = frozenset({"lat", "latitude", "lon", "lng", "longitude"})
_GPX_FIELDS = {
    "course": "course",
    "heading": "course",
    "bearing": "course",
    "speed": "speed",
    "hdop": "hdop",
}
_DOCTYPE = re.compile(rb"<!\s*(DOCTYPE|ENTITY)", re.IGNORECASE)


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
        1-based ``label`` number of every row in the source (CSV line, GPX trkpt, ...).
    label
        What ``numbers`` count: ``"line"``, ``"record"``, ``"trkpt"``, ``"feature"``,
        ``"vertex"`` or ``"point"``.
    source
        Where the rows came from, for messages (``"trip.gpx trk 2"``, ``"<bytes>"``).
    """

    trace_id: str
    frame: pd.DataFrame
    numbers: IntArray
    label: str
    source: str


def infer_format(path: str | os.PathLike[str]) -> str:
    """
    Trace format named by a file's suffix.

    Parameters
    ----------
    path
        File name; ``.csv``, ``.csv.gz``, ``.gpx``, ``.geojson``, ``.json``, ``.parquet``
        and ``.pq`` are known (case-insensitive).

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
    source: str | os.PathLike[str] | bytes,
    *,
    format: str | None = None,
    default_trace_id: str | None = None,
) -> list[RawTrace]:
    """
    Read every trace of a file or body into unvalidated tables.

    Parameters
    ----------
    source
        A file path, or the raw bytes of a body (then ``format`` is required).
    format
        One of :data:`FORMATS`; inferred from the file suffix when ``None``. ``"json"`` and
        ``"geojson"`` both accept either layout and tell them apart by content.
    default_trace_id
        Id of traces the source does not name; default: the file stem, or ``"trace"``.

    Returns
    -------
    list of RawTrace
        In order of first appearance in the source; never empty.

    Raises
    ------
    TraceFileError
        The file is missing, unreadable, of an unknown format, empty or malformed.
    InvalidTraceError
        Rows of a grouped file lack their ``trace_id``.
    """
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
    ctx = _Context(name=name, path=path_str, fmt=fmt, default_id=default_id)
    if fmt == "csv":
        traces = _read_csv(data, ctx)
    elif fmt == "parquet":
        traces = _read_parquet(data, ctx)
    elif fmt == "gpx":
        traces = _read_gpx(data, ctx)
    else:
        traces = _read_json(data, ctx)
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

    def error(self, problem: str) -> TraceFileError:
        msg = f"trace file {self.name!r} ({self.fmt}): {problem}"
        return TraceFileError(msg, path=self.path, format=self.fmt)


# --------------------------------------------------------------------------- tables


def _find_trace_id_column(columns: list[str], ctx: _Context) -> str | None:
    found = [c for c in columns if str(c).strip().lower() in _TRACE_ID_NAMES]
    if len(found) > 1:
        msg = f"has {len(found)} trace_id columns ({', '.join(map(repr, found))}); keep one"
        raise ctx.error(msg)
    return found[0] if found else None


def _group_frame(
    frame: pd.DataFrame, numbers: IntArray, label: str, ctx: _Context
) -> list[RawTrace]:
    """Split a table into traces by its trace_id column, keeping first-appearance order."""
    if len(frame) == 0:
        return []
    id_col = _find_trace_id_column([str(c) for c in frame.columns], ctx)
    if id_col is None:
        frame = frame.reset_index(drop=True)
        return [RawTrace(ctx.default_id, frame, numbers, label, ctx.name)]
    ids = frame[id_col]
    missing = (
        ids.isna().to_numpy() | (ids.astype("string").str.strip() == "").fillna(True).to_numpy()
    )
    if missing.any():
        bad = np.flatnonzero(missing)
        where = ", ".join(f"{label} {numbers[i]}" for i in bad[:5])
        more = f" and {bad.size - 5} more" if bad.size > 5 else ""
        msg = (
            f"trace file {ctx.name!r}: {bad.size} rows have no trace_id ({where}{more}); "
            "fill the trace_id column in every row or drop the column for a single-trace file"
        )
        raise InvalidTraceError(msg, field="trace_id", rows=bad.tolist())
    codes, uniques = pd.factorize(ids.astype("string").str.strip(), sort=False)
    order = np.argsort(codes, kind="stable")
    bounds = np.cumsum(np.bincount(codes, minlength=len(uniques)))[:-1]
    traces = []
    for tid, idx in zip(uniques, np.split(order, bounds), strict=True):
        sub = frame.iloc[idx].reset_index(drop=True)
        traces.append(RawTrace(str(tid), sub, numbers[idx], label, ctx.name))
    return traces


def _read_csv(data: bytes, ctx: _Context) -> list[RawTrace]:
    compressed = data[:2] == b"\x1f\x8b"
    if compressed:
        try:
            data = gzip.decompress(data)
        except (OSError, EOFError) as exc:
            msg = f"is not valid gzip: {exc}"
            raise ctx.error(msg) from exc
    try:
        header = pd.read_csv(io.BytesIO(data), nrows=0)
        id_col = _find_trace_id_column([str(c) for c in header.columns], ctx)
        frame = pd.read_csv(
            io.BytesIO(data),
            skip_blank_lines=False,
            dtype={id_col: str} if id_col is not None else None,
        )
    except pd.errors.EmptyDataError as exc:
        msg = "is empty; expected a header line and rows"
        raise ctx.error(msg) from exc
    except (pd.errors.ParserError, UnicodeDecodeError, ValueError) as exc:
        msg = f"is not readable as CSV: {exc}"
        raise ctx.error(msg) from exc
    # Blank lines are not data: drop them but keep the line numbers of the others right
    # (header = line 1, first data row = line 2; one line per record assumed).
    keep = frame.notna().any(axis=1).to_numpy()
    numbers = np.flatnonzero(keep).astype(np.int64) + 2
    if not keep.all():
        frame = frame.loc[keep]
    return _group_frame(frame.reset_index(drop=True), numbers, "line", ctx)


def _read_parquet(data: bytes, ctx: _Context) -> list[RawTrace]:
    try:
        frame = pd.read_parquet(io.BytesIO(data))
    except (OSError, ValueError, ImportError) as exc:
        msg = f"is not readable as Parquet: {exc}"
        raise ctx.error(msg) from exc
    numbers = np.arange(1, len(frame) + 1, dtype=np.int64)
    return _group_frame(frame.reset_index(drop=True), numbers, "record", ctx)


# --------------------------------------------------------------------------- GPX


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


def _read_gpx(data: bytes, ctx: _Context) -> list[RawTrace]:
    data = _check_no_dtd(data, ctx)
    try:
        root = ET.fromstring(data)
    except ET.ParseError as exc:
        msg = f"is not well-formed XML: {exc}"
        raise ctx.error(msg) from exc
    if _local(root.tag) != "gpx":
        msg = f"root element is <{_local(root.tag)}>, expected <gpx>"
        raise ctx.error(msg)
    tracks = [el for el in root if _local(el.tag) == "trk"]
    named: list[tuple[int, str | None, list[dict[str, object]]]] = []
    for k, trk in enumerate(tracks, start=1):
        name: str | None = None
        points: list[dict[str, object]] = []
        for child in trk:
            tag = _local(child.tag)
            if tag == "name" and child.text and child.text.strip():
                name = child.text.strip()
            elif tag == "trkseg":
                points.extend(_gpx_point(pt) for pt in child if _local(pt.tag) == "trkpt")
        named.append((k, name, points))
    if not any(points for _, _, points in named):
        msg = "has no <trk>/<trkseg>/<trkpt> points (routes and waypoints are not traces)"
        raise ctx.error(msg)
    traces = []
    for k, tid, points in _name_tracks(named, ctx, "trk"):
        numbers = np.arange(1, len(points) + 1, dtype=np.int64)
        frame = pd.DataFrame.from_records(points)
        traces.append(RawTrace(tid, frame, numbers, "trkpt", f"{ctx.name} trk {k}"))
    return traces


def _gpx_point(pt: ET.Element) -> dict[str, object]:
    rec: dict[str, object] = {"lat": pt.get("lat"), "lon": pt.get("lon"), "time": None}
    for el in pt.iter():
        if el is pt or el.text is None:
            continue
        tag = _local(el.tag)
        if tag == "time":
            rec["time"] = el.text.strip()
        elif tag in _GPX_FIELDS:
            rec[_GPX_FIELDS[tag]] = el.text.strip()
    return rec


def _name_tracks(
    named: list[tuple[int, str | None, list[dict[str, object]]]], ctx: _Context, what: str
) -> list[tuple[int, str, list[dict[str, object]]]]:
    """Give every non-empty track an id: its own name, the stem, or ``<stem>-<k>``."""
    unnamed = sum(1 for _, name, pts in named if name is None and pts)
    seen: dict[str, int] = {}
    out = []
    for k, name, points in named:
        if not points:
            continue
        tid = (
            name
            if name is not None
            else (ctx.default_id if unnamed == 1 else f"{ctx.default_id}-{k}")
        )
        if tid in seen:
            msg = (
                f"{what} {seen[tid]} and {what} {k} are both named {tid!r}; "
                "give each trace its own name (or merge them)"
            )
            raise ctx.error(msg)
        seen[tid] = k
        out.append((k, tid, points))
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
        drop = [c for c in frame.columns if str(c).strip().lower() in _TRACE_ID_NAMES]
        frame = frame.drop(columns=drop)
        ctx = _Context(ctx.name, ctx.path, ctx.fmt, str(tid))
    return _group_frame(frame, numbers, "point", ctx)


def _read_geojson(doc: Mapping[str, object], ctx: _Context) -> list[RawTrace]:
    features = doc.get("features") if doc.get("type") == "FeatureCollection" else [doc]
    if not isinstance(features, list):
        msg = "'features' is not a list"
        raise ctx.error(msg)
    point_records: list[dict[str, object]] = []
    point_numbers: list[int] = []
    lines: list[tuple[int, str | None, list[dict[str, object]]]] = []
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
        if gtype == "LineString" and isinstance(coords, list):
            lines.append((k, *_linestring_records(k, props, coords, ctx)))
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
        traces.extend(
            _group_frame(frame, np.asarray(point_numbers, dtype=np.int64), "feature", ctx)
        )
    if lines:
        taken = {t.trace_id for t in traces}
        for k, tid, records in _name_tracks(lines, ctx, "LineString"):
            if tid in taken:
                msg = f"trace_id {tid!r} is used by Point features and a LineString"
                raise ctx.error(msg)
            numbers = np.arange(1, len(records) + 1, dtype=np.int64)
            frame = pd.DataFrame.from_records(records)
            traces.append(RawTrace(tid, frame, numbers, "vertex", f"{ctx.name} LineString {k}"))
    return traces


def _lonlat(coords: object) -> tuple[object, object]:
    if isinstance(coords, list | tuple) and len(coords) >= 2:
        return coords[0], coords[1]
    return None, None


def _linestring_records(
    k: int, props: Mapping[str, object], coords: list[object], ctx: _Context
) -> tuple[str | None, list[dict[str, object]]]:
    """Vertices of a LineString feature with per-vertex list properties as columns."""
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
        if isinstance(value, list):
            if len(value) != n:
                msg = (
                    f"feature {k}: property {key!r} has {len(value)} values for {n} coordinates; "
                    "give one value per vertex"
                )
                raise ctx.error(msg)
            if name.strip().lower() not in _COORD_NAMES:
                columns[name] = value
    records = []
    for i, c in enumerate(coords):
        lon, lat = _lonlat(c)
        rec: dict[str, object] = {key: vals[i] for key, vals in columns.items()}
        rec["lon"], rec["lat"] = lon, lat
        records.append(rec)
    tid = props.get("trace_id")
    return (None if tid is None else str(tid)), records
