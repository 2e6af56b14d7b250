"""
The noise-free truth check: exact traces must match within 0.1 % of the true length.

Every extract x sampling interval (:data:`TRUTH_INTERVALS`, 0.1 s being the 10 Hz truth) x
every subset of the true columns (:data:`TRUTH_SUBSETS`): information that is exactly right
must never make the matched length worse.
"""

from __future__ import annotations

import itertools
import math
from typing import TYPE_CHECKING

from mapmatch.evaluation.accuracy.conditions import SEED
from mapmatch.evaluation.accuracy.matrix import matrix_tasks
from mapmatch.evaluation.accuracy.tables import length_error, rows_markdown, worst_rows

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence
    from pathlib import Path

    from mapmatch.evaluation.accuracy.tasks import CellTask, TripRow

__all__ = [
    "TRUTH_INTERVALS",
    "TRUTH_SUBSETS",
    "TRUTH_TOLERANCE",
    "truth_markdown",
    "truth_report",
    "truth_tasks",
]

#: Sampling intervals of the noise-free truth check (0.1 s: the 10 Hz truth).
TRUTH_INTERVALS = (0.1, 1.0, 5.0, 15.0, 30.0)
#: Every subset of the true columns the truth check feeds (``none`` is positions only).
TRUTH_SUBSETS = tuple(
    "+".join(c) or "none"
    for n in range(4)
    for c in itertools.combinations(("heading", "speed", "odometer"), n)
)
#: The largest |matched - true| / true length the truth check accepts on any trip.
TRUTH_TOLERANCE = 0.001


def truth_tasks(
    extracts: Sequence[Path],
    *,
    intervals: Sequence[float] = TRUTH_INTERVALS,
    subsets: Sequence[str] = TRUTH_SUBSETS,
    trips: int = 5,
    seed: int = SEED,
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


def truth_markdown(rows: Sequence[TripRow]) -> tuple[str, list[TripRow]]:
    """The truth check's table (worst ``|length error|`` over extracts and trips) and failures."""
    conditions = list(dict.fromkeys(r.condition for r in rows))
    subsets = list(dict.fromkeys(r.input_class for r in rows))
    failing = [r for r in rows if r.score is None or abs(r.score.length_error) > TRUTH_TOLERANCE]
    lines = [
        "| interval | " + " | ".join(subsets) + " |",
        "|---|" + "--:|" * len(subsets),
    ]
    for condition in conditions:
        values = []
        for spec in subsets:
            group = [r for r in rows if r.condition == condition and r.input_class == spec]
            bad = sum(1 for r in group if r in failing)
            worst = max((abs(length_error(r)) for r in group), default=math.nan)
            text = "failed" if math.isinf(worst) else f"{100 * worst:.3f} %"
            values.append(f"{text} ({bad}/{len(group)})" if bad else text)
        lines.append(f"| {condition.removeprefix('truth-')} | " + " | ".join(values) + " |")
    return "\n".join(lines), failing


def truth_report(rows: Sequence[TripRow], worst: int) -> tuple[list[str], list[TripRow]]:
    """The truth check's report lines (table, verdict, the worst failures) and the failures."""
    table, failing = truth_markdown(rows)
    lines = [
        "Noise-free truth: worst |matched - true| / true length over every extract and "
        "trip (trips beyond 0.1 % / trips)",
        "",
        table,
        "",
        f"{'PASS' if not failing else 'FAIL'}: {len(rows) - len(failing)}/{len(rows)} "
        "matches within 0.1 % of the true length",
    ]
    if failing:
        lines += ["", rows_markdown(worst_rows(failing, worst))]
    return lines, failing
