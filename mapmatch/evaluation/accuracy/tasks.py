"""
The accuracy matrix's units of work and of result: a cell's task, one trip's row.

A :class:`CellTask` is the trips of one extract and condition, matched in every column spec;
it is what a worker process runs. A :class:`TripRow` is one trip matched with one spec.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from mapmatch.evaluation.accuracy.conditions import SEED
from mapmatch.evaluation.accuracy.extracts import extract_name

if TYPE_CHECKING:
    from mapmatch.evaluation.scoring import TripScore

__all__ = ["CellTask", "TripRow"]


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
    seed: int = SEED
    first: int = 0
    config: tuple[tuple[str, object], ...] = ()
    sim: tuple[tuple[str, object], ...] = ()

    @property
    def name(self) -> str:
        """The extract's name (file name without the OSM suffixes)."""
        return extract_name(Path(self.extract))


@dataclass(frozen=True, slots=True)
class TripRow:
    """
    One trip matched with one column spec: its score, or the error that stopped the match.

    ``ends_error`` is the trip's :meth:`~mapmatch.evaluation.simulate.SimulatedTrip.ends_error`:
    what the exact route cut at the noisy end fixes gets wrong, whatever the matcher.

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
    ends_error: float = float("nan")

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
            "ends_error": self.ends_error,
            "error": self.error,
        }
        if self.score is not None:
            score = self.score.to_dict()
            score.pop("trace_id")
            score.pop("points")
            out.update(score)
        return out
