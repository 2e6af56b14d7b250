"""
Batch matching: folders of trace files in, one output per trace and ``summary.csv`` out.

:func:`run_batch` is the engine behind ``mapmatch match``:

1. the road network is loaded once here, so that its compiled form is in the disk cache;
2. the inputs are found and every file is scanned for its traces (an unreadable file becomes
   a ``failed`` summary row and the batch goes on); each trace gets a safe, unique output
   name; with ``resume`` the traces whose outputs are complete are skipped;
3. the remaining traces are cut into tasks (a chunk of traces of one file) and run in this
   process, a local process pool, or on a Dask cluster (:mod:`mapmatch.batch.executors`).
   A task (:func:`match_chunk`) loads the network lazily once per worker process from the
   cache, reads its file, matches and writes each trace atomically, and returns one summary
   row per trace; a failing trace is recorded with its error and the task goes on;
4. rows are appended to ``summary.csv`` as tasks finish, and the file is rewritten in input
   order at the end.

"Complete" on resume means: the trace's main output file exists (written last, by rename,
so never partial; see :mod:`mapmatch.batch.outputs`), ``summary.csv`` holds an ``ok`` row
for it under the same output name, and ``run.json`` shows the earlier run used the same
network, format and matcher options.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import socket
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from math import ceil
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import roadnets
from mapmatch.batch.executors import make_executor
from mapmatch.batch.inputs import (
    STDIN,
    BatchInputError,
    FileScan,
    TraceRef,
    assign_output_names,
    discover_inputs,
    error_line,
    scan_file,
)
from mapmatch.batch.outputs import (
    FORMATS,
    SUMMARY_NAME,
    SummaryLog,
    SummaryRow,
    atomic_write,
    outputs_complete,
    read_summary,
    remove_temporaries,
    write_result,
    write_summary,
)
from mapmatch.config import MatchConfig
from mapmatch.errors import InvalidTraceError, MapMatchError
from mapmatch.matcher import match
from mapmatch.trace import Trace, read_traces, trace_from_raw
from mapmatch.trace.readers import read_raw_traces

if TYPE_CHECKING:
    from collections.abc import Sequence
    from typing import BinaryIO

__all__ = [
    "MANIFEST_NAME",
    "BatchError",
    "BatchOptions",
    "BatchProgress",
    "BatchReport",
    "ChunkOutcome",
    "ChunkTask",
    "match_chunk",
    "run_batch",
    "worker_network",
]

#: File in the output folder recording what a batch was run with (for ``--resume``).
MANIFEST_NAME = "run.json"
_MAX_CHUNK = 32
_CHUNKS_PER_SLOT = 4


class BatchError(MapMatchError, ValueError):
    """A batch cannot start: bad options, or ``--resume`` into a folder made otherwise."""


@dataclass(frozen=True, slots=True, kw_only=True)
class BatchOptions:
    """
    What to match and how.

    Attributes
    ----------
    inputs
        Trace files, folders (searched recursively) and ``-`` for CSV on standard input.
    out_dir
        Output folder; created if needed.
    network
        OSM extract; ``None`` for the embedded default network.
    cache_dir
        Compiled-network cache shared by all workers; ``None`` for the default
        (``$MAPMATCH_CACHE_DIR`` or ``~/.cache/mapmatch``).
    format
        ``geojson``, ``csv`` or ``parquet``.
    config
        Matcher parameters, the same for every trace.
    workers
        Local worker processes (``None``: one per core; 1: in this process).
    scheduler
        Dask scheduler address; runs the tasks on that cluster instead.
    scheduler_timeout_s
        How long to try to connect to ``scheduler``.
    resume
        Skip traces whose outputs are complete from an earlier run into ``out_dir``.
    chunk_traces
        Traces per task; default: enough tasks for about four per worker, at most 32 traces.
    log_level
        Level of the ``mapmatch`` logger inside tasks (``None``: leave it); the per-trace
        distance warnings are in ``summary.csv`` anyway.
    id_column
        The column naming the traces of table files (CSV, Parquet ...); default: the usual
        id columns (``trace_id``, ``trip_id``, ``vehicle_id`` ...; see
        :mod:`mapmatch.trace.readers`).
    """

    inputs: tuple[str, ...]
    out_dir: Path
    network: str | None = None
    cache_dir: str | None = None
    format: str = "geojson"
    config: MatchConfig = field(default_factory=MatchConfig)
    workers: int | None = None
    scheduler: str | None = None
    scheduler_timeout_s: float = 30.0
    resume: bool = False
    chunk_traces: int | None = None
    log_level: int | None = None
    id_column: str | None = None


@dataclass(frozen=True, slots=True)
class ChunkTask:
    """Work for one task: some traces of one file, and how to match and write them."""

    path: str
    display: str
    format: str | None
    traces: tuple[tuple[int, str, str, int], ...]  # (index, trace_id, output name, points)
    network: str | None
    cache_dir: str | None
    config: MatchConfig
    out_dir: str
    out_format: str
    log_level: int | None
    id_column: str | None = None


@dataclass(frozen=True, slots=True)
class ChunkOutcome:
    """What a task sends back: one summary row per trace and its worker's figures."""

    rows: tuple[SummaryRow, ...]
    host: str
    pid: int
    max_rss_kib: int
    seconds: float
    cpu_s: float


