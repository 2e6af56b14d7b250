"""
``GET/POST /match/v1/{profile}/{coordinates}``: OSRM's match service (see :mod:`api.osrm_schemas`).

An OSRM client pointed at this service gets OSRM's answer shape and OSRM's error answers
(``{"code", "message"}``, HTTP 400 for a bad request), under the same token, limits, time
budget and metrics as ``POST /v1/match``. ``POST`` takes the same options as a form body
(``application/x-www-form-urlencoded``) for traces too long for a URL, and
``POST /match/v1/{profile}`` takes the coordinates in that body too.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Final

from fastapi import APIRouter, Request
from starlette.responses import Response  # noqa: TC002 - FastAPI reads the return type

from api.compat import compat_responses, respond, run_compat
from api.deps import get_settings
from api.errors import UnsupportedMediaTypeError
from api.intake import BodyLimits, read_limited_body
from api.osrm_schemas import (
    OPTIONS,
    OsrmErrorResponse,
    OsrmMatchResponse,
    OsrmRequestError,
    build_answer,
    build_input,
    osrm_error,
    parse_form,
    parse_request,
)

if TYPE_CHECKING:
    from api.service import MatchOutcome

__all__ = ["router"]

router = APIRouter(tags=["osrm"])

FORM: Final = "application/x-www-form-urlencoded"

_OPTION_DOCS: Final = {
    "timestamps": "Seconds since the UNIX epoch, one per coordinate, `;`-separated, "
    "non-decreasing. Optional: without them durations come from the speed limits.",
    "radiuses": "GPS accuracy (1-sigma, metres) per coordinate, `;`-separated; empty or 0 = "
    "unknown (5 m).",
    "bearings": "`{value},{range}` per coordinate, `;`-separated: the value is the heading "
    "(degrees from north); the range is checked but not used per fix.",
    "hints": "Hints of an earlier answer, one per coordinate; checked, not used.",
    "generate_hints": "`true` (default) or `false`: tracepoints carry a `hint`.",
    "approaches": "`unrestricted` (or empty) per coordinate; `curb` is refused.",
    "exclude": "Refused when not empty: the network has no classes to exclude.",
    "gaps": "`split` (default): a new matching where the time to the next fix is more than "
    "10 x the median interval; `ignore`.",
    "tidy": "`true`: drop a fix until 15 m and 5 s have passed since the last kept one; "
    "`false` (default).",
    "waypoints": "Coordinate indices, `;`-separated, first and last included: legs run "
    "between them only.",
    "steps": "`false` (default) only: turn-by-turn steps are not supported.",
    "annotations": "`false` (default), `true`, or a list of distance, duration, speed, "
    "weight, datasources (`nodes` is refused).",
    "geometries": "`polyline` (default), `polyline6` or `geojson`.",
    "overview": "`simplified` (default, 5 m), `full` or `false`.",
    "skip_waypoints": "`true`: leave out `tracepoints`.",
    "network": "This service's own: the network to match on (GET /v1/networks); default the first.",
}
_PARAMETERS: Final = [
    {
        "name": name,
        "in": "query",
        "required": False,
        "schema": {"type": "string"},
        "description": _OPTION_DOCS[name],
    }
    for name in OPTIONS
]
_FORM_BODY: Final[dict[str, Any]] = {
    "required": False,
    "description": "The same options as a form (and `coordinates`, without them in the path).",
    "content": {FORM: {"schema": {"type": "object", "additionalProperties": {"type": "string"}}}},
}
_RESPONSES: Final = compat_responses(
    OsrmMatchResponse, OsrmErrorResponse, "The matchings and tracepoints."
)


def _path_parameter(name: str, description: str) -> dict[str, Any]:
    return {
        "name": name,
        "in": "path",
        "required": True,
        "schema": {"type": "string"},
        "description": description,
    }


# read from the path by the route itself, so that no framework validation answers first
_VERSION = _path_parameter("version", "Protocol version: `v1`.")
_PROFILE = _path_parameter("profile", "`driving` (or `car`): the network's drivable roads.")
_COORDINATES = _path_parameter(
    "coordinates",
    "`{lon},{lat};{lon},{lat}...`, `polyline({polyline})` or `polyline6({polyline6})` "
    "(URL-encoded), optionally followed by `.json`.",
)


_MATCH: Final[dict[str, Any]] = {
    "summary": "OSRM-compatible match",
    "description": "OSRM's match service (project-osrm.org, Match service) on this matcher; "
    "what maps to what is in the README's HTTP section.",
    "response_model": None,
    "responses": _RESPONSES,
}
_IN_PATH: Final = [_VERSION, _PROFILE, _COORDINATES, *_PARAMETERS]


@router.get(
    "/match/{version}/{profile}/{coordinates}",
    **_MATCH,
    openapi_extra={"parameters": _IN_PATH},
)
@router.post(
    "/match/{version}/{profile}/{coordinates}",
    **_MATCH,
    openapi_extra={"parameters": _IN_PATH, "requestBody": _FORM_BODY},
)
async def osrm_match(request: Request) -> Response:
    """Match the coordinates in the path; options in the query (or a form body)."""
    path = request.path_params
    return await _answer(request, path["version"], path["profile"], path["coordinates"])


@router.post(
    "/match/{version}/{profile}",
    summary="OSRM-compatible match, coordinates in the body",
    description="As `/match/v1/{profile}/{coordinates}`, with `coordinates` and the options in "
    "a form body (`application/x-www-form-urlencoded`).",
    response_model=None,
    responses=_RESPONSES,
    openapi_extra={"parameters": [_VERSION, _PROFILE, *_PARAMETERS], "requestBody": _FORM_BODY},
)
async def osrm_match_form(request: Request) -> Response:
    """Match the coordinates of the form body."""
    path = request.path_params
    return await _answer(request, path["version"], path["profile"], None)


async def _answer(request: Request, version: str, profile: str, path: str | None) -> Response:
    async def work() -> MatchOutcome:
        settings = get_settings(request)
        params = list(request.query_params.multi_items())
        if request.method == "POST":
            params += await _form(request, BodyLimits.of(settings))
        coordinates = path
        if coordinates is None:
            given = [value for key, value in params if key == "coordinates"]
            if len(given) != 1:
                msg = "give the coordinates once: in the path, or as `coordinates` in the form"
                raise OsrmRequestError(msg, "InvalidUrl", field="coordinates")
            coordinates = given[0]
            params = [(k, v) for k, v in params if k != "coordinates"]
        return await run_compat(
            request,
            lambda: build_input(
                parse_request(version, profile, coordinates, params, max_points=settings.max_points)
            ),
            build_answer,
        )

    return await respond(request, work, osrm_error)


async def _form(request: Request, limits: BodyLimits) -> list[tuple[str, str]]:
    """The options of a POST body (none when it is empty)."""
    media = request.headers.get("content-type", "").split(";", 1)[0].strip().lower()
    body = await read_limited_body(request, "form", limits)
    if not body.strip():
        return []
    if media not in (FORM, ""):
        msg = f"cannot read a body of {media!r}; send the options as {FORM}"
        raise UnsupportedMediaTypeError(msg, field="Content-Type")
    return parse_form(body)
