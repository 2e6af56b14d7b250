"""Valhalla's ``POST /trace_attributes`` against a real ``mapmatch serve`` on loopback.

The documented example requests are Valhalla's own (docs/api/map-matching/api-reference.md,
"Example trace_attributes requests"), verbatim: they are traces in York, Pennsylvania, which no
network here covers, so they must answer Valhalla's "No suitable edges near location" (171),
or the costing error (125) for the pedestrian one. The same requests with the trace moved onto
the served Monaco network check the documented response items
(:class:`api.valhalla_schemas.ValhallaResponse`, strict: an unknown member fails).
"""

from __future__ import annotations

import itertools
import json
from typing import TYPE_CHECKING, Any

import pytest

from api.polyline import decode, encode
from api.valhalla_schemas import ValhallaErrorResponse, ValhallaResponse

if TYPE_CHECKING:
    import httpx

    from mapmatch.evaluation.simulate import SimulatedTrip

YORK_SHAPE = [
    {"lat": 39.983841, "lon": -76.735741},
    {"lat": 39.983704, "lon": -76.735298},
    {"lat": 39.983578, "lon": -76.734848},
    {"lat": 39.983551, "lon": -76.734253},
    {"lat": 39.983555, "lon": -76.734116},
    {"lat": 39.983589, "lon": -76.733315},
    {"lat": 39.983719, "lon": -76.732445},
    {"lat": 39.983818, "lon": -76.731712},
    {"lat": 39.983776, "lon": -76.731506},
    {"lat": 39.983696, "lon": -76.731369},
]
YORK_POLYLINE = (
    "_grbgAh~{nhF?lBAzBFvBHxBEtBKdB?fB@dBZdBb@hBh@jBb@x@\\|@x@pB\\x@v@hBl@nBPbCXtBn@|@z@ZbAEbAa@~@q@z@"
    "QhA]pAUpAVhAPlAWtASpAAdA[dASdAQhAIlARjANnAZhAf@n@`A?lB^nCRbA\\xB`@vBf@tBTbCFbARzBZvBThBRnBNrBP`CH"
    "bCF`CNdCb@vBX`ARlAJfADhA@dAFdAP`AR`Ah@hBd@bBl@rBV|B?vB]tBCvBBhAF`CFnBXtAVxAVpAVtAb@|AZ`Bd@~BJfA@f"
    "AHdADhADhABjAGzAInAAjAB|BNbCR|BTjBZtB`@lBh@lB\\|Bl@rBXtBN`Al@g@t@?nAA~AKvACvAAlAMdAU`Ac@hAShAI`AJ"
    "`AIdAi@bAu@|@k@p@]p@a@bAc@z@g@~@Ot@Bz@f@X`BFtBXdCLbAf@zBh@fBb@xAb@nATjAKjAW`BI|AEpAHjAPdAAfAGdAFj"
    "Av@p@XlAVnA?~A?jAInAPtAVxAXnAf@tBDpBJpBXhBJfBDpAZ|Ax@pAz@h@~@lA|@bAnAd@hAj@tAR~AKxAc@xAShA]hAIdAA"
    "jA]~A[v@BhB?dBSv@Ct@CvAI~@Oz@Pv@dAz@lAj@~A^`B^|AXvAVpAXdBh@~Ap@fCh@hB\\zBN`Aj@xBFdA@jALbAPbAJdAHd"
    "AJbAHbAHfAJhALbA\\lBTvBAdC@bC@jCKjASbC?`CM`CDpB\\xAj@tB\\fA\\bAVfAJdAJbAXz@L|BO`AOdCDdA@~B\\z@l@v@l"
    "@v@l@r@j@t@b@x@b@r@z@jBVfCJdAJdANbCPfCF|BRhBS~BS`AYbAe@~BQdA"
)
#: The documented trace_attributes requests (shape, polyline, include, exclude filters).
DOCUMENTED: dict[str, dict[str, Any]] = {
    "shape": {
        "shape": YORK_SHAPE,
        "costing": "auto",
        "shape_match": "walk_or_snap",
        "filters": {
            "attributes": ["edge.names", "edge.id", "edge.weighted_grade", "edge.speed"],
            "action": "include",
        },
    },
    "encoded_polyline": {
        "encoded_polyline": YORK_POLYLINE,
        "shape_match": "map_snap",
        "costing": "pedestrian",
        "directions_options": {"units": "miles"},
    },
    "exclude": {
        "shape": YORK_SHAPE,
        "costing": "auto",
        "shape_match": "walk_or_snap",
        "filters": {
            "attributes": ["edge.names", "edge.begin_shape_index", "edge.end_shape_index", "shape"],
            "action": "exclude",
        },
    },
}
MATCHED_FILTER = {
    "attributes": [
        "edge.id",
        "matched.point",
        "matched.type",
        "matched.edge_index",
        "matched.begin_route_discontinuity",
        "matched.end_route_discontinuity",
        "matched.distance_along_edge",
    ],
    "action": "include",
}


