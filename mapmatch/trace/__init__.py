"""
The trace input stage: validate, sort and report one vehicle trace; read trace files.

:class:`Trace` holds one vehicle's fixes; :func:`read_traces` reads a source of many;
:func:`input_columns` lists the input columns, declared once (:mod:`.columns`) for the
readers, validation and the HTTP point model.

Validation happens once, when a :class:`Trace` is built. A row that breaks a rule raises
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
Declared once in :mod:`mapmatch.trace.columns` (:func:`input_columns`): ``time`` (``t``,
``timestamp``, ``datetime``, ``ts``); ``lat`` (``latitude``); ``lon`` (``lng``,
``longitude``); optional ``heading`` (``bearing``, ``course``, ``heading_deg``), ``speed``
(``speed_mps``), ``accuracy`` (``accuracy_m``), ``hdop``, ``odometer`` (``odometer_m``),
``segment``. Tables are grouped into traces by their id columns (``trace_id``, ``trip_id``,
``vehicle_id`` ...; see :mod:`mapmatch.trace.readers`).

Modules
-------
``model`` the :class:`Trace` value object and its constructors; ``validation`` the rules in
order, built on ``checks`` (row rules and their messages), ``times`` (parsing, units) and
``ordering`` (sorting, merging, plausible times); ``report`` :class:`TraceReport`;
``frames`` table columns to fields; ``sources`` :func:`read_traces`; ``guards``
:func:`check_match_inputs`; ``readers`` the file formats; ``chinacrs`` GCJ-02/BD-09.
"""

from __future__ import annotations

from mapmatch.trace.columns import FIELD_ALIASES, Column, input_columns
from mapmatch.trace.guards import check_match_inputs
from mapmatch.trace.model import Trace
from mapmatch.trace.ordering import IMPLAUSIBLE_SHARE, MAX_PLAUSIBLE_SPEED_MPS, MOVING_STEP_M
from mapmatch.trace.report import TIME_SOURCES, TraceReport
from mapmatch.trace.sources import read_traces, trace_from_raw
from mapmatch.trace.validation import SUPPORTED_CRS, UERE_M
from mapmatch.types import FloatArray

__all__ = [
    "FIELD_ALIASES",
    "IMPLAUSIBLE_SHARE",
    "MAX_PLAUSIBLE_SPEED_MPS",
    "MOVING_STEP_M",
    "SUPPORTED_CRS",
    "TIME_SOURCES",
    "UERE_M",
    "Column",
    "FloatArray",
    "Trace",
    "TraceReport",
    "check_match_inputs",
    "input_columns",
    "read_traces",
    "trace_from_raw",
]
