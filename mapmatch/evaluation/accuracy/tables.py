"""
The accuracy matrix as markdown: the pooled table, one figure per extract, per-trip rows.

Percentages print as ``12.3 %`` (``-`` for NaN), signed length errors as ``+1.23 %``.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Sequence

    from mapmatch.evaluation.accuracy.summary import Cell
    from mapmatch.evaluation.accuracy.tasks import TripRow

__all__ = [
    "extract_markdown",
    "length_error",
    "matrix_markdown",
    "pct",
    "rows_markdown",
    "signed",
    "worst_rows",
]


def pct(value: float, digits: int = 1) -> str:
    """A share as a percentage with ``digits`` decimals; ``-`` for NaN."""
    return "-" if math.isnan(value) else f"{100 * value:.{digits}f} %"


def signed(value: float) -> str:
    """A relative error as a signed percentage with two decimals; ``-`` for NaN."""
    return "-" if math.isnan(value) else f"{100 * value:+.2f} %"


def matrix_markdown(pooled: Sequence[Cell]) -> str:
    """The pooled cells as one markdown table, a row per condition and input class."""
    lines = [
        "| condition | input | trips | failed | mismatch mean | mismatch p95 | length error "
        "mean | \\|length error\\| p95 | within 1 % | within 2 % | spurious U-turn/loop "
        "| verdict right | points/s | exact route, noisy ends: within 1 % / 2 % "
        "| matched route, exact ends: within 1 % / 2 % |",
        "|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|",
    ]
    for c in pooled:
        verdict = f"{pct(c.verdict_accuracy, 0)} of {c.verdict_trips}" if c.verdict_trips else "-"
        lines.append(
            f"| {c.condition} | {c.input_class} | {c.trips} | {c.failed} "
            f"| {pct(c.mismatch_mean, 2)} | {pct(c.mismatch_p95, 2)} "
            f"| {signed(c.length_error_mean)} | {pct(c.length_abs_p95, 2)} "
            f"| {pct(c.within_1pct, 0)} | {pct(c.within_2pct, 0)} "
            f"| {pct(c.spurious_share, 0)} ({c.spurious_uturns} U, {c.spurious_loops} L) "
            f"| {verdict} | {c.points_per_s:,.0f} "
            f"| {pct(c.ends_within_1pct, 0)} / {pct(c.ends_within_2pct, 0)} "
            f"| {pct(c.exact_ends_within_1pct, 0)} / {pct(c.exact_ends_within_2pct, 0)} |"
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


def worst_rows(rows: Sequence[TripRow], count: int) -> list[TripRow]:
    """The ``count`` worst rows: failed matches first, then the largest ``|length error|``."""
    return sorted(rows, key=lambda r: (r.score is None, abs(length_error(r))), reverse=True)[:count]


def length_error(row: TripRow) -> float:
    """The row's relative length error; infinite when its match failed."""
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
            f"| {r.canyons} | {signed(s.length_error)} | {pct(s.mismatch, 2)} "
            f"| {s.uturns}/{s.true_uturns} | {s.loops}/{s.true_loops} | {verdict} | |"
        )
    return "\n".join(lines)
