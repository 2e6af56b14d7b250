"""
Output side of batch matching: per-trace files written atomically, and ``summary.csv``.

(Over 400 lines on purpose: every output format's writer and summary.csv share the atomic-write
and naming rules.)

Per trace, in the output folder:

``geojson``
    ``<name>.geojson``: the FeatureCollection of :func:`mapmatch.export.geojson_bytes`.
``csv`` / ``parquet``
    ``<name>.csv|parquet``: the per-point table of :func:`mapmatch.export.points_frame`, and
    ``<name>.edges.csv|parquet``: one row per matched edge (:func:`mapmatch.export.edges_frame`).
    CSV times are ISO 8601 UTC, Parquet keeps the dtypes (``Int64`` ids, UTC datetimes).
``geoparquet``
    The same two tables with geometries (snapped Points, driven LineStrings) and GeoParquet
    metadata, plus ``<name>.segments.parquet`` (one LineString per segment); read them with
    ``geopandas.read_parquet``.
``gpkg``
    ``<name>.gpkg``: one GeoPackage with the layers ``segments``, ``edges`` and ``points``.

Every file is written to a hidden temporary file in the same folder, flushed to the disk and
renamed into place (:mod:`mapmatch.batch.files`), so a file under its final name is always
complete. The sidecars are renamed first and the main file last: a trace's outputs are
complete exactly when its main file exists (:func:`outputs_complete`).

``summary.csv`` has one row per trace (and one per unreadable file). While a batch runs, rows
are appended and flushed one by one (:class:`SummaryLog`); a line without its final newline
(a run killed mid-write) is ignored by :func:`read_summary`. At the end the file is rewritten
atomically in input order.
"""

from __future__ import annotations

import contextlib
import csv
import io
import math
from dataclasses import asdict, dataclass, fields
from functools import partial
from pathlib import Path  # noqa: TC003 - the doctests use it
from typing import TYPE_CHECKING, Any

from mapmatch import export
from mapmatch.batch.files import (
    Committer,
    atomic_write,
    remove_temporaries,
    sync_folder,
)
from mapmatch.batch.inputs import printable

if TYPE_CHECKING:
    from collections.abc import Iterable

    from mapmatch.export import GeoKind
    from mapmatch.result import MatchResult

__all__ = [
    "FORMATS",
    "SUMMARY_NAME",
    "WARNING_SEPARATOR",
    "SummaryLog",
    "SummaryRow",
    "atomic_write",
    "output_paths",
    "outputs_complete",
    "read_summary",
    "remove_temporaries",
    "sync_folder",
    "write_result",
    "write_summary",
]

#: Output formats of a batch.
FORMATS = ("geojson", "csv", "parquet", "geoparquet", "gpkg")
#: What the files of a format hold, main file (the points) last: (name suffix, kind).
_FILES: dict[str, tuple[tuple[str, GeoKind | None], ...]] = {
    "geojson": ((".geojson", None),),
    "csv": ((".edges.csv", "edges"), (".csv", "points")),
    "parquet": ((".edges.parquet", "edges"), (".parquet", "points")),
    "geoparquet": (
        (".segments.parquet", "segments"),
        (".edges.parquet", "edges"),
        (".parquet", "points"),
    ),
    "gpkg": ((".gpkg", None),),
}
#: File name of the per-trace summary in the output folder.
SUMMARY_NAME = "summary.csv"
#: Joins a trace's warnings in the ``warnings`` column of ``summary.csv``.
WARNING_SEPARATOR = " | "


