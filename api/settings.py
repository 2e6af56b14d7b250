"""
Deployment settings of the HTTP service, read from ``MAPMATCH_*`` environment variables.

These say where the service runs and what it may spend, never how it matches: every matching
parameter lives in :class:`mapmatch.MatchConfig`, and a request may override the fields of
:data:`mapmatch.OVERRIDABLE` through its ``options``.

==============================  ==============================================================
variable                        meaning
==============================  ==============================================================
``MAPMATCH_NETWORKS``           OSM extracts to serve: a JSON list, or paths separated by
                                ``os.pathsep`` (``:``); empty = the embedded default (Monaco)
``MAPMATCH_CACHE_DIR``          folder of compiled networks (also read by :mod:`roadnets`)
``MAPMATCH_TOKEN``              bearer token every route but ``/healthz`` requires; unset = open
``MAPMATCH_MAX_BODY_BYTES``     largest request body, bytes (10 MB)
``MAPMATCH_MAX_POINTS``         most points in one trace (100 000)
``MAPMATCH_TIME_BUDGET_S``      seconds a match request may take, queueing included (30 s)
``MAPMATCH_MATCH_THREADS``      matches running at once in one worker process (2)
``MAPMATCH_WORKER_PROCESSES``   worker processes on the machine (``serve --workers`` sets it;
                                with one per core a worker runs one short match at a time)
``MAPMATCH_MAX_QUEUED``         matches waiting for a thread before 503 ``overloaded`` (64)
``MAPMATCH_MAX_DECOMPRESSED_BYTES``  largest body after gzip, bytes (40 MB)
``MAPMATCH_MAX_COLUMNS``        most columns of a CSV body (256)
``MAPMATCH_ROUTE_TABLE_MB``     largest route table for sparse traces a network keeps, read
                                from the cache or built at load (256 MB; 0 = none)
``MAPMATCH_MEMORY_BUDGET_MB``   most memory one match may need, by the cost model of
                                :mod:`api.costs` (2048 MB; more is 413 ``over_budget``)
``MAPMATCH_HEADER_TIMEOUT_S``   seconds a connection may take to send a request's headers, and
                                may stay idle between requests (10 s)
``MAPMATCH_BODY_TIMEOUT_S``     seconds a request may take to send its body (30 s; 408)
``MAPMATCH_KEEPALIVE_TIMEOUT_S``  seconds an idle keep-alive connection is kept (5 s)
``MAPMATCH_MAX_CONNECTIONS``    connections and requests at once per worker; more answer 503
                                at once (1024)
``MAPMATCH_MAX_HEADER_BYTES``   largest request line plus headers, bytes (16 KiB; more: 400)
``MAPMATCH_GZIP_MIN_BYTES``     answers at least this long are gzipped for a client that sends
                                ``Accept-Encoding: gzip`` (1000; 0 = never)
``MAPMATCH_CORS_ORIGINS``       browser origins allowed to call the service (CORS), a JSON
                                list or separated by ``,``; ``*`` = any; empty = no CORS
``MAPMATCH_ACCESS_LOG``         one JSON line per request on stderr (true)
``MAPMATCH_DOCS_ASSETS``        ``bundled``: ``/docs`` and ``/redoc`` load the packaged
                                Swagger UI and ReDoc (offline); ``cdn``: FastAPI's CDN links
``MAPMATCH_MAX_TRIPS``          live trips (``/v1/trips``) open at once per worker (10 000)
``MAPMATCH_TRIP_IDLE_S``        a live trip without a request this long expires (600 s)
``MAPMATCH_TRIP_MAX_BYTES``     memory a live trip may hold; more fixes are refused (8 MB)
``MAPMATCH_TRIP_MAX_LAG_S``     longest lag a live trip may ask for, seconds (600)
==============================  ==============================================================
"""

from __future__ import annotations

import json
import os
from typing import Annotated, Literal

from pydantic import Field, SecretStr, ValidationError, field_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

from mapmatch.errors import ConfigError
from roadnets.route_store import DEFAULT_BUDGET_MB

__all__ = ["Settings", "SettingsError", "load_settings"]


class SettingsError(ConfigError):
    """A deployment setting (command-line option or ``MAPMATCH_*`` variable) is invalid."""


