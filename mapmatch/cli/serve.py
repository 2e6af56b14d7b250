"""
``mapmatch serve``: run the HTTP matching service (uvicorn, ``api.main:app``).

This module never imports :mod:`api` (the core does not depend on the HTTP layer): it passes
its options to the app through ``MAPMATCH_*`` environment variables, which every worker process
reads when it imports ``api.main``. Before starting uvicorn it compiles any network missing
from the cache, so that the workers all memory-map one cached copy instead of each compiling
its own, and so that a bad ``--network`` fails here with one line instead of in every worker.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from typing import TYPE_CHECKING, Any

import roadnets
from mapmatch.errors import ConfigError

if TYPE_CHECKING:
    import argparse

__all__ = ["APP", "add_parser", "run", "settings_environment"]

#: Import string of the ASGI app uvicorn runs.
APP = "api.main:app"
_MULTIPROC_ENV = "PROMETHEUS_MULTIPROC_DIR"


def add_parser(sub: Any) -> None:
    """Register the ``serve`` sub-command."""
    parser = sub.add_parser(
        "serve",
        help="run the HTTP matching service",
        description=(
            "Serve POST /v1/match, GET /v1/networks, /healthz, /readyz, /metrics and the "
            "OpenAPI docs at /docs. Every option can also be set as a MAPMATCH_* environment "
            "variable (MAPMATCH_TOKEN keeps the token out of the process list)."
        ),
    )
    parser.add_argument(
        "--network",
        action="append",
        dest="networks",
        default=None,
        metavar="PATH",
        help="OSM extract to serve (repeatable; the first is the default; "
        "default: the embedded network)",
    )
    parser.add_argument("--host", default="127.0.0.1", help="bind address (default 127.0.0.1)")
    parser.add_argument("--port", type=int, default=8000, help="TCP port (default 8000)")
    parser.add_argument(
        "--workers", type=int, default=1, help="worker processes (default 1)", metavar="N"
    )
    parser.add_argument("--cache-dir", default=None, help="folder of compiled networks")
    parser.add_argument(
        "--token", default=None, help="require 'Authorization: Bearer TOKEN' (not on /healthz)"
    )
    parser.add_argument("--max-body-bytes", type=int, default=None, help="default 10000000")
    parser.add_argument("--max-points", type=int, default=None, help="default 100000")
    parser.add_argument(
        "--time-budget-s", type=float, default=None, help="seconds per match request (30)"
    )
    parser.add_argument(
        "--match-threads", type=int, default=None, help="matches at once per worker (4)"
    )
    parser.add_argument("--no-access-log", action="store_true", help="no JSON access log lines")
    parser.add_argument(
        "--log-level",
        default="warning",
        choices=("critical", "error", "warning", "info", "debug"),
        help="uvicorn's own log level (default warning)",
    )
    parser.set_defaults(run=run)


def settings_environment(args: argparse.Namespace) -> dict[str, str]:
    """
    The ``MAPMATCH_*`` variables that carry the command-line options to the app.

    Only options given on the command line are set, so variables already in the environment
    keep working. Networks travel as ``os.pathsep``-separated paths made absolute.

    Examples
    --------
    >>> import argparse
    >>> ns = argparse.Namespace(networks=None, cache_dir=None, token=None, max_body_bytes=None,
    ...                         max_points=500, time_budget_s=None, match_threads=None,
    ...                         no_access_log=True)
    >>> settings_environment(ns)
    {'MAPMATCH_MAX_POINTS': '500', 'MAPMATCH_ACCESS_LOG': 'false'}
    """
    env: dict[str, str] = {}
    if args.networks:
        env["MAPMATCH_NETWORKS"] = os.pathsep.join(os.path.abspath(p) for p in args.networks)
    if args.cache_dir is not None:
        env["MAPMATCH_CACHE_DIR"] = os.path.abspath(args.cache_dir)
    if args.token is not None:
        env["MAPMATCH_TOKEN"] = args.token
    for name in ("max_body_bytes", "max_points", "time_budget_s", "match_threads"):
        value = getattr(args, name)
        if value is not None:
            env[f"MAPMATCH_{name.upper()}"] = str(value)
    if args.no_access_log:
        env["MAPMATCH_ACCESS_LOG"] = "false"
    return env


def run(args: argparse.Namespace) -> int:
    """Compile missing networks into the cache, then run uvicorn until interrupted."""
    import uvicorn

    if args.workers < 1:
        msg = f"--workers must be >= 1 (got {args.workers})"
        raise ConfigError(msg)
    os.environ.update(settings_environment(args))
    cache_dir = os.environ.get("MAPMATCH_CACHE_DIR") or None
    sources: list[str | None] = [*_network_sources(os.environ.get("MAPMATCH_NETWORKS", ""))]
    for source in sources or [None]:
        roadnets.load(source, cache_dir=cache_dir)  # fills the cache; errors end here, exit 2

    multiproc_dir = None
    if args.workers > 1 and not os.environ.get(_MULTIPROC_ENV):
        # Workers then write their metrics there and /metrics sums them (see api.metrics).
        multiproc_dir = tempfile.mkdtemp(prefix="mapmatch-metrics-")
        os.environ[_MULTIPROC_ENV] = multiproc_dir
    try:
        uvicorn.run(
            APP,
            host=args.host,
            port=args.port,
            workers=args.workers,
            access_log=False,  # the app writes its own JSON access log
            log_level=args.log_level,
            timeout_graceful_shutdown=10,
        )
    finally:
        if multiproc_dir is not None:
            os.environ.pop(_MULTIPROC_ENV, None)
            shutil.rmtree(multiproc_dir, ignore_errors=True)
    return 0


def _network_sources(value: str) -> list[str]:
    """``MAPMATCH_NETWORKS`` as api.settings reads it: a JSON list or ``os.pathsep``-separated."""
    text = value.strip()
    if text.startswith("["):
        return [str(p) for p in json.loads(text)]
    return [p for p in text.split(os.pathsep) if p.strip()]
