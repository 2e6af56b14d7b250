"""
Running the matrix: simulate a cell's trips, match each in every column spec, in processes.

Each worker process loads a network once (and warms it up with one untimed match, so the
R-tree and compiled kernels are not in the first timed trip); :func:`run_tasks` hands the
tasks to local processes and gives the rows back in task order.
"""

from __future__ import annotations

import contextlib
import logging
import sys
import time
from typing import TYPE_CHECKING

import roadnets
from mapmatch.batch.executors import make_executor
from mapmatch.errors import MapMatchError
from mapmatch.evaluation.accuracy.conditions import columns_of, condition_config
from mapmatch.evaluation.accuracy.overrides import match_config
from mapmatch.evaluation.accuracy.tasks import CellTask, TripRow
from mapmatch.evaluation.scoring import score_geojson
from mapmatch.evaluation.simulate import (
    SimulatedTrip,
    SimulationConfig,
    simulate_trip,
    with_columns,
)
from mapmatch.matcher import match

if TYPE_CHECKING:
    from collections.abc import Sequence
    from typing import Any

    from mapmatch.config import MatchConfig
    from mapmatch.result import MatchResult

__all__ = ["match_row", "run_cell", "run_tasks", "task_trip", "worker_network"]

_log = logging.getLogger("mapmatch")
_NETWORKS: dict[str, roadnets.RoadNetwork] = {}


def worker_network(path: str) -> roadnets.RoadNetwork:
    """The network, loaded once per process and warmed up by one untimed match."""
    if path not in _NETWORKS:
        net = roadnets.load(path)
        warm = SimulationConfig(route_length_m=500.0)
        with contextlib.suppress(MapMatchError):  # a bad match shows up in the timed ones
            match(simulate_trip(net, warm, seed=0).trace, net)  # R-tree, compiled kernels
        _NETWORKS[path] = net
    return _NETWORKS[path]


def task_trip(task: CellTask, index: int) -> SimulatedTrip:
    """Trip ``index`` of a task: seed ``task.seed + index``, id ``<extract>:<condition>:<i>``."""
    cfg = condition_config(task.condition)
    if task.sim:
        cfg = cfg.replace(**dict(task.sim))
    return simulate_trip(
        worker_network(task.extract),
        cfg,
        seed=task.seed + index,
        trace_id=f"{task.name}:{task.condition}:{index}",
    )


def match_row(
    task: CellTask,
    trip: SimulatedTrip,
    index: int,
    spec: str,
    config: MatchConfig,
    truth: dict[str, Any],
) -> tuple[TripRow, MatchResult | None]:
    """
    Match trip ``index`` of ``task`` with the columns of ``spec`` and score it on ``truth``.

    Returns the row and the match (``None`` when the matcher raised: the row names the error).
    """
    trace = with_columns(trip.trace, columns_of(spec))
    net = worker_network(task.extract)
    failure: MapMatchError | None = None
    started = time.perf_counter()
    try:
        result: MatchResult | None = match(trace, net, config)
    except MapMatchError as exc:
        result, failure = None, exc
    seconds = time.perf_counter() - started
    error = f"{type(failure).__name__}: {failure}" if failure is not None else ""
    score = score_geojson(result.to_geojson(), truth) if result is not None else None
    row = TripRow(
        extract=task.name,
        condition=task.condition,
        input_class=spec,
        index=index,
        seed=task.seed + index,
        points=len(trip.trace),
        match_s=seconds,
        stops=len(trip.stops),
        outages=len(trip.outages),
        canyons=len(trip.canyons),
        score=score,
        error=error,
        ends_error=trip.ends_error(),
    )
    return row, result


def run_cell(task: CellTask) -> list[TripRow]:
    """Simulate a task's trips and match each in every column spec (a worker's job)."""
    _log.setLevel(logging.ERROR)  # one verdict warning per trip would drown the output
    config = match_config(dict(task.config))
    rows: list[TripRow] = []
    for index in range(task.first, task.first + task.trips):
        trip = task_trip(task, index)
        truth = trip.truth_record()
        rows += [match_row(task, trip, index, spec, config, truth)[0] for spec in task.specs]
    return rows


def run_tasks(
    tasks: Sequence[CellTask], *, workers: int = 2, progress: bool = True
) -> list[TripRow]:
    """
    Run tasks on ``workers`` local processes (1: in this process); rows in task order.

    Raises
    ------
    RuntimeError
        A task failed outside the matcher (a network that does not load ...).
    """
    executor = make_executor(workers, None, preload=["mapmatch.evaluation.accuracy"])
    done: dict[int, list[TripRow]] = {}
    position = {id(t): i for i, t in enumerate(tasks)}
    started = time.perf_counter()
    try:
        for task, outcome in executor.run(run_cell, list(tasks)):
            if isinstance(outcome, BaseException):
                msg = f"task {task.name} / {task.condition} failed: {outcome!r}"
                raise RuntimeError(msg) from outcome
            done[position[id(task)]] = outcome
            if progress:
                print(
                    f"  [{len(done)}/{len(tasks)}] {task.name} {task.condition}: "
                    f"{len(outcome)} matches, {time.perf_counter() - started:.0f} s",
                    file=sys.stderr,
                    flush=True,
                )
    finally:
        executor.close()
    return [row for i in sorted(done) for row in done[i]]