@dataclass(frozen=True, slots=True)
class BatchReport:
    """
    The outcome of a batch.

    Attributes
    ----------
    rows
        Every summary row in input order (resumed ones included).
    resumed
        Traces skipped because an earlier run completed them.
    seconds
        Wall time of the batch.
    executor
        Where the tasks ran (``"2 processes"`` ...).
    out_dir
        The output folder.
    worker_max_rss_kib
        Peak resident memory of each worker process that ran a task, by ``"host:pid"``.
    worker_busy_s
        Seconds each worker process spent in tasks, by ``"host:pid"``.
    worker_cpu_s
        CPU seconds each worker process used in tasks (below ``worker_busy_s`` when the
        machine's cores are shared with other work).
    """

    rows: tuple[SummaryRow, ...]
    resumed: int
    seconds: float
    executor: str
    out_dir: Path
    worker_max_rss_kib: dict[str, int]
    worker_busy_s: dict[str, float]
    worker_cpu_s: dict[str, float]

    @property
    def traces_ok(self) -> int:
        """Traces matched and written."""
        return sum(1 for r in self.rows if r.ok)

    @property
    def traces_failed(self) -> int:
        """Traces (and unreadable files) that failed."""
        return sum(1 for r in self.rows if not r.ok)

    @property
    def points(self) -> int:
        """Fixes in the traces matched."""
        return sum(r.points for r in self.rows if r.ok)

    @property
    def matched_length_m(self) -> float:
        """Matched road length of all traces, metres."""
        return float(sum(r.matched_length_m for r in self.rows if r.ok))

    def _ok_sum(self, name: str) -> int:
        return sum(int(getattr(r, name)) for r in self.rows if r.ok)

    @property
    def reordered_rows(self) -> int:
        """Rows sorted into time order, over the matched traces."""
        return self._ok_sum("reordered_rows")

    @property
    def merged_rows(self) -> int:
        """True duplicates merged, over the matched traces."""
        return self._ok_sum("merged_rows")

    @property
    def dropped_rows(self) -> int:
        """Source records the readers could not use, over the matched traces."""
        return self._ok_sum("dropped_rows")

    @property
    def shared_time_rows(self) -> int:
        """Points kept that share the previous point's time, over the matched traces."""
        return self._ok_sum("shared_time_rows")

    @property
    def input_rows(self) -> int:
        """Rows read, over the matched traces."""
        return self._ok_sum("input_rows")

    @property
    def time_sources(self) -> dict[str, int]:
        """Matched traces by what their times were (``ok``, ``absent``, ``implausible``)."""
        return dict(Counter(r.time for r in self.rows if r.ok).most_common())

    @property
    def traces_with_warnings(self) -> int:
        """Matched traces whose validation said something (``warnings`` column)."""
        return sum(1 for r in self.rows if r.ok and r.warnings)

    @property
    def verdicts(self) -> dict[str, int]:
        """Distance-check verdicts of the matched traces, by count."""
        return dict(Counter(r.verdict for r in self.rows if r.ok).most_common())

    @property
    def exit_code(self) -> int:
        """0 when every trace matched, 1 when any trace or file failed."""
        return 0 if self.traces_failed == 0 else 1


class BatchProgress(Protocol):
    """Told how far the batch is (the command line draws a progress bar)."""

    def start(self, *, total_traces: int, total_points: int, resumed: int) -> None:
        """The batch knows its size; ``resumed`` traces are done already."""

    def update(self, rows: Sequence[SummaryRow]) -> None:
        """These traces just finished."""


