"""Every kind of bad request gets its 4xx and stable error code, and the server keeps serving."""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import pytest

if TYPE_CHECKING:
    from collections.abc import Callable

    import httpx

    from mapmatch.evaluation.simulate import SimulatedTrip

JSON = {"content-type": "application/json"}
CSV = {"content-type": "text/csv"}


@dataclass(frozen=True)
class Case:
    """A bad request and the answer it must get."""

    build: Callable[[list[dict[str, Any]], bytes], dict[str, Any]]  # (points, csv) -> httpx kwargs
    status: int
    code: str
    field: str | None = None
    rows: list[int] | None = None
    says: str = ""  # a phrase the message must contain


def _with(points: list[dict[str, Any]], i: int, **changes: Any) -> list[dict[str, Any]]:
    out = [dict(p) for p in points]
    out[i].update(changes)
    return out


def _body(**members: Any) -> dict[str, Any]:
    return {"json": members}


def _raw(text: str | bytes, headers: dict[str, str] = JSON, **kw: Any) -> dict[str, Any]:
    return {"content": text.encode() if isinstance(text, str) else text, "headers": headers, **kw}


CASES: dict[str, Case] = {
    "malformed JSON": Case(lambda p, c: _raw('{"points": [1, 2'), 400, "invalid_json", says="JSON"),
    "body is a list": Case(lambda p, c: {"json": p}, 422, "invalid_request", says="JSON object"),
    "points missing": Case(lambda p, c: _body(trace_id="x"), 422, "invalid_trace", "points"),
    "wrong type": Case(
        lambda p, c: _body(points=_with(p, 1, lat="north")),
        422,
        "invalid_trace",
        "points[1].lat",
        [1],
        says="north",
    ),
    "NaN latitude": Case(
        lambda p, c: _raw(json.dumps({"points": _with(p, 2, lat=float("nan"))})),
        422,
        "invalid_trace",
        "points[2].lat",
        [2],
        says="finite",
    ),
    "latitude 95": Case(
        lambda p, c: _body(points=_with(p, 3, lat=95)),
        422,
        "invalid_trace",
        "points[3].lat",
        [3],
        says="90",
    ),
    "negative speed": Case(
        lambda p, c: _body(points=_with(p, 4, speed=-3)),
        422,
        "invalid_trace",
        "points[4].speed",
        [4],
    ),
    "time of a wrong type": Case(
        lambda p, c: _body(points=_with(p, 0, time=[1])),
        422,
        "invalid_trace",
        "points[0].time",
        [0],
    ),
    "unparsable time string": Case(
        lambda p, c: _body(points=_with(p, 2, time="yesterday")),
        422,
        "invalid_trace",
        "points[2].time",
        [2],
        says="yesterday",
    ),
    "empty trace": Case(lambda p, c: _body(points=[]), 422, "invalid_trace", "points", says="2"),
    "single point": Case(lambda p, c: _body(points=p[:1]), 422, "invalid_trace", "points"),
    "some points without a time": Case(
        lambda p, c: _body(points=[p[0], {k: v for k, v in p[1].items() if k != "time"}, p[2]]),
        422,
        "invalid_trace",
        "points[1].time",
        [1],
        says="leave the time column out",
    ),
    "trace off the map": Case(
        lambda p, c: _body(points=[{"time": i, "lat": 0.0, "lon": 0.001 * i} for i in range(5)]),
        422,
        "no_road_nearby",
        says="no road",
    ),
    "unknown network (body)": Case(
        lambda p, c: _body(points=p, network="atlantis"), 404, "unknown_network", "network"
    ),
    "unknown network (query)": Case(
        lambda p, c: _raw(c, CSV, params={"network": "atlantis"}), 404, "unknown_network"
    ),
    "sigma -1": Case(
        lambda p, c: _body(points=p, options={"sigma_m": -1}),
        422,
        "invalid_options",
        "options.sigma_m",
        says="greater than 0",
    ),
    "radius 10 km": Case(
        lambda p, c: _body(points=p, options={"search_radius_m": 10_000}),
        422,
        "invalid_options",
        "options.search_radius_m",
        says="200",
    ),
    "radius 10 km (query)": Case(
        lambda p, c: _raw(c, CSV, params={"search_radius_m": 10_000}),
        422,
        "invalid_options",
        "query.search_radius_m",
        says="200",
    ),
    "unknown option": Case(
        lambda p, c: _body(points=p, options={"max_search_radius_m": 500}),
        422,
        "invalid_options",
        "options.max_search_radius_m",
    ),
    "band of the wrong shape": Case(
        lambda p, c: _body(points=p, options={"distance_band": [0.1, 0.2]}),
        422,
        "invalid_options",
        "options.distance_band[0]",
    ),
    "option in body and query": Case(
        lambda p, c: {"json": {"points": p, "options": {"sigma_m": 4}}, "params": {"sigma_m": 4}},
        422,
        "invalid_options",
        "options.sigma_m",
        says="both",
    ),
    "unknown query parameter": Case(
        lambda p, c: _raw(c, CSV, params={"sigma": 4}), 422, "invalid_request", "query.sigma"
    ),
    "unknown body member": Case(
        lambda p, c: _body(points=p, colour="red"), 422, "invalid_request", "colour"
    ),
    "text/plain": Case(
        lambda p, c: _raw(c, {"content-type": "text/plain"}), 415, "unsupported_media_type"
    ),
    "no content type": Case(lambda p, c: _raw(c, {}), 415, "unsupported_media_type"),
    "CSV without a lat column": Case(
        lambda p, c: _raw(c.replace(b"lat,", b"latt,", 1), CSV), 422, "invalid_trace", "lat"
    ),
    "CSV latitude 95 on one row": Case(
        lambda p, c: _raw(_csv_with_lat(c, 4, "95.0"), CSV), 422, "invalid_trace", "lat", [4]
    ),
    "CSV of two traces": Case(
        lambda p, c: _raw(_two_traces(c), CSV), 422, "invalid_body", says="2 traces"
    ),
    "binary garbage as CSV": Case(
        lambda p, c: _raw(b"\x00\xff\xfe\x01" * 64, CSV), 422, "invalid_body"
    ),
    "GPX with entities": Case(
        lambda p, c: _raw(
            '<?xml version="1.0"?><!DOCTYPE gpx [<!ENTITY a "aaaa">]><gpx><trk><name>&a;</name>'
            "</trk></gpx>",
            {"content-type": "application/gpx+xml"},
        ),
        422,
        "invalid_body",
    ),
    "GeoJSON that is not JSON": Case(
        lambda p, c: _raw("nope", {"content-type": "application/geo+json"}), 422, "invalid_body"
    ),
    "body over the size limit": Case(
        lambda p, c: _raw(c * 40, CSV), 413, "body_too_large", says="300,000"
    ),
    "more points than the limit": Case(
        lambda p, c: _body(points=[dict(p[0], time=float(i)) for i in range(1001)]),
        413,
        "too_many_points",
        "points",
        says="1,000",
    ),
    "more CSV rows than the limit": Case(
        lambda p, c: _raw(_repeat_rows(c, 1001), CSV), 413, "too_many_points"
    ),
}


