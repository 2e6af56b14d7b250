"""Which reader reads a source: the format from the suffix (or ``format=``), then the reader."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Final

import pandas as pd

from mapmatch.errors import TraceFileError
from mapmatch.trace.readers.delimited import read_csv
from mapmatch.trace.readers.geojson import read_json
from mapmatch.trace.readers.gpx import read_gpx
from mapmatch.trace.readers.kml import read_kml
from mapmatch.trace.readers.nmea import read_nmea
from mapmatch.trace.readers.raw import Context, RawTrace
from mapmatch.trace.readers.tables import read_parquet, read_table

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping

__all__ = ["FORMATS", "infer_format", "read_raw_traces"]

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


_READERS: Final[Mapping[str, Callable[[bytes, Context], list[RawTrace]]]] = {
    "csv": read_csv,
    "parquet": read_parquet,
    "gpx": read_gpx,
    "kml": read_kml,
    "nmea": read_nmea,
    "json": read_json,
    "geojson": read_json,  # both layouts, told apart by content
}


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
        Column whose values name the traces of a table; default: the rule of
        :mod:`mapmatch.trace.readers.grouping`.

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
        ctx = Context("<table>", None, "table", default_trace_id or "trace", id_column)
        traces = read_table(source, ctx)
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
    ctx = Context(name=name, path=path_str, fmt=fmt, default_id=default_id, id_column=id_column)
    traces = _READERS.get(fmt, read_json)(data, ctx)
    if not traces:
        msg = "holds no trace points"
        raise ctx.error(msg)
    return traces
