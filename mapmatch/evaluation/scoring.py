"""
Accuracy of matches against ground truth: route mismatch, length, U-turns, loops, verdict.

Newson & Krumm's route mismatch, the matched length and what spoils it (U-turns and loops the
vehicle never drove), and the distance verdict. Route mismatch does not see a piece of road
driven forward twice (it is "covered" either way), so a match can have a small mismatch and a
length several per cent too long; the length error and the spurious U-turn and loop counts are
first-class figures here.
"""

from __future__ import annotations

import itertools
import math
from collections import Counter, defaultdict
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from mapmatch.types import FloatArray

__all__ = [
    "TripScore",
    "Turnbacks",
    "count_turnbacks",
    "end_shortfalls",
    "score_geojson",
    "summarise",
]

_Key = tuple[int, int, int]


@dataclass(frozen=True, slots=True)
class Turnbacks:
    """U-turns and loops of a path of directed edges (see :func:`count_turnbacks`)."""

    uturns: int
    loops: int


def _twins(a: Mapping[str, Any], b: Mapping[str, Any]) -> bool:
    """Two reversed edges are one road's two directions: same way and same length."""
    ways_a, ways_b = a.get("osm_way_ids"), b.get("osm_way_ids")
    if ways_a and ways_b and not set(ways_a) & set(ways_b):
        return False
    len_a, len_b = a.get("length_m"), b.get("length_m")
    if len_a is None or len_b is None:
        return True
    return abs(float(len_a) - float(len_b)) <= 0.01 + 1e-4 * float(len_a)


def count_turnbacks(edges: Sequence[Mapping[str, Any]]) -> Turnbacks:
    """
    Count the U-turns and loops of one connected path of directed edges.

    ``edges`` are in driving order, as a segment's ``edges`` in the match GeoJSON or the
    ``edges`` of a truth record (``u``, ``v``, ``key``, ``start_offset_m``,
    ``end_offset_m``, optionally ``osm_way_ids``). Stretches of zero length are skipped (a
    path that starts exactly at the end of an edge). A **U-turn** is an edge followed by its
    reverse twin, ``(u, v)`` then ``(v, u)`` on the same OSM way and of the same length
    (a two-edge ring of one way, ``(u, v)`` then ``(v, u)`` round a small roundabout, is not
    one): turning back at a node, or in the middle of the road (the matcher's mid-road
    U-turn is the stretch up to the turn on one edge and the stretch back on its twin); a
    stretch driven backwards (end offset below start offset) counts as one too. A **loop**
    is a directed edge ``(u, v, key)`` driven again: each repeat counts once (round a ring
    three times: two loops).

    Examples
    --------
    >>> def e(u, v, lo=0.0, hi=100.0):
    ...     return {"u": u, "v": v, "key": 0, "osm_way_ids": [7], "length_m": 100.0,
    ...             "start_offset_m": lo, "end_offset_m": hi}
    >>> count_turnbacks([e(1, 2, 0, 60), e(2, 1, 40, 100), e(1, 3)])  # back mid-road
    Turnbacks(uturns=1, loops=0)
    >>> count_turnbacks([e(1, 2), e(2, 3), e(3, 1), e(1, 2)])  # round a ring again
    Turnbacks(uturns=0, loops=1)
    """
    path = [e for e in edges if float(e["end_offset_m"]) != float(e["start_offset_m"])]
    uturns = sum(1 for e in path if float(e["end_offset_m"]) < float(e["start_offset_m"]))
    for a, b in itertools.pairwise(path):
        au, av, bu, bv = int(a["u"]), int(a["v"]), int(b["u"]), int(b["v"])
        if au == bv and av == bu and au != av and _twins(a, b):
            uturns += 1
    driven = Counter((int(e["u"]), int(e["v"]), int(e["key"])) for e in path)
    return Turnbacks(uturns=uturns, loops=sum(n - 1 for n in driven.values()))


