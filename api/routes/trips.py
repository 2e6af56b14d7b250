"""
``/v1/trips``: live trips, one vehicle's fixes matched as they arrive (:mod:`api.trips`).

(Over 400 lines on purpose: the four trip routes share their request models and the answers they
build.)

- ``POST /v1/trips`` opens a trip: ``{"trip_id"?, "network"?, "lag_s"?, "max_lag_s"?,
  "options"?}`` (all optional; an empty body is a trip with the defaults). 201.
- ``POST /v1/trips/{trip_id}/fixes`` adds one fix (a JSON object with ``time``, ``lat``,
  ``lon`` and optional ``heading``, ``speed``, ``accuracy`` or ``hdop``, ``odometer``), or a
  batch (a JSON array, or ``{"fixes": [...]}``), in time order. It answers what settled, the
  provisional position (unless ``?position=false``) and the running distance check. One bad
  fix answers 422 ``invalid_trace`` and leaves the trip as it was; in a batch, bad fixes are
  listed in ``rejected`` (their status, code and message each) and the others are added (422 when
  none is).
- ``GET /v1/trips/{trip_id}`` answers where the trip stands (its counts, position and check).
- ``DELETE /v1/trips/{trip_id}`` closes it and answers its match, the GeoJSON of
  ``POST /v1/match``.

Auth, request metrics and the access log are the middleware's, as for every route; bodies are
read under the same limits as ``POST /v1/match`` (size, gzip, points per request, time), and
the matching runs in the same match threads under the same time budget.
"""

from __future__ import annotations

import json
import math
import threading
from typing import TYPE_CHECKING, Annotated, Any, Final

from fastapi import APIRouter, Path, Query, Request
from fastapi.responses import Response
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from api.deps import (  # noqa: TC001 - FastAPI resolves them at runtime
    MetricsDep,
    ReadyNetworksDep,
    ServiceDep,
    SettingsDep,
)
from api.errors import RequestFieldError, rule_for
from api.intake import BodyLimits, read_limited_body
from api.middleware import SCOPE_KEY
from api.routes.common import ERROR_SCHEMA_REF
from api.routes.match import GeoJSONResponse
from api.schemas import MatchOptions  # noqa: TC001 - pydantic resolves it at runtime
from api.service import _config, parse_json, validation_error
from api.trips import Trip, TripRegistry
from mapmatch import InvalidTraceError
from mapmatch.export import geojson_bytes
from mapmatch.online import DEFAULT_LAG_S

if TYPE_CHECKING:
    from api.metrics import ServiceMetrics
    from api.settings import Settings
    from mapmatch import MatchedPoints
    from mapmatch.online import LiveDistance, LivePosition, LiveUpdate

__all__ = ["TripOpen", "get_trips", "router"]

router = APIRouter(tags=["live trips"])
_MAKING: Final = threading.Lock()


class TripOpen(BaseModel):
    """The JSON body of ``POST /v1/trips`` (every member optional)."""

    model_config = ConfigDict(extra="forbid")

    trip_id: str | None = Field(
        default=None,
        min_length=1,
        max_length=200,
        pattern=r"^[A-Za-z0-9._:~-]+$",
        description="The trip's id (e.g. the vehicle id and a trip number); default: a fresh "
        "one. Letters, digits and . _ : ~ - only.",
    )
    network: str | None = Field(
        default=None, min_length=1, max_length=200, description="Network id; default: the first."
    )
    lag_s: float = Field(
        default=DEFAULT_LAG_S,
        ge=0,
        allow_inf_nan=False,
        description="Seconds after which an observation may settle (trip time); at most "
        "MAPMATCH_TRIP_MAX_LAG_S.",
    )
    max_lag_s: float | None = Field(
        default=None,
        ge=0,
        allow_inf_nan=False,
        description="Seconds after which it settles whatever the window says; default 4 lags.",
    )
    options: MatchOptions | None = Field(
        default=None, description="Matcher parameters to override for this trip."
    )


def get_trips(request: Request) -> TripRegistry:
    """The app's live trips (made with the app's first trip request)."""
    state = request.app.state
    registry: TripRegistry | None = getattr(state, "trips", None)
    if registry is None:
        with _MAKING:
            registry = getattr(state, "trips", None)
            if registry is None:
                settings: Settings = state.settings
                metrics: ServiceMetrics = state.metrics
                registry = TripRegistry(settings, metrics)
                state.trips = registry
    return registry