# --------------------------------------------------------------------------- workers

_NETWORKS: dict[tuple[str | None, str | None], roadnets.RoadNetwork] = {}
_NETWORK_LOCK = threading.Lock()
_FILE_LOCK = threading.Lock()
_LAST_FILE: dict[str, tuple[tuple[object, ...], list[Trace | str]]] = {}


def worker_network(source: str | None, cache_dir: str | None) -> roadnets.RoadNetwork:
    """
    The road network, loaded at most once per process (memoised by source and cache).

    Parameters
    ----------
    source
        OSM extract, or ``None`` for the embedded default.
    cache_dir
        Compiled-network cache; in workers this reads the memory-mapped cache entry the
        parent wrote.
    """
    key = (source, cache_dir)
    with _NETWORK_LOCK:
        net = _NETWORKS.get(key)
        if net is None:
            net = roadnets.load(source, cache_dir=cache_dir)
            _NETWORKS[key] = net
        return net


def _read_file(
    path: str, fmt: str | None, display: str, id_column: str | None = None
) -> list[Trace | str]:
    """
    Every trace of a file, or the one-line error of each trace that is invalid.

    The last file read is kept, so the chunks of one file that land on the same worker
    read it once.
    """
    stat = os.stat(path)
    key = (path, fmt, id_column, stat.st_mtime_ns, stat.st_size)
    with _FILE_LOCK:
        cached = _LAST_FILE.get("file")
        if cached is not None and cached[0] == key:
            return cached[1]
    default_id = "stdin" if display == STDIN else None
    items: list[Trace | str]
    try:
        items = list(
            read_traces(path, format=fmt, default_trace_id=default_id, id_column=id_column)
        )
    except InvalidTraceError as exc:
        # One trace is invalid: read the others one by one so that only it fails.
        raws = read_raw_traces(path, format=fmt, default_trace_id=default_id, id_column=id_column)
        items = []
        for raw in raws:
            if exc.trace_id is not None and raw.trace_id == exc.trace_id:
                items.append(error_line(exc))
                continue
            try:
                items.append(trace_from_raw(raw))
            except Exception as inner:
                items.append(error_line(inner))
    with _FILE_LOCK:
        _LAST_FILE["file"] = (key, items)
    return items


def _max_rss_kib() -> int:
    try:
        import resource
    except ImportError:  # pragma: no cover - Windows
        return 0
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)


def match_chunk(task: ChunkTask) -> ChunkOutcome:
    """
    Match and write the traces of one task; never raises for a bad trace.

    Runs in a worker (or this process): loads the network once per process
    (:func:`worker_network`), reads the file, and for each trace matches it, writes its
    outputs atomically and makes its summary row. A trace that fails gets a ``failed`` row
    with its error's first line.

    Parameters
    ----------
    task
        The file, the traces of it to do, and the options.

    Returns
    -------
    ChunkOutcome
        One row per trace of the task, in task order, and the worker's peak memory.
    """
    started = time.perf_counter()
    cpu_started = time.process_time()
    if task.log_level is not None:
        logging.getLogger("mapmatch").setLevel(task.log_level)
    rows: list[SummaryRow] = []
    out_dir = Path(task.out_dir)
    try:
        net = worker_network(task.network, task.cache_dir)
        items = _read_file(task.path, task.format, task.display, task.id_column)
    except Exception as exc:
        err = error_line(exc)
        rows = [
            SummaryRow.failed(
                source=task.display, error=err, trace_id=tid, index=index, points=points
            )
            for index, tid, _name, points in task.traces
        ]
        return _outcome(rows, started, cpu_started)
    for index, tid, name, points in task.traces:
        t0 = time.perf_counter()
        try:
            item = items[index] if index < len(items) else None
            if isinstance(item, str):
                rows.append(
                    SummaryRow.failed(
                        source=task.display, error=item, trace_id=tid, index=index, points=points
                    )
                )
                continue
            if item is None or item.trace_id != tid:
                msg = f"{task.display}: trace {tid!r} is gone; the file changed during the batch"
                raise BatchInputError(msg)
            result = match(item, net, task.config)
            write_result(result, out_dir, name, task.out_format)
            rows.append(
                SummaryRow.matched(
                    result,
                    source=task.display,
                    index=index,
                    output=name,
                    seconds=time.perf_counter() - t0,
                )
            )
        except Exception as exc:
            row = SummaryRow.failed(
                source=task.display, error=error_line(exc), trace_id=tid, index=index, points=points
            )
            rows.append(dataclasses.replace(row, seconds=time.perf_counter() - t0))
    return _outcome(rows, started, cpu_started)