def _ok(answer: httpx.Response) -> dict[str, Any]:
    assert answer.status_code == 200, answer.text
    doc = answer.json()
    ValhallaResponse.model_validate(doc)
    return doc


def _error(answer: httpx.Response, status: int, code: int) -> str:
    assert answer.status_code == status, answer.text
    doc = answer.json()
    ValhallaErrorResponse.model_validate(doc)
    assert (doc["error_code"], doc["status_code"]) == (code, status), doc
    assert doc["status"] == {400: "Bad Request", 401: "Unauthorized"}.get(status, doc["status"])
    return str(doc["error"])


def _shape(trip: SimulatedTrip, *, times: bool = True) -> list[dict[str, float]]:
    t = trip.trace
    points = []
    for time, lon, lat in zip(t.time_s, t.lon, t.lat, strict=True):
        point = {"lat": round(float(lat), 6), "lon": round(float(lon), 6)}
        if times:
            point["time"] = float(time)
        points.append(point)
    return points


def _v1(client: httpx.Client, shape: list[dict[str, float]]) -> dict[str, Any]:
    points = [
        {"lat": p["lat"], "lon": p["lon"], **({"time": p["time"]} if "time" in p else {})}
        for p in shape
    ]
    answer = client.post("/v1/match", json={"points": points})
    assert answer.status_code == 200, answer.text
    return answer.json()


def _v1_edges(doc: dict[str, Any]) -> list[dict[str, Any]]:
    segments = [f for f in doc["features"] if f["properties"]["kind"] == "segment"]
    return [e for s in segments for e in s["properties"]["edges"]]


# ----------------------------------------------------------------------------- Valhalla's examples


@pytest.mark.parametrize("name", ["shape", "exclude"])
def test_documented_requests_off_the_map_say_no_suitable_edges(
    client: httpx.Client, name: str
) -> None:
    message = _error(client.post("/trace_attributes", json=DOCUMENTED[name]), 400, 171)
    assert message.startswith("No suitable edges near location")


def test_documented_polyline_request_is_refused_for_its_costing(client: httpx.Client) -> None:
    message = _error(
        client.post("/trace_attributes", json=DOCUMENTED["encoded_polyline"]), 400, 125
    )
    assert "pedestrian" in message
    car = {**DOCUMENTED["encoded_polyline"], "costing": "auto"}
    _error(client.post("/trace_attributes", json=car), 400, 171)  # read, then off the map


def test_include_filter_on_the_map(client: httpx.Client, trip: SimulatedTrip) -> None:
    request = {**DOCUMENTED["shape"], "shape": _shape(trip)}
    doc = _ok(client.post("/trace_attributes", json=request))
    assert set(doc) == {"edges", "units", "warnings"}
    assert {k for e in doc["edges"] for k in e} <= {"names", "id", "speed"}
    assert all("id" in e and "speed" in e for e in doc["edges"])
    assert any("edge.weighted_grade" in w["text"] for w in doc["warnings"])


