"""``POST /v1/match``: match one trace onto the road network and answer its GeoJSON."""

from __future__ import annotations

from typing import Any, Final

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse

from api.compression import accepts_gzip
from api.deps import MatchContextDep, match_query_parameters
from api.intake import MEDIA_TYPES, BodyLimits, body_format, read_limited_body
from api.middleware import SCOPE_KEY
from api.routes.common import error_responses
from api.schemas import MatchResponse

__all__ = ["GEOJSON", "MATCH_REQUEST_BODY", "GeoJSONResponse", "router"]

GEOJSON: Final = "application/geo+json"

#: The request body of ``POST /v1/match`` in OpenAPI (one schema per content type).
MATCH_REQUEST_BODY: Final[dict[str, Any]] = {
    "required": True,
    "description": (
        "A trace: a JSON object (`application/json`), or a GeoJSON (`application/geo+json`: "
        "Point features with a `time` property, or a LineString with `properties.times`), GPX "
        "(`application/gpx+xml`, one `<trk>`) or CSV (`text/csv`, a header row with time, lat, "
        "lon and optional heading, speed, accuracy, hdop, odometer, trace_id columns) document "
        "holding exactly one trace. For the file formats the query parameters carry network, "
        "trace_id, fused_distance_m, crs and the options."
    ),
    "content": {
        "application/json": {"schema": {"$ref": "#/components/schemas/MatchRequest"}},
        "application/geo+json": {
            "schema": {"type": "object", "description": "A GeoJSON FeatureCollection."}
        },
        "application/gpx+xml": {"schema": {"type": "string", "description": "A GPX 1.1 file."}},
        "text/csv": {"schema": {"type": "string", "description": "A CSV file with a header."}},
    },
}


class GeoJSONResponse(JSONResponse):
    """A GeoJSON document (``application/geo+json``), given as its finished bytes."""

    media_type = GEOJSON

    def render(self, content: object) -> bytes:
        """The bytes as they are (the service serialised them already)."""
        if isinstance(content, bytes):
            return content
        return super().render(content)


router = APIRouter(tags=["match"])


@router.post(
    "/v1/match",
    summary="Match one trace onto the road network",
    description=(
        "Answers a GeoJSON FeatureCollection (docs/DESIGN.md's output): one Feature per matched "
        "segment, then one per point. Content types read: " + ", ".join(MEDIA_TYPES) + "."
    ),
    response_class=GeoJSONResponse,
    responses={
        200: {
            "model": MatchResponse,
            "content": {GEOJSON: {"schema": {"$ref": "#/components/schemas/MatchResponse"}}},
            "description": "The match.",
        },
        **error_responses(400, 401, 404, 413, 415, 422, 500, 503, 504),
    },
    openapi_extra={"requestBody": MATCH_REQUEST_BODY, "parameters": match_query_parameters()},
)
async def match_trace(request: Request, context: MatchContextDep) -> GeoJSONResponse:
    """Match the body's trace and answer its GeoJSON (gzipped in the match thread if asked)."""
    settings, metrics = context.settings, context.metrics
    fmt = body_format(request.headers.get("content-type"))
    body = await read_limited_body(request, fmt, BodyLimits.of(settings))
    gzip_min_bytes = (
        settings.gzip_min_bytes if accepts_gzip(request.headers.get("accept-encoding")) else 0
    )
    outcome = await context.service.submit(body, fmt, context.query, gzip_min_bytes=gzip_min_bytes)
    request.scope[SCOPE_KEY].update(
        points=outcome.points, network=outcome.network, trace_id=outcome.trace_id
    )
    metrics.points.inc(outcome.points)
    metrics.matched_points.inc(outcome.matched_points)
    metrics.breaks.inc(outcome.breaks)
    metrics.match_seconds.observe(outcome.seconds)
    if outcome.content_encoding is None:
        return GeoJSONResponse(outcome.content)
    return GeoJSONResponse(
        outcome.content,
        headers={"content-encoding": outcome.content_encoding, "vary": "Accept-Encoding"},
    )
