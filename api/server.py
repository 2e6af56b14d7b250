"""
Running the service: uvicorn serving :func:`api.app.create_app` in one or more processes.

:func:`serve` is what ``mapmatch serve`` calls. Every worker process builds its own app with
``create_app(settings)`` from the one :class:`~api.settings.Settings` object the command line
made (pickled to the workers, which uvicorn starts with ``spawn``), so no worker re-reads its
options from environment variables. With several workers the parent binds one listening
socket per worker, all on the same address with ``SO_REUSEPORT``, and supervises them
(:class:`WorkerSupervisor`, uvicorn's multi-process supervisor: a worker that dies is
restarted on its socket); the workers write their Prometheus metrics to one shared folder so
that ``/metrics`` sums them.

Why a socket per worker: with one shared socket, every worker wakes for a new connection and
the first one accepts all that are waiting (asyncio accepts up to the backlog at a time), so
the few long-lived keep-alive connections of a load balancer or a client pool all land on one
worker and the others idle (measured: 16 keep-alive clients, 2 workers, one at 105 % CPU and
the other at 0.2 %). With ``SO_REUSEPORT`` the kernel spreads connections over the sockets.
"""

from __future__ import annotations

import functools
import logging
import os
import shutil
import socket
import tempfile
from typing import TYPE_CHECKING

import uvicorn
from uvicorn.config import STARTUP_FAILURE
from uvicorn.supervisors import Multiprocess
from uvicorn.supervisors.multiprocess import Process

from api.app import create_app
from api.connections import GuardedH11Protocol, ServiceConfig
from api.errors import ServiceError
from api.logs import configure_logging
from api.metrics import MULTIPROC_ENV

if TYPE_CHECKING:
    from api.settings import Settings

__all__ = ["WorkerSupervisor", "listening_sockets", "serve", "uvicorn_config"]

_log = logging.getLogger("uvicorn.error")


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
    settings = settings.model_copy(update={"worker_processes": workers})
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


def listening_sockets(host: str, port: int, count: int, backlog: int) -> list[socket.socket]:
    """
    ``count`` listening sockets on ``host:port`` with ``SO_REUSEPORT`` (port 0: one free port).

    The port is first bound without ``SO_REUSEPORT``, so that a port another server holds
    (with or without the option: a second ``mapmatch serve`` would otherwise share it
    silently) is refused, then released and bound once per worker.

    Raises
    ------
    ServiceError
        The address cannot be bound (the port is taken, the host is not this machine's).
    """
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    # proto IPPROTO_TCP, not 0: asyncio sets TCP_NODELAY only on sockets that say they are
    # TCP, and the connections accepted here inherit it. Without it Nagle holds the answer's
    # body until the client acknowledges its head, and the client delays that by 40 ms:
    # measured, every request on 2 workers took 48 ms (3.4 ms on 1 worker, where uvicorn
    # binds the socket itself).
    out: list[socket.socket] = []
    try:
        with socket.socket(family, socket.SOCK_STREAM) as probe:
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # past TIME_WAIT
            probe.bind((host, port))
            port = probe.getsockname()[1]
        for _ in range(count):
            sock = socket.socket(family, socket.SOCK_STREAM, socket.IPPROTO_TCP)
            out.append(sock)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
            sock.bind((host, port))
            sock.listen(backlog)
            sock.set_inheritable(True)
    except OSError as exc:
        for sock in out:
            sock.close()
        msg = f"cannot listen on {host}:{port} ({exc.strerror}); is another server using the port?"
        raise ServiceError(msg) from None
    return out


class WorkerSupervisor(Multiprocess):
    """
    uvicorn's multi-process supervisor, each worker on a listening socket of its own.

    Worker ``i`` serves ``sockets[i]`` (one per worker, :func:`listening_sockets`); a
    worker that dies or hangs is replaced on the same socket, and ``SIGHUP`` replaces every
    worker in turn, each new one on its predecessor's socket before the old one stops. The
    number of workers is fixed (``SIGTTIN`` / ``SIGTTOU`` are refused): a socket without a
    worker would hold the connections the kernel hands it.
    """

    def _started(self, index: int) -> Process:
        process = Process(self.config, [self.sockets[index]])
        process.start()
        return process

    def init_processes(self) -> None:
        """Start one worker per socket."""
        self.processes = [self._started(i) for i in range(len(self.sockets))]

    def keep_subprocess_alive(self) -> None:
        """Replace a dead or hung worker on its socket (stop all if one could not start)."""
        for index, process in enumerate(self.processes):
            if self.should_exit.is_set():
                return
            if process.is_alive(timeout=self.config.timeout_worker_healthcheck):
                continue
            process.kill()
            process.join()
            if process.exitcode == STARTUP_FAILURE:  # the app or the socket is broken
                _log.error("worker [%s] failed to start; stopping", process.pid)
                self.should_exit.set()
                return
            _log.info("worker [%s] died; starting another on its socket", process.pid)
            self.processes[index] = self._started(index)

    def restart_all(self) -> None:
        """Replace each worker in turn, the new one serving before the old one stops."""
        for index, old in enumerate(self.processes):
            if self.should_exit.is_set():
                return
            new = self._started(index)
            if not new.wait_until_ready(self.config.timeout_worker_healthcheck, self.should_exit):
                new.kill()
                new.join()
                _log.error("new worker [%s] not ready in time; restart aborted", new.pid)
                return
            old.terminate()
            old.join()
            self.processes[index] = new

    def handle_ttin(self) -> None:
        """Refused: one worker per socket (restart with another ``--workers``)."""
        _log.warning("SIGTTIN ignored: the number of workers is fixed (one per socket)")

    def handle_ttou(self) -> None:
        """Refused, as :meth:`handle_ttin`."""
        _log.warning("SIGTTOU ignored: the number of workers is fixed (one per socket)")


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
            sockets = listening_sockets(host, port, workers, config.backlog)
            try:
                WorkerSupervisor(config, sockets).run()
            finally:
                for sock in sockets:
                    sock.close()
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