def _responses(*errors: tuple[int, str]) -> dict[int | str, dict[str, Any]]:
    content = {"application/json": {"schema": {"$ref": ERROR_SCHEMA_REF}}}
    return {status: {"content": content, "description": text} for status, text in errors}


_AUTH = (401, "Bearer token missing or wrong (`unauthorized`), when the server has a token.")
_UNKNOWN = (
    404,
    "No such open trip here (`unknown_trip`): never opened, closed, expired, or open on "
    "another worker.",
)
_BODY = (
    413,
    "Body over the limits (`body_too_large`, `too_many_points`), or the trip holds its memory "
    "cap (`trip_too_large`).",
)
_BAD = (
    422,
    "A bad member or option (`invalid_request`, `invalid_options`), or bad fixes "
    "(`invalid_trace`; in a batch, only when none is accepted).",
)
_QUERY = (422, "A bad path or query parameter (`invalid_request`).")
_TRIP_ID = Path(description="The trip's id, as POST /v1/trips answered it.")
TripId = Annotated[str, _TRIP_ID]

_OPEN_SCHEMA = TripOpen.model_json_schema(ref_template="#/components/schemas/{model}")
_OPEN_SCHEMA.pop("$defs", None)  # MatchOptions: in the components already (POST /v1/match)
#: The request body of ``POST /v1/trips`` in OpenAPI.
OPEN_REQUEST_BODY: Final[dict[str, Any]] = {
    "required": False,
    "description": "The trip's id, network, lag and matcher options, all optional.",
    "content": {"application/json": {"schema": _OPEN_SCHEMA}},
}
#: The request body of ``POST /v1/trips/{trip_id}/fixes`` in OpenAPI.
FIXES_REQUEST_BODY: Final[dict[str, Any]] = {
    "required": True,
    "description": (
        "One fix (an object with time, lat, lon and optional heading, speed, accuracy or hdop, "
        'odometer), a JSON array of fixes, or {"fixes": [...]}, in time order.'
    ),
    "content": {
        "application/json": {
            "schema": {
                "oneOf": [{"type": "object"}, {"type": "array", "items": {"type": "object"}}]
            }
        }
    },
}

_BUSY = (
    503,
    "Networks loading (`not_ready`), every match thread busy (`overloaded`), or the worker "
    "holds MAPMATCH_MAX_TRIPS trips (`too_many_trips`).",
)


def _json(content: object, status: int = 200) -> Response:
    return Response(
        json.dumps(content, allow_nan=False).encode(),
        status_code=status,
        media_type="application/json",
    )


def _number(value: float, digits: int = 3) -> float | None:
    return None if not math.isfinite(value) else round(float(value), digits)


def _points(points: MatchedPoints, first: int) -> list[dict[str, Any]]:
    out = []
    for i in range(len(points.time_s)):
        matched = bool(points.matched[i])
        out.append(
            {
                "fix": first + i,
                "time": _number(points.time_s[i]),
                "matched": matched,
                "lon": _number(points.lon[i], 7),
                "lat": _number(points.lat[i], 7),
                "u": int(points.u[i]) if matched else None,
                "v": int(points.v[i]) if matched else None,
                "key": int(points.key[i]) if matched else None,
                "offset_m": _number(points.offset_m[i]),
                "distance_m": _number(points.distance_m[i]),
                "confidence": round(float(points.confidence[i]), 4),
                "segment": int(points.segment[i]) if matched else None,
                "interpolated": bool(points.interpolated[i]),
                "outlier": bool(points.outlier[i]),
            }
        )
    return out


def _position(position: LivePosition | None) -> dict[str, Any] | None:
    if position is None:
        return None
    return {
        "fix": position.fix,
        "time": _number(position.time_s),
        "lon": _number(position.lon, 7),
        "lat": _number(position.lat, 7),
        "u": position.u,
        "v": position.v,
        "key": position.key,
        "offset_m": _number(position.offset_m),
        "distance_m": _number(position.distance_m),
        "confidence": round(position.confidence, 4),
    }


