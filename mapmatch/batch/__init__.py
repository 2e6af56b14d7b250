"""Batch matching: folders of trace files in, one output per trace and ``summary.csv`` out.

``run`` drives a batch (:func:`run_batch`), ``inputs`` finds and scans the trace files,
``tasks`` matches and writes some traces of one file in a worker, ``outputs`` writes each
trace's files and the summary atomically, ``report`` is what a batch did, ``executors`` runs
the tasks in this process, a local process pool or on a Dask cluster, and ``many`` is
:func:`mapmatch.match_many`, the same for traces in memory.
"""

from __future__ import annotations

from mapmatch.batch.run import (
    MANIFEST_NAME,
    BatchError,
    BatchOptions,
    BatchProgress,
    BatchReport,
    ChunkOutcome,
    ChunkTask,
    match_chunk,
    run_batch,
    worker_network,
)

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
