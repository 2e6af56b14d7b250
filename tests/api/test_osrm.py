"""OSRM's match service (``/match/v1/driving/...``) against a real ``mapmatch serve`` on loopback.

The documented examples are OSRM's own: its Node bindings' tests run on a Monaco extract with
three coordinates and timestamps (``test/nodejs/match.js`` in osrm-backend), and the embedded
network is Monaco, so the same requests are sent here with the same assertions; the response
shapes are OSRM's documented Route, RouteLeg, Annotation and Waypoint objects
(:class:`api.osrm_schemas.OsrmMatchResponse`, strict: an unknown member fails).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import pytest
import requests

from api.osrm_schemas import OsrmErrorResponse, OsrmMatchResponse
from api.polyline import decode, encode

if TYPE_CHECKING:
    import httpx

    from mapmatch.evaluation.simulate import SimulatedTrip

# OSRM's fixtures (osrm-backend test/nodejs/constants.js and match.js), on Monaco
THREE = [(7.41337, 43.72956), (7.41546, 43.73077), (7.41862, 43.73216)]
THREE_TIMES = [1424684612, 1424684616, 1424684620]
FOUR_SPLIT = [*THREE, (7.41902, 43.73487)]
FOUR_SPLIT_TIMES = [1700, 1750, 1424684616, 1424684620]
# Valhalla's documented trace (York, Pennsylvania): no network here covers it
YORK = [(-76.735741, 39.983841), (-76.735298, 39.983704), (-76.734848, 39.983578)]


def _path(coords: list[tuple[float, float]]) -> str:
    return "/match/v1/driving/" + ";".join(f"{lon},{lat}" for lon, lat in coords)


def _ok(answer: httpx.Response) -> dict[str, Any]:
    assert answer.status_code == 200, answer.text
    doc = answer.json()
    OsrmMatchResponse.model_validate(doc)  # the documented shape, nothing else
    assert doc["code"] == "Ok"
    return doc


def _error(answer: httpx.Response, status: int, code: str) -> str:
    assert answer.status_code == status, answer.text
    doc = answer.json()
    OsrmErrorResponse.model_validate(doc)
    assert doc["code"] == code, doc
    return str(doc["message"])


def _times(values: list[int] | list[float]) -> str:
    return ";".join(str(v) for v in values)


# ----------------------------------------------------------------------------- OSRM's examples


def test_match_in_monaco(client: httpx.Client) -> None:
    doc = _ok(client.get(_path(THREE), params={"timestamps": _times(THREE_TIMES)}))
    assert len(doc["matchings"]) == 1
    for m in doc["matchings"]:
        assert min(m["distance"], m["duration"], m["confidence"]) > 0
        assert isinstance(m["legs"], list)
        assert m["geometry"]
        assert len(m["legs"]) == 2
        assert sum(leg["distance"] for leg in m["legs"]) == pytest.approx(m["distance"], abs=0.2)
        assert (m["weight_name"], m["weight"]) == ("duration", m["duration"])
    assert len(doc["tracepoints"]) == 3
    for k, t in enumerate(doc["tracepoints"]):
        assert t["hint"]
        assert t["name"]
        assert (t["matchings_index"], t["waypoint_index"]) == (0, k)
        assert t["distance"] < 20  # metres from the input coordinate
        assert t["location"] == pytest.approx(THREE[k], abs=3e-4)
    # the timestamps are 4 s apart: the legs take that long
    assert [leg["duration"] for leg in doc["matchings"][0]["legs"]] == [4.0, 4.0]


def test_match_in_monaco_without_timestamps(client: httpx.Client) -> None:
    doc = _ok(client.get(_path(THREE)))
    assert len(doc["tracepoints"]) == 3
    assert len(doc["matchings"]) == 1
    m = doc["matchings"][0]
    # without times the duration is the speed-limit estimate, so a plausible town speed
    assert 2.0 < m["distance"] / m["duration"] < 30.0


def test_geometry_compression(client: httpx.Client) -> None:
    plain = _ok(client.get(_path(THREE), params={"geometries": "geojson", "overview": "full"}))
    line = plain["matchings"][0]["geometry"]
    assert line["type"] == "LineString"
    assert len(line["coordinates"]) >= 2
    compressed = _ok(client.get(_path(THREE), params={"overview": "full"}))
    text = compressed["matchings"][0]["geometry"]
    assert isinstance(text, str)
    decoded = [(lon, lat) for lat, lon in decode(text, 5)]
    assert np.allclose(decoded, line["coordinates"], atol=1e-5)
    six = _ok(client.get(_path(THREE), params={"geometries": "polyline6", "overview": "full"}))
    decoded6 = [[lon, lat] for lat, lon in decode(six["matchings"][0]["geometry"], 6)]
    assert np.allclose(decoded6, line["coordinates"], atol=1e-6)
    # simplified: no more vertices than full, same ends
    simple = _ok(client.get(_path(THREE), params={"geometries": "geojson"}))
    coords = simple["matchings"][0]["geometry"]["coordinates"]
    assert 2 <= len(coords) <= len(line["coordinates"])
    assert (coords[0], coords[-1]) == (line["coordinates"][0], line["coordinates"][-1])


def test_speed_annotations_only(client: httpx.Client) -> None:
    params = {
        "timestamps": _times(THREE_TIMES),
        "radiuses": "4.07;4.07;4.07",
        "annotations": "speed",
        "overview": "false",
        "geometries": "geojson",
    }
    m = _ok(client.get(_path(THREE), params=params))["matchings"][0]
    assert "geometry" not in m
    for leg in m["legs"]:
        assert leg["steps"] == []
        assert set(leg["annotation"]) == {"speed"}
        assert leg["annotation"]["speed"]


def test_several_annotations_and_the_full_geometry(client: httpx.Client) -> None:
    params = {
        "timestamps": _times(THREE_TIMES),
        "annotations": "duration,distance",
        "overview": "full",
        "geometries": "geojson",
    }
    m = _ok(client.get(_path(THREE), params=params))["matchings"][0]
    steps = 0
    for leg in m["legs"]:
        note = leg["annotation"]
        assert set(note) == {"duration", "distance"}
        assert len(note["duration"]) == len(note["distance"])
        assert sum(note["distance"]) == pytest.approx(leg["distance"], abs=0.2)
        assert sum(note["duration"]) == pytest.approx(
            leg["duration"], abs=0.1 * len(note["duration"])
        )
        steps += len(note["distance"])
    # one annotation per pair of consecutive coordinates of the full geometry
    assert steps == len(m["geometry"]["coordinates"]) - 1


def test_all_options(client: httpx.Client) -> None:
    params = {
        "timestamps": _times(THREE_TIMES),
        "radiuses": "4.07;4.07;4.07",
        "steps": "false",
        "annotations": "true",
        "overview": "false",
        "geometries": "geojson",
        "gaps": "split",
        "tidy": "false",
    }
    m = _ok(client.get(_path(THREE), params=params))["matchings"][0]
    assert m["confidence"] > 0
    for leg in m["legs"]:
        note = leg["annotation"]
        assert set(note) == {"distance", "duration", "speed", "weight", "datasources", "metadata"}
        assert note["datasources"] == [0] * len(note["distance"])  # from the timestamps
        assert note["metadata"]["datasource_names"][0] == "timestamps"
    assert "geometry" not in m


def test_waypoints_collapse_the_legs(client: httpx.Client) -> None:
    doc = _ok(client.get(_path(THREE), params={"waypoints": "0;2"}))
    assert len(doc["matchings"]) == 1
    assert len(doc["matchings"][0]["legs"]) == 1
    assert [t["waypoint_index"] for t in doc["tracepoints"]] == [0, None, 1]
    free = _ok(client.get(_path(THREE)))["matchings"][0]
    assert doc["matchings"][0]["distance"] == pytest.approx(free["distance"], abs=0.2)


@pytest.mark.parametrize(
    ("params", "code", "words"),
    [
        ({"waypoints": "0"}, "InvalidOptions", "at least two"),
        ({"waypoints": "1;2"}, "InvalidValue", "First and last"),
        ({"waypoints": "2;0"}, "InvalidValue", "First and last"),
        ({"waypoints": "0;3;2"}, "InvalidOptions", "indices of input coordinates"),
        ({"timestamps": "1424684612;1424684616"}, "InvalidOptions", "2 elements for 3"),
        ({"timestamps": "a;b;c"}, "InvalidQuery", "timestamps[0]"),
        ({"timestamps": "3;2;1"}, "InvalidValue", "monotonically increasing"),
        ({"gaps": "invalid gaps param"}, "InvalidQuery", "split, ignore"),
        ({"tidy": "invalid tidy param"}, "InvalidQuery", "true or false"),
        ({"radiuses": "5;-1;5"}, "InvalidValue", "radiuses[1]"),
        ({"radiuses": "5;unlimited;5"}, "InvalidValue", "standard deviation"),
        ({"bearings": "90,20;400,10;"}, "InvalidValue", "bearings[1]"),
        ({"bearings": "90;;"}, "InvalidQuery", "{value},{range}"),
        ({"annotations": "nodes"}, "InvalidOptions", "node ids"),
        ({"annotations": "colour"}, "InvalidQuery", "annotations"),
        ({"steps": "true"}, "InvalidOptions", "turn-by-turn"),
        ({"approaches": "curb;curb;curb"}, "InvalidOptions", "curb"),
        ({"exclude": "motorway"}, "InvalidOptions", "exclude"),
        ({"geometries": "wkt"}, "InvalidQuery", "polyline, polyline6, geojson"),
        ({"overview": "sometimes"}, "InvalidQuery", "simplified, full, false"),
        ({"alternatives": "true"}, "InvalidQuery", "unknown option 'alternatives'"),
        ({"network": "atlantis"}, "InvalidValue", "atlantis"),
    ],
)
def test_invalid_options_answer_osrm_codes(
    client: httpx.Client, params: dict[str, str], code: str, words: str
) -> None:
    message = _error(client.get(_path(THREE), params=params), 400, code)
    assert words in message


def test_a_split_trace_cannot_keep_its_waypoints(client: httpx.Client) -> None:
    params = {"timestamps": _times(FOUR_SPLIT_TIMES), "waypoints": "0;3"}
    _error(client.get(_path(FOUR_SPLIT), params=params), 400, "NoMatch")
    # without waypoints the huge gap in time splits the trace into matchings
    doc = _ok(client.get(_path(FOUR_SPLIT), params={"timestamps": _times(FOUR_SPLIT_TIMES)}))
    assert len(doc["matchings"]) >= 1
    assert "message" in doc  # 1700 -> 1750 s then a jump of years: the lone fixes are counted


@pytest.mark.parametrize(
    ("path", "code", "words"),
    [
        ("/match/v2/driving/7.41337,43.72956;7.41546,43.73077", "InvalidVersion", "v1"),
        ("/match/v1/foot/7.41337,43.72956;7.41546,43.73077", "InvalidOptions", "drivable"),
        ("/match/v1/driving/7.41337,43.72956", "InvalidOptions", "at least two"),
        ("/match/v1/driving/43.72956,95.0;7.41546,43.73077", "InvalidValue", "coordinate 0"),
        ("/match/v1/driving/7.41337;7.41546,43.73077", "InvalidQuery", "coordinate 0"),
        ("/match/v1/driving/polyline(~~~)", "InvalidQuery", "polyline"),
        ("/match/v1/driving/7.41337,43.72956;7.41546,43.73077.flatbuffers", "InvalidQuery", ""),
    ],
)
def test_malformed_urls_answer_osrm_codes(
    client: httpx.Client, path: str, code: str, words: str
) -> None:
    assert words in _error(client.get(path), 400, code)


def test_no_road_nearby_is_no_segment(client: httpx.Client) -> None:
    message = _error(client.get(_path(YORK)), 400, "NoSegment")
    assert "no road within" in message


def test_too_many_coordinates_is_too_big(client: httpx.Client) -> None:
    coords = [(7.41337 + 1e-5 * i, 43.72956) for i in range(1001)]  # the server takes 1000
    message = _error(
        client.post("/match/v1/driving", data={"coordinates": _coords(coords)}), 400, "TooBig"
    )
    assert "1,000" in message


def test_repeated_option_is_invalid_query(client: httpx.Client) -> None:
    answer = client.get(_path(THREE) + "?tidy=true&tidy=false")
    assert "twice" in _error(answer, 400, "InvalidQuery")


def _coords(coords: list[tuple[float, float]]) -> str:
    return ";".join(f"{lon:.7f},{lat:.7f}" for lon, lat in coords)


# ----------------------------------------------------------------------------- mapping


def test_polyline_coordinates_match_like_plain_ones(client: httpx.Client) -> None:
    plain = _ok(client.get(_path(THREE), params={"overview": "full"}))
    text = encode([(lat, lon) for lon, lat in THREE], 5)
    for form in (f"polyline({text})", f"polyline6({encode([(la, lo) for lo, la in THREE], 6)})"):
        doc = _ok(
            client.get(
                f"/match/v1/driving/{requests.utils.quote(form, safe='()')}",
                params={"overview": "full"},
            )
        )
        assert doc["matchings"][0]["distance"] == pytest.approx(
            plain["matchings"][0]["distance"], abs=1.0
        )


def test_tidy_drops_fixes_too_close_and_says_so(client: httpx.Client) -> None:
    # a car held at a light for 20 s (1 m of scatter), then it drives on
    held = [(7.41337 + 1e-6 * (i % 2), 43.72956) for i in range(20)]
    coords = [*held, THREE[1], THREE[2]]
    times = [*range(1_700_000_000, 1_700_000_020), 1_700_000_040, 1_700_000_060]
    params = {"timestamps": _times(times), "tidy": "true"}
    doc = _ok(client.get(_path(coords), params=params))
    points = doc["tracepoints"]
    assert len(points) == len(coords)
    # OSRM's tidy: one kept until 15 m and 5 s have passed, the last always kept
    assert points[0] is not None
    assert all(p is None for p in points[1:20])
    assert None not in points[20:]
    assert "19 removed by tidy" in doc["message"]
    untidy = _ok(client.get(_path(coords), params={"timestamps": _times(times)}))
    assert sum(p is not None for p in untidy["tracepoints"]) > 3


def test_gaps_split_or_ignore(client: httpx.Client, trip: SimulatedTrip) -> None:
    trace = trip.trace.slice(0, 40)
    times = trace.time_s.copy()
    times[20:] += 600.0  # ten minutes parked half-way, at 1 Hz
    coords = list(zip(trace.lon.tolist(), trace.lat.tolist(), strict=True))
    base = {"timestamps": _times([int(t) for t in times])}
    split = _ok(client.post("/match/v1/driving", data={"coordinates": _coords(coords), **base}))
    assert len(split["matchings"]) == 2
    assert {t["matchings_index"] for t in split["tracepoints"][:20]} == {0}
    assert {t["matchings_index"] for t in split["tracepoints"][20:]} == {1}
    data = {"coordinates": _coords(coords), **base, "gaps": "ignore"}
    ignored = _ok(client.post("/match/v1/driving", data=data))
    assert len(ignored["matchings"]) == 1


def test_bearings_and_radiuses_reach_the_matcher(client: httpx.Client) -> None:
    params = {
        "timestamps": _times(THREE_TIMES),
        "radiuses": ";0;8",  # empty and 0: unknown
        "bearings": "60,45;;70,30",
        "hints": ";;",
        "generate_hints": "false",
    }
    doc = _ok(client.get(_path(THREE), params=params))
    assert all("hint" not in t for t in doc["tracepoints"])
    skipped = _ok(client.get(_path(THREE), params={"skip_waypoints": "true"}))
    assert "tracepoints" not in skipped


# ----------------------------------------------------------------------------- real client


def _match_features(doc: dict[str, Any]) -> list[dict[str, Any]]:
    return [f for f in doc["features"] if f["properties"]["kind"] == "segment"]


def test_plain_requests_script_gets_the_route_of_v1_match(live, trip: SimulatedTrip) -> None:
    """What an OSRM user's script does: build the URL, GET it with requests, read the JSON."""
    trace = trip.trace
    coords = ";".join(f"{lon:.6f},{lat:.6f}" for lon, lat in zip(trace.lon, trace.lat, strict=True))
    stamps = ";".join(str(int(t)) for t in trace.time_s)
    url = f"{live.base_url}/match/v1/driving/{coords}"
    params = {"timestamps": stamps, "overview": "full", "geometries": "polyline6"}
    osrm = requests.get(url, params=params, timeout=60)
    assert osrm.status_code == 200, osrm.text
    answer = osrm.json()
    assert answer["code"] == "Ok"
    # the same fixes (rounded as in the URL) through POST /v1/match
    points = [
        {"time": float(int(t)), "lon": round(float(lon), 6), "lat": round(float(lat), 6)}
        for t, lon, lat in zip(trace.time_s, trace.lon, trace.lat, strict=True)
    ]
    ours = requests.post(f"{live.base_url}/v1/match", json={"points": points}, timeout=60)
    assert ours.status_code == 200, ours.text
    segments = _match_features(ours.json())
    assert len(answer["matchings"]) == len(segments) == 1
    line = [(round(lon, 6), round(lat, 6)) for lon, lat in segments[0]["geometry"]["coordinates"]]
    matched = [(lon, lat) for lat, lon in decode(answer["matchings"][0]["geometry"], 6)]
    # the same path: every vertex of /v1/match's line, in order, and only the places of the
    # tracepoints (where the legs meet) in between
    ours_line, theirs = _dedupe(line), _dedupe(matched)
    assert _in_order(ours_line, theirs)
    assert len(theirs) - len(ours_line) <= len(trace)
    assert answer["matchings"][0]["distance"] == pytest.approx(
        ours.json()["matched_length_m"], abs=0.5
    )
    names = [e["name"] for e in segments[0]["properties"]["edges"] if e["name"]]
    summaries = " ".join(leg["summary"] for leg in answer["matchings"][0]["legs"])
    assert set(summaries.replace(",", " ").split()) <= set(" ".join(names).split())
    assert all(tp is not None for tp in answer["tracepoints"])


