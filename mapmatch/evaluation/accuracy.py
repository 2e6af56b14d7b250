"""
The accuracy matrix: how well the matched *length* holds up, whatever the input.

Every extract x input class (:data:`mapmatch.evaluation.simulate.INPUT_CLASSES`: positions only, +
accuracy, + heading & speed, + odometer) x condition (:data:`CONDITIONS`: clean 1 s / 15 s /
30 s, and realistic 1 s / 15 s noise with a 2 % high odometer). The same simulated trips (fixed
seeds) feed every input class of a condition, stripped to that class's columns. Per cell: route
mismatch, length error, share of trips within 1 % / 2 %, share of trips with a U-turn or loop
the truth does not have, and whether the distance verdict is the one the true length gives.

The noise-free truth check (:func:`truth_tasks`) matches exact traces at several sampling
rates with every subset of the true columns (speed, heading, odometer): the matched length
must be within 0.1 % of the true one on every trip.

Run it as ``benchmarks/bench_accuracy.py`` or ``mapmatch bench --matrix`` / ``--truth``; see
:func:`add_arguments` for the options.
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime
import itertools
import json
import logging
import math
import os
import re
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

import roadnets
from mapmatch.batch.executors import make_executor
from mapmatch.config import MatchConfig
from mapmatch.errors import ConfigError, MapMatchError
from mapmatch.evaluation.scoring import TripScore, score_geojson, summarise
from mapmatch.evaluation.simulate import (
    INPUT_CLASSES,
    TRUE_COLUMNS,
    SimulatedTrip,
    SimulationConfig,
    simulate_trip,
    with_columns,
    write_trips,
)
from mapmatch.matcher import match

if TYPE_CHECKING:
    import argparse
    from collections.abc import Iterable, Mapping, Sequence

    from mapmatch.result import MatchResult

__all__ = [
    "CONDITIONS",
    "TRUTH_INTERVALS",
    "TRUTH_SUBSETS",
    "Cell",
    "CellTask",
    "TripRow",
    "add_arguments",
    "cells",
    "columns_of",
    "condition_config",
    "default_extracts",
    "match_config",
    "matrix_tasks",
    "parse_overrides",
    "run_cli",
    "run_tasks",
    "truth_tasks",
]

_log = logging.getLogger("mapmatch")
_ROOT = Path(__file__).resolve().parents[2]  # the repository (mapmatch/evaluation/../..)
SHARED_EXTRACTS = _ROOT.parent / "shared" / "data" / "osm"
TEST_EXTRACTS = _ROOT / "tests" / "data"
_QUICK = ("monaco_2020", "helsinki_center_2019")
_ROUTE_M = 3000.0
_SEED = 1000

#: The matrix's conditions: clean sampling sets (white noise, 2 % outliers of 40 m, the
#: simulator's brief stops and +-0.5 % odometer) and the realistic preset
#: (:meth:`SimulationConfig.realistic`: AR(1) 0.95/s 6 m, canyons, stops at a third of the
#: junctions for 5-40 s, heading noise 3 + 87 exp(-v) deg, 20-60 s outages, odometer 2 % high).
CONDITIONS: dict[str, SimulationConfig] = {
    "1s-5m": SimulationConfig(
        interval_s=1.0, noise_m=5.0, outlier_rate=0.02, route_length_m=_ROUTE_M
    ),
    "15s-10m": SimulationConfig(
        interval_s=15.0, noise_m=10.0, outlier_rate=0.02, route_length_m=_ROUTE_M
    ),
    "30s-20m": SimulationConfig(
        interval_s=30.0, noise_m=20.0, outlier_rate=0.02, route_length_m=_ROUTE_M
    ),
    "realistic-1s": SimulationConfig.realistic(interval_s=1.0, route_length_m=_ROUTE_M),
    "realistic-15s": SimulationConfig.realistic(interval_s=15.0, route_length_m=_ROUTE_M),
}
#: Sampling intervals of the noise-free truth check (0.1 s: the 10 Hz truth).
TRUTH_INTERVALS = (0.1, 1.0, 5.0, 15.0, 30.0)
#: Every subset of the true columns the truth check feeds (``none`` is positions only).
TRUTH_SUBSETS = tuple(
    "+".join(c) or "none"
    for n in range(4)
    for c in itertools.combinations(("heading", "speed", "odometer"), n)
)
_TRUTH_TOLERANCE = 0.001


def condition_config(name: str) -> SimulationConfig:
    """
    The simulation settings of a condition.

    A key of :data:`CONDITIONS`, or ``truth-<s>s``: noise-free at that interval (e.g.
    ``truth-0.1s``).

    Raises
    ------
    ConfigError
        An unknown condition.
    """
    if name in CONDITIONS:
        return CONDITIONS[name]
    found = re.fullmatch(r"truth-([0-9]*\.?[0-9]+)s", name)
    if found:
        return SimulationConfig.noise_free(
            interval_s=float(found.group(1)), route_length_m=_ROUTE_M
        )
    msg = f"unknown condition {name!r}; known: {sorted(CONDITIONS)} or truth-<interval>s"
    raise ConfigError(msg)


def columns_of(spec: str) -> tuple[str, ...]:
    """
    The optional columns a spec keeps: an input class, ``none``, or columns joined by ``+``.

    Examples
    --------
    >>> columns_of("heading_speed"), columns_of("odometer+speed"), columns_of("none")
    (('accuracy', 'heading', 'speed'), ('odometer', 'speed'), ())
    """
    if spec in INPUT_CLASSES:
        return INPUT_CLASSES[spec]
    if spec == "none":
        return ()
    parts = tuple(spec.split("+"))
    unknown = sorted(set(parts) - set(TRUE_COLUMNS))
    if unknown:
        msg = (
            f"unknown input class or column(s) {unknown} in {spec!r}; classes: "
            f"{list(INPUT_CLASSES)}, columns: {list(TRUE_COLUMNS)} joined by '+', or 'none'"
        )
        raise ConfigError(msg)
    return parts


def _parse_value(name: str, text: str, default: object) -> object:
    if isinstance(default, bool):
        if text.lower() not in ("true", "false", "1", "0", "yes", "no"):
            msg = f"{name} takes true or false (got {text!r})"
            raise ConfigError(msg)
        return text.lower() in ("true", "1", "yes")
    try:
        if isinstance(default, int):
            return int(text)
        if isinstance(default, float):
            return float(text)
        if isinstance(default, tuple):
            return tuple(float(x) for x in text.split(","))
    except ValueError:
        kind = "comma-separated numbers" if isinstance(default, tuple) else type(default).__name__
        msg = f"{name} takes {kind} (got {text!r})"
        raise ConfigError(msg) from None
    return text


def parse_overrides(pairs: Iterable[str], defaults: Any) -> dict[str, object]:
    """
    ``["key=value", ...]`` as typed field values of the dataclass instance ``defaults``.

    Values are read as the field's default is typed: ``true``/``false``, integers, floats,
    comma-separated numbers for pairs (``distance_band=-0.04,0.01``), else text.

    Raises
    ------
    ConfigError
        A pair without ``=`` or an unknown field (the message lists the known ones).

    Examples
    --------
    >>> parse_overrides(["uturn_penalty=20", "use_travel=false"], MatchConfig())
    {'uturn_penalty': 20.0, 'use_travel': False}
    """
    fields = {f.name for f in dataclasses.fields(defaults)}
    out: dict[str, object] = {}
    for pair in pairs:
        name, sep, text = pair.partition("=")
        name = name.strip()
        if not sep:
            msg = f"override {pair!r} must be key=value"
            raise ConfigError(msg)
        if name not in fields:
            msg = f"unknown field {name!r} of {type(defaults).__name__}; known: {sorted(fields)}"
            raise ConfigError(msg)
        out[name] = _parse_value(name, text.strip(), getattr(defaults, name))
    return out


def match_config(overrides: Mapping[str, object]) -> MatchConfig:
    """
    The default :class:`MatchConfig` with any of its fields changed (validated).

    Unlike :meth:`MatchConfig.replace` (the fields a request may set) every field is open:
    this is for trying parameters.
    """
    return dataclasses.replace(MatchConfig(), **overrides)  # type: ignore[arg-type]


def _extract_name(path: Path) -> str:
    return path.name.split(".osm")[0]


def default_extracts(*, quick: bool = False) -> list[Path]:
    """
    The extracts the matrix runs on.

    Every shared extract (``../shared/data/osm``), else the embedded network and the
    extracts in ``tests/data``; ``quick``: two of them (Monaco and Helsinki when present).
    """
    found = sorted(SHARED_EXTRACTS.glob("*.osm*"))
    if not found:
        found = [roadnets.default_network_path(), *sorted(TEST_EXTRACTS.glob("*.osm*"))]
    if quick:
        named = [p for name in _QUICK for p in found if _extract_name(p) == name]
        found = (named + [p for p in found if p not in named])[:2]
    return found


@dataclass(frozen=True, slots=True)
class CellTask:
    """
    One worker task: the trips of one extract and condition, matched in every column spec.

    Trip ``i`` has seed ``seed + i`` and id ``<extract>:<condition>:<i>``; the same seed
    drives the same route under every condition (the route is drawn first).
    """

    extract: str
    condition: str
    specs: tuple[str, ...]
    trips: int
    seed: int = _SEED
    first: int = 0
    config: tuple[tuple[str, object], ...] = ()
    sim: tuple[tuple[str, object], ...] = ()

    @property
    def name(self) -> str:
        """The extract's name (file name without the OSM suffixes)."""
        return _extract_name(Path(self.extract))


