"""What a batch did: its rows, where it ran, what it left out, and honest figures."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from collections.abc import Sequence
    from pathlib import Path

    from mapmatch.batch.outputs import SummaryRow

__all__ = ["BatchProgress", "BatchReport"]


@dataclass(frozen=True, slots=True)
class BatchReport:
    """
    The outcome of a batch.

    Attributes
    ----------
    rows
        Every summary row in input order (resumed ones included).
    resumed
        Traces skipped because an earlier run completed them.
    seconds
        Wall time of the batch.
    executor
        Where the tasks ran (``"2 processes"`` ...).
    out_dir
        The output folder.
    worker_max_rss_kib
        Peak resident memory of each worker process that ran a task, by ``"host:pid"``.
    worker_busy_s
        Seconds each worker process spent in tasks, by ``"host:pid"``.
    worker_cpu_s
        CPU seconds each worker process used in tasks (below ``worker_busy_s`` when the
        machine's cores are shared with other work).
    match_s
        Seconds spent inside ``match()``, over every trace matched in this run (each
        worker's own time, summed): the time :attr:`points_per_s` divides by.
    warmup_s
        Seconds each worker spent on its first, tiny match (loading the compiled kernels),
        summed; not in :attr:`match_s`.
    points_now
        Fixes of the traces matched in this run (resumed ones left out).
    skipped_inputs
        Files of the input folders left out because they lie in an output folder.
    retried
        Traces run again in a fresh pool after their worker process died.
    notes
        Sentences about how the batch ran that the summary repeats (a capped ``--workers``).
    """

    rows: tuple[SummaryRow, ...]
    resumed: int
    seconds: float
    executor: str
    out_dir: Path
    worker_max_rss_kib: dict[str, int]
    worker_busy_s: dict[str, float]
    worker_cpu_s: dict[str, float]
    match_s: float = 0.0
    warmup_s: float = 0.0
    points_now: int = 0
    skipped_inputs: tuple[str, ...] = ()
    retried: int = 0
    notes: tuple[str, ...] = ()

    @property
    def nothing_to_do(self) -> bool:
        """Every trace was complete from an earlier run (``--resume``) and no file failed."""
        return self.points_now == 0 and self.resumed > 0 and self.resumed == len(self.rows)

    @property
    def points_per_s(self) -> float:
        """Fixes matched in this run per second of matching (NaN when nothing was matched)."""
        if self.points_now == 0 or self.match_s <= 0:
            return float("nan")
        return self.points_now / self.match_s

    @property
    def traces_ok(self) -> int:
        """Traces matched and written."""
        return sum(1 for r in self.rows if r.ok)

    @property
    def traces_failed(self) -> int:
        """Traces (and unreadable files) that failed."""
        return sum(1 for r in self.rows if not r.ok)

    @property
    def points(self) -> int:
        """Fixes in the traces matched."""
        return sum(r.points for r in self.rows if r.ok)

    @property
    def matched_length_m(self) -> float:
        """Matched road length of all traces, metres."""
        return float(sum(r.matched_length_m for r in self.rows if r.ok))

    def _ok_sum(self, name: str) -> int:
        return sum(int(getattr(r, name)) for r in self.rows if r.ok)

    @property
    def reordered_rows(self) -> int:
        """Rows sorted into time order, over the matched traces."""
        return self._ok_sum("reordered_rows")

    @property
    def merged_rows(self) -> int:
        """True duplicates merged, over the matched traces."""
        return self._ok_sum("merged_rows")

    @property
    def dropped_rows(self) -> int:
        """Source records the readers could not use, over the matched traces."""
        return self._ok_sum("dropped_rows")

    @property
    def shared_time_rows(self) -> int:
        """Points kept that share the previous point's time, over the matched traces."""
        return self._ok_sum("shared_time_rows")

    @property
    def input_rows(self) -> int:
        """Rows read, over the matched traces."""
        return self._ok_sum("input_rows")

    @property
    def time_sources(self) -> dict[str, int]:
        """Matched traces by what their times were (``ok``, ``absent``, ``implausible``)."""
        return dict(Counter(r.time for r in self.rows if r.ok).most_common())

    @property
    def traces_with_warnings(self) -> int:
        """Matched traces whose validation said something (``warnings`` column)."""
        return sum(1 for r in self.rows if r.ok and r.warnings)

    @property
    def verdicts(self) -> dict[str, int]:
        """Distance-check verdicts of the matched traces, by count."""
        return dict(Counter(r.verdict for r in self.rows if r.ok).most_common())

    @property
    def exit_code(self) -> int:
        """0 when every trace matched, 1 when any trace or file failed."""
        return 0 if self.traces_failed == 0 else 1


class BatchProgress(Protocol):
    """Told how far the batch is (the command line draws a progress bar)."""

    def start(self, *, total_traces: int, total_points: int, resumed: int) -> None:
        """The batch knows its size; ``resumed`` traces are done already."""

    def update(self, rows: Sequence[SummaryRow]) -> None:
        """These traces just finished."""
