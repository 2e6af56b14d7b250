"""
The accuracy matrix itself: its tasks (extract x condition, every column spec) and its report.

The report: the pooled table, the within-1 % and spurious shares per extract, issue 11's
acceptance rules on every extract cell, optionally the full per-extract table, and the worst
trips with the id to re-run them by.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from mapmatch.evaluation.accuracy.conditions import (
    CONDITIONS,
    SEED,
    columns_of,
    condition_config,
)
from mapmatch.evaluation.accuracy.overrides import match_config
from mapmatch.evaluation.accuracy.rules import acceptance
from mapmatch.evaluation.accuracy.summary import cells
from mapmatch.evaluation.accuracy.tables import (
    extract_markdown,
    matrix_markdown,
    rows_markdown,
    worst_rows,
)
from mapmatch.evaluation.accuracy.tasks import CellTask
from mapmatch.evaluation.simulate import INPUT_CLASSES

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence
    from pathlib import Path

    from mapmatch.evaluation.accuracy.tasks import TripRow

__all__ = ["matrix_report", "matrix_tasks"]


def matrix_tasks(
    extracts: Sequence[Path],
    *,
    conditions: Sequence[str] = tuple(CONDITIONS),
    classes: Sequence[str] = tuple(INPUT_CLASSES),
    trips: int = 30,
    seed: int = SEED,
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


def matrix_report(
    rows: Sequence[TripRow], *, per_extract: bool, worst: int
) -> tuple[list[str], dict[str, object]]:
    """
    The matrix's report lines and its cells for the JSON report.

    ``per_extract`` adds the full table per extract, ``worst`` lists that many worst trips
    (0: none). The dict holds ``cells`` (pooled) and ``extract_cells``, as ``to_dict`` gives.
    """
    pooled, by_extract = cells(rows, per_extract=False), cells(rows, per_extract=True)
    report: dict[str, object] = {
        "cells": [c.to_dict() for c in pooled],
        "extract_cells": [c.to_dict() for c in by_extract],
    }
    lines = [
        "Pooled over the extracts:",
        "",
        matrix_markdown(pooled),
        "",
        extract_markdown(by_extract, "within_1pct", "Length within 1 % (% of trips)"),
        "",
        extract_markdown(by_extract, "spurious_share", "Spurious U-turn or loop (% of trips)"),
        "",
        "Acceptance (issue 11), per extract cell:",
        *acceptance(by_extract),
    ]
    if per_extract:
        lines += ["", matrix_markdown(by_extract).replace("| condition |", "| cell |")]
    if worst:
        lines += [f"\nWorst {worst} trips (re-run one with --inspect TRIP_ID):", ""]
        lines.append(rows_markdown(worst_rows(rows, worst)))
    return lines, report