def _distance(distance: LiveDistance) -> dict[str, Any]:
    out = distance.to_dict()
    for name in ("matched_length_m", "fused_length_m", "relative_error", "settled_until_s"):
        value = out.get(name)
        if isinstance(value, float):
            out[name] = _number(value, 6 if name == "relative_error" else 3)
    return out


def _update(trip: Trip, update: LiveUpdate, position: bool) -> dict[str, Any]:
    edges = []
    for segment, edge in zip(update.segments, update.edges, strict=True):
        item = edge.to_dict()
        item.pop("edge", None)  # the network's own index: not stable across builds
        for name in ("length_m", "start_offset_m", "end_offset_m", "speed_limit_kph"):
            item[name] = _number(item[name])
        edges.append({"segment": segment, **item})
    refused = rule_for(InvalidTraceError(""))  # each refused fix answers as one alone would
    return {
        "trip_id": trip.trip_id,
        "accepted": update.accepted,
        "merged": update.merged,
        "rejected": [
            {
                "index": r.index,
                "status": refused.status,
                "code": refused.code,
                "field": r.field,
                "message": r.message,
            }
            for r in update.rejected
        ],
        "settled": {
            "first_fix": update.first_fix,
            "points": _points(update.points, update.first_fix),
            "edges": edges,
        },
        "position": _position(trip.matcher.position()) if position else None,
        "distance": _distance(update.distance),
        "fixes": trip.matcher.fixes,
        "settled_fixes": trip.matcher.settled_fixes,
    }


@router.post(
    "/v1/trips",
    summary="Open a live trip",
    status_code=201,
    responses=_responses(_AUTH, (400, "Malformed JSON (`invalid_json`)."), _BAD, _BUSY),
    openapi_extra={"requestBody": OPEN_REQUEST_BODY},
)
async def open_trip(
    request: Request, settings: SettingsDep, networks: ReadyNetworksDep
) -> Response:
    """Open a trip and answer its id, network and lag."""
    body = await read_limited_body(request, "json", BodyLimits.of(settings))
    doc = parse_json(body) if body.strip() else {}
    if not isinstance(doc, dict):
        msg = 'the body must be a JSON object such as {"trip_id": "cab-7"}, or empty'
        raise RequestFieldError(msg)
    try:
        spec = TripOpen.model_validate(doc)
    except ValidationError as exc:
        raise validation_error(exc.errors(include_url=False)) from None
    registry = get_trips(request)
    if spec.lag_s > registry.max_lag_s or (spec.max_lag_s or 0.0) > 4 * registry.max_lag_s:
        msg = (
            f"lag_s is at most {registry.max_lag_s:g} s here (MAPMATCH_TRIP_MAX_LAG_S), max_lag_s "
            f"four times that (got lag_s {spec.lag_s:g}, max_lag_s {spec.max_lag_s})"
        )
        raise RequestFieldError(msg, field="lag_s")
    net = networks.get(spec.network)
    config = _config(spec.options.overrides() if spec.options else {})
    trip = registry.open(spec.trip_id, net, config, spec.lag_s, spec.max_lag_s)
    request.scope[SCOPE_KEY].update(trip_id=trip.trip_id, network=trip.network)
    return _json(
        {
            "trip_id": trip.trip_id,
            "network": trip.network,
            "lag_s": trip.matcher.lag_s,
            "max_lag_s": trip.matcher.max_lag_s,
            "idle_expiry_s": registry.idle_s,
            "max_fixes_per_request": settings.max_points,
        },
        status=201,
    )


