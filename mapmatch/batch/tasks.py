"""
The worker side of a batch: one task matches and writes some traces of one file.

:func:`match_chunk` runs in a worker process (or in the batch's own process), with the road
network the executor sent it once. It reads its file (once per worker for the chunks of one
file), validates each trace from the reader's rows (so errors name the file's line or record
numbers), matches, writes each trace's outputs atomically and returns one summary row per
trace; a failing trace gets a ``failed`` row and the task goes on.

A trace's files are flushed to the disk and renamed into place on a thread of the worker
(:class:`~mapmatch.batch.files.Committer`) while it matches the next trace; the task returns
once every file is in place. Each worker appends a trace's row to a journal of its own in
the output folder (``.tmp-rows-<host>-<pid>.csv``, flushed) once its files are in place:
when a worker dies, the batch reads the journals to tell the traces it finished (their
outputs are on disk: reported ``ok``, not failed) from those to run again
(:mod:`mapmatch.batch.run`).
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import logging
import os
import socket
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

import numpy as np

from mapmatch.batch.files import TMP_PREFIX, Committer
from mapmatch.batch.inputs import STDIN, BatchInputError, error_line, printable
from mapmatch.batch.outputs import SummaryRow, write_result
from mapmatch.matcher import match
from mapmatch.trace import trace_from_raw
from mapmatch.trace.readers import read_raw_traces

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig
    from mapmatch.trace import Trace
    from mapmatch.trace.readers.raw import RawTrace
    from roadnets import RoadNetwork

__all__ = [
    "JOURNAL_PREFIX",
    "ChunkOutcome",
    "ChunkTask",
    "match_chunk",
    "read_journals",
    "remove_journals",
]

#: File name start of the workers' journals (a temporary: removed when a batch starts).
JOURNAL_PREFIX = f"{TMP_PREFIX}rows-"


@dataclass(frozen=True, slots=True)
class ChunkTask:
    """Work for one task: some traces of one file, and how to match and write them."""

    path: str
    display: str
    format: str | None
    traces: tuple[tuple[int, str, str, int], ...]  # (index, trace_id, output name, points)
    config: MatchConfig
    out_dir: str
    out_format: str
    log_level: int | None
    id_column: str | None = None
    crs: str = "wgs84"

    def only(self, keep: set[int]) -> list[ChunkTask]:
        """One task per trace of this one whose index is in ``keep`` (a retry)."""
        return [dataclasses.replace(self, traces=(t,)) for t in self.traces if t[0] in keep]


@dataclass(frozen=True, slots=True)
class ChunkOutcome:
    """What a task sends back: one summary row per trace and its worker's figures."""

    rows: tuple[SummaryRow, ...]
    host: str
    pid: int
    max_rss_kib: int
    seconds: float
    cpu_s: float
    match_s: float = 0.0  # inside match() only
    warmup_s: float = 0.0  # this worker's first match of a tiny trace (kernels loaded)


class _FileTraces:
    """
    The traces of a file read by :func:`read_raw_traces`, each validated when first asked for.

    ``items[i]`` is trace ``i`` as a :class:`Trace`, or the one-line error of a trace that is
    invalid. A worker validates only the traces of its own chunks (all of them before, the
    other workers' too: 0.3 s of 1,000 traces each), and each once.
    """

    def __init__(self, raws: list[RawTrace], crs: str) -> None:
        self._raws = raws
        self._crs = crs
        self._done: dict[int, Trace | str] = {}

    def __len__(self) -> int:
        return len(self._raws)

    def __getitem__(self, index: int) -> Trace | str:
        done = self._done.get(index)
        if done is None:
            raw = self._raws[index]
            clean = dataclasses.replace(raw, trace_id=printable(str(raw.trace_id)))
            try:
                done = trace_from_raw(clean, crs=self._crs)
            except Exception as exc:
                done = error_line(exc)
            done = self._done.setdefault(index, done)  # two threads: the first one's
        return done