@dataclass(frozen=True, slots=True)
class TripRow:
    """
    One trip matched with one column spec: its score, or the error that stopped the match.

    ``trip_id`` (``<extract>:<condition>:<index>``) re-runs it with ``--inspect``.
    """

    extract: str
    condition: str
    input_class: str
    index: int
    seed: int
    points: int
    match_s: float
    stops: int
    outages: int
    canyons: int
    score: TripScore | None
    error: str = ""

    @property
    def trip_id(self) -> str:
        """``<extract>:<condition>:<index>``."""
        return f"{self.extract}:{self.condition}:{self.index}"

    def flat(self) -> dict[str, object]:
        """The row with its score's fields inline (one CSV / JSON row)."""
        out: dict[str, object] = {
            "trip_id": self.trip_id,
            "extract": self.extract,
            "condition": self.condition,
            "input_class": self.input_class,
            "index": self.index,
            "seed": self.seed,
            "points": self.points,
            "match_s": round(self.match_s, 6),
            "stops": self.stops,
            "outages": self.outages,
            "canyons": self.canyons,
            "error": self.error,
        }
        if self.score is not None:
            score = self.score.to_dict()
            score.pop("trace_id")
            score.pop("points")
            out.update(score)
        return out


_NETWORKS: dict[str, roadnets.RoadNetwork] = {}


