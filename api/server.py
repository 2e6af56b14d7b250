"""
Running the service: uvicorn serving :func:`api.app.create_app` in one or more processes.

:func:`serve` is what ``mapmatch serve`` calls. Every worker process builds its own app with
``create_app(settings)`` from the one :class:`~api.settings.Settings` object the command line
made (pickled to the workers, which uvicorn starts with ``spawn``), so no worker re-reads its
options from environment variables. With several workers the parent binds the socket and
supervises them (uvicorn's multi-process supervisor restarts a worker that dies), and the
workers write their Prometheus metrics to one shared folder so that ``/metrics`` sums them.
"""

from __future__ import annotations

import functools
import os
import shutil
import tempfile
from typing import TYPE_CHECKING

import uvicorn
from uvicorn.supervisors import Multiprocess

from api.app import create_app
from api.connections import GuardedH11Protocol, ServiceConfig
from api.errors import ServiceError
from api.logs import configure_logging
from api.metrics import MULTIPROC_ENV

if TYPE_CHECKING:
    from api.settings import Settings

__all__ = ["serve", "uvicorn_config"]


def uvicorn_config(
    settings: Settings, *, host: str, port: int, workers: int, log_level: str
) -> uvicorn.Config:
    """
    The uvicorn configuration of the service: the app factory bound to ``settings``.

    The connection limits come from the settings too: a request head within
    ``header_timeout_s`` (:mod:`api.connections`), idle keep-alive connections closed after
    ``keepalive_timeout_s``, at most ``max_connections`` connections and requests at once
    (503 beyond), request heads of at most ``max_header_bytes``.

    Parameters
    ----------
    settings
        The deployment settings every worker builds its app with.
    host, port
        Where to listen.
    workers
        Worker processes.
    log_level
        uvicorn's own log level.
    """
    return ServiceConfig(
        functools.partial(create_app, settings),
        factory=True,
        host=host,
        port=port,
        workers=workers,
        http=GuardedH11Protocol,
        header_timeout_s=settings.header_timeout_s,
        timeout_keep_alive=settings.keepalive_timeout_s,
        limit_concurrency=settings.max_connections,
        h11_max_incomplete_event_size=settings.max_header_bytes,
        access_log=False,  # the app writes its own JSON access log
        log_config=None,  # uvicorn's lines go to the root logger: JSON (api.logs)
        log_level=log_level,
        lifespan="on",
        ws="none",
        timeout_graceful_shutdown=10,
    )


def serve(settings: Settings, *, host: str, port: int, workers: int, log_level: str) -> None:
    """
    Serve until interrupted (SIGINT or SIGTERM), in ``workers`` processes.

    Raises
    ------
    ServiceError
        The server could not start (the port is taken, the address cannot be bound).
    """
    configure_logging()  # the supervisor's own lines are JSON too
    config = uvicorn_config(settings, host=host, port=port, workers=workers, log_level=log_level)
    multiproc_dir = None
    if workers > 1 and not os.environ.get(MULTIPROC_ENV):
        # The workers inherit it and write their metrics there (see api.metrics).
        multiproc_dir = tempfile.mkdtemp(prefix="mapmatch-metrics-")
        os.environ[MULTIPROC_ENV] = multiproc_dir
    try:
        if workers > 1:
            try:
                sock = config.bind_socket()
            except SystemExit:  # uvicorn logged why (address in use ...)
                msg = f"cannot listen on {host}:{port}; is another server using the port?"
                raise ServiceError(msg) from None
            Multiprocess(config, sockets=[sock]).run()
            return
        server = uvicorn.Server(config)
        server.run()
        if not server.started:
            msg = f"the server did not start on {host}:{port}; the log above says why"
            raise ServiceError(msg)
    finally:
        if multiproc_dir is not None:
            os.environ.pop(MULTIPROC_ENV, None)
            shutil.rmtree(multiproc_dir, ignore_errors=True)
