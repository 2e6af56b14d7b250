"""
Traces from a source: :func:`read_traces` (files, bodies, tables), :func:`trace_from_raw`.

:func:`trace_from_raw` validates one trace a reader of :mod:`mapmatch.trace.readers`
returned, keeping its line numbers, segments and dropped records.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from mapmatch.trace.model import Trace
from mapmatch.trace.readers import RawTrace, read_raw_traces

if TYPE_CHECKING:
    import os

    import pandas as pd

__all__ = ["read_traces", "trace_from_raw"]


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
