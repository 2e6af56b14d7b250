"""
Batch matching: folders of trace files in, one output per trace and ``summary.csv`` out.

(Over 400 lines on purpose: the batch's steps (check the output folder, plan, run, retry,
summarise) share one plan and one progress report.)

:func:`run_batch` is the engine behind ``mapmatch match``:

1. the output folder is made and checked writable (else one clear error, before any work);
   the road network is loaded once here, so that its compiled form is in the disk cache;
2. the inputs are found (files in an output folder are never read back) and every file is
   scanned for its traces (an unreadable file becomes a ``failed`` summary row and the batch
   goes on); each trace gets a safe output name that no other trace's files can meet; with
   ``resume`` the traces whose outputs are complete are skipped;
3. the remaining traces are cut into tasks (a chunk of traces of one file) and run in this
   process, a local process pool (at most one worker per core unless forced), or on a Dask
   cluster (:mod:`mapmatch.batch.executors`), the network sent to each worker once. A task
   (:func:`~mapmatch.batch.tasks.match_chunk`) reads its file, matches and writes each trace
   atomically and returns one summary row per trace; a failing trace is recorded with its
   error and the task goes on;
4. when a worker process dies, the traces of its tasks that it finished (their rows are in
   its journal, their files on disk) are reported as they are, and the others are run once
   more, one per task, in a fresh pool; only a trace lost twice is reported failed;
5. rows are appended to ``summary.csv`` as tasks finish; at the end the temporaries of dead
   workers are removed, the file is rewritten in input order and the folder is synced to
   the disk.

"Complete" on resume means: the trace's main output file exists (written last, by rename,
so never partial; see :mod:`mapmatch.batch.outputs`), ``summary.csv`` holds an ``ok`` row
for it under the same output name, and ``run.json`` shows the earlier run used the same
network, format, coordinate frame and matcher options.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import tempfile
import threading
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from math import ceil
from pathlib import Path
from typing import TYPE_CHECKING, Any

import roadnets
from mapmatch.batch.executors import WorkerLostError, available_cores, make_executor
from mapmatch.batch.files import atomic_write, remove_temporaries, sync_folder
from mapmatch.batch.inputs import (
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
    outputs_complete,
    read_summary,
    write_summary,
)
from mapmatch.batch.report import BatchProgress, BatchReport
from mapmatch.batch.tasks import (
    ChunkOutcome,
    ChunkTask,
    match_chunk,
    read_journals,
    remove_journals,
)
from mapmatch.config import MatchConfig
from mapmatch.errors import MapMatchError
from mapmatch.trace import SUPPORTED_CRS

if TYPE_CHECKING:
    from collections.abc import Callable
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
#: Traces per task in this process: the disk flushes of one run behind the next's matching.
_INLINE_CHUNK = 8
_log = logging.getLogger(__name__)

Key = tuple[str, int, str]


class BatchError(MapMatchError, ValueError):
    """A batch cannot start: bad options, an unusable output folder, or a foreign ``--resume``."""


@dataclass(frozen=True, slots=True, kw_only=True)
class BatchOptions:
    """
    What to match and how.

    Paths may be given as ``str`` or any ``os.PathLike`` (``pathlib.Path``), and ``inputs``
    as one path instead of a sequence; they are kept as ``str`` (``out_dir`` as ``Path``).

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
        One of :data:`~mapmatch.batch.outputs.FORMATS`.
    config
        Matcher parameters, the same for every trace.
    workers
        Local worker processes (``None``: one per core; 1: in this process); more than the
        cores this process may use are cut to that number unless ``force_workers``.
    force_workers
        Start ``workers`` processes even when there are fewer cores.
    scheduler
        Dask scheduler address; runs the tasks on that cluster instead.
    scheduler_timeout_s
        How long to try to connect to ``scheduler``.
    resume
        Skip traces whose outputs are complete from an earlier run into ``out_dir``.
    chunk_traces
        Traces per task; default: enough tasks for about four per worker, at most 32.
    log_level
        Level of the ``mapmatch`` logger inside tasks (``None``: leave it); the per-trace
        distance warnings are in ``summary.csv`` anyway.
    id_column
        The column naming the traces of table files (CSV, Parquet ...); default: the usual
        id columns (``trace_id``, ``trip_id``, ``vehicle_id`` ...; see
        :mod:`mapmatch.trace.readers`).
    crs
        Frame of the coordinates in the files: ``"wgs84"``, ``"gcj02"`` or ``"bd09"``.
    """

    inputs: tuple[str, ...]
    out_dir: Path
    network: str | None = None
    cache_dir: str | None = None
    format: str = "geojson"
    config: MatchConfig = field(default_factory=MatchConfig)
    workers: int | None = None
    force_workers: bool = False
    scheduler: str | None = None
    scheduler_timeout_s: float = 30.0
    resume: bool = False
    chunk_traces: int | None = None
    log_level: int | None = None
    id_column: str | None = None
    crs: str = "wgs84"

    def __post_init__(self) -> None:
        inputs: Any = self.inputs
        if isinstance(inputs, str | os.PathLike):  # one path, not its characters
            inputs = (inputs,)
        if not isinstance(inputs, Iterable):
            msg = f"inputs must be paths (str or os.PathLike), got {type(inputs).__name__}"
            raise BatchError(msg)
        named = tuple(inputs)
        bad = [p for p in named if not isinstance(p, str | os.PathLike)]
        if bad:
            msg = (
                f"inputs must be paths (str or os.PathLike); got {type(bad[0]).__name__} {bad[0]!r}"
            )
            raise BatchError(msg)
        object.__setattr__(self, "inputs", tuple(os.fspath(p) for p in named))
        object.__setattr__(self, "out_dir", Path(self.out_dir))
        for name in ("network", "cache_dir"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, os.fspath(value))


# --------------------------------------------------------------------------- network

_NETWORKS: dict[tuple[str | None, str | None], roadnets.RoadNetwork] = {}
_NETWORK_LOCK = threading.Lock()


def worker_network(source: str | None, cache_dir: str | None) -> roadnets.RoadNetwork:
    """
    The road network, loaded at most once per process (memoised by source and cache).

    Parameters
    ----------
    source
        OSM extract, or ``None`` for the embedded default.
    cache_dir
        Compiled-network cache.
    """
    key = (source, cache_dir)
    with _NETWORK_LOCK:
        net = _NETWORKS.get(key)
        if net is None:
            net = roadnets.load(source, cache_dir=cache_dir)
            _NETWORKS[key] = net
        return net


# --------------------------------------------------------------------------- set-up


def _fingerprint(options: BatchOptions, net: roadnets.RoadNetwork) -> dict[str, object]:
    out: dict[str, object] = {
        "format": options.format,
        "id_column": options.id_column,
        "network": {"id": net.network_id, "sha256": net.source_sha256},
        "config": {k: _jsonable(v) for k, v in dataclasses.asdict(options.config).items()},
    }
    if options.crs != "wgs84":  # earlier runs (all WGS84) resume unchanged
        out["crs"] = options.crs
    return out


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
                for k in set(fingerprint) | set(theirs if isinstance(theirs, dict) else {})
                if not isinstance(theirs, dict) or theirs.get(k) != fingerprint.get(k)
            )
            msg = (
                f"--resume: {out_dir} was written with another {', '.join(differ) or 'setup'}; "
                "use the same options, or drop --resume (or use a new --out) to start over"
            )
            raise BatchError(msg)
    payload = {"fingerprint": fingerprint, "started": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    text = json.dumps(payload, indent=2, sort_keys=True) + "\n"
    atomic_write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def _usable_out_dir(out_dir: Path) -> None:
    """Make the output folder and prove it takes a file, or raise one clear BatchError."""
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=out_dir, prefix=".tmp-probe-"):
            pass
    except OSError as exc:
        what = "cannot create" if not out_dir.is_dir() else "cannot write into"
        msg = (
            f"{what} the output folder {str(out_dir)!r}: {exc.strerror or exc}; "
            "give --out a folder you may write to"
        )
        raise BatchError(msg) from exc


def _worker_count(options: BatchOptions, pending: int) -> tuple[int, list[str]]:
    """Local worker processes to start, and what the summary should say about it."""
    cores = available_cores()
    asked = options.workers if options.workers is not None else cores
    notes: list[str] = []
    if asked > cores and not options.force_workers and options.scheduler is None:
        note = (
            f"--workers {asked} cut to {cores}, the cores this process may use "
            "(--force-workers starts them all)"
        )
        _log.warning(note)
        notes.append(note)
        asked = cores
    return max(1, min(asked, pending)), notes  # no pool of processes for one trace


def _chunk_size(options: BatchOptions, pending: int, slots: int) -> int:
    if options.chunk_traces is not None:
        return max(1, options.chunk_traces)
    if slots <= 1:  # in this process: chunks only pace the summary and the progress bar
        return _INLINE_CHUNK
    return max(1, min(_MAX_CHUNK, ceil(pending / (slots * _CHUNKS_PER_SLOT))))


# --------------------------------------------------------------------------- the run


@dataclass
class _Tally:
    """What the finished tasks reported, as they come in."""

    log: SummaryLog
    progress: BatchProgress | None
    rows: dict[Key, SummaryRow] = field(default_factory=dict)
    rss: dict[str, int] = field(default_factory=dict)
    busy: dict[str, float] = field(default_factory=dict)
    cpu: dict[str, float] = field(default_factory=dict)
    match_s: float = 0.0
    warmup_s: float = 0.0
    retried: int = 0

    def record(self, rows: tuple[SummaryRow, ...] | list[SummaryRow]) -> None:
        self.log.append(rows)
        for row in rows:
            self.rows[row.key] = row
        if self.progress is not None and rows:
            self.progress.update(list(rows))

    def outcome(self, outcome: ChunkOutcome) -> None:
        where = f"{outcome.host}:{outcome.pid}"
        self.rss[where] = max(self.rss.get(where, 0), outcome.max_rss_kib)
        self.busy[where] = self.busy.get(where, 0.0) + outcome.seconds
        self.cpu[where] = self.cpu.get(where, 0.0) + outcome.cpu_s
        self.match_s += outcome.match_s
        self.warmup_s += outcome.warmup_s
        self.record(outcome.rows)


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
        Unknown format or frame, an output folder that cannot be made or written, or
        ``resume`` into a folder written with other options.
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
    if options.crs not in SUPPORTED_CRS:
        msg = f"unknown crs {options.crs!r}; use one of {', '.join(SUPPORTED_CRS)}"
        raise BatchError(msg)
    out_dir = Path(options.out_dir).resolve()
    _usable_out_dir(out_dir)
    network = str(Path(options.network).resolve()) if options.network else None
    cache_dir = str(Path(options.cache_dir).resolve()) if options.cache_dir else None
    net = worker_network(network, cache_dir)  # compiles into the cache once, here
    found = discover_inputs(options.inputs, spool_dir=out_dir, stdin=stdin, out_dir=out_dir)
    _check_manifest(out_dir, _fingerprint(options, net), options.resume)
    remove_temporaries(out_dir)

    scans: list[FileScan] = [scan_file(f, id_column=options.id_column) for f in found.files]
    names = assign_output_names(
        (scan.file.display, ref.index, ref.trace_id) for scan in scans for ref in scan.traces
    )
    summary_path = out_dir / SUMMARY_NAME
    done: dict[Key, SummaryRow] = {}
    if options.resume:
        for row in read_summary(summary_path):
            complete = outputs_complete(out_dir, row.output, options.format)
            if row.ok and names.get(row.key) == row.output and complete:
                done[row.key] = row
    tally = _Tally(SummaryLog(summary_path, keep=list(done.values())), progress)
    executor = None
    notes: list[str] = []
    try:
        for scan in scans:
            if scan.error is not None:
                tally.record([SummaryRow.failed(source=scan.file.display, error=scan.error)])
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
            # read (or build, within its budget) the route table for sparse traces once, here:
            # the workers then map the cache entry's copy instead of each building its own
            net.sparse_route_table()
            workers, notes = _worker_count(options, len(pending))
            executor = make_executor(
                workers,
                options.scheduler,
                preload=["mapmatch.batch.tasks", "mapmatch.batch.warm"],
                timeout_s=options.scheduler_timeout_s,
                shared=net,
            )
            size = _chunk_size(options, len(pending), executor.slots)
            tasks = _tasks(pending, names, size, options, out_dir)
            retry = _retry_hook(out_dir, tally)
            for task, outcome in executor.run(match_chunk, tasks, retry=retry):
                if isinstance(outcome, BaseException):
                    tally.record(_lost(task, outcome, read_journals(out_dir)))
                else:
                    tally.outcome(outcome)
    finally:
        tally.log.close()
        if executor is not None:
            executor.close()
        remove_journals(out_dir)
        remove_temporaries(out_dir)  # what a worker that died was writing

    ordered: list[SummaryRow] = []
    for scan in scans:
        if scan.error is not None:
            ordered.append(tally.rows[(scan.file.display, -1, "")])
        for ref in scan.traces:
            key = (scan.file.display, ref.index, ref.trace_id)
            ordered.append(done[key] if key in done else tally.rows[key])
    write_summary(summary_path, ordered)
    sync_folder(out_dir)
    return BatchReport(
        rows=tuple(ordered),
        resumed=len(done),
        seconds=time.perf_counter() - started,
        executor=executor.description if executor is not None else "nothing to do",
        out_dir=out_dir,
        worker_max_rss_kib=tally.rss,
        worker_busy_s=tally.busy,
        worker_cpu_s=tally.cpu,
        match_s=tally.match_s,
        warmup_s=tally.warmup_s,
        points_now=sum(r.points for k, r in tally.rows.items() if r.ok and k not in done),
        skipped_inputs=found.skipped,
        retried=tally.retried,
        notes=tuple(notes),
    )


def _retry_hook(out_dir: Path, tally: _Tally) -> Callable[[ChunkTask], list[ChunkTask]]:
    """
    What to run again of a task whose worker died: its traces not in a worker's journal.

    The journalled ones (matched and written, or failed on their own) are recorded at once,
    as they are; the rest become one task each, so a trace that kills its worker again
    takes no other with it.
    """

    def retry(task: ChunkTask) -> list[ChunkTask]:
        journal = read_journals(out_dir)
        finished, again = _split(task, journal)
        tally.record(finished)
        tally.retried += len(again)
        return task.only(again)

    return retry


def _split(task: ChunkTask, journal: dict[Key, SummaryRow]) -> tuple[list[SummaryRow], set[int]]:
    """The journalled rows of a task's traces, and the indices of the others."""
    finished: list[SummaryRow] = []
    again: set[int] = set()
    for index, tid, name, _points in task.traces:
        row = journal.get((task.display, index, tid))
        written = row is not None and (
            not row.ok or outputs_complete(Path(task.out_dir), name, task.out_format)
        )
        if row is not None and written:
            finished.append(row)
        else:
            again.add(index)
    return finished, again


def _lost(
    task: ChunkTask, error: BaseException, journal: dict[Key, SummaryRow]
) -> list[SummaryRow]:
    """Rows of a task that ended without its outcome: journalled rows, else failures."""
    finished, lost = _split(task, journal)
    why = "worker lost" if isinstance(error, WorkerLostError) else "task failed"
    failed = [
        SummaryRow.failed(
            source=task.display,
            error=f"{why}: {error_line(error)}",
            trace_id=tid,
            index=i,
            points=n,
        )
        for i, tid, _name, n in task.traces
        if i in lost
    ]
    return finished + failed


def _tasks(
    pending: list[tuple[FileScan, TraceRef]],
    names: dict[Key, str],
    size: int,
    options: BatchOptions,
    out_dir: Path,
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
                    config=options.config,
                    out_dir=str(out_dir),
                    out_format=options.format,
                    log_level=options.log_level,
                    id_column=options.id_column,
                    crs=options.crs,
                )
            )
    return tasks
