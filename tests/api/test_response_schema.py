"""The documented answer of POST /v1/match is what a real match produces, member for member."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

import mapmatch
from api import schemas
from api.schemas import MatchResponse

if TYPE_CHECKING:
    import httpx

    import roadnets
    from mapmatch.evaluation.simulate import SimulatedTrip


def _without_timings(doc: dict[str, Any]) -> dict[str, Any]:
    out = json.loads(json.dumps(doc))
    out["stats"].pop("timings_s")
    return out


def test_a_real_match_is_exactly_the_documented_answer(
    client: httpx.Client, default_net: roadnets.RoadNetwork, trips: list[SimulatedTrip], bodies
) -> None:
    for trip in trips:
        result = mapmatch.match(trip.trace, default_net)
        local = json.loads(json.dumps(result.to_geojson()))
        # every member documented (unknown ones are refused), every documented one present
        MatchResponse.model_validate(local)
        body = {"points": bodies.points(trip.trace), "trace_id": trip.trace.trace_id}
        answer = client.post("/v1/match", json=body)
        assert answer.status_code == 200, answer.text
        served = answer.json()
        MatchResponse.model_validate(served)
        # the service sends the library's document, nothing added or lost
        assert _without_timings(served) == _without_timings(local)


def test_openapi_answer_schema_is_the_response_model(client: httpx.Client) -> None:
    spec = client.get("/openapi.json").json()
    ok = spec["paths"]["/v1/match"]["post"]["responses"]["200"]["content"]
    schema = ok["application/geo+json"]["schema"]
    assert schema == {"$ref": "#/components/schemas/MatchResponse"}
    models = spec["components"]["schemas"]
    for name in ("MatchResponse", "StatsOut", "EdgeOut", "PointProperties", "SegmentProperties"):
        assert models[name]["additionalProperties"] is False, name
        assert set(models[name]["properties"]) == set(getattr(schemas, name).model_fields), name