def _network(path: str) -> roadnets.RoadNetwork:
    """The network, loaded once per process and warmed up by one untimed match."""
    if path not in _NETWORKS:
        net = roadnets.load(path)
        warm = SimulationConfig(route_length_m=500.0)
        with contextlib.suppress(MapMatchError):  # a bad match shows up in the timed ones
            match(simulate_trip(net, warm, seed=0).trace, net)  # R-tree, compiled kernels
        _NETWORKS[path] = net
    return _NETWORKS[path]


def _simulate(task: CellTask, index: int) -> SimulatedTrip:
    cfg = condition_config(task.condition)
    if task.sim:
        cfg = cfg.replace(**dict(task.sim))
    return simulate_trip(
        _network(task.extract),
        cfg,
        seed=task.seed + index,
        trace_id=f"{task.name}:{task.condition}:{index}",
    )


def _match_one(
    trip: SimulatedTrip, spec: str, net: roadnets.RoadNetwork, config: MatchConfig
) -> tuple[MatchResult | None, float, str]:
    trace = with_columns(trip.trace, columns_of(spec))
    started = time.perf_counter()
    try:
        result = match(trace, net, config)
    except MapMatchError as exc:
        return None, time.perf_counter() - started, f"{type(exc).__name__}: {exc}"
    return result, time.perf_counter() - started, ""


def run_cell(task: CellTask) -> list[TripRow]:
    """Simulate a task's trips and match each in every column spec (a worker's job)."""
    _log.setLevel(logging.ERROR)  # one verdict warning per trip would drown the output
    net = _network(task.extract)
    config = match_config(dict(task.config))
    rows: list[TripRow] = []
    for index in range(task.first, task.first + task.trips):
        trip = _simulate(task, index)
        truth = trip.truth_record()
        for spec in task.specs:
            result, seconds, error = _match_one(trip, spec, net, config)
            score = score_geojson(result.to_geojson(), truth) if result is not None else None
            rows.append(_row(task, trip, index, spec, seconds, score, error))
    return rows


def _row(
    task: CellTask,
    trip: SimulatedTrip,
    index: int,
    spec: str,
    seconds: float,
    score: TripScore | None,
    error: str,
) -> TripRow:
    return TripRow(
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
    )


def matrix_tasks(
    extracts: Sequence[Path],
    *,
    conditions: Sequence[str] = tuple(CONDITIONS),
    classes: Sequence[str] = tuple(INPUT_CLASSES),
    trips: int = 30,
    seed: int = _SEED,
    config: Mapping[str, object] | None = None,
    sim: Mapping[str, object] | None = None,
) -> list[CellTask]:
    """
    The matrix's tasks, one per extract and condition, heaviest (1 s) first.

    Raises
    ------
    ConfigError
        An unknown condition or class, or overrides that break a rule.
    """
    for name in conditions:
        condition_config(name)
    for spec in classes:
        columns_of(spec)
    overrides = tuple((config or {}).items())
    sim_overrides = tuple((sim or {}).items())
    match_config(dict(overrides))  # fail here, not in a worker
    for name in conditions:
        condition_config(name).replace(**dict(sim_overrides))
    order = sorted(conditions, key=lambda c: condition_config(c).interval_s)
    return [
        CellTask(str(path), name, tuple(classes), trips, seed, 0, overrides, sim_overrides)
        for name in order
        for path in extracts
    ]