def _in_order(part: list[tuple[float, float]], whole: list[tuple[float, float]]) -> bool:
    """Whether ``part`` is a subsequence of ``whole`` (positions equal within 1.5e-6 deg)."""
    k = 0
    for p in whole:
        if k < len(part) and abs(p[0] - part[k][0]) < 1.5e-6 and abs(p[1] - part[k][1]) < 1.5e-6:
            k += 1
    return k == len(part)


def _dedupe(line: list[tuple[float, float]]) -> list[tuple[float, float]]:
    out: list[tuple[float, float]] = []
    for p in line:
        if not out or p != out[-1]:
            out.append(p)
    return out


def test_form_post_of_a_long_trip_matches_like_get(
    client: httpx.Client, trip: SimulatedTrip
) -> None:
    trace = trip.trace
    coords = list(zip(trace.lon.tolist(), trace.lat.tolist(), strict=True))
    stamps = _times([int(t) for t in trace.time_s])
    get = _ok(client.get("/match/v1/driving/" + _coords(coords), params={"timestamps": stamps}))
    post = _ok(
        client.post(
            "/match/v1/driving", data={"coordinates": _coords(coords), "timestamps": stamps}
        )
    )
    assert post["matchings"] == get["matchings"]
    posted_options = _ok(
        client.post("/match/v1/driving/" + _coords(coords), data={"timestamps": stamps})
    )
    assert posted_options["matchings"] == get["matchings"]
    twice = client.post(
        "/match/v1/driving/" + _coords(coords) + "?timestamps=" + stamps,
        data={"timestamps": stamps},
    )
    _error(twice, 400, "InvalidQuery")
    wrong = client.post(
        "/match/v1/driving", content=b"{}", headers={"content-type": "application/json"}
    )
    _error(wrong, 415, "InvalidQuery")


# ----------------------------------------------------------------------------- service


def test_same_token_and_metrics_as_v1_match(secured, token: str) -> None:
    import httpx

    url = secured.base_url + _path(THREE)
    assert httpx.get(url, timeout=60).status_code == 401
    auth = {"Authorization": f"Bearer {token}"}
    answer = httpx.get(url, headers=auth, timeout=60)
    assert answer.status_code == 200, answer.text
    bad = httpx.get(url, params={"tidy": "maybe"}, headers=auth, timeout=60)
    assert bad.status_code == 400
    metrics = httpx.get(secured.base_url + "/metrics", headers=auth, timeout=60).text
    assert 'mapmatch_matches_total{outcome="ok"}' in metrics
    assert 'mapmatch_matches_total{outcome="invalid_request"}' in metrics
    assert 'route="/match/{version}/{profile}/{coordinates}"' in metrics
    assert "mapmatch_points_matched_total" in metrics
