"""
``POST /trace_attributes``: Valhalla's trace attributes (see :mod:`api.valhalla_schemas`).

A Valhalla client pointed at this service gets Valhalla's answer shape and Valhalla's error
object (``{"error_code", "error", "status_code", "status"}``), under the same token, limits,
time budget and metrics as ``POST /v1/match``. ``GET /trace_attributes?json={...}`` takes the
request in the query, as Valhalla does.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Final

from fastapi import APIRouter, Request
from starlette.responses import Response  # noqa: TC002 - FastAPI reads the return type

from api.compat import compat_responses, respond, run_compat
from api.deps import get_settings
from api.intake import BodyLimits, read_limited_body
from api.valhalla_schemas import (
    ValhallaErrorResponse,
    ValhallaRequestError,
    ValhallaResponse,
    build_answer,
    build_input,
    parse_request,
    valhalla_error,
)

if TYPE_CHECKING:
    from api.service import MatchOutcome

__all__ = ["router"]

router = APIRouter(tags=["valhalla"])

_BODY: Final[dict[str, Any]] = {
    "required": True,
    "description": "Valhalla's trace_attributes request: `shape` [{lat, lon, time?}] or "
    "`encoded_polyline` (precision 6), `costing` `auto`, `shape_match`, `filters`, `units`, "
    "`use_timestamps`, `trace_options`; read whatever the Content-Type.",
    "content": {"application/json": {"schema": {"type": "object"}}},
}
_RESPONSES: Final = compat_responses(
    ValhallaResponse, ValhallaErrorResponse, "The edges and matched points."
)
#: Read by the route itself, so that no framework validation answers first.
_JSON_PARAMETER: Final = {
    "name": "json",
    "in": "query",
    "required": True,
    "schema": {"type": "string"},
    "description": "The request as JSON text.",
}
_DESCRIPTION: Final = (
    "Valhalla's trace_attributes (valhalla.github.io, Map Matching service) on this "
    "matcher; what maps to what is in the README's HTTP section."
)


@router.post(
    "/trace_attributes",
    summary="Valhalla-compatible trace attributes",
    description=_DESCRIPTION,
    response_model=None,
    responses=_RESPONSES,
    openapi_extra={"requestBody": _BODY},
)
async def trace_attributes(request: Request) -> Response:
    """Match the body's shape and answer the attributes of the edges driven."""
    return await _answer(request, None)


@router.get(
    "/trace_attributes",
    summary="Valhalla-compatible trace attributes, request in the query",
    description=_DESCRIPTION,
    response_model=None,
    responses=_RESPONSES,
    openapi_extra={"parameters": [_JSON_PARAMETER]},
)
async def trace_attributes_get(request: Request) -> Response:
    """As ``POST /trace_attributes``, with the request in ``?json=``."""
    return await _answer(request, request.query_params.get("json", "").encode())


async def _answer(request: Request, query: bytes | None) -> Response:
    async def work() -> MatchOutcome:
        settings = get_settings(request)
        if query is None:
            body = await read_limited_body(request, "json", BodyLimits.of(settings))
        elif query:
            body = query
        else:
            msg = "Failed to parse json request: give the request as ?json={...}"
            raise ValhallaRequestError(100, msg, field="json")
        return await run_compat(
            request,
            lambda: build_input(parse_request(body, max_points=settings.max_points)),
            build_answer,
        )

    return await respond(request, work, valhalla_error)