def truth_tasks(
    extracts: Sequence[Path],
    *,
    intervals: Sequence[float] = TRUTH_INTERVALS,
    subsets: Sequence[str] = TRUTH_SUBSETS,
    trips: int = 5,
    seed: int = _SEED,
    config: Mapping[str, object] | None = None,
) -> list[CellTask]:
    """The noise-free truth check's tasks: every extract x interval, every column subset."""
    return matrix_tasks(
        extracts,
        conditions=[f"truth-{s:g}s" for s in intervals],
        classes=subsets,
        trips=trips,
        seed=seed,
        config=config,
    )


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


@dataclass(frozen=True, slots=True)
class Cell:
    """
    The figures of one cell (``extract`` is ``all`` when pooled over extracts).

    Shares are over every trip of the cell: a trip whose match failed counts as outside
    the length bands. ``verdict_trips`` / ``verdict_accuracy``: trips with an odometer and no
    break, and the share of them whose verdict is the one the true length gives (NaN when
    none). ``points_per_s``: fixes matched per second of matching in the run's processes.
    """

    extract: str
    condition: str
    input_class: str
    trips: int
    failed: int
    points: int
    points_per_s: float
    mismatch_mean: float
    mismatch_p95: float
    length_error_mean: float
    length_abs_p95: float
    length_abs_max: float
    within_1pct: float
    within_2pct: float
    spurious_share: float
    spurious_uturns: int
    spurious_loops: int
    verdict_trips: int
    verdict_accuracy: float

    def to_dict(self) -> dict[str, object]:
        """JSON-ready (NaN becomes ``None``)."""
        return {
            k: (None if isinstance(v, float) and math.isnan(v) else v)
            for k, v in dataclasses.asdict(self).items()
        }


def _cell(extract: str, condition: str, spec: str, rows: list[TripRow]) -> Cell:
    scores = [r.score for r in rows if r.score is not None]
    ok = len(scores) / len(rows) if rows else 0.0
    seconds = sum(r.match_s for r in rows if r.score is not None)
    points = sum(r.points for r in rows if r.score is not None)
    nan = float("nan")
    if not scores:
        return Cell(
            extract=extract,
            condition=condition,
            input_class=spec,
            trips=len(rows),
            failed=len(rows),
            points=0,
            points_per_s=nan,
            mismatch_mean=nan,
            mismatch_p95=nan,
            length_error_mean=nan,
            length_abs_p95=nan,
            length_abs_max=nan,
            within_1pct=0.0,
            within_2pct=0.0,
            spurious_share=nan,
            spurious_uturns=0,
            spurious_loops=0,
            verdict_trips=0,
            verdict_accuracy=nan,
        )
    s = summarise(scores)
    return Cell(
        extract=extract,
        condition=condition,
        input_class=spec,
        trips=len(rows),
        failed=len(rows) - len(scores),
        points=points,
        points_per_s=points / seconds if seconds > 0 else nan,
        mismatch_mean=s["mismatch_mean"],
        mismatch_p95=s["mismatch_p95"],
        length_error_mean=s["length_error_mean"],
        length_abs_p95=s["length_error_abs_p95"],
        length_abs_max=s["length_error_abs_max"],
        within_1pct=s["within_1pct"] * ok,
        within_2pct=s["within_2pct"] * ok,
        spurious_share=s["spurious_share"] * ok,
        spurious_uturns=int(s["spurious_uturns"]),
        spurious_loops=int(s["spurious_loops"]),
        verdict_trips=int(s["verdict_trips"]),
        verdict_accuracy=s["verdict_accuracy"],
    )


def cells(rows: Sequence[TripRow], *, per_extract: bool) -> list[Cell]:
    """Group rows into cells: per extract, or pooled over extracts (``extract`` = ``all``)."""
    groups: dict[tuple[str, str, str], list[TripRow]] = {}
    for row in rows:
        key = (row.extract if per_extract else "all", row.condition, row.input_class)
        groups.setdefault(key, []).append(row)
    return [_cell(*key, group) for key, group in groups.items()]


def _pct(value: float, digits: int = 1) -> str:
    return "-" if math.isnan(value) else f"{100 * value:.{digits}f} %"


