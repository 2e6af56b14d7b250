"""Accuracy of matches against ground truth (Newson & Krumm's route mismatch and more)."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

__all__ = ["TripScore", "score_geojson", "summarise"]

_Key = tuple[int, int, int]


@dataclass(frozen=True, slots=True)
class TripScore:
    """
    How well one trace was matched.

    ``mismatch`` is Newson & Krumm's route mismatch fraction: (length wrongly added + length
    wrongly missed) / true length, with lengths compared edge by edge (directed) along the
    driven offsets. ``point_accuracy`` is the share of fixes matched to their true directed
    edge. ``length_error`` is (matched - true) / true.
    """

    trace_id: str
    points: int
    true_length_m: float
    matched_length_m: float
    added_m: float
    missed_m: float
    mismatch: float
    point_accuracy: float
    length_error: float
    breaks: int

    def to_dict(self) -> dict[str, Any]:
        """Plain dictionary."""
        return asdict(self)


def _intervals(edges: Sequence[Mapping[str, Any]]) -> dict[_Key, list[tuple[float, float]]]:
    out: dict[_Key, list[tuple[float, float]]] = defaultdict(list)
    for e in edges:
        key = (int(e["u"]), int(e["v"]), int(e["key"]))
        lo, hi = float(e["start_offset_m"]), float(e["end_offset_m"])
        if hi > lo:
            out[key].append((lo, hi))
    return out


def _union_length(spans: list[tuple[float, float]]) -> float:
    total, end = 0.0, -np.inf
    for lo, hi in sorted(spans):
        if hi <= end:
            continue
        total += hi - max(lo, end)
        end = hi
    return total


def _overlap(a: list[tuple[float, float]], b: list[tuple[float, float]]) -> float:
    spans = [
        (max(x0, y0), min(x1, y1)) for x0, x1 in a for y0, y1 in b if min(x1, y1) > max(x0, y0)
    ]
    return _union_length(spans)


def score_geojson(result: Mapping[str, Any], truth: Mapping[str, Any]) -> TripScore:
    """
    Score a match against the truth record of its trace.

    ``result`` is the match's GeoJSON, as :meth:`MatchResult.to_geojson` or ``mapmatch
    match`` write it; ``truth`` a line of ``truth.jsonl``.

    Examples
    --------
    >>> edge = {"u": 1, "v": 2, "key": 0, "start_offset_m": 0.0, "end_offset_m": 100.0}
    >>> wrong = {"u": 5, "v": 6, "key": 0, "start_offset_m": 0.0, "end_offset_m": 10.0}
    >>> seg = {"properties": {"kind": "segment", "edges": [edge, wrong]}}
    >>> score = score_geojson({"trace_id": "t", "features": [seg], "breaks": []},
    ...                       {"length_m": 100.0, "edges": [edge], "point_edges": []})
    >>> score.added_m, score.missed_m, score.mismatch
    (10.0, 0.0, 0.1)
    """
    features = result.get("features", [])
    matched_edges = [
        e
        for f in features
        if f["properties"].get("kind") == "segment"
        for e in f["properties"]["edges"]
    ]
    truth_spans = _intervals(truth["edges"])
    matched_spans = _intervals(matched_edges)
    true_len = sum(_union_length(v) for v in truth_spans.values())
    matched_len = float(sum(e["end_offset_m"] - e["start_offset_m"] for e in matched_edges))
    matched_union = sum(_union_length(v) for v in matched_spans.values())
    common = sum(
        _overlap(truth_spans[k], matched_spans[k])
        for k in truth_spans.keys() & matched_spans.keys()
    )
    added, missed = matched_union - common, true_len - common
    point_edges = truth.get("point_edges", [])
    points = [f["properties"] for f in features if f["properties"].get("kind") == "point"]
    right = sum(
        1
        for p, t in zip(points, point_edges, strict=False)
        if p.get("matched") and (p["u"], p["v"], p["key"]) == tuple(t)
    )
    n_points = len(point_edges) or len(points)
    reference = float(truth.get("length_m", true_len)) or true_len
    return TripScore(
        trace_id=str(result.get("trace_id", truth.get("trace_id", ""))),
        points=n_points,
        true_length_m=reference,
        matched_length_m=matched_len,
        added_m=round(added, 6),
        missed_m=round(missed, 6),
        mismatch=(added + missed) / true_len if true_len > 0 else float("nan"),
        point_accuracy=right / n_points if n_points else float("nan"),
        length_error=(matched_len - reference) / reference if reference > 0 else float("nan"),
        breaks=len(result.get("breaks", [])),
    )


def summarise(scores: Sequence[TripScore]) -> dict[str, float]:
    """Mean and median route mismatch, mean point accuracy, mean and max |length error|."""
    mismatch = np.array([s.mismatch for s in scores])
    return {
        "traces": float(len(scores)),
        "points": float(sum(s.points for s in scores)),
        "mismatch_mean": float(np.nanmean(mismatch)),
        "mismatch_median": float(np.nanmedian(mismatch)),
        "point_accuracy": float(np.nanmean([s.point_accuracy for s in scores])),
        "length_error_mean": float(np.nanmean([s.length_error for s in scores])),
        "length_error_abs_max": float(np.nanmax(np.abs([s.length_error for s in scores]))),
    }
