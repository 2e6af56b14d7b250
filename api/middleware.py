"""
The one middleware around every request.

It sets the request id, checks the bearer token, catches bugs, counts Prometheus metrics and
writes the JSON access log. It is a plain ASGI middleware (no per-request task, no body
buffering). It sits inside Starlette's ``ServerErrorMiddleware`` and catches whatever the routes
and exception handlers let through, so a bug answers ``500 internal_error`` in the API's error
shape, its traceback goes to the log with the request id, and the worker carries on.
"""

from __future__ import annotations

import logging
import re
import time
import uuid
from typing import TYPE_CHECKING, Final

from starlette.datastructures import Headers, MutableHeaders

from api.errors import UnauthorizedError, error_answer, rule_for
from api.logs import ACCESS_LOGGER

if TYPE_CHECKING:
    from starlette.types import ASGIApp, Message, Receive, Scope, Send

    from api.deps import BearerToken
    from api.metrics import ServiceMetrics

__all__ = ["SCOPE_KEY", "ServiceMiddleware", "send_error"]

#: Key of the per-request dict in the ASGI scope that routes fill for logs and metrics.
SCOPE_KEY: Final = "mapmatch"
_OPEN_PATHS: Final = frozenset({"/healthz"})
_REQUEST_ID = re.compile(r"[A-Za-z0-9._:-]{1,64}")
_log = logging.getLogger("api")
_access = logging.getLogger(ACCESS_LOGGER)


async def send_error(send: Send, exc: BaseException) -> None:
    """Answer ``exc`` in the API's error shape (status, code, message from the error table)."""
    answer = error_answer(exc)
    headers = [
        (b"content-type", b"application/json"),
        (b"content-length", b"%d" % len(answer.body)),
    ]
    headers += [(k.lower().encode(), v.encode()) for k, v in answer.headers.items()]
    await send({"type": "http.response.start", "status": answer.status, "headers": headers})
    await send({"type": "http.response.body", "body": answer.body})


class ServiceMiddleware:
    """
    Wrap the app: request id, auth, catch-all, metrics, access log.

    Parameters
    ----------
    app
        The ASGI app inside.
    token
        The bearer token every path but ``/healthz`` requires; ``None`` = no authentication.
    metrics
        Where request counts and latencies go.
    access_log
        Whether to write one JSON line per request.
    """

    def __init__(
        self,
        app: ASGIApp,
        *,
        token: BearerToken | None,
        metrics: ServiceMetrics,
        access_log: bool,
    ) -> None:
        self.app = app
        self._token = token
        self._metrics = metrics
        self._access_log = access_log

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Handle one ASGI connection scope."""
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = time.perf_counter()
        headers = Headers(scope=scope)
        given_id = headers.get("x-request-id", "")
        request_id = given_id if _REQUEST_ID.fullmatch(given_id) else uuid.uuid4().hex
        info: dict[str, object] = {"request_id": request_id}
        scope[SCOPE_KEY] = info
        status = 500
        response_started = False

        async def send_wrapper(message: Message) -> None:
            nonlocal status, response_started
            if message["type"] == "http.response.start":
                response_started = True
                status = int(message["status"])
                MutableHeaders(scope=message).append("x-request-id", request_id)
            await send(message)

        try:
            if self._token is not None and scope["path"] not in _OPEN_PATHS:
                problem = self._token.problem(headers.get("authorization"))
                if problem:
                    info["error"] = "unauthorized"
                    await send_error(send_wrapper, UnauthorizedError(problem))
                    return
            await self.app(scope, receive, send_wrapper)
        except Exception as exc:
            info["error"] = rule_for(exc).code
            _log.error(
                "unhandled error in %s %s",
                scope.get("method"),
                scope.get("path"),
                exc_info=True,
                extra={"request_id": request_id},
            )
            if not response_started:
                await send_error(send_wrapper, exc)
        finally:
            self._record(scope, info, status, time.perf_counter() - started)

    def _record(self, scope: Scope, info: dict[str, object], status: int, seconds: float) -> None:
        route = scope.get("route")
        template = str(getattr(route, "path", "")) or "unmatched"
        method = str(scope.get("method", ""))
        self._metrics.requests.labels(route=template, method=method, status=str(status)).inc()
        self._metrics.latency.labels(route=template, status=str(status)).observe(seconds)
        if template == "/v1/match" and method == "POST":
            self._metrics.matches.labels(outcome=str(info.get("error", "ok"))).inc()
        if self._access_log:
            client = scope.get("client")
            _access.info(
                "request",
                extra={
                    **info,
                    "method": method,
                    "path": scope.get("path"),
                    "route": template,
                    "status": status,
                    "duration_ms": round(seconds * 1000.0, 3),
                    "client": client[0] if client else None,
                },
            )