@dataclass(frozen=True, slots=True)
class SummaryRow:
    """
    One line of ``summary.csv``: a trace's outcome, or an unreadable file's.

    Attributes
    ----------
    trace_id
        The trace's id; empty for a file that could not be read.
    source
        The input file as given on the command line (``-`` for standard input).
    index
        0-based position of the trace in its file; -1 for an unreadable file.
    output
        Output name (without suffix) in the output folder; empty when nothing was written.
    status
        ``ok`` or ``failed``.
    points, matched_points, breaks
        Fixes in the trace, fixes matched, and breaks where the trace was split.
    matched_length_m, fused_length_m, relative_error
        The distance check (NaN when unknown).
    verdict
        ``pass``, ``over``, ``under``, ``incomplete``; empty when failed.
    time
        What the trace's times were: ``ok``, ``absent`` or ``implausible`` (matched by
        distance only, see :class:`~mapmatch.trace.TraceReport`); empty when failed.
    input_rows, reordered_rows, merged_rows, dropped_rows, shared_time_rows
        What validation did to the trace's rows: rows read, rows sorted into time order,
        true duplicates merged, source records the reader dropped, points kept that share the
        previous point's time (all 0 when failed).
    warnings
        The trace's warnings, joined by `` | `` (empty for a clean trace).
    seconds
        Wall time spent on the trace (reading, matching, writing).
    error
        ``ErrorClass: first line of the message`` when failed, else empty.
    """

    trace_id: str
    source: str
    index: int
    output: str
    status: str
    points: int
    matched_points: int
    breaks: int
    matched_length_m: float
    fused_length_m: float
    relative_error: float
    verdict: str
    time: str
    input_rows: int
    reordered_rows: int
    merged_rows: int
    dropped_rows: int
    shared_time_rows: int
    warnings: str
    seconds: float
    error: str

    @property
    def ok(self) -> bool:
        """Whether the trace was matched and written."""
        return self.status == "ok"

    @property
    def key(self) -> tuple[str, int, str]:
        """``(source, index, trace_id)``: identifies the trace across runs."""
        return (self.source, self.index, self.trace_id)

    @classmethod
    def failed(
        cls, *, source: str, error: str, trace_id: str = "", index: int = -1, points: int = 0
    ) -> SummaryRow:
        """A row for a trace or file that failed with ``error``."""
        nan = float("nan")
        return cls(
            trace_id=trace_id,
            source=source,
            index=index,
            output="",
            status="failed",
            points=points,
            matched_points=0,
            breaks=0,
            matched_length_m=nan,
            fused_length_m=nan,
            relative_error=nan,
            verdict="",
            time="",
            input_rows=0,
            reordered_rows=0,
            merged_rows=0,
            dropped_rows=0,
            shared_time_rows=0,
            warnings="",
            seconds=0.0,
            error=error,
        )

    def __post_init__(self) -> None:
        for f in fields(self):  # a file name that is not UTF-8 must still print and save
            value = getattr(self, f.name)
            if isinstance(value, str):
                object.__setattr__(self, f.name, printable(value))

    def to_csv_values(self) -> list[str]:
        """
        The row's cells as ``summary.csv`` writes them (no line breaks inside).

        A text cell a spreadsheet would run as a formula (starting with ``=``, ``+``, ``@``,
        a tab, or ``-`` and more) is written with a leading ``'``, as is one that starts
        with ``'`` itself; :meth:`from_csv_values` takes it off again.
        """
        out: list[str] = []
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, float):
                if math.isnan(value):
                    text = ""
                elif f.name == "seconds":
                    text = f"{value:.3f}"
                else:
                    text = f"{value:.10g}"
            elif isinstance(value, str):
                text = _defused(value.replace("\r", " ").replace("\n", " "))
            else:
                text = str(value)
            out.append(text)
        return out

    @classmethod
    def from_csv_values(cls, values: list[str]) -> SummaryRow:
        """Parse the cells written by :meth:`to_csv_values`; raises ``ValueError``."""
        names = [f.name for f in fields(cls)]
        if len(values) != len(names):
            msg = f"summary row has {len(values)} cells, expected {len(names)}"
            raise ValueError(msg)
        raw = dict(zip(names, values, strict=True))
        kwargs: dict[str, Any] = {}
        for f in fields(cls):
            text = raw[f.name]
            if f.type == "int":
                kwargs[f.name] = int(text)
            elif f.type == "float":
                kwargs[f.name] = float(text) if text else float("nan")
            else:
                kwargs[f.name] = text[1:] if text.startswith("'") else text
        return cls(**kwargs)

    def to_dict(self) -> dict[str, object]:
        """The row as a plain dictionary."""
        return asdict(self)

    @classmethod
    def matched(
        cls, result: MatchResult, *, source: str, index: int, output: str, seconds: float
    ) -> SummaryRow:
        """The row of a trace that was matched and written."""
        check, stats = result.distance_check, result.stats
        return cls(
            trace_id=result.trace_id,
            source=source,
            index=index,
            output=output,
            status="ok",
            points=int(stats.points),
            matched_points=int(stats.matched_points),
            breaks=len(result.breaks),
            matched_length_m=float(result.matched_length_m),
            fused_length_m=float(check.fused_length_m),
            relative_error=float(check.relative_error),
            verdict=str(check.verdict),
            time=str(stats.time_source),
            input_rows=int(stats.input_rows),
            reordered_rows=int(stats.reordered_rows),
            merged_rows=int(stats.merged_rows),
            dropped_rows=int(stats.dropped_rows),
            shared_time_rows=int(stats.shared_time_rows),
            warnings=WARNING_SEPARATOR.join(stats.warnings),
            seconds=seconds,
            error="",
        )


SUMMARY_COLUMNS = tuple(f.name for f in fields(SummaryRow))


