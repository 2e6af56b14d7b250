"""
The HTTP routes. Each one is thin: read the request, call the service, answer.

Errors are raised, never answered here: :mod:`api.errors` maps them to their status and code.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Any, Final, cast

from fastapi import APIRouter, Query, Request
from fastapi.responses import Response

from api.middleware import SCOPE_KEY
from api.schemas import (
    ErrorResponse,
    HealthResponse,
    MatchQuery,
    MatchResponse,
    NetworksResponse,
    ReadyResponse,
)
from api.service import MEDIA_TYPES, body_format, read_body

if TYPE_CHECKING:
    from api.metrics import ServiceMetrics
    from api.networks import NetworkRegistry
    from api.service import MatchService
    from api.settings import Settings

__all__ = ["MATCH_REQUEST_BODY", "router"]

GEOJSON: Final = "application/geo+json"


def _errors(*statuses: int) -> dict[int | str, dict[str, Any]]:
    described = {
        400: "Malformed JSON (`invalid_json`).",
        401: "Bearer token missing or wrong (`unauthorized`), when the server has a token.",
        404: "Unknown network (`unknown_network`).",
        413: "Body over the size limit (`body_too_large`) or too many points (`too_many_points`).",
        415: "Unsupported Content-Type (`unsupported_media_type`).",
        422: "A bad field, point, option or file (`invalid_request`, `invalid_trace`, "
        "`invalid_options`, `invalid_body`), or no road near the trace (`no_road_nearby`).",
        500: "A bug (`internal_error`); the log has the traceback under the request id.",
        503: "Networks still loading (`not_ready`) or failed (`network_unavailable`), or every "
        "match thread busy (`overloaded`).",
        504: "The match ran past the time budget (`timeout`).",
    }
    return {s: {"model": ErrorResponse, "description": described[s]} for s in statuses}


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

router = APIRouter()


@router.post(
    "/v1/match",
    summary="Match one trace onto the road network",
    description=(
        "Answers a GeoJSON FeatureCollection (DESIGN.md's output): one Feature per matched "
        "segment, then one per point. Content types read: " + ", ".join(MEDIA_TYPES) + "."
    ),
    response_class=Response,
    responses={
        200: {"model": MatchResponse, "content": {GEOJSON: {}}, "description": "The match."},
        **_errors(400, 401, 404, 413, 415, 422, 500, 503, 504),
    },
    openapi_extra={"requestBody": MATCH_REQUEST_BODY},
    tags=["match"],
)
async def match_trace(request: Request, query: Annotated[MatchQuery, Query()]) -> Response:
    """Match the body's trace and answer its GeoJSON."""
    service = cast("MatchService", request.app.state.service)
    settings = cast("Settings", request.app.state.settings)
    fmt = body_format(request.headers.get("content-type"))
    body = await read_body(request, settings.max_body_bytes)
    outcome = await service.submit(body, fmt, query)
    request.scope[SCOPE_KEY].update(
        points=outcome.points, network=outcome.network, trace_id=outcome.trace_id
    )
    metrics = cast("ServiceMetrics", request.app.state.metrics)
    metrics.points.inc(outcome.points)
    metrics.matched_points.inc(outcome.matched_points)
    metrics.breaks.inc(outcome.breaks)
    metrics.match_seconds.observe(outcome.seconds)
    return Response(outcome.content, media_type=GEOJSON)


@router.get(
    "/v1/networks",
    summary="The road networks this service matches on",
    response_model=NetworksResponse,
    responses=_errors(401, 500, 503),
    tags=["networks"],
)
async def list_networks(request: Request) -> NetworksResponse:
    """Id, source, bbox and counts of every network, the default first."""
    networks = cast("NetworkRegistry", request.app.state.networks)
    return NetworksResponse.model_validate({"networks": networks.describe()})


@router.get(
    "/healthz",
    summary="Liveness: the process answers",
    response_model=HealthResponse,
    responses=_errors(500),
    tags=["operations"],
)
async def healthz() -> HealthResponse:
    """Always 200 while the process serves; needs no token."""
    return HealthResponse(status="alive")


@router.get(
    "/readyz",
    summary="Readiness: every network is loaded",
    response_model=ReadyResponse,
    responses=_errors(401, 500, 503),
    tags=["operations"],
)
async def readyz(request: Request) -> ReadyResponse:
    """200 once the networks are loaded; 503 while loading or after a failure."""
    networks = cast("NetworkRegistry", request.app.state.networks)
    networks.get(None)
    return ReadyResponse(status="ready", networks=networks.ids())


@router.get(
    "/metrics",
    summary="Prometheus metrics",
    response_class=Response,
    responses={
        200: {"content": {"text/plain": {"schema": {"type": "string"}}}, "description": "Text."},
        **_errors(401, 500),
    },
    tags=["operations"],
)
async def metrics(request: Request) -> Response:
    """Request counts and latencies by route and status, points matched, breaks."""
    service_metrics = cast("ServiceMetrics", request.app.state.metrics)
    content, media_type = service_metrics.render()
    return Response(content, media_type=media_type)