def _signed(value: float) -> str:
    return "-" if math.isnan(value) else f"{100 * value:+.2f} %"


def matrix_markdown(pooled: Sequence[Cell]) -> str:
    """The pooled cells as one markdown table, a row per condition and input class."""
    lines = [
        "| condition | input | trips | failed | mismatch mean | mismatch p95 | length error "
        "mean | \\|length error\\| p95 | within 1 % | within 2 % | spurious U-turn/loop "
        "| verdict right | points/s |",
        "|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|",
    ]
    for c in pooled:
        verdict = f"{_pct(c.verdict_accuracy, 0)} of {c.verdict_trips}" if c.verdict_trips else "-"
        lines.append(
            f"| {c.condition} | {c.input_class} | {c.trips} | {c.failed} "
            f"| {_pct(c.mismatch_mean, 2)} | {_pct(c.mismatch_p95, 2)} "
            f"| {_signed(c.length_error_mean)} | {_pct(c.length_abs_p95, 2)} "
            f"| {_pct(c.within_1pct, 0)} | {_pct(c.within_2pct, 0)} "
            f"| {_pct(c.spurious_share, 0)} ({c.spurious_uturns} U, {c.spurious_loops} L) "
            f"| {verdict} | {c.points_per_s:,.0f} |"
        )
    return "\n".join(lines)


def extract_markdown(per_extract: Sequence[Cell], field: str, title: str) -> str:
    """One figure per extract (rows) and condition (columns), the classes side by side."""
    conditions = list(dict.fromkeys(c.condition for c in per_extract))
    classes = list(dict.fromkeys(c.input_class for c in per_extract))
    by_key = {(c.extract, c.condition, c.input_class): c for c in per_extract}
    lines = [
        f"{title} per extract; each cell: {' / '.join(classes)}",
        "",
        "| extract | " + " | ".join(conditions) + " |",
        "|---|" + "--:|" * len(conditions),
    ]
    for extract in dict.fromkeys(c.extract for c in per_extract):
        values = []
        for condition in conditions:
            parts = []
            for spec in classes:
                cell = by_key.get((extract, condition, spec))
                value = getattr(cell, field) if cell else math.nan
                parts.append("-" if math.isnan(value) else f"{100 * value:.0f}")
            values.append(" / ".join(parts))
        lines.append(f"| {extract} | " + " | ".join(values) + " |")
    return "\n".join(lines)


def acceptance(per_extract: Sequence[Cell]) -> list[str]:
    """
    Issue 11's acceptance figures checked on every per-extract cell; one line per rule.

    At 1 s and 15 s (clean and realistic): length within 1 % on >= 95 % of trips, route
    mismatch mean <= 1 % (1 s) / <= 2 % (15 s), spurious U-turn or loop on <= 2 % of trips;
    at 30 s: within 2 % on >= 90 %; realistic with the odometer: verdict right on >= 95 %.
    """
    rules: list[tuple[str, list[str]]] = []

    def check(name: str, selected: list[Cell], passes: Any, shown: str, digits: int) -> None:
        failing = [
            f"{c.extract}/{c.condition}/{c.input_class} {_pct(getattr(c, shown), digits)}"
            for c in selected
            if not passes(c)
        ]
        rules.append((f"{name}: {len(selected) - len(failing)}/{len(selected)} cells", failing))

    def interval(c: Cell) -> float:
        return condition_config(c.condition).interval_s

    dense = [c for c in per_extract if interval(c) in (1.0, 15.0)]
    check("within 1 % on >= 95 %", dense, lambda c: c.within_1pct >= 0.95, "within_1pct", 0)
    check(
        "mismatch mean <= 1 % (1 s) / 2 % (15 s)",
        dense,
        lambda c: c.mismatch_mean <= (0.01 if interval(c) == 1.0 else 0.02),
        "mismatch_mean",
        2,
    )
    check(
        "spurious U-turn/loop on <= 2 %",
        dense,
        lambda c: c.spurious_share <= 0.02,
        "spurious_share",
        0,
    )
    sparse = [c for c in per_extract if interval(c) == 30.0]
    check("30 s: within 2 % on >= 90 %", sparse, lambda c: c.within_2pct >= 0.90, "within_2pct", 0)
    judged = [c for c in per_extract if c.condition.startswith("realistic") and c.verdict_trips > 0]
    check(
        "realistic + odometer: verdict right on >= 95 %",
        judged,
        lambda c: c.verdict_accuracy >= 0.95,
        "verdict_accuracy",
        0,
    )
    lines = []
    for head, failing in rules:
        more = f"; failing: {', '.join(failing[:12])}" if failing else ""
        more += f" (+{len(failing) - 12} more)" if len(failing) > 12 else ""
        lines.append(f"- {head}{more}")
    return lines