def _outcome(rows: list[SummaryRow], started: float, cpu_started: float) -> ChunkOutcome:
    return ChunkOutcome(
        rows=tuple(rows),
        host=socket.gethostname(),
        pid=os.getpid(),
        max_rss_kib=_max_rss_kib(),
        seconds=time.perf_counter() - started,
        cpu_s=time.process_time() - cpu_started,
    )


# --------------------------------------------------------------------------- parent


def _fingerprint(options: BatchOptions, net: roadnets.RoadNetwork) -> dict[str, object]:
    return {
        "format": options.format,
        "id_column": options.id_column,
        "network": {"id": net.network_id, "sha256": net.source_sha256},
        "config": {k: _jsonable(v) for k, v in dataclasses.asdict(options.config).items()},
    }


def _jsonable(value: object) -> object:
    return list(value) if isinstance(value, tuple) else value


def _check_manifest(out_dir: Path, fingerprint: dict[str, object], resume: bool) -> None:
    path = out_dir / MANIFEST_NAME
    if resume and path.exists():
        try:
            earlier = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            earlier = None
        if isinstance(earlier, dict) and earlier.get("fingerprint") != fingerprint:
            theirs = earlier.get("fingerprint") or {}
            differ = sorted(
                k
                for k in fingerprint
                if not isinstance(theirs, dict) or theirs.get(k) != fingerprint[k]
            )
            msg = (
                f"--resume: {out_dir} was written with another {', '.join(differ) or 'setup'}; "
                "use the same options, or drop --resume (or use a new --out) to start over"
            )
            raise BatchError(msg)
    payload = {"fingerprint": fingerprint, "started": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    text = json.dumps(payload, indent=2, sort_keys=True) + "\n"
    atomic_write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def _chunk_size(options: BatchOptions, pending: int, slots: int) -> int:
    if options.chunk_traces is not None:
        return max(1, options.chunk_traces)
    if slots <= 1:
        return 1
    return max(1, min(_MAX_CHUNK, ceil(pending / (slots * _CHUNKS_PER_SLOT))))


def run_batch(
    options: BatchOptions,
    *,
    progress: BatchProgress | None = None,
    stdin: BinaryIO | None = None,
) -> BatchReport:
    """
    Match every trace of the inputs and write one output per trace plus ``summary.csv``.

    Parameters
    ----------
    options
        Inputs, output folder, network, format, matcher options, where to run.
    progress
        Told the batch's size, then each finished trace.
    stdin
        Stream read for the input ``-``; default standard input.

    Returns
    -------
    BatchReport
        Every trace's row; ``exit_code`` is 1 when any failed.

    Raises
    ------
    BatchError
        Unknown format, or ``resume`` into a folder written with other options.
    BatchInputError
        An input does not exist or no trace file was found.
    RoadNetworkError
        The network cannot be loaded.
    SchedulerError
        The Dask scheduler cannot be reached.
    """
    started = time.perf_counter()
    if options.format not in FORMATS:
        msg = f"unknown output format {options.format!r}; use one of {', '.join(FORMATS)}"
        raise BatchError(msg)
    out_dir = Path(options.out_dir).resolve()
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        msg = f"cannot create the output folder {str(out_dir)!r}: {exc.strerror or exc}"
        raise BatchError(msg) from exc
    network = str(Path(options.network).resolve()) if options.network else None
    cache_dir = str(Path(options.cache_dir).resolve()) if options.cache_dir else None
    net = worker_network(network, cache_dir)  # compiles into the cache once, here
    files = discover_inputs(options.inputs, spool_dir=out_dir, stdin=stdin)
    _check_manifest(out_dir, _fingerprint(options, net), options.resume)
    remove_temporaries(out_dir)

    scans: list[FileScan] = [scan_file(f, id_column=options.id_column) for f in files]
    names = assign_output_names(
        (scan.file.display, ref.index, ref.trace_id) for scan in scans for ref in scan.traces
    )
    summary_path = out_dir / SUMMARY_NAME
    done: dict[tuple[str, int, str], SummaryRow] = {}
    if options.resume:
        for row in read_summary(summary_path):
            complete = outputs_complete(out_dir, row.output, options.format)
            if row.ok and names.get(row.key) == row.output and complete:
                done[row.key] = row
    log = SummaryLog(summary_path, keep=list(done.values()))
    new_rows: dict[tuple[str, int, str], SummaryRow] = {}
    worker_rss: dict[str, int] = {}
    worker_busy: dict[str, float] = {}
    worker_cpu: dict[str, float] = {}
    executor = None
    try:
        for scan in scans:
            if scan.error is not None:
                row = SummaryRow.failed(source=scan.file.display, error=scan.error)
                new_rows[row.key] = row
                log.append([row])
        pending = [
            (scan, ref)
            for scan in scans
            for ref in scan.traces
            if (scan.file.display, ref.index, ref.trace_id) not in done
        ]
        if progress is not None:
            progress.start(
                total_traces=len(pending) + len(done),
                total_points=sum(ref.points for _, ref in pending),
                resumed=len(done),
            )
        if pending:
            workers = options.workers if options.workers is not None else os.cpu_count() or 1
            executor = make_executor(
                min(workers, len(pending)),  # no pool of processes for one trace
                options.scheduler,
                preload=["mapmatch.batch"],
                timeout_s=options.scheduler_timeout_s,
            )
            size = _chunk_size(options, len(pending), executor.slots)
            tasks = _tasks(pending, names, size, options, out_dir, network, cache_dir)
            for task, outcome in executor.run(match_chunk, tasks):
                if isinstance(outcome, BaseException):
                    err = f"task failed: {error_line(outcome)}"
                    rows: tuple[SummaryRow, ...] = tuple(
                        SummaryRow.failed(
                            source=task.display, error=err, trace_id=tid, index=i, points=n
                        )
                        for i, tid, _name, n in task.traces
                    )
                else:
                    rows = outcome.rows
                    where = f"{outcome.host}:{outcome.pid}"
                    worker_rss[where] = max(worker_rss.get(where, 0), outcome.max_rss_kib)
                    worker_busy[where] = worker_busy.get(where, 0.0) + outcome.seconds
                    worker_cpu[where] = worker_cpu.get(where, 0.0) + outcome.cpu_s
                log.append(rows)
                for row in rows:
                    new_rows[row.key] = row
                if progress is not None:
                    progress.update(rows)
    finally:
        log.close()
        if executor is not None:
            executor.close()

    ordered: list[SummaryRow] = []
    for scan in scans:
        if scan.error is not None:
            ordered.append(new_rows[(scan.file.display, -1, "")])
        for ref in scan.traces:
            key = (scan.file.display, ref.index, ref.trace_id)
            ordered.append(done[key] if key in done else new_rows[key])
    write_summary(summary_path, ordered)
    return BatchReport(
        rows=tuple(ordered),
        resumed=len(done),
        seconds=time.perf_counter() - started,
        executor=executor.description if executor is not None else "nothing to do",
        out_dir=out_dir,
        worker_max_rss_kib=worker_rss,
        worker_busy_s=worker_busy,
        worker_cpu_s=worker_cpu,
    )


def _tasks(
    pending: list[tuple[FileScan, TraceRef]],
    names: dict[tuple[str, int, str], str],
    size: int,
    options: BatchOptions,
    out_dir: Path,
    network: str | None,
    cache_dir: str | None,
) -> list[ChunkTask]:
    by_file: dict[str, tuple[FileScan, list[tuple[int, str, str, int]]]] = {}
    for scan, ref in pending:
        entry = by_file.setdefault(scan.file.display, (scan, []))
        key = (scan.file.display, ref.index, ref.trace_id)
        entry[1].append((ref.index, ref.trace_id, names[key], ref.points))
    tasks: list[ChunkTask] = []
    for scan, traces in by_file.values():
        for start in range(0, len(traces), size):
            tasks.append(
                ChunkTask(
                    path=scan.file.path,
                    display=scan.file.display,
                    format=scan.file.format,
                    traces=tuple(traces[start : start + size]),
                    network=network,
                    cache_dir=cache_dir,
                    config=options.config,
                    out_dir=str(out_dir),
                    out_format=options.format,
                    log_level=options.log_level,
                    id_column=options.id_column,
                )
            )
    return tasks
