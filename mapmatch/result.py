"""What a match returns: segments of driven edges, snapped points, length and its check."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    import pandas as pd

    from mapmatch.distance import DistanceCheck

__all__ = ["Diagnostics", "MatchResult", "MatchStats", "MatchedEdge", "MatchedPoints", "Segment"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True, slots=True)
class MatchedEdge:
    """
    One directed edge of a matched path, and the part of it that was driven.

    ``u``/``v`` are OSM node ids and ``key`` tells parallel edges apart; ``edge`` is the
    edge's index in the network's arrays. ``start_offset_m``/``end_offset_m`` bound the
    driven stretch, metres from the edge's start.
    """

    edge: int
    u: int
    v: int
    key: int
    osm_way_ids: tuple[int, ...]
    length_m: float
    start_offset_m: float
    end_offset_m: float

    @property
    def driven_m(self) -> float:
        """Metres driven on this edge."""
        return self.end_offset_m - self.start_offset_m

    def to_dict(self) -> dict[str, Any]:
        """The edge as DESIGN.md's output schema has it."""
        return {
            "u": self.u,
            "v": self.v,
            "key": self.key,
            "osm_way_ids": list(self.osm_way_ids),
            "length_m": round(self.length_m, 3),
            "start_offset_m": round(self.start_offset_m, 3),
            "end_offset_m": round(self.end_offset_m, 3),
        }


@dataclass(frozen=True, slots=True)
class Segment:
    """
    A connected matched piece of the trace: fixes ``first..last`` and the path driven.

    ``lon``/``lat`` trace the path's geometry (WGS84) in driving order.
    """

    index: int
    first: int
    last: int
    edges: list[MatchedEdge]
    lon: FloatArray
    lat: FloatArray

    @property
    def length_m(self) -> float:
        """Metres along the path, from the first fix's projection to the last's."""
        return float(sum(e.driven_m for e in self.edges))


@dataclass(frozen=True, slots=True)
class MatchedPoints:
    """
    Per-fix outcome, one array entry per input fix (after sorting).

    Unmatched fixes have ``matched`` False, ``edge``/``u``/``v``/``key`` -1 and NaN
    positions; ``confidence`` is the posterior probability of the chosen candidate.
    ``interpolated`` marks fixes left out of the model (outliers, a stopped car's repeats)
    whose position was interpolated along the path; ``outlier`` those judged outliers.
    """

    time_s: FloatArray
    raw_lon: FloatArray
    raw_lat: FloatArray
    matched: BoolArray
    edge: IntArray
    u: IntArray
    v: IntArray
    key: IntArray
    offset_m: FloatArray
    distance_m: FloatArray
    lon: FloatArray
    lat: FloatArray
    confidence: FloatArray
    segment: IntArray
    interpolated: BoolArray
    outlier: BoolArray


@dataclass(frozen=True, slots=True)
class MatchStats:
    """
    Counts and timings of one match.

    ``input_rows``, ``reordered_rows``, ``merged_rows`` (true duplicates merged),
    ``shared_time_rows`` (points kept that share the previous point's time),
    ``dropped_rows`` (source records the reader could not use) and ``time_source``
    (``"ok"``, ``"absent"``, ``"implausible"``: only ``"ok"`` times entered the model) repeat
    the trace's :class:`~mapmatch.trace.TraceReport`, and ``warnings`` its sentences.
    """

    points: int
    matched_points: int
    candidates: int
    reordered_rows: int
    timings_s: dict[str, float]
    warnings: tuple[str, ...]
    model_points: int
    outliers: int
    break_repairs: int
    input_rows: int = 0
    merged_rows: int = 0
    shared_time_rows: int = 0
    dropped_rows: int = 0
    time_source: str = "ok"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return {
            "points": self.points,
            "matched_points": self.matched_points,
            "candidates": self.candidates,
            "input_rows": self.input_rows,
            "reordered_rows": self.reordered_rows,
            "merged_rows": self.merged_rows,
            "shared_time_rows": self.shared_time_rows,
            "dropped_rows": self.dropped_rows,
            "time_source": self.time_source,
            "model_points": self.model_points,
            "outliers": self.outliers,
            "break_repairs": self.break_repairs,
            "timings_s": {k: round(v, 6) for k, v in self.timings_s.items()},
            "warnings": list(self.warnings),
        }


@dataclass(frozen=True, slots=True)
class Diagnostics:
    """
    The model's inside view, for inspecting a match (``match(..., diagnostics=True)``).

    One entry per candidate of every fix that entered the model: ``fix`` (trace index),
    ``edge`` (network edge index), ``u``/``v``/``key`` (OSM), ``lon``/``lat`` (projection),
    ``distance_m``, ``log_emission``, ``log_transition`` (from the previous model fix's chosen
    candidate; NaN at the first fix of a segment), ``posterior`` and ``chosen``.
    ``model_fixes`` lists the trace indices that entered the model.
    """

    model_fixes: IntArray
    fix: IntArray
    edge: IntArray
    u: IntArray
    v: IntArray
    key: IntArray
    lon: FloatArray
    lat: FloatArray
    distance_m: FloatArray
    log_emission: FloatArray
    log_transition: FloatArray
    posterior: FloatArray
    chosen: BoolArray

    @property
    def candidates(self) -> pd.DataFrame:
        """The candidates as a table, one row each."""
        import pandas as pd

        names = ("fix", "edge", "u", "v", "key", "lon", "lat", "distance_m", "log_emission")
        columns = {name: getattr(self, name) for name in names}
        columns.update(
            log_transition=self.log_transition, posterior=self.posterior, chosen=self.chosen
        )
        return pd.DataFrame(columns)