def _csv_with_lat(csv: bytes, row: int, value: str) -> bytes:
    lines = csv.decode().splitlines()
    header = lines[0].split(",")
    cells = lines[row + 1].split(",")
    cells[header.index("lat")] = value
    lines[row + 1] = ",".join(cells)
    return ("\n".join(lines) + "\n").encode()


def _two_traces(csv: bytes) -> bytes:
    lines = csv.decode().splitlines()
    half = len(lines) // 2
    rows = [f"{'a' if i < half else 'b'},{line}" for i, line in enumerate(lines[1:])]
    return ("trace_id," + lines[0] + "\n" + "\n".join(rows) + "\n").encode()


def _repeat_rows(csv: bytes, count: int) -> bytes:
    lines = csv.decode().splitlines()
    header = lines[0].split(",")
    first = lines[1].split(",")
    rows = []
    for i in range(count):
        first[header.index("time")] = str(1_700_000_000 + i)
        rows.append(",".join(first))
    return ("\n".join([lines[0], *rows]) + "\n").encode()


@pytest.fixture(scope="module")
def good(trip: SimulatedTrip, bodies) -> tuple[list[dict[str, Any]], bytes]:
    content, _ = bodies.file("csv", trip.trace)
    return bodies.points(trip.trace), content


@pytest.mark.parametrize("name", list(CASES))
def test_bad_request_gets_its_error(client: httpx.Client, good, name: str) -> None:
    case = CASES[name]
    points, csv = good
    answer = client.post("/v1/match", **case.build(points, csv))
    assert answer.status_code == case.status, answer.text
    assert answer.headers["content-type"] == "application/json"
    error = answer.json()["error"]
    assert error["code"] == case.code, error
    assert error["message"]
    if case.field is not None:
        assert error.get("field") == case.field, error
    if case.rows is not None:
        assert error.get("rows") == case.rows, error
    assert case.says in error["message"], error
    # and the server keeps serving
    assert client.get("/healthz").status_code == 200


def test_not_found_and_wrong_method_answer_in_the_error_shape(client: httpx.Client) -> None:
    missing = client.get("/v2/match")
    assert missing.status_code == 404
    assert missing.json()["error"]["code"] == "not_found"
    wrong = client.get("/v1/match")
    assert wrong.status_code == 405
    assert wrong.json()["error"]["code"] == "method_not_allowed"


def test_no_bad_request_produced_a_server_error(client: httpx.Client, good) -> None:
    # runs after the table above: the server is up, matches, and never answered 5xx
    points, _ = good
    for case in CASES.values():
        client.post("/v1/match", **case.build(points, good[1]))
    assert client.post("/v1/match", json={"points": points}).status_code == 200
    text = client.get("/metrics").text
    pattern = r'mapmatch_http_requests_total\{[^}]*route="([^"]+)",status="(\d+)"'
    answered = re.findall(pattern, text)
    assert ("/v1/match", "422") in answered, text
    # /readyz answers 503 while the server starts; nothing else may be a 5xx
    assert [(r, s) for r, s in answered if s.startswith("5") and r != "/readyz"] == []