def test_exclude_filter_on_the_map(client: httpx.Client, trip: SimulatedTrip) -> None:
    request = {**DOCUMENTED["exclude"], "shape": _shape(trip)}
    doc = _ok(client.post("/trace_attributes", json=request))
    assert "shape" not in doc
    for edge in doc["edges"]:
        assert not {"names", "begin_shape_index", "end_shape_index"} & set(edge)
        assert {"way_id", "length", "speed_limit", "road_class"} <= set(edge)
    assert len(doc["matched_points"]) == len(trip.trace)


def test_matched_points_filter_on_the_map(client: httpx.Client, trip: SimulatedTrip) -> None:
    request = {"shape": _shape(trip), "costing": "auto", "filters": MATCHED_FILTER}
    doc = _ok(client.post("/trace_attributes", json=request))
    assert all(set(e) == {"id"} for e in doc["edges"])
    points = doc["matched_points"]
    assert len(points) == len(trip.trace)
    for p in points:
        assert {"lat", "lon", "type", "edge_index", "distance_along_edge"} <= set(p)
        assert 0 <= p["edge_index"] < len(doc["edges"])
        assert 0.0 <= p["distance_along_edge"] <= 1.0
    assert {p["type"] for p in points} <= {"matched", "interpolated"}


# ----------------------------------------------------------------------------- mapping


def test_edges_are_the_roads_of_v1_match(client: httpx.Client, trip: SimulatedTrip) -> None:
    shape = _shape(trip)
    doc = _ok(client.post("/trace_attributes", json={"shape": shape, "costing": "auto"}))
    reference = _v1(client, shape)
    ours = _v1_edges(reference)
    edges = doc["edges"]
    # the same roads, in the same order, with the same attributes
    assert [e["way_id"] for e in edges] == [e["osm_way_ids"][0] for e in ours]
    assert [e.get("names", [None])[0] for e in edges] == [e["name"] for e in ours]
    assert [e["speed_limit"] for e in edges] == [round(e["speed_limit_kph"]) for e in ours]
    assert sum(e["length"] for e in edges) == pytest.approx(
        reference["matched_length_m"] / 1000, abs=0.001 * len(edges)
    )
    assert doc["units"] == "kilometers"
    # shape indices point into the shape; consecutive edges meet at one vertex
    shape_points = decode(doc["shape"], 6)
    assert edges[0]["begin_shape_index"] == 0
    assert edges[-1]["end_shape_index"] == len(shape_points) - 1
    for a, b in itertools.pairwise(edges):
        assert a["end_shape_index"] == b["begin_shape_index"]
        assert a["begin_shape_index"] <= a["end_shape_index"]
    # the matched points lie on their edge's stretch of the shape
    for p in doc["matched_points"]:
        e = edges[p["edge_index"]]
        stretch = shape_points[e["begin_shape_index"] : e["end_shape_index"] + 1]
        lats = [q[0] for q in stretch]
        assert min(lats) - 2e-5 <= p["lat"] <= max(lats) + 2e-5
        assert p["distance_from_trace_point"] < 30


def test_times_elapsed_and_speeds(client: httpx.Client, trip: SimulatedTrip) -> None:
    shape = _shape(trip)
    timed = _ok(
        client.post(
            "/trace_attributes", json={"shape": shape, "costing": "auto", "use_timestamps": True}
        )
    )["edges"]
    ours = _v1_edges(_v1(client, shape))
    assert [e["begin_time"] for e in timed] == [e["entry_time"] for e in ours]
    assert [e["end_time"] for e in timed] == [e["exit_time"] for e in ours]
    start = shape[0]["time"]
    assert [e["end_node"]["elapsed_time"] for e in timed] == pytest.approx(
        [e["exit_time"] - start for e in ours], abs=1e-3
    )
    for e, o in zip(timed, ours, strict=True):
        if o["mean_speed_kph"] is not None:
            assert abs(e["speed"] - o["mean_speed_kph"]) <= 0.51  # whole km/h (2 decimals there)
    # Valhalla's default: elapsed times at the roads' speeds, not from the timestamps
    costed = _ok(client.post("/trace_attributes", json={"shape": shape, "costing": "auto"}))
    elapsed = [e["end_node"]["elapsed_time"] for e in costed["edges"]]
    expected = slack = 0.0
    for e, t in zip(costed["edges"], elapsed, strict=True):
        assert e["speed"] == e["speed_limit"]
        expected += e["length"] / e["speed_limit"] * 3600
        slack += 0.0005 / e["speed_limit"] * 3600  # lengths are given to the metre
        assert t == pytest.approx(expected, abs=0.01 + slack)
    # begin/end times come with the shape's times whatever use_timestamps says
    assert costed["edges"][0]["begin_time"] == timed[0]["begin_time"]


