"""The matcher on hand-made networks where the right answer is known."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pytest

import mapmatch
from tests.mapmatch.toy import drive, load, trace_of, write_osm

if TYPE_CHECKING:
    from pathlib import Path

    import roadnets

PRIMARY = {"highway": "primary"}
ONEWAY = {"highway": "primary", "oneway": "yes"}


def _ways_driven(result: mapmatch.MatchResult) -> list[int]:
    return result.way_ids()


@pytest.fixture(scope="module")
def dual_carriageway(tmp_path_factory: pytest.TempPathFactory) -> roadnets.RoadNetwork:
    # two one-way carriageways 12 m apart: way 1 eastbound at y=0, way 2 westbound at y=12
    path = tmp_path_factory.mktemp("toy") / "dual.osm"
    return load(
        write_osm(
            path,
            [
                (1, [(0, 0), (250, 0), (500, 0)], ONEWAY),
                (2, [(500, 12), (250, 12), (0, 12)], ONEWAY),
            ],
        )
    )


@pytest.mark.parametrize(("direction", "way"), [("east", 1), ("west", 2)])
def test_parallel_roads_told_apart_by_heading(
    dual_carriageway: roadnets.RoadNetwork, direction: str, way: int
) -> None:
    line = [(20.0, 6.0), (480.0, 6.0)] if direction == "east" else [(480.0, 6.0), (20.0, 6.0)]
    x, y, heading, t = drive(line, speed_mps=12.0)
    trace = trace_of(x, y, time_s=t, heading=heading, speed=12.0)
    result = mapmatch.match(trace, dual_carriageway)
    assert _ways_driven(result) == [way]
    assert result.points.matched.all()
    assert result.matched_length_m == pytest.approx(460.0, abs=15.0)


def test_a_oneway_road_is_never_driven_backwards(tmp_path: Path) -> None:
    # way 3: one-way eastbound at y=0; way 4: two-way at y=15; the car drives west at y=3
    net = load(
        write_osm(
            tmp_path / "oneway.osm",
            [
                (3, [(0, 0), (200, 0), (400, 0)], ONEWAY),
                (4, [(0, 15), (200, 15), (400, 15)], PRIMARY),
            ],
        )
    )
    x, y, _, t = drive([(380.0, 3.0), (20.0, 3.0)], speed_mps=10.0)
    result = mapmatch.match(trace_of(x, y, time_s=t), net)
    assert _ways_driven(result) == [4]
    a = net.arrays
    for segment in result.segments:
        for edge in segment.edges:
            # westbound: the edge's end lies west of its start
            assert a.node_x[a.edge_v[edge.edge]] < a.node_x[a.edge_u[edge.edge]]


def test_a_loop_driven_twice_counts_twice(tmp_path: Path) -> None:
    square = [(0, 0), (100, 0), (100, 100), (0, 100), (0, 0)]
    ways = [(10 + i, [square[i], square[i + 1]], PRIMARY) for i in range(4)]
    net = load(write_osm(tmp_path / "loop.osm", ways))
    rng = np.random.default_rng(3)
    x, y, heading, t = drive(square + square[1:] + [(100.0, 0.0)], speed_mps=8.0)
    x, y = x + rng.normal(0, 2, len(x)), y + rng.normal(0, 2, len(y))
    result = mapmatch.match(trace_of(x, y, time_s=t, heading=heading, speed=8.0), net)
    assert len(result.segments) == 1
    assert result.matched_length_m == pytest.approx(900.0, rel=0.02)
    assert result.way_ids() == [10, 11, 12, 13, 10, 11, 12, 13, 10]


def test_a_u_turn_in_the_middle_of_the_road(tmp_path: Path) -> None:
    net = load(write_osm(tmp_path / "uturn.osm", [(20, [(0, 0), (400, 0)], PRIMARY)]))
    x, y, heading, t = drive([(20.0, 1.0), (200.0, 1.0), (30.0, 1.0)], speed_mps=10.0)
    result = mapmatch.match(trace_of(x, y, time_s=t, heading=heading, speed=10.0), net)
    assert len(result.segments) == 1
    edges = [e.edge for e in result.segments[0].edges]
    assert len(edges) == 2
    assert net.arrays.edge_twin[edges[0]] == edges[1]
    assert result.matched_length_m == pytest.approx(350.0, abs=12.0)


def test_a_trace_that_leaves_the_map_is_split(tmp_path: Path) -> None:
    net = load(write_osm(tmp_path / "leave.osm", [(30, [(0, 0), (300, 0), (600, 0)], PRIMARY)]))
    x1, y1, _, _ = drive([(10.0, 0.0), (200.0, 0.0)], speed_mps=10.0)
    x2 = np.linspace(250, 350, 10)
    y2 = np.full(10, 1000.0)  # a kilometre away from any road
    x3, y3, _, _ = drive([(400.0, 0.0), (590.0, 0.0)], speed_mps=10.0)
    x = np.concatenate((x1, x2, x3))
    y = np.concatenate((y1, y2, y3))
    t = np.arange(len(x), dtype=float) * 1.0
    t[len(x1) :] += 30.0  # the off-map stretch took time
    result = mapmatch.match(trace_of(x, y, time_s=t), net)
    first_back = len(x1) + len(x2)
    assert result.breaks == [first_back]
    assert len(result.segments) == 2
    assert not result.points.matched[len(x1) : first_back].any()
    assert result.points.matched[: len(x1)].all()
    assert result.points.matched[first_back:].all()
    assert result.distance_check.verdict == "incomplete"


def test_a_stopped_vehicle_does_not_drive(tmp_path: Path) -> None:
    net = load(
        write_osm(
            tmp_path / "stop.osm",
            [(40, [(0, 0), (200, 0), (400, 0)], PRIMARY), (41, [(200, 0), (200, 200)], PRIMARY)],
        )
    )
    rng = np.random.default_rng(11)
    n = 90
    x = 190.0 + rng.normal(0, 4, n)
    y = 2.0 + rng.normal(0, 4, n)
    result = mapmatch.match(trace_of(x, y, time_s=np.arange(n, dtype=float), speed=0.0), net)
    assert len(result.segments) == 1
    assert result.matched_length_m < 10.0
    assert len(result.segments[0].edges) <= 2


def test_no_road_anywhere_near_is_an_error(dual_carriageway: roadnets.RoadNetwork) -> None:
    x = np.array([0.0, 10.0, 20.0])
    y = np.full(3, 5000.0)
    with pytest.raises(mapmatch.NoCandidatesError, match="no road within"):
        mapmatch.match(trace_of(x, y, time_s=np.arange(3.0)), dual_carriageway)


def test_geojson_follows_the_output_schema(dual_carriageway: roadnets.RoadNetwork) -> None:
    x, y, heading, t = drive([(20.0, 6.0), (480.0, 6.0)], speed_mps=12.0)
    trace = trace_of(x, y, time_s=t, heading=heading, speed=12.0, trace_id="east")
    doc = mapmatch.match(trace, dual_carriageway).to_geojson()
    assert doc["type"] == "FeatureCollection"
    assert doc["trace_id"] == "east"
    assert set(doc) >= {"network", "matched_length_m", "distance_check", "breaks", "stats"}
    assert set(doc["network"]) == {"id", "source", "crs"}
    segments = [f for f in doc["features"] if f["properties"]["kind"] == "segment"]
    points = [f for f in doc["features"] if f["properties"]["kind"] == "point"]
    assert len(segments) == 1
    assert len(points) == len(x)
    seg = segments[0]
    assert seg["geometry"]["type"] == "LineString"
    assert seg["properties"]["point_range"] == [0, len(x) - 1]
    edge = seg["properties"]["edges"][0]
    assert {
        "u",
        "v",
        "key",
        "osm_way_ids",
        "length_m",
        "start_offset_m",
        "end_offset_m",
    } <= set(edge)  # and the street, times and speeds (tests/mapmatch/test_export.py)
    assert edge["osm_way_ids"] == [1]
    assert sum(e["end_offset_m"] - e["start_offset_m"] for e in seg["properties"]["edges"]) == (
        pytest.approx(doc["matched_length_m"], abs=0.01)
    )
    point = points[3]["properties"]
    assert set(point) >= {
        "index",
        "time",
        "matched",
        "u",
        "v",
        "key",
        "offset_m",
        "distance_m",
        "confidence",
    }
    assert 0.0 <= point["confidence"] <= 1.0
    lon, lat = points[3]["geometry"]["coordinates"]
    assert abs(lat - 45.0) < 0.001
    assert abs(lon - 8.0) < 0.01
    check = doc["distance_check"]
    assert check["source"] == "chord"
    assert set(check) == {
        "matched_length_m",
        "fused_length_m",
        "source",
        "relative_error",
        "band",
        "verdict",
        "evidence",
        "uturns",
    }
    assert check["evidence"] == "heading"  # the drive reports its heading
    assert check["uturns"] == 0
