"""Scoring against the simulator's truth: length, U-turns, loops and the distance verdict."""

from __future__ import annotations

import copy
import json
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest

import mapmatch
from mapmatch.cli import main
from mapmatch.evaluation.scoring import TripScore, count_turnbacks, score_geojson, summarise
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trip, write_trips

if TYPE_CHECKING:
    from pathlib import Path

    import roadnets


def _edge(u: int, v: int, lo: float = 0.0, hi: float = 80.0, *, way: int = 7) -> dict[str, Any]:
    return {
        "u": u,
        "v": v,
        "key": 0,
        "osm_way_ids": [way],
        "length_m": 80.0,
        "start_offset_m": lo,
        "end_offset_m": hi,
    }


def _result(*segments: list[dict[str, Any]], check: dict[str, Any] | None = None) -> dict[str, Any]:
    features = [
        {"properties": {"kind": "segment", "segment": i, "edges": edges}}
        for i, edges in enumerate(segments)
    ]
    out: dict[str, Any] = {
        "trace_id": "t",
        "features": features,
        "breaks": list(range(1, len(segments))),
    }
    if check is not None:
        out["distance_check"] = check
    return out


def _truth(edges: list[dict[str, Any]]) -> dict[str, Any]:
    length = sum(e["end_offset_m"] - e["start_offset_m"] for e in edges)
    return {"trace_id": "t", "length_m": length, "edges": edges, "point_edges": []}


# 1 -> 2 -> 3 -> 4 along one street, 80 m blocks
STREET = [_edge(1, 2), _edge(2, 3), _edge(3, 4)]


def test_a_mid_road_uturn_is_counted_and_spurious() -> None:
    # drive 50 m into 2->3, turn, come back 50 m, turn again: two U-turns, +100 m
    spur = [_edge(1, 2), _edge(2, 3, 0, 50), _edge(3, 2, 30, 80), _edge(2, 3), _edge(3, 4)]
    score = score_geojson(_result(spur), _truth(STREET))
    assert (score.uturns, score.loops, score.true_uturns) == (2, 1, 0)
    assert (score.spurious_uturns, score.spurious_loops) == (2, 1)  # 2->3 driven twice
    assert score.spurious
    assert score.length_error == pytest.approx(100.0 / 240.0)
    assert score.mismatch == pytest.approx(50.0 / 240.0)  # the route barely sees it


def test_ends_short_or_beyond_the_truth_are_told_apart_from_the_route() -> None:
    # starts 20 m late, runs 15 m past the true end onto the next block
    early_stop = [_edge(1, 2, 20, 80), _edge(2, 3), _edge(3, 4), _edge(4, 5, 0, 15)]
    score = score_geojson(_result(early_stop), _truth(STREET))
    assert (score.start_shortfall_m, score.end_shortfall_m) == (20.0, -15.0)
    assert score.length_error == pytest.approx(-5.0 / 240.0)
    assert score.length_error_exact_ends == pytest.approx(0.0)
    # a spur in the middle is the route's, not the ends'
    spur = [_edge(1, 2, 10, 80), _edge(2, 3, 0, 50), _edge(3, 2, 30, 80), _edge(2, 3), _edge(3, 4)]
    score = score_geojson(_result(spur), _truth(STREET))
    assert (score.start_shortfall_m, score.end_shortfall_m) == (10.0, 0.0)
    assert score.length_error_exact_ends == pytest.approx(100.0 / 240.0)
    # ends on the wrong road: short by everything up to where the roads meet
    score = score_geojson(_result([_edge(1, 2), _edge(2, 9)]), _truth(STREET))
    assert (score.start_shortfall_m, score.end_shortfall_m) == (0.0, 160.0 - 80.0)


def test_a_uturn_at_a_node_and_a_backwards_stretch() -> None:
    at_node = [_edge(1, 2), _edge(2, 3), _edge(3, 2), _edge(2, 3), _edge(3, 4)]
    assert count_turnbacks(at_node).uturns == 2
    backwards = [_edge(1, 2), _edge(2, 3, 60, 20)]
    assert count_turnbacks(backwards).uturns == 1
    # zero-length stretches (a path starting exactly at an edge's end) are not driven
    assert count_turnbacks([_edge(2, 1, 80, 80), *STREET]).uturns == 0


def test_a_ring_of_one_way_is_a_loop_not_a_uturn() -> None:
    # a two-edge roundabout ring of one OSM way: 5 -> 6 (30 m) and 6 -> 5 (12 m)
    ring = [
        {**_edge(5, 6, 0, 30), "length_m": 30.0, "osm_way_ids": [9]},
        {**_edge(6, 5, 0, 12), "length_m": 12.0, "osm_way_ids": [9]},
    ]
    entry = _edge(1, 5, way=8)
    exit_ = _edge(6, 10, way=8)
    truth = [entry, ring[0], exit_]
    circled = [entry, ring[0], ring[1], ring[0], ring[1], ring[0], exit_]
    score = score_geojson(_result(circled), _truth(truth))
    assert (score.uturns, score.loops) == (0, 3)  # 5->6 twice more, 6->5 once more
    assert score.spurious_loops == 3
    # another way between the same nodes is no U-turn either
    assert count_turnbacks([_edge(1, 2), _edge(2, 1, way=99)]).uturns == 0


def test_turnbacks_the_truth_has_are_not_spurious() -> None:
    dead_end = [_edge(1, 2), _edge(2, 3), _edge(3, 2), _edge(2, 1)]
    score = score_geojson(_result(dead_end), _truth(dead_end))
    assert (score.uturns, score.true_uturns, score.spurious_uturns) == (1, 1, 0)
    assert not score.spurious
    # counted per segment: a break between two pieces is no U-turn
    pieces = _result([_edge(1, 2), _edge(2, 3, 0, 40)], [_edge(3, 2, 40, 80), _edge(2, 1)])
    assert score_geojson(pieces, _truth(STREET)).uturns == 0


