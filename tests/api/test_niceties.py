"""Gzip answers, CORS, encoded polylines in and out (issue 16)."""

from __future__ import annotations

import asyncio
import gzip
import json
from typing import TYPE_CHECKING

import httpx
import pytest

from api.app import create_app
from api.polyline import decode, encode
from api.schemas import MatchQuery
from api.service import MatchOutcome
from api.settings import Settings

if TYPE_CHECKING:
    from pathlib import Path


def test_answers_are_gzipped_when_asked(client: httpx.Client, trip, bodies) -> None:
    body = {"points": bodies.points(trip.trace)}
    raw = httpx.post(
        client.base_url.join("/v1/match"),
        json=body,
        headers={"Accept-Encoding": "gzip"},
        timeout=60,
    )
    assert raw.headers["content-encoding"] == "gzip"
    assert raw.headers["vary"] == "Accept-Encoding"
    plain = client.post("/v1/match", json=body, headers={"Accept-Encoding": "identity"})
    assert "content-encoding" not in plain.headers
    assert raw.json()["features"] == plain.json()["features"]  # httpx inflated it
    assert int(raw.headers["content-length"]) < len(plain.content) / 3
    # the bytes on the wire are gzip indeed
    with httpx.stream(
        "POST", client.base_url.join("/v1/match"), json=body, headers={"Accept-Encoding": "gzip"}
    ) as stream:
        wire = b"".join(stream.iter_raw())
    assert json.loads(gzip.decompress(wire))["features"] == plain.json()["features"]


def test_an_outcome_is_gzipped_from_its_threshold_on_and_once() -> None:
    document = b'{"type":"FeatureCollection","features":[]}' * 40
    outcome = MatchOutcome(document, "t", "n", 2, 2, 0, 0.001)
    packed = outcome.gzipped(len(document))
    assert packed.content_encoding == "gzip"
    assert gzip.decompress(packed.content) == document
    assert packed.gzipped(1) is packed  # never twice
    assert outcome.gzipped(len(document) + 1) is outcome  # shorter than the threshold
    assert outcome.gzipped(0) is outcome  # 0: never
    assert outcome.gzipped(-1) is outcome


def test_the_service_gzips_an_answer_in_its_match_thread(cache_dir: Path, trip, bodies) -> None:
    service = create_app(Settings(cache_dir=str(cache_dir), access_log=False)).state.service
    service.networks.load_all()
    body = json.dumps({"points": bodies.points(trip.trace), "trace_id": "t"}).encode()
    try:
        plain = service.run(body, "json", MatchQuery())
        packed = asyncio.run(service.submit(body, "json", MatchQuery(), gzip_min_bytes=100))
        kept = asyncio.run(service.submit(body, "json", MatchQuery()))
    finally:
        service.runner.shutdown()
    assert packed.content_encoding == "gzip"
    document = json.loads(gzip.decompress(packed.content))
    assert document["features"] == json.loads(plain.content)["features"]
    assert kept.content_encoding is None
    assert json.loads(kept.content)["features"] == document["features"]


def test_cors_preflight_and_origin(start_thread_server, cache_dir: Path, token: str) -> None:
    settings = Settings(
        cache_dir=str(cache_dir),
        token=token,
        cors_origins="https://maps.example.org, https://ops.example.org",
        access_log=False,
    )
    auth = {"Authorization": f"Bearer {token}"}
    with start_thread_server(settings, ready_headers=auth) as server:
        preflight = httpx.options(
            server.base_url + "/v1/match",
            headers={
                "Origin": "https://maps.example.org",
                "Access-Control-Request-Method": "POST",
                "Access-Control-Request-Headers": "authorization, content-type",
            },
        )
        assert preflight.status_code == 200, preflight.text  # no token needed for it
        allowed = preflight.headers["access-control-allow-origin"]
        assert allowed == "https://maps.example.org"
        listing = httpx.get(
            server.base_url + "/v1/networks", headers={**auth, "Origin": "https://ops.example.org"}
        )
        assert listing.headers["access-control-allow-origin"] == "https://ops.example.org"
        assert "x-request-id" in listing.headers["access-control-expose-headers"].lower()
        other = httpx.get(
            server.base_url + "/v1/networks", headers={**auth, "Origin": "https://evil.example"}
        )
        assert "access-control-allow-origin" not in other.headers


@pytest.mark.parametrize("precision", [5, 6])
def test_polyline_in_matches_like_points(
    client: httpx.Client, trip, bodies, precision: int
) -> None:
    points = bodies.points(trip.trace, odometer=False)
    factor = 10**precision
    rounded = [
        {"time": p["time"], "lat": round(p["lat"] * factor) / factor,
         "lon": round(p["lon"] * factor) / factor}
        for p in points
    ]  # fmt: skip
    line = encode([(p["lat"], p["lon"]) for p in points], precision)
    by_points = client.post("/v1/match", json={"points": rounded})
    by_line = client.post(
        "/v1/match",
        json={"polyline": line, "precision": precision, "times": [p["time"] for p in points]},
    )
    assert by_line.status_code == 200, by_line.text
    assert by_line.json()["features"] == by_points.json()["features"]


def test_polyline_out_is_the_segment_path(client: httpx.Client, trip, bodies) -> None:
    body = {"points": bodies.points(trip.trace)}
    answer = client.post("/v1/match", json=body, params={"polyline": 6})
    assert answer.status_code == 200, answer.text
    segments = [f for f in answer.json()["features"] if f["properties"]["kind"] == "segment"]
    assert segments
    for seg in segments:
        decoded = decode(seg["properties"]["polyline"], 6)
        coords = seg["geometry"]["coordinates"]
        assert len(decoded) == len(coords)
        for (lat, lon), (x, y) in zip(decoded, coords, strict=True):
            assert (lat, lon) == pytest.approx((y, x), abs=1e-6)


@pytest.mark.parametrize(
    ("body", "field"),
    [
        ({"polyline": "_p~iF~ps|U_ulL\x01"}, "polyline"),
        ({"polyline": "_p~iF~ps|U_ulLnnqC_mqNvxq`@", "times": [0, 1]}, "times"),
        ({"polyline": "_p~iF~ps|U", "points": []}, "polyline"),
        ({"polyline": "_p~iF~ps|U_ulLnnqC", "precision": 7}, "precision"),
    ],
)
def test_a_bad_polyline_names_the_field(client: httpx.Client, body, field: str) -> None:
    answer = client.post("/v1/match", json=body)
    assert answer.status_code == 422, answer.text
    assert answer.json()["error"]["field"] == field