_FILE_LOCK = threading.Lock()
_LAST_FILE: dict[str, tuple[tuple[object, ...], _FileTraces]] = {}
_JOURNALS: dict[str, TextIO] = {}
_FROZEN: list[bool] = []
_WARM: list[float] = []
_COMMITTER: list[Committer] = []


def _committer() -> Committer:
    """The committer of this process (flushes and renames the outputs behind the matching)."""
    if not _COMMITTER:
        _COMMITTER.append(Committer())
    return _COMMITTER[0]


def _warm_up(net: RoadNetwork, config: MatchConfig) -> float:
    """
    Match a two-fix trace along one edge once per process; the seconds it took.

    The first match of a process loads (or compiles) the matcher's kernels, which costs more
    than many matches: paid here, it is reported as warm-up, not as matching time.
    """
    if _WARM:
        return 0.0
    from mapmatch.trace import Trace

    started = time.perf_counter()
    a = net.arrays
    edge = int(np.argmax(a.edge_length_m))
    lo, hi = int(a.edge_geom_ptr[edge]), int(a.edge_geom_ptr[edge + 1])
    lon, lat = net.unproject(a.geom_x[[lo, hi - 1]], a.geom_y[[lo, hi - 1]])
    with contextlib.suppress(Exception):  # a warm-up that fails changes nothing
        match(Trace(time=[0.0, 60.0], lon=lon, lat=lat, trace_id="warm-up"), net, config)
    _WARM.append(time.perf_counter() - started)
    return _WARM[0]


def _read_file(task: ChunkTask) -> _FileTraces:
    """
    Every trace of the task's file, or the one-line error of each that is invalid.

    The reader's rows are validated trace by trace (when a chunk asks for the trace), so one
    bad trace fails alone and its error names the file's line (or record) numbers. The last
    file read is kept, so the chunks of one file that land on the same worker read it once.
    """
    stat = os.stat(task.path)
    key = (task.path, task.format, task.id_column, task.crs, stat.st_mtime_ns, stat.st_size)
    with _FILE_LOCK:
        cached = _LAST_FILE.get("file")
        if cached is not None and cached[0] == key:
            return cached[1]
    default_id = "stdin" if task.display == STDIN else None
    raws = read_raw_traces(
        task.path, format=task.format, default_trace_id=default_id, id_column=task.id_column
    )
    items = _FileTraces(raws, task.crs)
    with _FILE_LOCK:
        _LAST_FILE["file"] = (key, items)
    return items


def _max_rss_kib() -> int:
    try:
        import resource
    except ImportError:  # pragma: no cover - Windows
        return 0
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)


def _journal_line(row: SummaryRow) -> str:
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow(row.to_csv_values())
    return buf.getvalue()


def _journal(out_dir: str, rows: list[SummaryRow]) -> None:
    """Append rows to this process's journal in ``out_dir`` (flushed, not synced)."""
    handle = _JOURNALS.get(out_dir)
    if handle is None:
        name = f"{JOURNAL_PREFIX}{printable(socket.gethostname())}-{os.getpid()}.csv"
        handle = (Path(out_dir) / name).open("a", encoding="utf-8", newline="")
        _JOURNALS[out_dir] = handle
    handle.write("".join(_journal_line(r) for r in rows))
    handle.flush()


def read_journals(out_dir: Path) -> dict[tuple[str, int, str], SummaryRow]:
    """Every complete row the workers journalled in ``out_dir``, by trace key."""
    rows: dict[tuple[str, int, str], SummaryRow] = {}
    for path in sorted(out_dir.glob(f"{JOURNAL_PREFIX}*.csv")):
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError):
            continue
        text = text[: text.rfind("\n") + 1]  # a line cut short by a kill is left out
        for values in csv.reader(io.StringIO(text)):
            try:
                row = SummaryRow.from_csv_values(values)
            except ValueError:
                continue
            rows[row.key] = row
    return rows


