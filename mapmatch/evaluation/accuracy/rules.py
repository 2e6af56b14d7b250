"""Issue 11's acceptance rules, checked on every per-extract cell of the matrix."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from mapmatch.evaluation.accuracy.conditions import condition_config
from mapmatch.evaluation.accuracy.tables import pct

if TYPE_CHECKING:
    from collections.abc import Sequence

    from mapmatch.evaluation.accuracy.summary import Cell

__all__ = ["acceptance"]


def acceptance(per_extract: Sequence[Cell]) -> list[str]:
    """
    Issue 11's acceptance figures checked on every per-extract cell; one line per rule.

    At 1 s and 15 s (clean and realistic): length within 1 % on >= 95 % of trips, route
    mismatch mean <= 1 % (1 s) / <= 2 % (15 s), spurious U-turn or loop on <= 2 % of trips;
    at 30 s: within 2 % on >= 90 %; realistic with the odometer: verdict right on >= 95 %.
    A failing length cell also shows what the exact route cut at the noisy end fixes
    reaches (``ends``, :attr:`Cell.ends_within_1pct`), and the rule counts the cells where
    even that is short of the target: no matcher passes those from the ends alone.
    """
    rules: list[tuple[str, list[str]]] = []

    def check(
        name: str,
        selected: list[Cell],
        passes: Any,
        shown: str,
        digits: int,
        target: float | None = None,
    ) -> None:
        failing = []
        for c in selected:
            if passes(c):
                continue
            entry = f"{c.extract}/{c.condition}/{c.input_class} {pct(getattr(c, shown), digits)}"
            if target is not None:
                entry += f" (ends {pct(getattr(c, 'ends_' + shown), 0)})"
            failing.append(entry)
        head = f"{name}: {len(selected) - len(failing)}/{len(selected)} cells"
        if target is not None:
            short = sum(getattr(c, "ends_" + shown) < target for c in selected)
            head += f" (the exact route at the noisy ends misses it in {short})"
        rules.append((head, failing))

    def interval(c: Cell) -> float:
        return condition_config(c.condition).interval_s

    dense = [c for c in per_extract if interval(c) in (1.0, 15.0)]
    check("within 1 % on >= 95 %", dense, lambda c: c.within_1pct >= 0.95, "within_1pct", 0, 0.95)
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
    check(
        "30 s: within 2 % on >= 90 %",
        sparse,
        lambda c: c.within_2pct >= 0.90,
        "within_2pct",
        0,
        0.90,
    )
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
