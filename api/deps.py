"""
What a route needs from the app, handed to it per request (FastAPI dependencies).

Routes declare what they use (``settings: SettingsDep``, ``networks: ReadyNetworksDep`` ...)
instead of reaching into ``request.app.state``; the objects live on the app that
:func:`api.app.create_app` built, one set per app, so several apps can share a process.

Authentication is checked here too (:class:`BearerToken`), but it is applied by
:class:`api.middleware.ServiceMiddleware` to every path, the documentation pages, their static
files and unknown routes included: a route-level dependency would leave the mounts open and let
a 404 tell a caller without a token which routes exist.
"""

from __future__ import annotations

import secrets
from dataclasses import dataclass
from typing import TYPE_CHECKING, Annotated, TypeVar

from fastapi import Depends, Request
from fastapi.exceptions import RequestValidationError
from pydantic import ValidationError

from api.errors import RepeatedParameterError, UnauthorizedError
from api.metrics import ServiceMetrics
from api.networks import NetworkRegistry
from api.schemas import MatchQuery
from api.service import MatchService
from api.settings import Settings

if TYPE_CHECKING:
    from collections.abc import Awaitable, Callable

T = TypeVar("T")

__all__ = [
    "BearerToken",
    "MatchContext",
    "MatchContextDep",
    "MetricsDep",
    "NetworksDep",
    "ReadyNetworksDep",
    "ServiceDep",
    "SettingsDep",
    "get_metrics",
    "get_networks",
    "get_service",
    "get_settings",
    "match_context",
    "match_query",
    "match_query_parameters",
    "on_the_loop",
    "ready_networks",
    "single_valued_query",
]

#: Query parameters of ``POST /v1/match`` that take several values (a band is two numbers).
_LISTS = frozenset(
    name
    for name, prop in MatchQuery.model_json_schema()["properties"].items()
    if "array" in (prop.get("type"), *(sub.get("type") for sub in prop.get("anyOf", ())))
)


def get_settings(request: Request) -> Settings:
    """The deployment settings of the app serving ``request``."""
    value: Settings = request.app.state.settings
    return value


def get_networks(request: Request) -> NetworkRegistry:
    """The app's networks, loaded or not."""
    value: NetworkRegistry = request.app.state.networks
    return value


def ready_networks(request: Request) -> NetworkRegistry:
    """
    The app's networks, once every one is loaded.

    Raises
    ------
    NotReadyError
        Still loading (503 ``not_ready``), before any body is read.
    RoadNetworkError
        Loading failed (503 ``network_unavailable``).
    """
    networks = get_networks(request)
    networks.get(None)
    return networks


def get_service(request: Request) -> MatchService:
    """The app's match service (its thread pool and limits)."""
    value: MatchService = request.app.state.service
    return value


def get_metrics(request: Request) -> ServiceMetrics:
    """The app's Prometheus metrics."""
    value: ServiceMetrics = request.app.state.metrics
    return value


def on_the_loop(accessor: Callable[[Request], T]) -> Callable[[Request], Awaitable[T]]:
    """
    ``accessor`` as an ``async`` dependency, called on the event loop.

    FastAPI runs a plain ``def`` dependency in a worker thread: two thread hops and a lock
    handed over per dependency and request, for a lookup that takes a microsecond (26 % of
    the interpreter lock's time under load went to solving five of them).
    """

    async def dependency(request: Request) -> T:
        return accessor(request)

    dependency.__name__ = dependency.__qualname__ = accessor.__name__
    dependency.__doc__ = accessor.__doc__
    return dependency


SettingsDep = Annotated[Settings, Depends(on_the_loop(get_settings))]
NetworksDep = Annotated[NetworkRegistry, Depends(on_the_loop(get_networks))]
ReadyNetworksDep = Annotated[NetworkRegistry, Depends(on_the_loop(ready_networks))]
ServiceDep = Annotated[MatchService, Depends(on_the_loop(get_service))]
MetricsDep = Annotated[ServiceMetrics, Depends(on_the_loop(get_metrics))]


