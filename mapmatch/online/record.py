"""
What a live trip has settled: its path, segment by segment, and every settled fix's place.

Settled output never changes, so it is kept as it came: per segment the path's stretches (edge,
start and end offset) in driving order, and the settled fixes' outcome in chunks of
:class:`~mapmatch.result.MatchedPoints`, compacted as they pile up. :meth:`Record.segments`
and :meth:`Record.points` give them in the shape of a :class:`~mapmatch.result.MatchResult`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Final

import numpy as np

from mapmatch.hmm.assemble import path_uturns
from mapmatch.result import MatchedPoints, Segment

if TYPE_CHECKING:
    from mapmatch.types import FloatArray, IntArray
    from roadnets import RoadNetwork
    from roadnets.arrays import Int32Array

__all__ = ["Record", "concat_points", "empty_points"]

_EPS_M: Final = 1e-6
_POINT_FIELDS: Final = tuple(f.name for f in dataclasses.fields(MatchedPoints))
_COMPACT_CHUNKS: Final = 16


def concat_points(chunks: list[MatchedPoints]) -> MatchedPoints:
    """Several runs of fixes' outcomes as one."""
    if len(chunks) == 1:
        return chunks[0]
    if not chunks:
        return empty_points()
    return MatchedPoints(
        **{name: np.concatenate([getattr(c, name) for c in chunks]) for name in _POINT_FIELDS}
    )


def empty_points() -> MatchedPoints:
    """The outcome of no fixes."""
    f, i, b = np.empty(0), np.empty(0, np.int64), np.empty(0, bool)
    return MatchedPoints(f, f, f, b, i, i, i, i, f, f, f, f, f, i, b, b)


@dataclass(slots=True)
class _Path:
    """One segment's settled path and fixes."""

    first: int
    last: int
    edge: list[int] = field(default_factory=list)
    start_m: list[float] = field(default_factory=list)
    end_m: list[float] = field(default_factory=list)


class Record:
    """The settled part of a live trip (see the module docstring)."""

    def __init__(self, edge_twin: Int32Array) -> None:
        self._twin = edge_twin
        self._paths: list[_Path] = []
        self._chunks: list[MatchedPoints] = []
        self._readings: list[FloatArray] = []  # the settled fixes' odometer (NaN: none)
        self._radii: list[FloatArray] = []  # the settled fixes' search radius
        self.fixes = 0
        self.length_m = 0.0
        self.uturns = 0  # an edge followed by its reverse twin, within a segment
        self.first_matched = False

    @property
    def segment_count(self) -> int:
        """Segments settled so far (the last may still grow)."""
        return len(self._paths)

    def add_points(
        self, points: MatchedPoints, odometer_m: FloatArray | None, radius_m: FloatArray
    ) -> None:
        """Append the outcome of the next settled fixes, their odometer readings and radii."""
        n = len(points.time_s)
        if not n:
            return
        if not self.fixes:
            self.first_matched = bool(points.matched[0])
        self._chunks.append(points)
        self._readings.append(np.full(n, np.nan) if odometer_m is None else odometer_m.copy())
        self._radii.append(np.array(radius_m, dtype=np.float64))
        self.fixes += n
        if len(self._chunks) > _COMPACT_CHUNKS:
            self._chunks = [concat_points(self._chunks)]
            self._readings = [np.concatenate(self._readings)]
            self._radii = [np.concatenate(self._radii)]

    def add_path(
        self,
        segment: int,
        first: int,
        last: int,
        edge: IntArray,
        start_m: FloatArray,
        end_m: FloatArray,
    ) -> tuple[int, int]:
        """
        Append stretches to segment ``segment`` (a new one when it is the next index).

        ``first``/``last`` are the trip numbers of the segment's first fix and of the last
        fix settled in it. A first stretch that carries on the segment's last one (same edge,
        starting where it ended) extends it. Returns the range of the segment's stretches
        that the call added or extended.
        """
        if segment == len(self._paths):
            self._paths.append(_Path(first, last))
        path = self._paths[segment]
        path.last = max(path.last, last)
        edges, lo, hi = edge.tolist(), start_m.tolist(), end_m.tolist()
        joined = np.array(path.edge[-1:] + edges, dtype=np.int64)
        self.uturns += int(path_uturns(self._twin, joined, 0, len(joined)))
        begin = len(path.edge)
        if (
            edges
            and path.edge
            and path.edge[-1] == edges[0]
            and abs(path.end_m[-1] - lo[0]) <= _EPS_M
        ):
            self.length_m += hi[0] - path.end_m[-1]
            path.end_m[-1] = hi[0]
            edges, lo, hi = edges[1:], lo[1:], hi[1:]
            begin -= 1
        path.edge.extend(edges)
        path.start_m.extend(lo)
        path.end_m.extend(hi)
        self.length_m += sum(b - a for a, b in zip(lo, hi, strict=True))
        return begin, len(path.edge)

    def stretches(self, segment: int, lo: int, hi: int) -> tuple[IntArray, FloatArray, FloatArray]:
        """Stretches ``lo..hi-1`` of a segment's path."""
        path = self._paths[segment]
        return (
            np.array(path.edge[lo:hi], dtype=np.int64),
            np.array(path.start_m[lo:hi], dtype=np.float64),
            np.array(path.end_m[lo:hi], dtype=np.float64),
        )

    def segments(self, net: RoadNetwork) -> list[Segment]:
        """The settled segments, as a match gives them."""
        return [
            Segment(
                i,
                p.first,
                p.last,
                np.array(p.edge, dtype=np.int64),
                np.array(p.start_m, dtype=np.float64),
                np.array(p.end_m, dtype=np.float64),
                net=net,
            )
            for i, p in enumerate(self._paths)
        ]

    def points(self) -> MatchedPoints:
        """Every settled fix's outcome, in trip order."""
        self._chunks = [concat_points(self._chunks)] if self._chunks else []
        return self._chunks[0] if self._chunks else empty_points()

    def odometer_m(self) -> FloatArray | None:
        """Every settled fix's odometer reading (NaN where it had none); ``None``: no reading."""
        self._readings = [np.concatenate(self._readings)] if self._readings else []
        readings = self._readings[0] if self._readings else np.empty(0)
        return readings if np.isfinite(readings).any() else None

    def radius_m(self) -> FloatArray:
        """Every settled fix's search radius."""
        self._radii = [np.concatenate(self._radii)] if self._radii else []
        return self._radii[0] if self._radii else np.empty(0)

    @property
    def nbytes(self) -> int:
        """Bytes held (approximately: the arrays, and 24 bytes per stretch)."""
        arrays = sum(int(getattr(c, n).nbytes) for c in self._chunks for n in _POINT_FIELDS)
        arrays += sum(int(r.nbytes) for r in self._readings)
        arrays += sum(int(r.nbytes) for r in self._radii)
        return arrays + sum(72 * len(p.edge) + 200 for p in self._paths) + 150 * len(self._chunks)