@dataclass(frozen=True, slots=True)
class TripScore:
    """
    How well one trace was matched.

    ``mismatch`` is Newson & Krumm's route mismatch fraction: (length wrongly added + length
    wrongly missed) / true length, with lengths compared edge by edge (directed) along the
    driven offsets. ``point_accuracy`` is the share of fixes matched to their true directed
    edge. ``length_error`` is (matched - true) / true.

    ``uturns`` / ``loops`` count the match's U-turns and repeated directed edges
    (:func:`count_turnbacks`, per segment), ``true_uturns`` / ``true_loops`` the truth's
    own; ``spurious_uturns`` / ``spurious_loops`` what the match has beyond them.
    ``verdict`` is the match's distance verdict (``distance_source`` the fused distance's
    source, ``fused_length_m`` its value) and ``true_verdict`` the verdict that same fused
    distance gets against the true length in the same band: a correct verdict is one that
    equals it (empty strings when the result has no distance check).

    ``start_shortfall_m`` / ``end_shortfall_m``: how far the matched path falls short of the
    true one at its start / its end (negative where it runs on beyond it), from
    :func:`end_shortfalls`; ``length_error_exact_ends`` the length error left with both ends
    where the truth has them, i.e. what the route between the ends gets wrong.
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
    uturns: int = 0
    loops: int = 0
    true_uturns: int = 0
    true_loops: int = 0
    spurious_uturns: int = 0
    spurious_loops: int = 0
    verdict: str = ""
    true_verdict: str = ""
    distance_source: str = ""
    fused_length_m: float = math.nan
    start_shortfall_m: float = math.nan
    end_shortfall_m: float = math.nan

    @property
    def length_error_exact_ends(self) -> float:
        """The length error with the path's ends moved to the true ones."""
        if self.true_length_m <= 0:
            return math.nan
        ends = self.start_shortfall_m + self.end_shortfall_m
        return (self.matched_length_m + ends - self.true_length_m) / self.true_length_m

    @property
    def spurious(self) -> bool:
        """The match holds a U-turn or a loop the vehicle did not drive."""
        return self.spurious_uturns > 0 or self.spurious_loops > 0

    @property
    def verdict_ok(self) -> bool:
        """The distance verdict is the one the true length would give."""
        return bool(self.verdict) and self.verdict == self.true_verdict

    def to_dict(self) -> dict[str, Any]:
        """Plain dictionary."""
        return asdict(self)


def _uncovered_lead(
    path: Sequence[Mapping[str, Any]], other: Mapping[_Key, list[tuple[float, float]]]
) -> float:
    """Metres from the start of ``path`` to its first point that ``other`` covers too."""
    lead = 0.0
    for e in path:
        lo, hi = float(e["start_offset_m"]), float(e["end_offset_m"])
        spans = other.get((int(e["u"]), int(e["v"]), int(e["key"])), [])
        starts = [max(a, lo) for a, b in spans if min(b, hi) > max(a, lo)]
        if starts:
            return lead + min(starts) - lo
        lead += max(hi - lo, 0.0)
    return lead


def _reversed_path(path: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """The path backwards, each stretch's offsets measured from its end (for the end's lead)."""
    return [
        {"u": e["u"], "v": e["v"], "key": e["key"],
         "start_offset_m": -float(e["end_offset_m"]), "end_offset_m": -float(e["start_offset_m"])}
        for e in reversed(path)
    ]  # fmt: skip


def end_shortfalls(
    truth_edges: Sequence[Mapping[str, Any]], matched_edges: Sequence[Mapping[str, Any]]
) -> tuple[float, float]:
    """
    How far the matched path falls short of the true one at its start and at its end.

    At the start: the true path's metres before the first point the match covers too, less
    the match's metres before the first point the truth covers (a match that starts early is
    negative); at the end the same from the last points back. Stretches are compared edge by
    edge (directed) along their offsets, as the route mismatch is. A match that shares no
    point with the truth has the whole true length short at each end.

    Examples
    --------
    >>> def e(u, lo, hi): return {"u": u, "v": u + 1, "key": 0, "start_offset_m": lo,
    ...                           "end_offset_m": hi}
    >>> end_shortfalls([e(1, 0, 100), e(2, 0, 50)], [e(1, 20, 100), e(2, 0, 60), e(3, 0, 5)])
    (20.0, -15.0)
    """
    truth, matched = _intervals(truth_edges), _intervals(matched_edges)
    start = _uncovered_lead(truth_edges, matched) - _uncovered_lead(matched_edges, truth)
    back_truth, back_matched = _reversed_path(truth_edges), _reversed_path(matched_edges)
    end = _uncovered_lead(back_truth, _intervals(back_matched)) - _uncovered_lead(
        back_matched, _intervals(back_truth)
    )
    return start, end


def _band_verdict(relative: float, band: Sequence[float]) -> str:
    """``over`` / ``under`` / ``pass`` of a relative error against a band (low, high)."""
    if math.isnan(relative):
        return "incomplete"
    return "over" if relative > band[1] else "under" if relative < band[0] else "pass"


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
    segments = [
        f["properties"]["edges"] for f in features if f["properties"].get("kind") == "segment"
    ]
    matched_edges = [e for edges in segments for e in edges]
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
    start_short, end_short = end_shortfalls(truth["edges"], matched_edges)
    turns = [count_turnbacks(edges) for edges in segments]
    uturns, loops = sum(t.uturns for t in turns), sum(t.loops for t in turns)
    true_turns = count_turnbacks(truth["edges"])
    check = result.get("distance_check") or {}
    verdict, true_verdict, source, fused = "", "", "", math.nan
    if check:
        verdict, source = str(check["verdict"]), str(check["source"])
        fused = float(check["fused_length_m"])
        relative = (fused - reference) / reference if reference > 0 else math.nan
        true_verdict = _band_verdict(relative, check["band"])
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
        uturns=uturns,
        loops=loops,
        true_uturns=true_turns.uturns,
        true_loops=true_turns.loops,
        spurious_uturns=max(uturns - true_turns.uturns, 0),
        spurious_loops=max(loops - true_turns.loops, 0),
        verdict=verdict,
        true_verdict=true_verdict,
        distance_source=source,
        fused_length_m=fused,
        start_shortfall_m=round(start_short, 6),
        end_shortfall_m=round(end_short, 6),
    )