def worst_rows(rows: Sequence[TripRow], count: int) -> list[TripRow]:
    """The ``count`` worst rows: failed matches first, then the largest ``|length error|``."""
    return sorted(rows, key=lambda r: (r.score is None, abs(_err(r))), reverse=True)[:count]


def _err(row: TripRow) -> float:
    return row.score.length_error if row.score is not None else math.inf


def rows_markdown(rows: Sequence[TripRow]) -> str:
    """Per-trip rows as a markdown table (worst trips, inspection)."""
    lines = [
        "| trip id | input | points | stops | outages | canyons | length error | mismatch "
        "| U-turns m/t | loops m/t | verdict (true) | error |",
        "|---|---|--:|--:|--:|--:|--:|--:|--:|--:|---|---|",
    ]
    for r in rows:
        s = r.score
        if s is None:
            lines.append(
                f"| {r.trip_id} | {r.input_class} | {r.points} | {r.stops} | {r.outages} "
                f"| {r.canyons} | - | - | - | - | - | {r.error} |"
            )
            continue
        verdict = f"{s.verdict} ({s.true_verdict})" if s.verdict else "-"
        lines.append(
            f"| {r.trip_id} | {r.input_class} | {r.points} | {r.stops} | {r.outages} "
            f"| {r.canyons} | {_signed(s.length_error)} | {_pct(s.mismatch, 2)} "
            f"| {s.uturns}/{s.true_uturns} | {s.loops}/{s.true_loops} | {verdict} | |"
        )
    return "\n".join(lines)


def truth_markdown(rows: Sequence[TripRow]) -> tuple[str, list[TripRow]]:
    """The truth check's table (worst ``|length error|`` over extracts and trips) and failures."""
    conditions = list(dict.fromkeys(r.condition for r in rows))
    subsets = list(dict.fromkeys(r.input_class for r in rows))
    failing = [r for r in rows if r.score is None or abs(r.score.length_error) > _TRUTH_TOLERANCE]
    lines = [
        "| interval | " + " | ".join(subsets) + " |",
        "|---|" + "--:|" * len(subsets),
    ]
    for condition in conditions:
        values = []
        for spec in subsets:
            group = [r for r in rows if r.condition == condition and r.input_class == spec]
            bad = sum(1 for r in group if r in failing)
            worst = max((abs(_err(r)) for r in group), default=math.nan)
            text = "failed" if math.isinf(worst) else f"{100 * worst:.3f} %"
            values.append(f"{text} ({bad}/{len(group)})" if bad else text)
        lines.append(f"| {condition.removeprefix('truth-')} | " + " | ".join(values) + " |")
    return "\n".join(lines), failing


def _extracts_from(args: argparse.Namespace) -> list[Path]:
    given = [Path(p) for p in (args.extract or [])]
    missing = [str(p) for p in given if not p.is_file()]
    if missing:
        msg = f"extract(s) not found: {missing}"
        raise ConfigError(msg)
    return given or default_extracts(quick=args.quick)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The matrix's options (shared by ``benchmarks/bench_accuracy.py`` and ``mapmatch bench``)."""
    parser.add_argument(
        "--truth",
        action="store_true",
        help="the noise-free truth check instead: every extract x 0.1/1/5/15/30 s x every "
        "subset of speed/heading/odometer; matched length within 0.1 %% on every trip",
    )
    parser.add_argument(
        "--quick", action="store_true", help="2 extracts, 10 trips per cell (development)"
    )
    parser.add_argument("--extract", action="append", default=None, help="OSM extract (repeatable)")
    parser.add_argument(
        "--conditions",
        default=None,
        help=f"comma-separated conditions (default all: {','.join(CONDITIONS)}; "
        "truth-<s>s for noise-free)",
    )
    parser.add_argument(
        "--classes",
        default=None,
        help=f"comma-separated input classes (default all: {','.join(INPUT_CLASSES)}), or "
        "column sets like speed+odometer",
    )
    parser.add_argument(
        "--trips", type=int, default=None, help="trips per cell (30; --quick 10; --truth 5)"
    )
    parser.add_argument(
        "--config",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="MatchConfig field override (repeatable), e.g. --config uturn_penalty=20",
    )
    parser.add_argument(
        "--sim",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="SimulationConfig override for every condition (repeatable), e.g. "
        "--sim canyon_per_km=1",
    )
    parser.add_argument("--workers", type=int, default=2, help="processes (2)")
    parser.add_argument("--seed", type=int, default=_SEED, help=f"first trip seed ({_SEED})")
    parser.add_argument("--rows", default=None, help="write every per-trip row to this CSV")
    parser.add_argument(
        "--worst", type=int, default=10, help="list the N worst trips after the table (10)"
    )
    parser.add_argument(
        "--per-extract", action="store_true", help="also print the full table per extract"
    )
    parser.add_argument(
        "--inspect",
        default=None,
        metavar="TRIP_ID",
        help="re-run one trip (<extract>:<condition>:<index>, as the tables name it) in the "
        "chosen classes and list its U-turns and loops",
    )
    parser.add_argument(
        "--out", default=None, help="with --inspect: write trace, truth, matches and maps here"
    )


