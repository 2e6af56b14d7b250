"""Third-party client libraries from PyPI against the OSRM and Valhalla routes on loopback.

OSRM publishes no HTTP client of its own (its npm ``osrm`` package binds the routing engine to
``.osrm`` files; it does not talk to a server), so the OSRM side uses ``py-osrm-client``, which
parses the answer into its Route / RouteLeg / Waypoint objects. The Valhalla side uses
``routingpy``'s request builder and HTTP client (its ``trace_attributes`` answer parser needs a
``sidewalk`` on every edge, which Valhalla itself leaves out where there is none, so it is not
used). Both are in the ``dev`` extra, so ``make test`` runs these tests; elsewhere they skip,
saying so, where the libraries are not installed.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import pytest

from api.polyline import decode

if TYPE_CHECKING:
    from mapmatch.evaluation.simulate import SimulatedTrip


def _v1_ways(live: Any, trip: SimulatedTrip) -> tuple[list[int], dict[str, Any]]:
    import requests

    t = trip.trace
    points = [
        {"time": float(time), "lon": round(float(lon), 6), "lat": round(float(lat), 6)}
        for time, lon, lat in zip(t.time_s, t.lon, t.lat, strict=True)
    ]
    answer = requests.post(f"{live.base_url}/v1/match", json={"points": points}, timeout=60)
    assert answer.status_code == 200, answer.text
    doc = answer.json()
    segments = [f for f in doc["features"] if f["properties"]["kind"] == "segment"]
    ways = [e["osm_way_ids"][0] for s in segments for e in s["properties"]["edges"]]
    return ways, doc


def test_py_osrm_client_reads_the_match(live, trip: SimulatedTrip) -> None:
    client_sync = pytest.importorskip(
        "osrm.client_sync", reason="py-osrm-client is not installed (pip install py-osrm-client)"
    )
    t = trip.trace
    coords = [(round(float(x), 6), round(float(y), 6)) for x, y in zip(t.lon, t.lat, strict=True)]
    # its URL builder writes lists as Python reprs, so timestamps cannot be sent through it
    with client_sync.OsrmClient(base_url=live.base_url) as client:
        match = client.match(coords, geometries="polyline6", overview="full", annotations=True)
    assert match.code.value == "Ok"
    assert len(match.matchings) == 1
    route = match.matchings[0]
    assert route.confidence > 0
    assert len(route.legs) == len(coords) - 1
    assert all(leg.annotation is not None for leg in route.legs)
    assert len(match.tracepoints) == len(coords)
    assert {wp.matchings_index for wp in match.tracepoints} == {0}
    _ways, doc = _v1_ways(live, trip)
    assert route.distance == pytest.approx(doc["matched_length_m"], rel=0.02)
    segments = [f for f in doc["features"] if f["properties"]["kind"] == "segment"]
    names = {e["name"] for f in segments for e in f["properties"]["edges"]}
    assert {wp.name for wp in match.tracepoints} <= names | {""}
    assert len(decode(route.geometry, 6)) >= 2


def test_routingpy_builds_and_sends_trace_attributes(live, trip: SimulatedTrip) -> None:
    routers = pytest.importorskip(
        "routingpy.routers", reason="routingpy is not installed (pip install routingpy)"
    )
    valhalla = routers.Valhalla(base_url=live.base_url)
    t = trip.trace
    locations = [
        valhalla.Waypoint([round(float(x), 6), round(float(y), 6)], time=float(time))
        for time, x, y in zip(t.time_s, t.lon, t.lat, strict=True)
    ]
    params = valhalla.get_trace_attributes_params(
        locations,
        profile="auto",
        shape_match="map_snap",
        filters=["edge.way_id", "edge.names", "shape", "matched.point", "matched.type"],
        filters_action="include",  # routingpy puts it beside "filters", not inside
    )
    doc = valhalla.client._request("/trace_attributes", post_params=params)
    ways, _ = _v1_ways(live, trip)
    assert [e["way_id"] for e in doc["edges"]] == ways
    assert all(set(e) <= {"way_id", "names"} for e in doc["edges"])
    assert len(doc["matched_points"]) == len(locations)
    assert {p["type"] for p in doc["matched_points"]} <= {"matched", "interpolated"}
