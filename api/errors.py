"""
The one table from errors to HTTP answers, and the errors of the HTTP layer itself.

Every error answer has the body ``{"error": {"code", "message", "field"?, "rows"?}}``: ``code``
is stable (programs branch on it), ``message`` says what is wrong, with the offending value,
and how to fix it, ``field`` names the offending field (``points[3].lat``, ``options.sigma_m``,
``network``) and ``rows`` the offending 0-based points or rows of the trace.

Routes never build error answers themselves: they raise, and :func:`error_response` looks the
exception's class up in :data:`ERROR_TABLE` (most specific class first, along its MRO).
Anything not in the table is a bug of ours and answers 500 ``internal_error``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

from mapmatch.errors import (
    ConfigError,
    InvalidTraceError,
    MapMatchError,
    NoCandidatesError,
    RoadNetworkError,
    TraceFileError,
)

if TYPE_CHECKING:
    from collections.abc import Iterable, Mapping

__all__ = [
    "ERROR_TABLE",
    "HTTP_CODES",
    "INTERNAL_ERROR",
    "BodyTimeoutError",
    "BodyTooLargeError",
    "ErrorAnswer",
    "ErrorRule",
    "IncompleteBodyError",
    "InvalidEncodingError",
    "InvalidJSONError",
    "MatchTimeoutError",
    "NotReadyError",
    "OptionError",
    "OverBudgetError",
    "OverloadedError",
    "RepeatedParameterError",
    "RequestFieldError",
    "ServiceError",
    "TooManyColumnsError",
    "TooManyPointsError",
    "TripTooLargeError",
    "TripsFullError",
    "UnauthorizedError",
    "UnknownNetworkError",
    "UnknownTripError",
    "UnsupportedEncodingError",
    "UnsupportedMediaTypeError",
    "error_answer",
    "error_body",
    "rule_for",
]


class ServiceError(MapMatchError):
    """
    An error of the HTTP layer (the request, the service's limits or state), not of matching.

    Parameters
    ----------
    msg
        The complete human-readable message.
    field
        The offending request field, if one is at fault.
    """

    def __init__(self, msg: str, *, field: str | None = None) -> None:
        self.field = field
        super().__init__(msg)


class InvalidJSONError(ServiceError, ValueError):
    """The body is not well-formed JSON."""


class RequestFieldError(ServiceError, ValueError):
    """A field of the request other than the points or options is missing or wrong."""


class OptionError(ConfigError):
    """A request option is unknown, out of bounds or given twice; names the field."""


class UnknownNetworkError(ServiceError, LookupError):
    """The request names a network this service does not serve."""


class UnknownTripError(ServiceError, LookupError):
    """No live trip of that id is open in this worker (never made, closed or expired)."""


class TripsFullError(ServiceError, RuntimeError):
    """The worker holds ``MAPMATCH_MAX_TRIPS`` open live trips already."""


class TripTooLargeError(ServiceError, ValueError):
    """A live trip holds ``MAPMATCH_TRIP_MAX_BYTES`` already: it takes no more fixes."""


class UnsupportedMediaTypeError(ServiceError, ValueError):
    """The body's Content-Type is not one the route reads."""


class BodyTooLargeError(ServiceError, ValueError):
    """The body is larger than ``MAPMATCH_MAX_BODY_BYTES``."""


class TooManyPointsError(ServiceError, ValueError):
    """The trace has more points than ``MAPMATCH_MAX_POINTS``."""


class TooManyColumnsError(ServiceError, ValueError):
    """A CSV body has more columns than ``MAPMATCH_MAX_COLUMNS``."""


class OverBudgetError(ServiceError, ValueError):
    """Matching the request would need more memory than ``MAPMATCH_MEMORY_BUDGET_MB``."""


class UnsupportedEncodingError(ServiceError, ValueError):
    """The body's Content-Encoding is neither identity nor gzip."""


class InvalidEncodingError(ServiceError, ValueError):
    """The body says it is gzip (or looks like a gzip file) but cannot be decompressed."""


class BodyTimeoutError(ServiceError, TimeoutError):
    """The body did not arrive within ``MAPMATCH_BODY_TIMEOUT_S``."""


class IncompleteBodyError(ServiceError, ConnectionError):
    """The client closed the connection before its body ended."""


class RepeatedParameterError(ServiceError, ValueError):
    """A query parameter that takes one value was given several times."""


class UnauthorizedError(ServiceError, PermissionError):
    """The bearer token is missing or wrong."""


class NotReadyError(ServiceError, RuntimeError):
    """The service is still loading its road networks."""


class OverloadedError(ServiceError, RuntimeError):
    """Every match thread is busy and the request could not start within its time budget."""


class MatchTimeoutError(ServiceError, TimeoutError):
    """The match ran past the request's time budget."""


@dataclass(frozen=True, slots=True)
class ErrorRule:
    """How one error class answers: HTTP status, stable code, and when it happens."""

    error: type[BaseException]
    status: int
    code: str
    when: str


#: The one table; looked up along the raised class's MRO, so the most specific class wins.
ERROR_TABLE: Final[tuple[ErrorRule, ...]] = (
    ErrorRule(InvalidJSONError, 400, "invalid_json", "the body is not well-formed JSON"),
    ErrorRule(InvalidEncodingError, 400, "invalid_encoding", "a gzip body cannot be inflated"),
    ErrorRule(IncompleteBodyError, 400, "incomplete_body", "the client left mid-body"),
    ErrorRule(UnauthorizedError, 401, "unauthorized", "bearer token missing or wrong"),
    ErrorRule(UnknownNetworkError, 404, "unknown_network", "no served network has that id"),
    ErrorRule(UnknownTripError, 404, "unknown_trip", "no open live trip has that id here"),
    ErrorRule(TripTooLargeError, 413, "trip_too_large", "a live trip over MAPMATCH_TRIP_MAX_BYTES"),
    ErrorRule(BodyTooLargeError, 413, "body_too_large", "body over MAPMATCH_MAX_BODY_BYTES"),
    ErrorRule(TooManyPointsError, 413, "too_many_points", "more points than MAPMATCH_MAX_POINTS"),
    ErrorRule(
        TooManyColumnsError, 413, "too_many_columns", "more CSV columns than MAPMATCH_MAX_COLUMNS"
    ),
    ErrorRule(OverBudgetError, 413, "over_budget", "would need more than the memory budget"),
    ErrorRule(BodyTimeoutError, 408, "body_timeout", "the body arrived too slowly"),
    ErrorRule(
        UnsupportedEncodingError, 415, "unsupported_encoding", "Content-Encoding not readable"
    ),
    ErrorRule(
        UnsupportedMediaTypeError, 415, "unsupported_media_type", "Content-Type not readable"
    ),
    ErrorRule(RequestFieldError, 422, "invalid_request", "a request field is missing or wrong"),
    ErrorRule(
        RepeatedParameterError, 422, "repeated_parameter", "a one-value query option repeated"
    ),
    ErrorRule(
        InvalidTraceError, 422, "invalid_trace", "a point is missing, of a wrong type or range"
    ),
    ErrorRule(TraceFileError, 422, "invalid_body", "a GPX/CSV/GeoJSON body cannot be read"),
    ErrorRule(ConfigError, 422, "invalid_options", "an option is unknown or out of bounds"),
    ErrorRule(NoCandidatesError, 422, "no_road_nearby", "no point has a road nearby"),
    ErrorRule(NotReadyError, 503, "not_ready", "the networks are still loading"),
    ErrorRule(OverloadedError, 503, "overloaded", "no match thread freed up within the budget"),
    ErrorRule(TripsFullError, 503, "too_many_trips", "MAPMATCH_MAX_TRIPS live trips are open"),
    ErrorRule(MatchTimeoutError, 504, "timeout", "the match ran past its time budget"),
    ErrorRule(RoadNetworkError, 503, "network_unavailable", "a network failed to load"),
    ErrorRule(MapMatchError, 422, "unprocessable", "any other deliberate error of the core"),
)

#: Codes of the answers the framework gives by itself (unknown route, wrong method ...).
HTTP_CODES: Final[Mapping[int, str]] = {
    400: "bad_request",
    401: "unauthorized",
    403: "forbidden",
    404: "not_found",
    405: "method_not_allowed",
    406: "not_acceptable",
    413: "body_too_large",
    415: "unsupported_media_type",
    422: "invalid_request",
}

#: Status and code of a bug of ours (anything the table does not know).
INTERNAL_ERROR: Final = ErrorRule(Exception, 500, "internal_error", "a bug; see the server log")

_BY_CLASS: Final = {rule.error: rule for rule in ERROR_TABLE}


def rule_for(exc: BaseException) -> ErrorRule:
    """
    The table's rule for an exception: its own class's, else its nearest base class's.

    Examples
    --------
    >>> rule_for(UnknownNetworkError("no such network")).code
    'unknown_network'
    >>> rule_for(OptionError("sigma_m must be > 0")).status
    422
    >>> rule_for(KeyError("bug")).code
    'internal_error'
    """
    for cls in type(exc).__mro__:
        rule = _BY_CLASS.get(cls)
        if rule is not None:
            return rule
    return INTERNAL_ERROR


#: At most this many offending rows are listed in an error body; ``rows_total`` counts all.
MAX_ERROR_ROWS: Final = 100
#: Messages longer than this many characters are cut, saying how much was left out.
MAX_MESSAGE_CHARS: Final = 2_000


def error_body(
    code: str, message: str, *, field: str | None = None, rows: Iterable[int] = ()
) -> dict[str, dict[str, object]]:
    """
    The JSON error document ``{"error": {"code", "message", "field"?, "rows"?, "rows_total"?}}``.

    Bounded whatever the error: at most :data:`MAX_ERROR_ROWS` rows (``rows_total`` then
    counts them all and the message says how many more) and :data:`MAX_MESSAGE_CHARS`
    characters of message, so a body with a million bad rows answers a few KB.

    Examples
    --------
    >>> error_body("invalid_trace", "lat out of range", field="points[2].lat", rows=[2])
    {'error': {'code': 'invalid_trace', 'message': 'lat out of range', 'field': 'points[2].lat', 'rows': [2]}}
    >>> error_body("invalid_trace", "bad", rows=range(250))["error"]["rows_total"]
    250
    """  # noqa: E501
    if len(message) > MAX_MESSAGE_CHARS:
        cut = len(message) - MAX_MESSAGE_CHARS
        message = f"{message[:MAX_MESSAGE_CHARS]} ... and {cut:,} more characters"
    inner: dict[str, object] = {"code": code, "message": message}
    if field:
        inner["field"] = field[:200]
    listed: list[int] = []
    total = 0
    for row in rows:
        total += 1
        if total <= MAX_ERROR_ROWS:
            listed.append(int(row))
    if listed:
        inner["rows"] = listed
    if total > MAX_ERROR_ROWS:
        inner["rows_total"] = total
        inner["message"] = (
            f"{inner['message']} (rows lists {MAX_ERROR_ROWS}, and {total - MAX_ERROR_ROWS:,} more)"
        )
    return {"error": inner}


@dataclass(frozen=True, slots=True)
class ErrorAnswer:
    """The HTTP answer to an error: status, stable code, JSON body and extra headers."""

    status: int
    code: str
    body: bytes
    headers: dict[str, str]


def error_answer(exc: BaseException) -> ErrorAnswer:
    """
    The answer to a raised exception, from :data:`ERROR_TABLE`.

    Errors of the project carry ``field`` and ``rows`` where they know them; 401 adds
    ``WWW-Authenticate`` and the 503s a ``Retry-After``.
    """
    rule = rule_for(exc)
    if rule is INTERNAL_ERROR:
        message = "internal error; the server log has the details (search for the request id)"
    else:
        message = str(exc)
    field = getattr(exc, "field", None)
    rows: Iterable[int] = getattr(exc, "rows", ())
    body = error_body(
        rule.code, message, field=field if isinstance(field, str) else None, rows=rows
    )
    headers: dict[str, str] = {}
    if rule.status == 401:
        headers["WWW-Authenticate"] = 'Bearer realm="mapmatch"'
    if rule.status == 503:
        headers["Retry-After"] = "1"
    if rule.status in (408, 413):
        headers["Connection"] = "close"  # the rest of the body is not read
    return ErrorAnswer(rule.status, rule.code, json.dumps(body).encode(), headers)
