"""
The app factory: :func:`create_app` builds the service's FastAPI app from its settings.

``mapmatch serve`` calls it in every worker process with the :class:`~api.settings.Settings`
it built from the command line and the ``MAPMATCH_*`` environment (see :mod:`api.server`);
``uvicorn api.main:app`` serves one built from the environment alone.

Startup is fast: the server accepts connections at once and loads the networks in a thread;
``/healthz`` answers 200 from the start, ``/readyz`` and ``/v1/match`` 503 ``not_ready`` until
the networks are loaded and warmed up.
"""

from __future__ import annotations

import asyncio
import json
import logging
from contextlib import asynccontextmanager
from typing import TYPE_CHECKING, Any

from fastapi import FastAPI
from fastapi.exceptions import RequestValidationError
from fastapi.middleware.cors import CORSMiddleware
from fastapi.middleware.gzip import GZipMiddleware
from fastapi.openapi.utils import get_openapi
from fastapi.responses import Response
from starlette.exceptions import HTTPException as StarletteHTTPException

from api.compression import GZIP_LEVEL
from api.deps import BearerToken
from api.docs import add_docs
from api.errors import HTTP_CODES, error_answer, error_body
from api.logs import configure_logging
from api.metrics import ServiceMetrics
from api.middleware import SCOPE_KEY, ServiceMiddleware
from api.networks import NetworkRegistry
from api.routes import osrm, router, valhalla
from api.schemas import ErrorResponse, MatchRequest
from api.service import MatchService, validation_error
from api.settings import Settings
from roadnets.errors import MapMatchError

if TYPE_CHECKING:
    from collections.abc import AsyncIterator

    from fastapi import Request

__all__ = ["create_app"]

_log = logging.getLogger("api")

_DESCRIPTION = """
Match vehicle traces onto OpenStreetMap roads (HMM map matching) and check the matched length
against the vehicle's own trip distance.

Every error answers `{"error": {"code", "message", "field"?, "rows"?}}`; `code` is stable.
When the server runs with a token, every route but `/healthz` needs
`Authorization: Bearer <token>`.

**Limits.** Bodies up to `MAPMATCH_MAX_BODY_BYTES` (10 MB; more is 413 `body_too_large`),
traces up to `MAPMATCH_MAX_POINTS` (100 000; more is 413 `too_many_points`). A match request
has `MAPMATCH_TIME_BUDGET_S` (30 s) including its wait for one of the worker process's
`MAPMATCH_MATCH_THREADS` match threads. Past the budget it answers 504 `timeout` (or 503
`overloaded` if it never got a thread) at once. What that frees: the worker's event loop and
the connection. It does not stop the computation: Python cannot kill a thread and the matcher
has no cancellation points, so the match thread finishes its work, throws the result away and
only then takes the next request. The pool is bounded, so abandoned matches delay other
matches (503 `overloaded` when the pool and its queue are full) but never pile up threads.
Matching holds the GIL except in its numba kernels (routing, Viterbi), so a long match also
slows the other requests of its process; run several workers (`--workers N`) for throughput.
"""