def test_miles(client: httpx.Client, trip: SimulatedTrip) -> None:
    shape = _shape(trip)
    km = _ok(client.post("/trace_attributes", json={"shape": shape, "costing": "auto"}))
    for units in ({"units": "miles"}, {"directions_options": {"units": "miles"}}):
        mi = _ok(
            client.post("/trace_attributes", json={"shape": shape, "costing": "auto", **units})
        )
        assert mi["units"] == "miles"
        for a, b in zip(km["edges"], mi["edges"], strict=True):
            assert b["length"] == pytest.approx(a["length"] / 1.609344, abs=1e-3)
            assert (
                b["speed_limit"] == round(a["speed_limit"] / 1.609344, 0)
                or abs(b["speed_limit"] - a["speed_limit"] / 1.609344) <= 1
            )


def test_encoded_polyline_with_durations_matches_like_shape(
    client: httpx.Client, trip: SimulatedTrip
) -> None:
    shape = _shape(trip)
    text = encode([(p["lat"], p["lon"]) for p in shape], 6)
    durations = [b["time"] - a["time"] for a, b in itertools.pairwise(shape)]
    request = {
        "encoded_polyline": text,
        "costing": "auto",
        "shape_match": "map_snap",
        "begin_time": shape[0]["time"],
        "durations": durations,
        "use_timestamps": True,
    }
    by_polyline = _ok(client.post("/trace_attributes", json=request))
    by_shape = _ok(
        client.post(
            "/trace_attributes", json={"shape": shape, "costing": "auto", "use_timestamps": True}
        )
    )
    assert [e["way_id"] for e in by_polyline["edges"]] == [e["way_id"] for e in by_shape["edges"]]
    assert by_polyline["edges"][-1]["end_time"] == by_shape["edges"][-1]["end_time"]
    get = client.get("/trace_attributes", params={"json": json.dumps(request)})
    assert _ok(get)["edges"] == by_polyline["edges"]


def test_a_break_marks_the_discontinuity(client: httpx.Client, trips: list[SimulatedTrip]) -> None:
    first, second = _shape(trips[0]), _shape(trips[1])
    offset = first[-1]["time"] + 1.0 - second[0]["time"]
    shape = first + [{**p, "time": p["time"] + offset} for p in second]
    reference = _v1(client, shape)
    doc = _ok(client.post("/trace_attributes", json={"shape": shape, "costing": "auto"}))
    points = doc["matched_points"]
    begins = [i for i, p in enumerate(points) if p.get("begin_route_discontinuity")]
    ends = [i for i, p in enumerate(points) if p.get("end_route_discontinuity")]
    assert ends == reference["breaks"]
    assert len(begins) == len(ends) >= 1
    assert all(b < e for b, e in zip(begins, ends, strict=True))


def test_warnings_name_what_is_not_used(client: httpx.Client, trip: SimulatedTrip) -> None:
    shape = _shape(trip)
    shape[3]["radius"] = 20
    request = {
        "shape": shape,
        "costing": "auto",
        "trace_options": {"gps_accuracy": 8, "search_radius": 40, "breakage_distance": 2000},
        "costing_options": {"auto": {"use_tolls": 0}},
        "id": "trip-7",
        "language": "de-DE",
    }
    doc = _ok(client.post("/trace_attributes", json=request))
    assert doc["id"] == "trip-7"
    text = " ".join(w["text"] for w in doc["warnings"])
    for words in ("radius of 1 shape point", "breakage_distance", "costing_options", "language"):
        assert words in text