def run_cli(args: argparse.Namespace) -> int:
    """
    Run the matrix, the truth check or one inspection as the parsed options say.

    ``args.json`` (a path, ``-`` for stdout, or ``None``) receives the JSON report.
    Returns 0, or 1 when the truth check finds a trip beyond 0.1 %.
    """
    match_overrides = parse_overrides(args.config, MatchConfig())
    sim_overrides = parse_overrides(args.sim, SimulationConfig())
    classes = args.classes.split(",") if args.classes else None
    conditions = args.conditions.split(",") if args.conditions else None
    if args.inspect:
        return _inspect(args, match_overrides, sim_overrides, classes)
    extracts = _extracts_from(args)
    if args.truth:
        trips = args.trips or 5
        tasks = truth_tasks(
            extracts,
            intervals=[condition_config(c).interval_s for c in conditions]
            if conditions
            else TRUTH_INTERVALS,
            subsets=classes or TRUTH_SUBSETS,
            trips=trips,
            seed=args.seed,
            config=match_overrides,
        )
    else:
        trips = args.trips or (10 if args.quick else 30)
        tasks = matrix_tasks(
            extracts,
            conditions=conditions or tuple(CONDITIONS),
            classes=classes or tuple(INPUT_CLASSES),
            trips=trips,
            seed=args.seed,
            config=match_overrides,
            sim=sim_overrides,
        )
    started = time.perf_counter()
    rows = run_tasks(tasks, workers=args.workers)
    seconds = time.perf_counter() - started
    head = (
        f"{datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, {os.cpu_count()} cores, "
        f"{args.workers} processes, {seconds:.0f} s; {len(extracts)} extracts, {trips} trips "
        f"per cell (seeds {args.seed}..{args.seed + trips - 1}), {len(rows)} matches; "
        f"MatchConfig overrides: {match_overrides or 'none'}"
        + (f"; simulation overrides: {sim_overrides}" if sim_overrides else "")
    )
    report: dict[str, object] = {"meta": {"summary": head, "seconds": seconds}}
    lines = [head, ""]
    code = 0
    if args.truth:
        table, failing = truth_markdown(rows)
        lines += [
            "Noise-free truth: worst |matched - true| / true length over every extract and "
            "trip (trips beyond 0.1 % / trips)",
            "",
            table,
            "",
            f"{'PASS' if not failing else 'FAIL'}: {len(rows) - len(failing)}/{len(rows)} "
            "matches within 0.1 % of the true length",
        ]
        if failing:
            lines += ["", rows_markdown(worst_rows(failing, args.worst))]
            code = 1
    else:
        pooled, per_extract = cells(rows, per_extract=False), cells(rows, per_extract=True)
        report["cells"] = [c.to_dict() for c in pooled]
        report["extract_cells"] = [c.to_dict() for c in per_extract]
        lines += [
            "Pooled over the extracts:",
            "",
            matrix_markdown(pooled),
            "",
            extract_markdown(per_extract, "within_1pct", "Length within 1 % (% of trips)"),
            "",
            extract_markdown(per_extract, "spurious_share", "Spurious U-turn or loop (% of trips)"),
            "",
            "Acceptance (issue 11), per extract cell:",
            *acceptance(per_extract),
        ]
        if args.per_extract:
            lines += ["", matrix_markdown(per_extract).replace("| condition |", "| cell |")]
        if args.worst:
            lines += [f"\nWorst {args.worst} trips (re-run one with --inspect TRIP_ID):", ""]
            lines.append(rows_markdown(worst_rows(rows, args.worst)))
    report["trips"] = [r.flat() for r in rows]
    print("\n".join(lines))
    if args.rows:
        _write_rows(Path(args.rows), rows)
    if args.json:
        text = json.dumps(report, indent=1, default=_json_default)
        if args.json == "-":
            print(text)
        else:
            Path(args.json).write_text(text, encoding="utf-8")
    return code


