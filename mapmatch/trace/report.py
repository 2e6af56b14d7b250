"""
What validation did to a trace's rows (:class:`TraceReport`), and where the rows came from.

:class:`Origin` is what a reader knew about the rows (file, line numbers, segments, records it
skipped); the checks use it to point at the offending place, the report repeats its notes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

if TYPE_CHECKING:
    from mapmatch.types import IntArray

__all__ = ["TIME_SOURCES", "Origin", "TraceReport", "in_source"]

TIME_SOURCES: Final = ("ok", "absent", "implausible")
"""Values of :attr:`TraceReport.time_source`; only ``"ok"`` times enter the model."""


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
        kept for the output, but they imply impossible speeds; see :mod:`mapmatch.trace`).
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
class Origin:
    """Where input rows came from, to point at them in messages."""

    source: str | None = None  # file (and track) name
    label: str = "line"  # what ``numbers`` count
    numbers: IntArray | None = None  # number of each input row in the source
    segment: IntArray | None = None  # per-row segment of the source (GPX trkseg ...)
    dropped: int = 0  # source records the reader skipped
    notes: tuple[str, ...] = ()  # what the reader did, for the report


def in_source(origin: Origin) -> str:
    """`` in <source>`` for a message, or nothing for rows without a named source."""
    return f" in {origin.source}" if origin.source else ""