def remove_journals(out_dir: Path) -> None:
    """Close this process's journal there and delete every worker's."""
    handle = _JOURNALS.pop(str(out_dir), None)
    if handle is not None:
        handle.close()
    for path in out_dir.glob(f"{JOURNAL_PREFIX}*.csv"):
        path.unlink(missing_ok=True)


def match_chunk(task: ChunkTask, net: RoadNetwork) -> ChunkOutcome:
    """
    Match and write the traces of one task; never raises for a bad trace.

    Parameters
    ----------
    task
        The file, the traces of it to do, and the options.
    net
        The road network (sent to this worker once by the executor).

    Returns
    -------
    ChunkOutcome
        One row per trace of the task, in task order, and the worker's figures.
    """
    started = time.perf_counter()
    cpu_started = time.process_time()
    if task.log_level is not None:
        logging.getLogger("mapmatch").setLevel(task.log_level)
    rows: list[SummaryRow] = []
    matching = 0.0
    warmup = _warm_up(net, task.config)
    try:
        items = _read_file(task)
    except Exception as exc:
        err = error_line(exc)
        rows = [
            SummaryRow.failed(
                source=task.display, error=err, trace_id=tid, index=index, points=points
            )
            for index, tid, _name, points in task.traces
        ]
        _journal(task.out_dir, rows)
        return _outcome(rows, started, cpu_started, matching, warmup)
    committer = _committer()
    written: dict[str, int] = {}  # output name -> position in rows, until its files are in place
    for index, tid, name, points in task.traces:
        t0 = time.perf_counter()
        try:
            item = items[index] if index < len(items) else None
            if isinstance(item, str):
                row = SummaryRow.failed(
                    source=task.display, error=item, trace_id=tid, index=index, points=points
                )
            else:
                if item is None or item.trace_id != tid:
                    msg = (
                        f"{task.display}: trace {tid!r} is gone; the file changed during the batch"
                    )
                    raise BatchInputError(msg)
                m0 = time.perf_counter()
                result = match(item, net, task.config)
                matching += time.perf_counter() - m0
                write_result(result, Path(task.out_dir), name, task.out_format, committer=committer)
                row = SummaryRow.matched(
                    result,
                    source=task.display,
                    index=index,
                    output=name,
                    seconds=time.perf_counter() - t0,
                )
                written[name] = len(rows)
        except Exception as exc:
            row = SummaryRow.failed(
                source=task.display, error=error_line(exc), trace_id=tid, index=index, points=points
            )
            row = dataclasses.replace(row, seconds=time.perf_counter() - t0)
        rows.append(row)
        if row.output not in written:
            _journal(task.out_dir, [row])
        _journal(task.out_dir, [rows[written.pop(g)] for g in committer.finished()])
    failed = committer.wait()  # every file in place (or failed) before the rows go back
    for name, why in failed.items():
        k = written.pop(name)
        rows[k] = dataclasses.replace(
            SummaryRow.failed(
                source=task.display,
                error=error_line(why),
                trace_id=rows[k].trace_id,
                index=rows[k].index,
                points=rows[k].points,
            ),
            seconds=rows[k].seconds,
        )
        _journal(task.out_dir, [rows[k]])
    _journal(task.out_dir, [rows[written.pop(g)] for g in committer.finished()])
    if not _FROZEN:  # network mapped, R-tree built, kernels loaded: spare the GC from them
        import roadnets

        roadnets.freeze_after_load()
        _FROZEN.append(True)
    return _outcome(rows, started, cpu_started, matching, warmup)


def _outcome(
    rows: list[SummaryRow], started: float, cpu_started: float, match_s: float, warmup_s: float
) -> ChunkOutcome:
    return ChunkOutcome(
        rows=tuple(rows),
        host=socket.gethostname(),
        pid=os.getpid(),
        max_rss_kib=_max_rss_kib(),
        seconds=time.perf_counter() - started,
        cpu_s=time.process_time() - cpu_started,
        match_s=match_s,
        warmup_s=warmup_s,
    )