def _json_default(value: object) -> object:
    if isinstance(value, float | np.floating) and math.isnan(value):
        return None
    msg = f"cannot write {value!r} as JSON"
    raise TypeError(msg)


def _write_rows(path: Path, rows: Sequence[TripRow]) -> None:
    import pandas as pd

    pd.DataFrame([r.flat() for r in rows]).to_csv(path, index=False)


def _extract_named(name: str) -> Path:
    for path in [*default_extracts(), roadnets.default_network_path()]:
        if _extract_name(path) == name or str(path) == name:
            return path
    if Path(name).is_file():
        return Path(name)
    known = sorted({_extract_name(p) for p in default_extracts()})
    msg = f"no extract named {name!r}; known: {known} (or give a path)"
    raise ConfigError(msg)


def _inspect(
    args: argparse.Namespace,
    match_overrides: Mapping[str, object],
    sim_overrides: Mapping[str, object],
    classes: Sequence[str] | None,
) -> int:
    """Re-run one trip in the chosen classes; print its scores and where it turns back."""
    extract, sep, rest = args.inspect.rpartition(":")
    name, _, condition = extract.rpartition(":")
    if not sep or not name or not rest.isdigit():
        msg = f"trip id {args.inspect!r} must be <extract>:<condition>:<index>"
        raise ConfigError(msg)
    index = int(rest)
    path = _extract_named(name)
    specs = tuple(
        classes or (INPUT_CLASSES if not condition.startswith("truth") else TRUTH_SUBSETS)
    )
    task = CellTask(
        str(path),
        condition,
        specs,
        1,
        args.seed,
        index,
        tuple(match_overrides.items()),
        tuple(sim_overrides.items()),
    )
    _log.setLevel(logging.ERROR)
    net = _network(task.extract)
    trip = _simulate(task, index)
    config = match_config(match_overrides)
    truth = trip.truth_record()
    out = Path(args.out) if args.out else None
    if out is not None:
        write_trips([trip], out)
    print(
        f"{args.inspect}: seed {task.seed + index}, {len(trip.trace)} fixes, "
        f"{trip.length_m:.1f} m, {len(trip.stops)} stops, {len(trip.outages)} outages, "
        f"{len(trip.canyons)} canyon stretches, odometer x{trip.odometer_scale:.4f}; the truth "
        f"has {trip.uturns} U-turns and {trip.loops} loops"
    )
    rows = []
    for spec in specs:
        result, seconds, error = _match_one(trip, spec, net, config)
        score = score_geojson(result.to_geojson(), truth) if result is not None else None
        rows.append(_row(task, trip, index, spec, seconds, score, error))
        if result is None:
            continue
        for line in _turnback_places(result, net):
            print(f"  {spec}: {line}")
        if out is not None:
            stem = trip.trace.trace_id.replace(":", "_")
            geojson = out / f"{stem}.{spec}.geojson"
            geojson.write_text(json.dumps(result.to_geojson()), encoding="utf-8")
            _write_map(result, net, out / f"{stem}.{spec}.html")
    print("\n" + rows_markdown(rows))
    if out is not None:
        print(f"\ntrace, truth and matches written to {out}")
    return 0


def _turnback_places(result: MatchResult, net: roadnets.RoadNetwork) -> list[str]:
    """Where a match turns back (twin edges in a row) or drives an edge again."""
    a = net.arrays
    lines = []
    for seg in result.segments:
        seen: dict[int, int] = {}
        driven = [e for e in seg.edges if e.driven_m > 0]  # as count_turnbacks counts them
        for i, e in enumerate(driven):
            before = driven[i - 1] if i else None
            if before is not None and a.edge_twin[before.edge] == e.edge:
                x, y = net.point_on_edge(np.array([e.edge]), np.array([e.start_offset_m]))
                lon, lat = net.unproject(x, y)
                lines.append(
                    f"U-turn in segment {seg.index} at driven edge #{i}: {before.u}->{before.v} "
                    f"for {before.driven_m:.0f} m, back {e.u}->{e.v} for {e.driven_m:.0f} m; "
                    f"turned at lon/lat {lon[0]:.6f},{lat[0]:.6f}"
                )
            if e.edge in seen:
                lines.append(
                    f"loop in segment {seg.index}: edge {e.u}->{e.v} (key {e.key}) driven again "
                    f"at #{i} (first at #{seen[e.edge]})"
                )
            seen.setdefault(e.edge, i)
    return lines


def _write_map(result: MatchResult, net: roadnets.RoadNetwork, path: Path) -> None:
    try:
        from mapmatch.viz import match_map

        match_map(result, net).save(str(path))
    except ImportError:  # the viz extra is optional
        return