def _share_within(errors: FloatArray, band: float) -> float:
    """The share of the known (not NaN) errors within ``band``; NaN when none is known."""
    known = errors[~np.isnan(errors)]
    return float(np.mean(known <= band)) if len(known) else float("nan")


def summarise(scores: Sequence[TripScore]) -> dict[str, float]:
    """
    Figures over many trips (NaN where no trip qualifies).

    ``mismatch_mean`` / ``_median`` / ``_p95`` route mismatch; ``point_accuracy`` mean share
    of fixes on their true edge; ``length_error_mean`` signed mean, ``length_error_abs_max``
    / ``_abs_p95`` of ``|length error|``; ``within_1pct`` / ``within_2pct`` share of trips
    whose matched length is within 1 % / 2 % of the true one, ``exact_ends_within_1pct`` /
    ``_2pct`` the same with each path's ends at the true ones; ``spurious_share`` share of
    trips with a U-turn or loop the truth does not have, ``spurious_uturns`` /
    ``spurious_loops`` their totals; ``verdict_trips`` trips whose fused distance is an
    odometer reading and that have no break, ``verdict_accuracy`` the share of those whose
    verdict is the one the true length gives.
    """
    mismatch = np.array([s.mismatch for s in scores])
    error = np.abs([s.length_error for s in scores])
    exact_ends = np.abs(np.array([s.length_error_exact_ends for s in scores], dtype=np.float64))
    judged = [s for s in scores if s.distance_source == "odometer" and s.breaks == 0]
    return {
        "traces": float(len(scores)),
        "points": float(sum(s.points for s in scores)),
        "mismatch_mean": float(np.nanmean(mismatch)),
        "mismatch_median": float(np.nanmedian(mismatch)),
        "mismatch_p95": float(np.nanpercentile(mismatch, 95)),
        "point_accuracy": float(np.nanmean([s.point_accuracy for s in scores])),
        "length_error_mean": float(np.nanmean([s.length_error for s in scores])),
        "length_error_abs_max": float(np.nanmax(error)),
        "length_error_abs_p95": float(np.nanpercentile(error, 95)),
        "within_1pct": float(np.mean(error <= 0.01)),
        "within_2pct": float(np.mean(error <= 0.02)),
        "exact_ends_within_1pct": _share_within(exact_ends, 0.01),
        "exact_ends_within_2pct": _share_within(exact_ends, 0.02),
        "spurious_share": float(np.mean([s.spurious for s in scores])),
        "spurious_uturns": float(sum(s.spurious_uturns for s in scores)),
        "spurious_loops": float(sum(s.spurious_loops for s in scores)),
        "verdict_trips": float(len(judged)),
        "verdict_accuracy": (
            float(np.mean([s.verdict_ok for s in judged])) if judged else float("nan")
        ),
    }
