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

from mapmatch.trace.columns import ID_COLUMNS
from mapmatch.trace.readers.dispatch import FORMATS, infer_format, read_raw_traces
from mapmatch.trace.readers.grouping import group_rows, id_columns
from mapmatch.trace.readers.raw import RawTrace
from mapmatch.trace.readers.tables import table_frame

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