def test_the_verdict_is_judged_against_the_true_length() -> None:
    check = {
        "matched_length_m": 240.0,
        "fused_length_m": 244.8,  # an odometer 2 % high
        "source": "odometer",
        "relative_error": 0.02,
        "band": [-0.04, 0.01],
        "verdict": "over",
    }
    right = score_geojson(_result(STREET, check=check), _truth(STREET))
    assert (right.verdict, right.true_verdict, right.distance_source) == (
        "over",
        "over",
        "odometer",
    )
    assert right.verdict_ok
    # a match 1.5 % too long hides the high meter: the verdict says pass, the truth over
    long = {**check, "matched_length_m": 243.6, "relative_error": 0.0049, "verdict": "pass"}
    wrong = score_geojson(_result(STREET, check=long), _truth(STREET))
    assert (wrong.verdict, wrong.true_verdict) == ("pass", "over")
    assert not wrong.verdict_ok
    # no distance check in the result: nothing to judge
    assert not score_geojson(_result(STREET), _truth(STREET)).verdict_ok


def _score(**fields: Any) -> TripScore:
    base: dict[str, Any] = {
        "trace_id": "t",
        "points": 10,
        "true_length_m": 1000.0,
        "matched_length_m": 1000.0,
        "added_m": 0.0,
        "missed_m": 0.0,
        "mismatch": 0.0,
        "point_accuracy": 1.0,
        "length_error": 0.0,
        "breaks": 0,
    }
    return TripScore(**{**base, **fields})


def test_summary_of_length_spurious_and_verdicts() -> None:
    scores = [
        _score(length_error=0.005, distance_source="odometer", verdict="over", true_verdict="over"),
        _score(
            length_error=-0.015, distance_source="odometer", verdict="pass", true_verdict="over"
        ),
        _score(length_error=0.03, spurious_uturns=2, uturns=2),
        _score(length_error=0.0, breaks=1, distance_source="odometer", verdict="incomplete"),
    ]
    summary = summarise(scores)
    assert summary["within_1pct"] == 0.5
    assert summary["within_2pct"] == 0.75
    assert np.isnan(summary["exact_ends_within_1pct"])  # no shortfalls given: unknown
    assert summary["spurious_share"] == 0.25
    assert summary["spurious_uturns"] == 2
    assert summary["verdict_trips"] == 2  # the trip with a break is not judged
    assert summary["verdict_accuracy"] == 0.5
    assert summary["length_error_abs_max"] == pytest.approx(0.03)
    assert summary["length_error_abs_p95"] == pytest.approx(
        np.percentile([0.005, 0.015, 0.03, 0], 95)
    )


def test_a_spur_on_a_real_route_is_found(default_net: roadnets.RoadNetwork) -> None:
    trip = simulate_trip(default_net, SimulationConfig(), seed=21)
    truth = trip.truth_record()
    edges = copy.deepcopy(truth["edges"])
    a = default_net.arrays
    two_way = [i for i, e in enumerate(trip.edges[1:-1], 1) if a.edge_twin[e.edge] >= 0]
    i = two_way[0]
    twin = int(a.edge_twin[trip.edges[i].edge])
    u, v, key = (int(x[0]) for x in default_net.edge_osm_ids(np.array([twin])))
    length = float(a.edge_length_m[twin])
    back = {**edges[i], "u": u, "v": v, "key": key, "length_m": round(length, 3)}
    spurred = [*edges[: i + 1], back, *edges[i:]]  # drive it, back, and again
    score = score_geojson(_result(spurred), truth)
    assert (score.spurious_uturns, score.spurious_loops) == (2, 1)
    assert score.length_error == pytest.approx(
        2 * edges[i]["length_m"] / truth["length_m"], rel=1e-3
    )
    assert score.true_uturns == truth["uturns"]


def test_a_real_match_of_a_high_odometer(default_net: roadnets.RoadNetwork) -> None:
    cfg = SimulationConfig(noise_m=3.0, odometer_bias=0.02, odometer_scale_error=0.0)
    trip = simulate_trip(default_net, cfg, seed=5)
    result = mapmatch.match(trip.trace, default_net)
    score = score_geojson(result.to_geojson(), trip.truth_record())
    assert score.distance_source == "odometer"
    assert score.verdict == result.distance_check.verdict
    assert score.true_verdict == "over"
    assert score.fused_length_m == pytest.approx(1.02 * trip.length_m, rel=1e-6)


def test_cli_evaluate_reports_uturns_and_verdicts(
    default_net: roadnets.RoadNetwork, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    trip = simulate_trip(default_net, SimulationConfig(route_length_m=1000), seed=2)
    write_trips([trip], tmp_path / "sim")
    truth = trip.truth_record()
    edges = truth["edges"]
    spur = {**edges[0], "u": edges[0]["v"], "v": edges[0]["u"]}
    matched = tmp_path / "matched"
    matched.mkdir()
    result = _result([*edges[:1], spur, *edges])
    result["trace_id"] = trip.trace.trace_id
    (matched / f"{trip.trace.trace_id}.geojson").write_text(json.dumps(result))
    assert main(["evaluate", str(tmp_path / "sim"), "--matched", str(matched), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["traces"][0]["spurious_uturns"] == 2
    assert out["summary"]["spurious_share"] == 1.0
    assert main(["evaluate", str(tmp_path / "sim"), "--matched", str(matched)]) == 0
    text = capsys.readouterr().out
    assert "spurious U-turn or loop on 100% of traces" in text