def _defused(text: str) -> str:
    """
    A text cell that no spreadsheet runs as a formula (OWASP's CSV injection advice).

    Examples
    --------
    >>> [_defused(t) for t in ("=1+1", "@SUM(A1)", "-2+3", "-", "'x", "bus-12")]
    ["'=1+1", "'@SUM(A1)", "'-2+3", '-', "''x", 'bus-12']
    """
    if text[:1] in ("=", "+", "@", "\t", "'") or (text.startswith("-") and len(text) > 1):
        return "'" + text
    return text


def output_paths(out_dir: Path, name: str, fmt: str) -> tuple[Path, ...]:
    """
    The files of one trace, main file last.

    Examples
    --------
    >>> [p.name for p in output_paths(Path("out"), "bus-1", "csv")]
    ['bus-1.edges.csv', 'bus-1.csv']
    >>> [p.name for p in output_paths(Path("out"), "bus-1", "geoparquet")]
    ['bus-1.segments.parquet', 'bus-1.edges.parquet', 'bus-1.parquet']
    >>> [p.name for p in output_paths(Path("out"), "bus-1", "geojson")]
    ['bus-1.geojson']
    """
    try:
        files = _FILES[fmt]
    except KeyError:
        msg = f"unknown output format {fmt!r}; use one of {', '.join(FORMATS)}"
        raise ValueError(msg) from None
    return tuple(out_dir / f"{name}{suffix}" for suffix, _ in files)


def outputs_complete(out_dir: Path, name: str, fmt: str) -> bool:
    """Whether every file of a trace exists under its final name (so is complete)."""
    return bool(name) and all(p.is_file() for p in output_paths(out_dir, name, fmt))


def write_result(
    result: MatchResult,
    out_dir: Path,
    name: str,
    fmt: str,
    *,
    committer: Committer | None = None,
) -> None:
    """
    Write one trace's outputs atomically (sidecars first, main file last).

    Parameters
    ----------
    result
        The match.
    out_dir
        Output folder (exists).
    name
        Output name without suffix (from :func:`~mapmatch.batch.inputs.assign_output_names`).
    fmt
        One of :data:`FORMATS`.
    committer
        Put the files in place on this committer's thread (grouped under ``name``); by
        default before returning.
    """
    paths = output_paths(out_dir, name, fmt)
    place = partial(atomic_write, committer=committer, group=name)
    if fmt == "geojson":
        data = export.geojson_bytes(result) + b"\n"
        place(paths[0], lambda tmp: tmp.write_bytes(data))
    elif fmt == "gpkg":
        place(paths[0], lambda tmp: export.write_geopackage(result, tmp))
    else:
        for path, (_, kind) in zip(paths, _FILES[fmt], strict=True):
            assert kind is not None
            place(path, partial(export.write_table, result, kind, fmt=fmt))
    if committer is not None:
        committer.seal(name)


def _row_line(row: SummaryRow) -> str:
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow(row.to_csv_values())
    return buf.getvalue()


def _header_line() -> str:
    return ",".join(SUMMARY_COLUMNS) + "\n"


def read_summary(path: Path) -> list[SummaryRow]:
    """
    The complete rows of a ``summary.csv``; a torn last line or a foreign row is skipped.

    Returns an empty list when the file does not exist or has another header.
    """
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return []
    if not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]  # drop a line cut short by a kill
    lines = list(csv.reader(io.StringIO(text)))
    if not lines or tuple(lines[0]) != SUMMARY_COLUMNS:
        return []
    rows: list[SummaryRow] = []
    for values in lines[1:]:
        with contextlib.suppress(ValueError):
            rows.append(SummaryRow.from_csv_values(values))
    return rows


def write_summary(path: Path, rows: Iterable[SummaryRow]) -> None:
    """Write ``summary.csv`` atomically with the given rows."""
    text = _header_line() + "".join(_row_line(r) for r in rows)
    atomic_write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


class SummaryLog:
    """
    Appends rows to ``summary.csv`` as traces finish, each flushed at once.

    Parameters
    ----------
    path
        The summary file; rewritten (atomically) with ``keep`` first.
    keep
        Rows of an earlier run to keep (``--resume``).
    """

    def __init__(self, path: Path, keep: Iterable[SummaryRow] = ()) -> None:
        self.path = path
        write_summary(path, keep)
        self._handle = path.open("a", encoding="utf-8", newline="")

    def append(self, rows: Iterable[SummaryRow]) -> None:
        """Append rows and flush them to the operating system."""
        for row in rows:
            self._handle.write(_row_line(row))
        self._handle.flush()

    def close(self) -> None:
        """Close the file."""
        self._handle.close()