# ----------------------------------------------------------------------------- errors


def _at(lon: float, time: float) -> dict[str, float]:
    return {"lat": 43.73, "lon": lon, "time": time}


@pytest.mark.parametrize(
    ("change", "code", "words"),
    [
        ({"costing": None}, 124, "costing"),
        ({"costing": "bicycle"}, 125, "bicycle"),
        ({"shape_match": "edge_walk"}, 445, "edge_walk"),
        ({"shape_match": "guess"}, 445, "guess"),
        ({"shape": None}, 126, "No shape"),
        ({"shape": [{"lat": 43.73, "lon": 7.42}]}, 123, "at least two"),
        ({"shape": [{"lat": 43.73, "lon": 7.42}, {"lat": "x", "lon": 7.42}]}, 134, "point 1"),
        ({"shape": [{"lat": 43.73, "lon": 7.42}, {"lat": 95, "lon": 7.42}]}, 134, "point 1"),
        ({"shape": [_at(7.42, 5), _at(7.4201, 4)]}, 134, "comes before"),
        ({"shape": [_at(7.42, 5), {"lat": 43.73, "lon": 7.4201}]}, 134, "or none"),
        ({"encoded_polyline": "~~~~"}, 134, "both"),
        ({"filters": {"attributes": ["edge.names"], "action": "keep"}}, 100, "include or exclude"),
        ({"units": "furlongs"}, 100, "kilometers or miles"),
        ({"trace_options": {"gps_accuracy": -1}}, 158, "sigma_m"),
        ({"trace_options": {"search_radius": "far"}}, 158, "search_radius"),
        ({"use_timestamps": True, "shape": [{"lat": 43.73, "lon": 7.42}] * 2}, 159, "time"),
        ({"network": "atlantis"}, 199, "atlantis"),
    ],
)
def test_bad_requests_answer_valhalla_codes(
    client: httpx.Client, change: dict[str, Any], code: int, words: str
) -> None:
    request: dict[str, Any] = {
        "shape": [{"lat": 43.7296, "lon": 7.4134}, {"lat": 43.7308, "lon": 7.4155}],
        "costing": "auto",
    }
    request.update(change)
    request = {k: v for k, v in request.items() if v is not None}
    assert words in _error(client.post("/trace_attributes", json=request), 400, code)


def test_polyline_and_body_errors(client: httpx.Client) -> None:
    bad = {"encoded_polyline": "~~~~", "costing": "auto"}
    assert "encoded_polyline" in _error(client.post("/trace_attributes", json=bad), 400, 134)
    durations = {
        "encoded_polyline": encode([(43.73, 7.42), (43.731, 7.421)], 6),
        "costing": "auto",
        "durations": [1, 2],
    }
    _error(client.post("/trace_attributes", json=durations), 400, 136)
    _error(client.post("/trace_attributes", content=b"{nope"), 400, 100)
    _error(client.post("/trace_attributes", content=b"[1, 2]"), 400, 100)
    _error(client.get("/trace_attributes"), 400, 100)
    many = {
        "shape": [{"lat": 43.73, "lon": 7.42 + 1e-5 * i} for i in range(1001)],
        "costing": "auto",
    }
    assert "1,000" in _error(client.post("/trace_attributes", json=many), 400, 153)


def test_same_token_as_v1_match(secured, token: str, trip: SimulatedTrip) -> None:
    import httpx

    body = {"shape": _shape(trip), "costing": "auto"}
    url = secured.base_url + "/trace_attributes"
    assert httpx.post(url, json=body, timeout=60).status_code == 401
    auth = {"Authorization": f"Bearer {token}"}
    _ok(httpx.post(url, json=body, headers=auth, timeout=60))
    _error(httpx.post(url, json={"costing": "auto"}, headers=auth, timeout=60), 400, 126)
    metrics = httpx.get(secured.base_url + "/metrics", headers=auth, timeout=60).text
    assert 'route="/trace_attributes"' in metrics
    assert 'mapmatch_matches_total{outcome="invalid_request"}' in metrics
