"""
A cell's figures: the rows of one extract (or all), condition and column spec, summed up.

Route mismatch, length error, shares within 1 % / 2 %, spurious U-turns and loops, verdict
accuracy and points/s, from :func:`mapmatch.evaluation.scoring.summarise`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from mapmatch.evaluation.scoring import summarise

if TYPE_CHECKING:
    from collections.abc import Sequence

    from mapmatch.evaluation.accuracy.tasks import TripRow

__all__ = ["Cell", "cells"]


@dataclass(frozen=True, slots=True)
class Cell:
    """
    The figures of one cell (``extract`` is ``all`` when pooled over extracts).

    Shares are over every trip of the cell: a trip whose match failed counts as outside
    the length bands. ``verdict_trips`` / ``verdict_accuracy``: trips with an odometer and no
    break, and the share of them whose verdict is the one the true length gives (NaN when
    none). ``points_per_s``: fixes matched per second of matching in the run's processes.
    ``ends_within_1pct`` / ``_2pct``: the share of trips whose exact route, cut at the noisy
    first and last fix, is within 1 % / 2 % (:attr:`TripRow.ends_error`): the most a matcher
    can reach where the neighbouring fixes say nothing of the ends (sparse sampling).
    ``exact_ends_within_1pct`` / ``_2pct``: the share of trips whose match would be within
    1 % / 2 % with its path's ends at the true ones
    (:attr:`~mapmatch.evaluation.scoring.TripScore.length_error_exact_ends`): what the route
    between the ends gets right. The two columns bracket a cell: the first is the noise at the
    ends, the second everything else.
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
    ends_within_1pct: float
    ends_within_2pct: float
    exact_ends_within_1pct: float
    exact_ends_within_2pct: float

    def to_dict(self) -> dict[str, object]:
        """JSON-ready (NaN becomes ``None``)."""
        return {
            k: (None if isinstance(v, float) and math.isnan(v) else v)
            for k, v in dataclasses.asdict(self).items()
        }


def _ends_within(rows: list[TripRow], band: float) -> float:
    errors = [abs(r.ends_error) for r in rows if not math.isnan(r.ends_error)]
    return sum(e <= band for e in errors) / len(errors) if errors else float("nan")


def _cell(extract: str, condition: str, spec: str, rows: list[TripRow]) -> Cell:
    ends = {
        "ends_within_1pct": _ends_within(rows, 0.01),
        "ends_within_2pct": _ends_within(rows, 0.02),
    }
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
            exact_ends_within_1pct=0.0,
            exact_ends_within_2pct=0.0,
            **ends,
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
        exact_ends_within_1pct=s["exact_ends_within_1pct"] * ok,
        exact_ends_within_2pct=s["exact_ends_within_2pct"] * ok,
        **ends,
    )


def cells(rows: Sequence[TripRow], *, per_extract: bool) -> list[Cell]:
    """Group rows into cells: per extract, or pooled over extracts (``extract`` = ``all``)."""
    groups: dict[tuple[str, str, str], list[TripRow]] = {}
    for row in rows:
        key = (row.extract if per_extract else "all", row.condition, row.input_class)
        groups.setdefault(key, []).append(row)
    return [_cell(*key, group) for key, group in groups.items()]