class Settings(BaseSettings):
    """
    Deployment settings of one service process (see the module docstring for the variables).

    Examples
    --------
    >>> Settings(networks="a.osm.pbf:b.osm.pbf").networks
    ('a.osm.pbf', 'b.osm.pbf')
    >>> Settings(networks='["a.osm.pbf"]', max_points=10).max_points
    10
    """

    model_config = SettingsConfigDict(
        env_prefix="MAPMATCH_", env_ignore_empty=True, extra="ignore", frozen=True
    )

    networks: Annotated[tuple[str, ...], NoDecode] = Field(
        default=(),
        description="OSM extracts to serve; empty = the embedded default network.",
    )
    cache_dir: str | None = Field(
        default=None, description="Folder of compiled networks (roadnets' default when unset)."
    )
    token: SecretStr | None = Field(
        default=None, description="Bearer token required by every route but /healthz."
    )
    max_body_bytes: int = Field(
        default=10_000_000, ge=1024, description="Largest accepted request body, bytes."
    )
    max_points: int = Field(default=100_000, ge=2, description="Most points in one trace.")
    time_budget_s: float = Field(
        default=30.0,
        gt=0,
        allow_inf_nan=False,
        description="Seconds a match request may take, including its wait for a thread.",
    )
    match_threads: int = Field(
        default=2,
        ge=1,
        le=256,
        description="Matches running at once in one process. Short ones (bodies up to 64 KiB) "
        "run in a lane of their own, as many at once as the worker's share of the cores (one "
        "when there are as many workers as cores: two would only contend for the interpreter "
        "lock), long ones in the other threads beside them, so a long trace never holds up "
        "the short ones.",
    )
    worker_processes: int = Field(
        default=1,
        ge=1,
        le=1024,
        description="Worker processes serving on this machine; `mapmatch serve --workers` sets "
        "it. With as many workers as cores each runs one short match at a time.",
    )
    max_queued: int = Field(
        default=64, ge=0, description="Matches waiting for a thread before 503 overloaded."
    )
    max_decompressed_bytes: int = Field(
        default=40_000_000, ge=1024, description="Largest request body after gzip, bytes."
    )
    max_columns: int = Field(
        default=256, ge=3, le=100_000, description="Most columns of a CSV body."
    )
    route_table_mb: float = Field(
        default=DEFAULT_BUDGET_MB,
        ge=0,
        allow_inf_nan=False,
        description="Largest route table for sparse traces a network keeps (read from the "
        "cache or built at load, shared by the workers), MB; 0: none, routes are searched.",
    )
    memory_budget_mb: float = Field(
        default=2048.0,
        gt=0,
        allow_inf_nan=False,
        description="Most memory one match may need (api.costs' estimate), MB.",
    )
    header_timeout_s: float = Field(
        default=10.0,
        gt=0,
        le=3600,
        description="Seconds to send a request's headers, and to start the next request.",
    )
    body_timeout_s: float = Field(
        default=30.0, gt=0, le=3600, description="Seconds a request may take to send its body."
    )
    keepalive_timeout_s: int = Field(
        default=5, ge=1, le=3600, description="Seconds an idle keep-alive connection is kept."
    )
    max_connections: int = Field(
        default=1024,
        ge=1,
        le=1_000_000,
        description="Connections and requests at once per worker; more answer 503 at once.",
    )
    max_header_bytes: int = Field(
        default=16_384,
        ge=1024,
        le=1_048_576,
        description="Largest request line plus headers, bytes.",
    )
    gzip_min_bytes: int = Field(
        default=1000,
        ge=0,
        description="Gzip answers at least this long when the client accepts gzip; 0 = never.",
    )
    cors_origins: Annotated[tuple[str, ...], NoDecode] = Field(
        default=(),
        description="Browser origins allowed to call the service (CORS); '*' = any.",
    )
    access_log: bool = Field(default=True, description="Write one JSON line per request.")
    max_trips: int = Field(
        default=10_000, ge=1, description="Live trips open at once per worker process."
    )
    trip_idle_s: float = Field(
        default=600.0,
        gt=0,
        allow_inf_nan=False,
        description="Seconds without a request after which a live trip expires.",
    )
    trip_max_bytes: int = Field(
        default=8_000_000, ge=100_000, description="Memory a live trip may hold, bytes."
    )
    trip_max_lag_s: float = Field(
        default=600.0,
        gt=0,
        allow_inf_nan=False,
        description="Longest lag a live trip may ask for, seconds.",
    )
    docs_assets: Literal["bundled", "cdn"] = Field(
        default="bundled",
        description="Where /docs and /redoc get Swagger UI and ReDoc: packaged files or a CDN.",
    )

    @field_validator("networks", mode="before")
    @classmethod
    def _split_networks(cls, value: object) -> object:
        """Accept a JSON list or an ``os.pathsep``-separated string of paths."""
        if not isinstance(value, str):
            return value
        text = value.strip()
        if text.startswith("["):
            return tuple(json.loads(text))
        return tuple(part for part in text.split(os.pathsep) if part.strip())

    @field_validator("cors_origins", mode="before")
    @classmethod
    def _split_origins(cls, value: object) -> object:
        """Accept a JSON list or a comma-separated string of origins."""
        if not isinstance(value, str):
            return value
        text = value.strip()
        if text.startswith("["):
            return tuple(json.loads(text))
        return tuple(part.strip() for part in text.split(",") if part.strip())

    @field_validator("token", mode="after")
    @classmethod
    def _empty_token_is_none(cls, value: SecretStr | None) -> SecretStr | None:
        """A blank token means no authentication, not a token of spaces."""
        if value is not None and not value.get_secret_value().strip():
            return None
        return value


def load_settings(**given: object) -> Settings:
    """
    The settings: ``given`` values first, then the ``MAPMATCH_*`` environment, then defaults.

    Raises
    ------
    SettingsError
        A value is invalid; one line naming the setting, its variable and the value.

    Examples
    --------
    >>> load_settings(max_points=500).max_points
    500
    >>> load_settings(max_points=1)
    Traceback (most recent call last):
    ...
    api.settings.SettingsError: invalid setting max_points (MAPMATCH_MAX_POINTS): Input should be greater than or equal to 2 (got 1)
    """  # noqa: E501
    try:
        return Settings(**given)  # type: ignore[arg-type]
    except ValidationError as exc:
        first = exc.errors(include_url=False)[0]
        name = ".".join(str(part) for part in first["loc"]) or "settings"
        problems = len(exc.errors())
        more = f" (and {problems - 1} more)" if problems > 1 else ""
        shown = repr(first["input"]) if name != "token" else "<hidden>"
        msg = (
            f"invalid setting {name} (MAPMATCH_{name.upper()}): {first['msg']} (got {shown}){more}"
        )
        raise SettingsError(msg, field=name) from None
