"""
The accuracy matrix's command line: its options and one entry point for all three modes.

Shared by ``benchmarks/bench_accuracy.py`` and ``mapmatch bench --matrix`` / ``--truth`` /
``--inspect``: :func:`add_arguments` declares the options, :func:`run_cli` runs the matrix
(:mod:`~mapmatch.evaluation.accuracy.matrix`), the truth check
(:mod:`~mapmatch.evaluation.accuracy.truth`) or one inspection
(:mod:`~mapmatch.evaluation.accuracy.inspection`), prints the report and writes its files.
"""

from __future__ import annotations

import datetime
import json
import math
import os
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mapmatch.config import MatchConfig
from mapmatch.errors import ConfigError
from mapmatch.evaluation.accuracy.conditions import CONDITIONS, SEED, condition_config
from mapmatch.evaluation.accuracy.extracts import default_extracts
from mapmatch.evaluation.accuracy.inspection import inspect_trip
from mapmatch.evaluation.accuracy.matrix import matrix_report, matrix_tasks
from mapmatch.evaluation.accuracy.overrides import parse_overrides
from mapmatch.evaluation.accuracy.runner import run_tasks
from mapmatch.evaluation.accuracy.truth import (
    TRUTH_INTERVALS,
    TRUTH_SUBSETS,
    truth_report,
    truth_tasks,
)
from mapmatch.evaluation.simulate import INPUT_CLASSES, SimulationConfig

if TYPE_CHECKING:
    import argparse
    from collections.abc import Sequence

    from mapmatch.evaluation.accuracy.tasks import TripRow

__all__ = ["add_arguments", "run_cli"]


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
    parser.add_argument("--seed", type=int, default=SEED, help=f"first trip seed ({SEED})")
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
        return inspect_trip(
            args.inspect,
            seed=args.seed,
            match_overrides=match_overrides,
            sim_overrides=sim_overrides,
            classes=classes,
            out=Path(args.out) if args.out else None,
        )
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
    code = 0
    if args.truth:
        body, failing = truth_report(rows, args.worst)
        code = 1 if failing else 0
    else:
        body, figures = matrix_report(rows, per_extract=args.per_extract, worst=args.worst)
        report.update(figures)
    report["trips"] = [r.flat() for r in rows]
    print("\n".join([head, "", *body]))
    if args.rows:
        _write_rows(Path(args.rows), rows)
    if args.json:
        text = json.dumps(report, indent=1, default=_json_default)
        if args.json == "-":
            print(text)
        else:
            Path(args.json).write_text(text, encoding="utf-8")
    return code


def _extracts_from(args: argparse.Namespace) -> list[Path]:
    """The ``--extract`` files (each must exist), else :func:`default_extracts`."""
    given = [Path(p) for p in (args.extract or [])]
    missing = [str(p) for p in given if not p.is_file()]
    if missing:
        msg = f"extract(s) not found: {missing}"
        raise ConfigError(msg)
    return given or default_extracts(quick=args.quick)


def _json_default(value: object) -> object:
    """NaN as ``null``; anything else json cannot write is an error."""
    if isinstance(value, float | np.floating) and math.isnan(value):
        return None
    msg = f"cannot write {value!r} as JSON"
    raise TypeError(msg)


def _write_rows(path: Path, rows: Sequence[TripRow]) -> None:
    """Every per-trip row as one CSV line."""
    import pandas as pd

    pd.DataFrame([r.flat() for r in rows]).to_csv(path, index=False)