@dataclass(frozen=True)
class MatchResult:
    """
    The outcome of matching one trace.

    Attributes
    ----------
    trace_id
        The trace's id.
    network
        ``{"id", "source", "crs"}`` of the network matched on.
    segments
        Connected matched pieces in order; a break starts a new one.
    points
        Per-fix outcome.
    breaks
        Fix indices where the trace was split (the first fix of every segment but the first).
    matched_length_m
        Metres along the matched edges, from the first fix's projection to the last's,
        summed over segments.
    distance_check
        The fused trip distance against :attr:`matched_length_m`.
    stats
        Counts and timings.
    diagnostics
        The model's candidates and scores when asked for (``match(..., diagnostics=True)``).
    """

    trace_id: str
    network: dict[str, str]
    segments: list[Segment]
    points: MatchedPoints
    breaks: list[int]
    matched_length_m: float
    distance_check: DistanceCheck
    stats: MatchStats
    diagnostics: Diagnostics | None = None

    def way_ids(self) -> list[int]:
        """OSM way ids driven, in order, consecutive repeats collapsed."""
        ways: list[int] = []
        for segment in self.segments:
            for edge in segment.edges:
                for way in edge.osm_way_ids:
                    if not ways or ways[-1] != way:
                        ways.append(way)
        return ways

    def to_geojson(self) -> dict[str, Any]:
        """
        The result as a GeoJSON FeatureCollection (DESIGN.md's output schema).

        One ``segment`` Feature per segment (LineString of the driven path) and one ``point``
        Feature per fix (snapped Point, or null geometry when unmatched).
        """
        features: list[dict[str, Any]] = []
        for seg in self.segments:
            coords = np.column_stack((seg.lon, seg.lat)).round(7).tolist()
            if len(coords) == 1:
                coords = coords * 2
            features.append(
                {
                    "type": "Feature",
                    "geometry": {"type": "LineString", "coordinates": coords},
                    "properties": {
                        "kind": "segment",
                        "segment": seg.index,
                        "point_range": [seg.first, seg.last],
                        "length_m": round(seg.length_m, 3),
                        "edges": [e.to_dict() for e in seg.edges],
                    },
                }
            )
        p = self.points
        for i in range(len(p.time_s)):
            matched = bool(p.matched[i])
            geometry = (
                {"type": "Point", "coordinates": [round(p.lon[i], 7), round(p.lat[i], 7)]}
                if matched
                else None
            )
            features.append(
                {
                    "type": "Feature",
                    "geometry": geometry,
                    "properties": {
                        "kind": "point",
                        "index": i,
                        "time": None if math.isnan(p.time_s[i]) else float(p.time_s[i]),
                        "matched": matched,
                        "u": int(p.u[i]) if matched else None,
                        "v": int(p.v[i]) if matched else None,
                        "key": int(p.key[i]) if matched else None,
                        "offset_m": _finite(p.offset_m[i]),
                        "distance_m": _finite(p.distance_m[i]),
                        "confidence": round(float(p.confidence[i]), 4),
                        "interpolated": bool(p.interpolated[i]),
                        "outlier": bool(p.outlier[i]),
                    },
                }
            )
        return {
            "type": "FeatureCollection",
            "trace_id": self.trace_id,
            "network": dict(self.network),
            "matched_length_m": round(self.matched_length_m, 3),
            "distance_check": self.distance_check.to_dict(),
            "breaks": list(self.breaks),
            "stats": self.stats.to_dict(),
            "features": features,
        }

    def to_dataframe(self) -> pd.DataFrame:
        """The per-fix table: time, raw and snapped position, edge, offset, confidence."""
        import pandas as pd

        p = self.points
        return pd.DataFrame(
            {
                "trace_id": self.trace_id,
                "index": np.arange(len(p.time_s)),
                "time": p.time_s,
                "raw_lon": p.raw_lon,
                "raw_lat": p.raw_lat,
                "matched": p.matched,
                "segment": p.segment,
                "lon": p.lon,
                "lat": p.lat,
                "u": p.u,
                "v": p.v,
                "key": p.key,
                "offset_m": p.offset_m,
                "distance_m": p.distance_m,
                "confidence": p.confidence,
                "interpolated": p.interpolated,
                "outlier": p.outlier,
            }
        )


def _finite(value: float) -> float | None:
    return None if math.isnan(value) else round(float(value), 3)
