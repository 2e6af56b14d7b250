"""POST /v1/match happy paths against a real ``mapmatch serve`` on loopback."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import pytest

if TYPE_CHECKING:
    import httpx

    from mapmatch.evaluation.simulate import SimulatedTrip


def _points(doc: dict[str, Any]) -> list[dict[str, Any]]:
    return [f for f in doc["features"] if f["properties"]["kind"] == "point"]


def _segments(doc: dict[str, Any]) -> list[dict[str, Any]]:
    return [f for f in doc["features"] if f["properties"]["kind"] == "segment"]


def _ways(doc: dict[str, Any]) -> set[int]:
    return {w for s in _segments(doc) for e in s["properties"]["edges"] for w in e["osm_way_ids"]}


def _true_ways(trip: SimulatedTrip) -> set[int]:
    return {e.osm_way_id for e in trip.edges}


def test_json_body_matches_the_driven_roads(client: httpx.Client, trip, bodies) -> None:
    body = {"points": bodies.points(trip.trace), "trace_id": "json-trip"}
    answer = client.post("/v1/match", json=body)
    assert answer.status_code == 200, answer.text
    assert answer.headers["content-type"] == "application/geo+json"
    doc = answer.json()
    assert doc["type"] == "FeatureCollection"
    assert doc["trace_id"] == "json-trip"
    assert doc["network"]["id"] == "monaco_2020"
    points = _points(doc)
    assert [p["properties"]["index"] for p in points] == list(range(len(trip.trace)))
    assert all(p["properties"]["matched"] for p in points)
    # the simulated route is the ground truth: same ways, same length within 5 %
    assert _ways(doc) == _true_ways(trip)
    assert doc["matched_length_m"] == pytest.approx(trip.length_m, rel=0.05)
    assert doc["distance_check"]["source"] == "odometer"
    assert answer.headers["x-request-id"]


@pytest.mark.parametrize("fmt", ["csv", "gpx", "geojson"])
def test_file_bodies_match_like_json(client: httpx.Client, trip, bodies, fmt: str) -> None:
    reference = client.post("/v1/match", json={"points": bodies.points(trip.trace, odometer=False)})
    assert reference.status_code == 200, reference.text
    content, headers = bodies.file(fmt, trip.trace.slice(0, len(trip.trace)))
    answer = client.post(
        "/v1/match", content=content, headers=headers, params={"trace_id": f"{fmt}-trip"}
    )
    assert answer.status_code == 200, answer.text
    doc = answer.json()
    assert len(_points(doc)) == len(trip.trace)
    assert _ways(doc) == _true_ways(trip)
    # GPX carries whole seconds and 7 decimals like the others: the same roads, same length
    assert doc["matched_length_m"] == pytest.approx(reference.json()["matched_length_m"], abs=1.0)
    expected_id = "gpx-trip" if fmt == "gpx" else f"{fmt}-trip"  # the GPX <trk> names itself
    assert doc["trace_id"] == expected_id


def test_query_parameters_carry_network_and_options_for_csv(
    client: httpx.Client, trip, bodies
) -> None:
    content, headers = bodies.file("csv", trip.trace)
    params = {"network": "monaco_2020", "sigma_m": 8, "distance_band": [-0.5, 0.5]}
    answer = client.post("/v1/match", content=content, headers=headers, params=params)
    assert answer.status_code == 200, answer.text
    assert answer.json()["distance_check"]["band"] == [-0.5, 0.5]


def test_json_options_are_applied(client: httpx.Client, trip, bodies) -> None:
    body = {"points": bodies.points(trip.trace), "options": {"distance_band": [-0.3, 0.2]}}
    answer = client.post("/v1/match", json=body)
    assert answer.status_code == 200, answer.text
    assert answer.json()["distance_check"]["band"] == [-0.3, 0.2]


def test_fused_distance_is_used_without_odometer(client: httpx.Client, trip, bodies) -> None:
    body = {"points": bodies.points(trip.trace, odometer=False), "fused_distance_m": 1234.5}
    check = client.post("/v1/match", json=body).json()["distance_check"]
    assert check["source"] == "caller"
    assert check["fused_length_m"] == 1234.5


def test_unsorted_and_repeated_times_are_sorted_and_reported(
    client: httpx.Client, trip, bodies
) -> None:
    points = bodies.points(trip.trace)
    shuffled = [points[1], points[0], *points[2:], dict(points[5])]  # one swap, one repeat
    answer = client.post("/v1/match", json={"points": shuffled})
    assert answer.status_code == 200, answer.text
    stats = answer.json()["stats"]
    assert stats["points"] == len(points)
    # the swapped pair and the repeat appended at the end are both out of time order
    assert stats["reordered_rows"] == 2
    assert stats["merged_rows"] == 1  # the repeat is the same fix: merged, and counted
    assert stats["input_rows"] == len(points) + 1
    assert stats["time_source"] == "ok"
    assert len(stats["warnings"]) == 2


def test_issue_12_points_without_times_match_by_distance(
    client: httpx.Client, trip, bodies
) -> None:
    points = [{"lat": p["lat"], "lon": p["lon"]} for p in bodies.points(trip.trace)]
    answer = client.post("/v1/match", json={"points": points})
    assert answer.status_code == 200, answer.text
    doc = answer.json()
    assert doc["stats"]["time_source"] == "absent"
    assert {p["properties"]["time"] for p in _points(doc)} == {None}
    assert doc["matched_length_m"] == pytest.approx(trip.length_m, rel=0.05)


def test_second_network_is_selected_by_id(client: httpx.Client, default_net, oakland_net) -> None:
    listing = client.get("/v1/networks").json()["networks"]
    assert [n["id"] for n in listing] == ["monaco_2020", "west-oakland_us"]
    assert [n["default"] for n in listing] == [True, False]
    for network in listing:  # read from the cache, or built there, before the worker was ready
        assert network["route_table"].startswith(("read from the cache", "built and stored"))
    oakland = listing[1]
    info = oakland_net.info()
    assert (oakland["nodes"], oakland["edges"]) == (info.nodes, info.edges)
    assert oakland["bbox"] == pytest.approx(list(info.bbox), abs=1e-6)
    assert oakland["source"] == "west-oakland_us.osm.bz2"
    # two points along one Oakland edge match there, and not on Monaco's network
    a = oakland_net.arrays
    start, stop = int(a.edge_geom_ptr[0]), int(a.edge_geom_ptr[1])
    lon, lat = oakland_net.unproject(a.geom_x[[start, stop - 1]], a.geom_y[[start, stop - 1]])
    points = [
        {"time": float(i), "lon": float(x), "lat": float(y)}
        for i, (x, y) in enumerate(zip(lon, lat, strict=True))
    ]
    answer = client.post("/v1/match", json={"points": points, "network": "west-oakland_us"})
    assert answer.status_code == 200, answer.text
    assert answer.json()["network"]["id"] == "west-oakland_us"
    off_map = client.post("/v1/match", json={"points": points})  # default network: Monaco
    assert off_map.status_code == 422
    assert off_map.json()["error"]["code"] == "no_road_nearby"