@router.post(
    "/v1/trips/{trip_id}/fixes",
    summary="Add fixes to a live trip; answer what settled",
    responses=_responses(
        _AUTH, (400, "Malformed JSON (`invalid_json`)."), _UNKNOWN, _BODY, _BAD, _BUSY
    ),
    openapi_extra={"requestBody": FIXES_REQUEST_BODY},
)
async def add_fixes(
    request: Request,
    trip_id: TripId,
    settings: SettingsDep,
    service: ServiceDep,
    position: Annotated[bool, Query(description="Answer the provisional position too.")] = True,
) -> Response:
    """Add one fix or a batch, in time order."""
    registry = get_trips(request)
    trip = registry.get(trip_id)
    request.scope[SCOPE_KEY].update(trip_id=trip.trip_id, network=trip.network)
    body = await read_limited_body(request, "json", BodyLimits.of(settings))
    doc = parse_json(body)
    batch: list[object] | None = None
    if isinstance(doc, list):
        batch = doc
    elif isinstance(doc, dict) and set(doc) == {"fixes"}:
        fixes = doc["fixes"]
        if not isinstance(fixes, list):
            msg = '"fixes" must be a JSON array of fixes'
            raise RequestFieldError(msg, field="fixes")
        batch = fixes
    if batch is not None and len(batch) > settings.max_points:
        msg = f"{len(batch):,} fixes in one request; at most {settings.max_points:,} (send fewer)"
        raise RequestFieldError(msg, field="fixes")

    def push() -> dict[str, Any]:
        with trip.lock:
            registry.check_size(trip)
            if batch is None:
                update = trip.matcher.push(doc)  # type: ignore[arg-type]  # read_fix checks it
            else:
                update = trip.matcher.push_many(batch)  # type: ignore[arg-type]
                if update.rejected and not update.accepted and not update.merged:
                    first = update.rejected[0]
                    msg = f"none of the {len(batch)} fixes was accepted; the first: {first.message}"
                    rows = [r.index for r in update.rejected]
                    raise InvalidTraceError(
                        msg, trace_id=trip.trip_id, field=first.field, rows=rows
                    )
            return _update(trip, update, position)

    try:
        answer = await service.runner.run(push)
    except InvalidTraceError:
        registry.metrics.fixes.labels(outcome="rejected").inc(len(batch) if batch else 1)
        raise
    live = registry.metrics
    live.fixes.labels(outcome="accepted").inc(answer["accepted"])
    live.fixes.labels(outcome="merged").inc(answer["merged"])
    live.fixes.labels(outcome="rejected").inc(len(answer["rejected"]))
    live.settled.inc(len(answer["settled"]["points"]))
    request.scope[SCOPE_KEY].update(points=answer["accepted"])
    return _json(answer)


@router.get(
    "/v1/trips/{trip_id}",
    summary="Where a live trip stands",
    responses=_responses(_AUTH, _UNKNOWN, _QUERY, _BUSY),
)
async def get_trip(request: Request, trip_id: TripId, service: ServiceDep) -> Response:
    """Its counts, provisional position and running distance check."""
    registry = get_trips(request)
    trip = registry.get(trip_id)

    def look() -> dict[str, Any]:
        with trip.lock:
            live = trip.matcher
            return {
                "trip_id": trip.trip_id,
                "network": trip.network,
                "opened_at": round(trip.opened_at, 3),
                "lag_s": live.lag_s,
                "max_lag_s": live.max_lag_s,
                "fixes": live.fixes,
                "settled_fixes": live.settled_fixes,
                "merged": live.merged,
                "rejected": live.rejected,
                "position": _position(live.position()),
                "distance": _distance(live.distance()),
                "bytes": live.nbytes,
                "expires_in_s": round(registry.idle_s, 3),
            }

    return _json(await service.runner.run(look))


@router.delete(
    "/v1/trips/{trip_id}",
    summary="Close a live trip and answer its match",
    response_class=GeoJSONResponse,
    responses=_responses(
        _AUTH,
        _UNKNOWN,
        (422, "Fewer than 2 fixes (`invalid_trace`) or no road near any (`no_road_nearby`)."),
        _BUSY,
        (504, "The closing match ran past the time budget (`timeout`)."),
    ),
)
async def close_trip(
    request: Request, trip_id: TripId, service: ServiceDep, metrics: MetricsDep
) -> GeoJSONResponse:
    """The trip's MatchResult as GeoJSON; the trip is gone afterwards (even on an error)."""
    registry = get_trips(request)
    trip = registry.remove(trip_id)
    request.scope[SCOPE_KEY].update(trip_id=trip.trip_id, network=trip.network)
    registry.metrics.trips.labels(event="closed").inc()

    def close() -> bytes:
        with trip.lock:
            result = trip.matcher.close()
        metrics.points.inc(result.stats.points)
        metrics.matched_points.inc(result.stats.matched_points)
        metrics.breaks.inc(len(result.breaks))
        return geojson_bytes(result)

    return GeoJSONResponse(await service.runner.run(close))
