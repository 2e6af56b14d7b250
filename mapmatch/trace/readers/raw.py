"""
What a reader returns, and the source it reads.

A reader returns unvalidated traces (:class:`RawTrace`) read from one source
(:class:`Context`: name, format, default id, how its errors are phrased).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

from mapmatch.errors import TraceFileError
from mapmatch.trace.checks import SHOW
from mapmatch.trace.columns import column

if TYPE_CHECKING:
    import pandas as pd

    from mapmatch.types import IntArray

__all__ = ["COORD_NAMES", "SHOW", "TABLE_ROW", "Context", "RawTrace", "with_notes"]

COORD_NAMES: Final = frozenset(column("lat").names + column("lon").names)
"""Names of the coordinate columns (lower case); a geometry replaces them."""

TABLE_ROW: Final = "table row"
"""The label of a table's rows (numbered from 0)."""


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


@dataclass(frozen=True, slots=True)
class Context:
    """The source being read: its name and path, format, default trace id, ``id_column``."""

    name: str
    path: str | None
    fmt: str
    default_id: str
    id_column: str | None = None

    def error(self, problem: str) -> TraceFileError:
        """The file error for ``problem``, naming the file and format."""
        msg = f"trace file {self.name!r} ({self.fmt}): {problem}"
        return TraceFileError(msg, path=self.path, format=self.fmt)

    def renamed(self, default_id: str) -> Context:
        """The same source with another default trace id."""
        return Context(self.name, self.path, self.fmt, default_id, self.id_column)


def with_notes(raw: RawTrace, notes: tuple[str, ...], dropped: int = 0) -> RawTrace:
    """The trace with more reader notes and dropped records."""
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
