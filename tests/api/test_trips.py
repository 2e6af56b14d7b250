"""Live trips over HTTP (issue 17): ``/v1/trips`` on a real server on loopback."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import httpx
import pytest

from api.settings import Settings
from api.trips import TripRegistry
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trips
from mapmatch.online import OnlineMatcher
from tests.api.conftest import thread_server
from tests.mapmatch.test_online import fixes_of

if TYPE_CHECKING:
    from collections.abc import Iterator

    import roadnets
    from tests.api.conftest import ThreadServer

TOKEN = "live-token"
AUTH = {"Authorization": f"Bearer {TOKEN}"}


@pytest.fixture(scope="module")
def server() -> Iterator[ThreadServer]:
    with thread_server(Settings(token=TOKEN, max_trips=3), ready_headers=AUTH) as running:
        yield running


@pytest.fixture(scope="module")
def client(server: ThreadServer) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=server.base_url, headers=AUTH, timeout=30.0) as http:
        yield http


@pytest.fixture(scope="module")
def fixes(default_net: roadnets.RoadNetwork) -> list[dict[str, Any]]:
    cfg = SimulationConfig.realistic(interval_s=1.0, outage_per_km=0.0)
    return fixes_of(simulate_trips(default_net, cfg, count=1, seed=31)[0].trace)


def _error(answer: httpx.Response) -> dict[str, Any]:
    body: dict[str, Any] = answer.json()["error"]
    return body


def test_a_live_trip_settles_as_it_goes_and_closes_to_its_match(
    client: httpx.Client, fixes: list[dict[str, Any]], default_net: roadnets.RoadNetwork
) -> None:
    opened = client.post("/v1/trips", json={"trip_id": "cab-7.1", "lag_s": 20})
    assert opened.status_code == 201
    assert opened.json()["trip_id"] == "cab-7.1"
    assert opened.json()["lag_s"] == 20.0
    settled_points: list[dict[str, Any]] = []
    for i, fix in enumerate(fixes[:150]):
        answer = client.post("/v1/trips/cab-7.1/fixes", json=fix)
        assert answer.status_code == 200, answer.text
        body = answer.json()
        assert body["accepted"] == 1
        assert body["fixes"] == i + 1
        assert body["settled"]["first_fix"] == len(settled_points)
        settled_points += body["settled"]["points"]
        if i > 5:
            assert body["position"]["confidence"] >= 0.0
    batch = client.post("/v1/trips/cab-7.1/fixes?position=false", json={"fixes": fixes[150:]})
    assert batch.status_code == 200
    assert batch.json()["accepted"] == len(fixes) - 150
    assert batch.json()["position"] is None
    settled_points += batch.json()["settled"]["points"]
    assert [p["fix"] for p in settled_points] == list(range(len(settled_points)))
    assert len(settled_points) > len(fixes) // 2
    state = client.get("/v1/trips/cab-7.1").json()
    assert state["fixes"] == len(fixes)
    assert state["settled_fixes"] == len(settled_points)
    assert state["distance"]["source"] == "odometer"
    closed = client.delete("/v1/trips/cab-7.1")
    assert closed.status_code == 200
    assert closed.headers["content-type"].startswith("application/geo+json")
    geojson = closed.json()
    # the same as the library's live matcher on the same fixes (one fix, then the batch)
    live = OnlineMatcher(default_net, lag=20, trip_id="cab-7.1")
    for fix in fixes[:150]:
        live.push(fix)
    live.push_many(fixes[150:])
    assert geojson["matched_length_m"] == pytest.approx(live.close().matched_length_m, abs=1e-3)
    points = [f for f in geojson["features"] if f["properties"]["kind"] == "point"]
    for got, was in zip(points, settled_points, strict=False):
        assert got["properties"]["u"] == was["u"]  # what settled is what the match says
        assert got["properties"]["offset_m"] == pytest.approx(was["offset_m"], abs=1e-3)
    assert client.get("/v1/trips/cab-7.1").status_code == 404


def test_a_live_trip_survives_bad_fixes(client: httpx.Client, fixes: list[dict[str, Any]]) -> None:
    trip = client.post("/v1/trips", json={}).json()["trip_id"]
    url = f"/v1/trips/{trip}/fixes"
    for fix in fixes[:20]:
        assert client.post(url, json=fix).status_code == 200
    wrong = client.post(url, json={**fixes[20], "lat": 123.0})
    assert wrong.status_code == 422
    assert _error(wrong)["code"] == "invalid_trace"
    assert _error(wrong)["field"] == "lat"
    older = client.post(url, json={**fixes[20], "time": fixes[5]["time"]})
    assert older.status_code == 422
    assert "time order" in _error(older)["message"]
    mixed = client.post(url, json=[fixes[20], {"time": "yesterday"}, fixes[21]])
    assert mixed.status_code == 200
    assert mixed.json()["accepted"] == 2
    rejected = mixed.json()["rejected"]
    assert [(r["index"], r["status"], r["code"], r["field"]) for r in rejected] == [
        (1, 422, "invalid_trace", "time")
    ]
    nothing = client.post(url, json=[{"lat": 1}, {"lon": 2}])
    assert nothing.status_code == 422
    assert _error(nothing)["rows"] == [0, 1]
    not_json = client.post(url, content=b"{oops", headers={"content-type": "application/json"})
    assert not_json.status_code == 400
    state = client.get(f"/v1/trips/{trip}").json()
    assert state["fixes"] == 22  # the bad ones left no trace
    assert state["rejected"] == 3
    for fix in fixes[22:60]:
        assert client.post(url, json=fix).status_code == 200
    assert client.delete(f"/v1/trips/{trip}").status_code == 200


def test_trips_are_refused_beyond_the_caps_and_need_the_token(
    server: ThreadServer, client: httpx.Client, fixes: list[dict[str, Any]]
) -> None:
    assert httpx.post(f"{server.base_url}/v1/trips", json={}).status_code == 401
    ids = [client.post("/v1/trips", json={}).json()["trip_id"] for _ in range(3)]
    full = client.post("/v1/trips", json={})
    assert full.status_code == 503
    assert _error(full)["code"] == "too_many_trips"
    taken = client.delete(f"/v1/trips/{ids[0]}")
    assert taken.status_code == 422  # no fixes: no match, but the trip is closed
    again = client.post("/v1/trips", json={"trip_id": ids[1]})
    assert again.status_code == 422  # the id is open: refused before the cap is
    assert _error(again)["field"] == "trip_id"
    assert client.post("/v1/trips", json={"lag_s": 10_000}).status_code == 422
    assert client.post("/v1/trips", json={"options": {"sigma_m": -1}}).status_code == 422
    assert client.post("/v1/trips", json={}).status_code == 201
    unknown = client.post("/v1/trips/nobody/fixes", json=fixes[0])
    assert unknown.status_code == 404
    assert _error(unknown)["code"] == "unknown_trip"
    for trip in client.get("/metrics").text.splitlines():
        if trip.startswith("mapmatch_live_trips_total") and 'event="opened"' in trip:
            assert float(trip.split()[-1]) >= 4
            break
    else:
        pytest.fail("no mapmatch_live_trips_total metric")
    app_trips: TripRegistry = server.app.state.trips
    for name in list(app_trips._trips):
        client.delete(f"/v1/trips/{name}")


def test_an_idle_trip_expires_and_a_full_one_takes_no_more_fixes(
    fixes: list[dict[str, Any]],
) -> None:
    now = [0.0]
    settings = Settings(trip_idle_s=60.0, trip_max_bytes=100_000)
    with thread_server(settings) as running:
        running.app.state.trips = TripRegistry(
            settings, running.app.state.metrics, clock=lambda: now[0]
        )
        with httpx.Client(base_url=running.base_url, timeout=30.0) as http:
            idle = http.post("/v1/trips", json={}).json()["trip_id"]
            busy = http.post("/v1/trips", json={}).json()["trip_id"]
            now[0] += 50.0
            assert http.get(f"/v1/trips/{busy}").status_code == 200  # used: it stays
            now[0] += 20.0  # idle for 70 s, busy for 20 s
            gone = http.get(f"/v1/trips/{idle}")
            assert gone.status_code == 404
            assert "expired after 60 s" in _error(gone)["message"]
            assert http.get(f"/v1/trips/{busy}").status_code == 200
            for start in range(0, len(fixes), 100):
                answer = http.post(f"/v1/trips/{busy}/fixes", json=fixes[start : start + 100])
                if answer.status_code != 200:
                    break
            assert answer.status_code == 413
            assert _error(answer)["code"] == "trip_too_large"
            assert http.get(f"/v1/trips/{busy}").status_code == 200  # the trip is intact
            assert http.delete(f"/v1/trips/{busy}").status_code == 200
