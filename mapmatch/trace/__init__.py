"""The trace input stage: validate, sort and report one vehicle trace; read trace files.

:class:`Trace` (``model``) holds one vehicle's fixes; :func:`read_traces` reads a file of many;
``columns`` declares the input columns once (:func:`input_columns`, for readers, validation
and the HTTP point model); ``readers`` parses the file formats, ``chinacrs`` converts
GCJ-02/BD-09 coordinates.
"""

from __future__ import annotations

from mapmatch.trace.columns import Column, input_columns
from mapmatch.trace.model import (
    FIELD_ALIASES,
    IMPLAUSIBLE_SHARE,
    MAX_PLAUSIBLE_SPEED_MPS,
    MOVING_STEP_M,
    SUPPORTED_CRS,
    TIME_SOURCES,
    UERE_M,
    FloatArray,
    Trace,
    TraceReport,
    check_match_inputs,
    read_traces,
    trace_from_raw,
)

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
