"""What the route modules share: the documented error answers of OpenAPI."""

from __future__ import annotations

from typing import Any, Final

__all__ = ["ERROR_SCHEMA_REF", "error_responses"]

_DESCRIBED: Final[dict[int, str]] = {
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


#: Where the error model sits in the OpenAPI document (:func:`api.app.create_app` puts it there).
ERROR_SCHEMA_REF: Final = "#/components/schemas/ErrorResponse"


def error_responses(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """
    The OpenAPI ``responses`` entries of these error statuses.

    Every error answers ``application/json`` in the :class:`~api.schemas.ErrorResponse`
    shape, whatever the route's own media type.
    """
    content = {"application/json": {"schema": {"$ref": ERROR_SCHEMA_REF}}}
    return {s: {"content": content, "description": _DESCRIBED[s]} for s in statuses}
