"""
``mapmatch serve``: run the HTTP matching service.

The one surface of :mod:`mapmatch` that imports the HTTP layer (import-linter allows exactly
this edge): it builds the service's :class:`api.settings.Settings` from the command line and
the ``MAPMATCH_*`` environment, validated once here, and hands that object to
:func:`api.server.serve`, which runs the app factory :func:`api.app.create_app` with it in
every worker. Before starting it compiles any network missing from the cache, so that the
workers all memory-map one cached copy instead of each compiling its own, and so that a bad
``--network`` or setting fails here with one line (exit 2) instead of in every worker.
"""

from __future__ import annotations

import argparse
import os
from typing import TYPE_CHECKING, Any

import roadnets
from mapmatch.machine import available_cores

if TYPE_CHECKING:
    from api.settings import Settings

__all__ = ["add_parser", "run", "settings_from_args"]

#: Command-line options that are :class:`api.settings.Settings` fields of the same name.
_SETTING_OPTIONS = ("max_body_bytes", "max_points", "time_budget_s", "match_threads", "token")


def _port(text: str) -> int:
    """A TCP port number, 0 .. 65535 (0: any free port)."""
    try:
        port = int(text)
    except ValueError:
        port = -1
    if not 0 <= port <= 65535:
        msg = f"must be a TCP port 0..65535 (got {text!r})"
        raise argparse.ArgumentTypeError(msg)
    return port


def _workers(text: str) -> int:
    """A worker count >= 1, or ``auto``: one per core this process may use."""
    if text.strip().lower() == "auto":
        return available_cores()
    try:
        count = int(text)
    except ValueError:
        count = 0
    if count < 1:
        msg = f"must be a whole number >= 1 or 'auto' (got {text!r})"
        raise argparse.ArgumentTypeError(msg)
    return count


def add_parser(sub: Any) -> None:
    """Register the ``serve`` sub-command."""
    parser = sub.add_parser(
        "serve",
        help="run the HTTP matching service",
        description=(
            "Serve POST /v1/match, GET /v1/networks, /healthz, /readyz, /metrics and the "
            "OpenAPI docs at /docs. Every option can also be set as a MAPMATCH_* environment "
            "variable (MAPMATCH_TOKEN keeps the token out of the process list); see "
            "api/settings.py for all of them."
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
    parser.add_argument("--port", type=_port, default=8000, help="TCP port (default 8000)")
    parser.add_argument(
        "--workers",
        type=_workers,
        default=1,
        metavar="N",
        help="worker processes, or 'auto': one per core this process may use (its CPU "
        "affinity, cut to a container's CPU quota); default 1, as a live trip (/v1/trips) "
        "lives in the worker that opened it; matching holds the GIL, so processes, not "
        "threads, use more cores; each worker holds about 300 MB of its own with the embedded "
        "network",
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
        "--match-threads", type=int, default=None, help="matches at once per worker (2)"
    )
    parser.add_argument("--no-access-log", action="store_true", help="no JSON access log lines")
    parser.add_argument(
        "--log-level",
        default="warning",
        choices=("critical", "error", "warning", "info", "debug"),
        help="uvicorn's own log level (default warning)",
    )
    parser.set_defaults(run=run)


def settings_from_args(args: argparse.Namespace) -> Settings:
    """
    The service's settings: the options given on the command line, else ``MAPMATCH_*``.

    Networks and the cache folder are made absolute.

    Raises
    ------
    api.settings.SettingsError
        A value is invalid (one line naming the setting).
    """
    from api.settings import load_settings

    given: dict[str, object] = {}
    if args.networks:
        given["networks"] = tuple(os.path.abspath(p) for p in args.networks)
    if args.cache_dir is not None:
        given["cache_dir"] = os.path.abspath(args.cache_dir)
    for name in _SETTING_OPTIONS:
        value = getattr(args, name)
        if value is not None:
            given[name] = value
    if args.no_access_log:
        given["access_log"] = False
    return load_settings(**given)


def run(args: argparse.Namespace) -> int:
    """Compile missing networks into the cache, then serve until interrupted."""
    from api.server import serve

    settings = settings_from_args(args)
    for source in settings.networks or (None,):
        roadnets.load(source, cache_dir=settings.cache_dir)  # fills the cache; errors: exit 2
    serve(settings, host=args.host, port=args.port, workers=args.workers, log_level=args.log_level)
    return 0