class BearerToken:
    """
    The bearer token a server requires, compared in constant time.

    Examples
    --------
    >>> check = BearerToken("s3cret")
    >>> check.problem("Bearer s3cret") is None
    True
    >>> check.problem("Basic czNjcmV0")
    "the Authorization header must be 'Bearer <token>'"
    """

    def __init__(self, token: str) -> None:
        self._token = token.encode()

    def problem(self, header: str | None) -> str | None:
        """What is wrong with an ``Authorization`` header, or ``None`` when it is right."""
        if not header:
            return "this service requires a bearer token: send 'Authorization: Bearer <token>'"
        scheme, _, credentials = header.partition(" ")
        if scheme.lower() != "bearer" or not credentials.strip():
            return "the Authorization header must be 'Bearer <token>'"
        if not secrets.compare_digest(credentials.strip().encode(), self._token):
            return "the bearer token is wrong"
        return None

    def check(self, header: str | None) -> None:
        """
        Raise when the header is not the token.

        Raises
        ------
        UnauthorizedError
            Missing, malformed or wrong (401 ``unauthorized``).
        """
        problem = self.problem(header)
        if problem is not None:
            raise UnauthorizedError(problem)


def single_valued_query(request: Request) -> None:
    """
    Refuse a query parameter given more than once (only list-valued ones may repeat).

    Raises
    ------
    RepeatedParameterError
        422 ``repeated_parameter`` naming ``query.<name>``, instead of silently keeping one.
    """
    seen: dict[str, int] = {}
    for key, _value in request.query_params.multi_items():
        seen[key] = seen.get(key, 0) + 1
    twice = sorted(k for k, count in seen.items() if count > 1 and k not in _LISTS)
    if twice:
        name = twice[0]
        msg = (
            f"query parameter {name!r} is given {seen[name]} times; it takes one value, give "
            "it once"
        )
        raise RepeatedParameterError(msg, field=f"query.{name}")


def match_query(request: Request) -> MatchQuery:
    """
    The query parameters of ``POST /v1/match``, read into a :class:`MatchQuery` directly.

    FastAPI's reading of a query model walks every field's annotation on every request
    (about 0.6 ms of a 100-point match's 5 ms in the service, nearly all of it for an empty
    query). This reads the parameters given, the list-valued ones as lists, and validates
    once; a bad value is the same ``RequestValidationError`` (at ``query.<name>``) FastAPI
    raises. :func:`match_query_parameters` documents them in OpenAPI.
    """
    params = request.query_params
    if not params:
        return MatchQuery()
    given = {key: params.getlist(key) if key in _LISTS else params[key] for key in params}
    try:
        return MatchQuery.model_validate(given)
    except ValidationError as exc:
        errors = [{**e, "loc": ("query", *e["loc"])} for e in exc.errors(include_url=False)]
        raise RequestValidationError(errors) from None


def match_query_parameters() -> list[dict[str, object]]:
    """The OpenAPI ``parameters`` of :func:`match_query`, from :class:`MatchQuery`'s schema."""
    return [
        {
            "name": name,
            "in": "query",
            "required": False,
            "schema": {k: v for k, v in prop.items() if k != "default"},
            "description": prop.get("description", ""),
        }
        for name, prop in MatchQuery.model_json_schema()["properties"].items()
    ]


@dataclass(frozen=True, slots=True)
class MatchContext:
    """
    What ``POST /v1/match`` reads per request, solved as one dependency.

    FastAPI solves each dependency of a request on the event loop; the match route's six, one
    by one, were about a fifth of the app's own CPU per request (190 against 148 us, the match
    stubbed). ``query`` is :func:`match_query`'s, the rest the app's own objects.
    """

    query: MatchQuery
    settings: Settings
    service: MatchService
    metrics: ServiceMetrics


def match_context(request: Request) -> MatchContext:
    """
    The match route's query and the app's objects, in the order it checks them.

    Raises
    ------
    RepeatedParameterError
        A query parameter given twice (:func:`single_valued_query`).
    RequestValidationError
        A bad query parameter (:func:`match_query`).
    NotReadyError, RoadNetworkError
        The networks are still loading or failed to (:func:`ready_networks`).
    """
    single_valued_query(request)
    query = match_query(request)
    ready_networks(request)
    return MatchContext(query, get_settings(request), get_service(request), get_metrics(request))


MatchContextDep = Annotated[MatchContext, Depends(on_the_loop(match_context))]