def create_app(settings: Settings | None = None) -> FastAPI:
    """
    Build the service's app.

    Parameters
    ----------
    settings
        Deployment settings; default: read from the ``MAPMATCH_*`` environment.

    Returns
    -------
    FastAPI
        The app; its networks load in a thread when it starts (ASGI lifespan).
    """
    settings = settings or Settings()
    configure_logging()
    networks = NetworkRegistry(settings.networks, settings.cache_dir, settings.route_table_mb)
    service = MatchService(networks, settings)
    metrics = ServiceMetrics()

    @asynccontextmanager
    async def lifespan(_app: FastAPI) -> AsyncIterator[None]:
        loading = asyncio.ensure_future(asyncio.to_thread(networks.load_all))
        try:
            yield
        finally:
            service.runner.shutdown()
            if loading.done() and not loading.cancelled() and loading.exception() is not None:
                _log.error("network loading crashed", exc_info=loading.exception())

    app = FastAPI(
        title="mapmatch",
        version="1",
        description=_DESCRIPTION,
        lifespan=lifespan,
        docs_url=None,  # /docs and /redoc come from api.docs, with bundled offline files
        redoc_url=None,
        openapi_url="/openapi.json",
    )
    add_docs(app, assets=settings.docs_assets)
    app.state.settings = settings
    app.state.networks = networks
    app.state.service = service
    app.state.metrics = metrics
    app.include_router(router)
    app.include_router(osrm.router)  # OSRM- and Valhalla-compatible routes (issue 16)
    app.include_router(valhalla.router)
    app.add_exception_handler(MapMatchError, _project_error)
    app.add_exception_handler(RequestValidationError, _validation_error)
    app.add_exception_handler(StarletteHTTPException, _http_error)
    token = BearerToken(settings.token.get_secret_value()) if settings.token else None
    app.add_middleware(
        ServiceMiddleware, token=token, metrics=metrics, access_log=settings.access_log
    )
    if settings.gzip_min_bytes:  # inside CORS, outside auth: error answers are gzipped too
        app.add_middleware(
            GZipMiddleware, minimum_size=settings.gzip_min_bytes, compresslevel=GZIP_LEVEL
        )
    if settings.cors_origins:  # outermost: a preflight carries no token
        app.add_middleware(
            CORSMiddleware,
            allow_origins=list(settings.cors_origins),
            allow_methods=["GET", "POST"],
            allow_headers=["Authorization", "Content-Type", "Content-Encoding", "X-Request-ID"],
            expose_headers=["X-Request-ID", "Retry-After"],
            max_age=600,
        )
    app.openapi = lambda: _openapi(app, secured=token is not None)  # type: ignore[method-assign]
    return app


def _answer(request: Request, exc: BaseException) -> Response:
    answer = error_answer(exc)
    info = request.scope.get(SCOPE_KEY)
    if isinstance(info, dict):
        info["error"] = answer.code
    return Response(
        answer.body,
        status_code=answer.status,
        headers=answer.headers,
        media_type="application/json",
    )


async def _project_error(request: Request, exc: Exception) -> Response:
    return _answer(request, exc)


async def _validation_error(request: Request, exc: Exception) -> Response:
    assert isinstance(exc, RequestValidationError)
    return _answer(request, validation_error(list(exc.errors()), prefix=("query",)))


async def _http_error(request: Request, exc: Exception) -> Response:
    assert isinstance(exc, StarletteHTTPException)
    code = HTTP_CODES.get(exc.status_code, "http_error")
    info = request.scope.get(SCOPE_KEY)
    if isinstance(info, dict):
        info["error"] = code
    body = error_body(code, str(exc.detail))
    return Response(
        json.dumps(body).encode(),
        status_code=exc.status_code,
        headers=dict(exc.headers or {}),
        media_type="application/json",
    )


def _openapi(app: FastAPI, *, secured: bool) -> dict[str, Any]:
    """The OpenAPI document, with the JSON body model and (with a token) the bearer scheme."""
    if app.openapi_schema:
        return app.openapi_schema
    schema = get_openapi(
        title=app.title, version=app.version, description=app.description, routes=app.routes
    )
    components = schema.setdefault("components", {})
    models = components.setdefault("schemas", {})
    for model in (MatchRequest, ErrorResponse):  # referenced by hand (api.routes)
        body = model.model_json_schema(ref_template="#/components/schemas/{model}")
        for name, definition in body.pop("$defs", {}).items():
            models.setdefault(name, definition)
        models[model.__name__] = body
    if secured:
        components["securitySchemes"] = {
            "bearerAuth": {"type": "http", "scheme": "bearer", "description": "MAPMATCH_TOKEN"}
        }
        schema["security"] = [{"bearerAuth": []}]
        schema["paths"]["/healthz"]["get"]["security"] = []
    app.openapi_schema = schema
    return schema
