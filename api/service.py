"""
What ``POST /v1/match`` does apart from HTTP, and the bounded thread pool it runs in.

(Over 400 lines on purpose: parsing, matching and the bounded thread pool with its time budget
are one request's path, read top to bottom.)

Read the body, build the trace and the matcher configuration, match, and serialise.

Route handlers stay thin: they read the body (:func:`api.intake.read_limited_body`) and hand it to
:meth:`MatchService.submit`, which runs :meth:`MatchService.run` in a match thread under the
request's time budget.

What "frees its worker" means
-----------------------------
A request past its budget is answered at once (504 ``timeout``, or 503 ``overloaded`` when it
never got a thread) and its event loop is free for other requests. Python cannot stop a running
thread, though, and the matcher has no cancellation points: the thread finishes the match (its
result thrown away) and holds its slot of the pool until then. The pool is bounded
(``MAPMATCH_MATCH_THREADS`` threads, ``MAPMATCH_MAX_QUEUED`` waiting), so runaway requests can
delay others but never pile up threads without bound; the point and body limits bound how long
one match can run. While a match thread runs Python code it holds the GIL and slows the other
requests of its process; numba's routing and Viterbi kernels release it (``nogil``).
"""

from __future__ import annotations

import asyncio
import json
import math
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Final, TypeVar

from pydantic import ValidationError
from pydantic_core import from_json

import mapmatch
from api.compression import gzipped
from api.costs import check_budget, match_cost
from api.errors import (
    InvalidJSONError,
    MatchTimeoutError,
    OptionError,
    OverloadedError,
    RequestFieldError,
    ServiceError,
    TooManyPointsError,
)
from api.polyline import PolylineError, decode, encode
from api.schemas import MatchEnvelope, MatchQuery
from mapmatch import OVERRIDABLE, ConfigError, InvalidTraceError, MatchConfig, TraceFileError
from mapmatch.export import geojson_bytes
from mapmatch.machine import available_cores

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable, Mapping, Sequence

    from pydantic_core import ErrorDetails

    from api.networks import NetworkRegistry
    from api.settings import Settings
    from roadnets import RoadNetwork

__all__ = [
    "MatchOutcome",
    "MatchRunner",
    "MatchService",
    "match_within",
    "parse_json",
    "past_budget",
    "short_lane_threads",
    "validation_error",
]

T = TypeVar("T")

_SHOW: Final = 5  # problems quoted in one message
_BASE_CONFIG: Final = MatchConfig()


def past_budget(budget_s: float, deadline: float) -> None:
    """Raise :class:`MatchTimeoutError` when ``deadline`` (``time.monotonic()``) has passed."""
    if time.monotonic() > deadline:
        msg = f"the match ran past the {budget_s:g} s time budget"
        raise MatchTimeoutError(msg)


def match_within(
    budget_s: float,
    deadline: float,
    trace: mapmatch.Trace,
    net: RoadNetwork,
    config: MatchConfig,
    **options: Any,
) -> mapmatch.MatchResult:
    """
    :func:`mapmatch.match` under the time budget (504 ``timeout`` past ``deadline``).

    Not started once ``deadline`` has passed, stopped between its stages after it, and not
    answered when it finished too late.
    """
    past_budget(budget_s, deadline)
    try:
        result = mapmatch.match(trace, net, config, deadline=deadline, **options)
    except mapmatch.DeadlineExceededError as exc:
        msg = f"the match ran past the {budget_s:g} s time budget ({exc.stage} stage done)"
        raise MatchTimeoutError(msg) from None
    past_budget(budget_s, deadline)
    return result


@dataclass(frozen=True, slots=True)
class MatchOutcome:
    """
    A finished match: the GeoJSON document as bytes, and figures for logs and metrics.

    ``content_encoding`` is ``"gzip"`` when ``content`` is the document gzipped
    (:meth:`MatchService.submit` with ``gzip_min_bytes``), ``None`` when it is the document.
    """

    content: bytes
    trace_id: str
    network: str
    points: int
    matched_points: int
    breaks: int
    seconds: float
    content_encoding: str | None = None

    @classmethod
    def of(cls, result: mapmatch.MatchResult, content: bytes, started: float) -> MatchOutcome:
        """The outcome of ``result`` answered as ``content``; ``started`` by perf_counter."""
        return cls(
            content=content,
            trace_id=result.trace_id,
            network=result.network["id"],
            points=result.stats.points,
            matched_points=result.stats.matched_points,
            breaks=len(result.breaks),
            seconds=time.perf_counter() - started,
        )

    def gzipped(self, min_bytes: int) -> MatchOutcome:
        """The outcome with its content gzipped if it is at least ``min_bytes`` long (> 0)."""
        if min_bytes <= 0 or len(self.content) < min_bytes or self.content_encoding:
            return self
        return replace(self, content=gzipped(self.content), content_encoding="gzip")


#: Request bodies up to this size (about 350 JSON points with every field, 1,500 CSV rows:
#: a match well under half a second) are short jobs, bigger ones long (:class:`MatchRunner`).
SHORT_JOB_BYTES = 65_536


def short_lane_threads(match_threads: int, worker_processes: int) -> int:
    """
    How many short matches one worker runs at once: its share of the cores, at least one.

    A match holds the interpreter lock except in its compiled kernels. With a core to itself
    (workers as many as cores) a worker goes fastest one match at a time, as two contend for
    the lock; alone on several cores, two together use the kernels' time on the other core
    (16 clients, 100-point traces, 2 cores: 2 workers 250-253 requests/s with two at once,
    268-279 with one; 1 worker 202-205 with two, 163-172 with one).

    Examples
    --------
    >>> short_lane_threads(2, worker_processes=available_cores())
    1
    """
    return max(1, min(match_threads, available_cores() // max(1, worker_processes)))


class MatchRunner:
    """
    A bounded pool of match threads in two lanes; every job runs under a time budget.

    Short jobs (bodies up to :data:`SHORT_JOB_BYTES`) run ``short_threads`` at a time in a
    lane of their own, long ones in the other ``threads - short_threads`` threads beside
    them, so a long trace never holds up the short ones and the short ones run no more at
    once than is fastest (:func:`short_lane_threads`). With ``short_threads >= threads``
    every job shares one pool.

    Parameters
    ----------
    threads
        Jobs running at once.
    max_queued
        Jobs waiting for a thread; one more is refused at once with :class:`OverloadedError`.
    budget_s
        Seconds a job may take from submission (waiting included).
    short_threads
        Short jobs running at once (default: all ``threads``, one pool).
    """

    def __init__(
        self, *, threads: int, max_queued: int, budget_s: float, short_threads: int | None = None
    ) -> None:
        short = threads if short_threads is None else max(1, min(short_threads, threads))
        self._short = ThreadPoolExecutor(max_workers=short, thread_name_prefix="match")
        self._long = (
            ThreadPoolExecutor(max_workers=threads - short, thread_name_prefix="match-long")
            if short < threads
            else self._short
        )
        self._capacity = threads + max_queued
        self.budget_s = budget_s
        self._lock = threading.Lock()
        self._in_system = 0  # queued + running, abandoned ones included

    @property
    def in_system(self) -> int:
        """Jobs queued or running, abandoned ones included."""
        return self._in_system

    async def run(self, fn: Callable[[], T], *, size: int = 0) -> T:
        """
        Run ``fn`` in a match thread and return its result within the budget.

        ``size`` is the job's request body in bytes: it picks the lane.

        Raises
        ------
        OverloadedError
            The pool is full, or the job was still waiting for a thread when the budget ran
            out (it is then never started).
        MatchTimeoutError
            The job ran past the budget; its thread finishes it and drops the result.
        """
        with self._lock:
            if self._in_system >= self._capacity:
                msg = (
                    f"the service is busy ({self._in_system} matches running or waiting); "
                    "retry shortly"
                )
                raise OverloadedError(msg)
            self._in_system += 1
        started = threading.Event()

        def job() -> T:
            started.set()
            return fn()

        lane = self._short if size <= SHORT_JOB_BYTES else self._long
        future = lane.submit(job)
        future.add_done_callback(self._release)
        try:
            return await asyncio.wait_for(asyncio.wrap_future(future), timeout=self.budget_s)
        except TimeoutError:
            future.cancel()
            if not started.is_set():
                msg = (
                    f"the service is busy: no match thread freed up within the "
                    f"{self.budget_s:g} s time budget; retry shortly"
                )
                raise OverloadedError(msg) from None
            msg = (
                f"the match ran past the {self.budget_s:g} s time budget; send a shorter "
                "trace, or split it"
            )
            raise MatchTimeoutError(msg) from None

    def _release(self, _future: Future[T]) -> None:
        with self._lock:
            self._in_system -= 1

    def shutdown(self) -> None:
        """Drop waiting jobs; running ones finish in their threads."""
        for lane in {self._short, self._long}:
            lane.shutdown(wait=False, cancel_futures=True)


class MatchService:
    """
    Turns a request body and its query parameters into a matched GeoJSON document.

    Parameters
    ----------
    networks
        The networks to match on.
    settings
        Limits (points, time budget, threads).
    """

    def __init__(self, networks: NetworkRegistry, settings: Settings) -> None:
        self.networks = networks
        self.max_points = settings.max_points
        self.memory_budget_mb = settings.memory_budget_mb
        self.runner = MatchRunner(
            threads=settings.match_threads,
            max_queued=settings.max_queued,
            budget_s=settings.time_budget_s,
            short_threads=short_lane_threads(settings.match_threads, settings.worker_processes),
        )

    async def submit(
        self, body: bytes, fmt: str, query: MatchQuery, *, gzip_min_bytes: int = 0
    ) -> MatchOutcome:
        """
        :meth:`run` in a match thread, under the time budget.

        With ``gzip_min_bytes`` (> 0) an answer at least that long is gzipped in the match
        thread too (:meth:`MatchOutcome.gzipped`), not on the event loop.
        """
        self.networks.get(query.network)  # answer not_ready / unknown_network before queueing
        deadline = time.monotonic() + self.runner.budget_s
        return await self.runner.run(
            lambda: self.run(body, fmt, query, deadline=deadline).gzipped(gzip_min_bytes),
            size=len(body),
        )

    def run(
        self, body: bytes, fmt: str, query: MatchQuery, *, deadline: float = math.inf
    ) -> MatchOutcome:
        """
        Parse, match and serialise one trace (blocking; runs in a match thread).

        Parameters
        ----------
        body
            The request body.
        fmt
            Its format, from :func:`body_format`.
        query
            The query parameters.

        deadline
            ``time.monotonic()`` past which the caller no longer waits: checked between the
            stages and inside the match (between its own stages), so an
            abandoned request stops as early as it can and frees its thread.

        Raises
        ------
        MapMatchError
            Any problem of the request; :mod:`api.errors` maps it to its answer.
        """
        started = time.perf_counter()
        if fmt == "json":
            trace, network_id, fused_m, overrides = self._from_json(body, query)
        else:
            trace = self._from_file(body, fmt, query)
            network_id, fused_m = query.network, query.fused_distance_m
            overrides = query.options()
        net = self.networks.get(network_id)
        config = _config(overrides)
        result = self.match(trace, net, config, overrides, deadline, fused_distance_m=fused_m)
        if query.polyline is None:
            content = geojson_bytes(result)  # written from the result's arrays
        else:
            content = _with_polylines(result, query.polyline)
        return MatchOutcome.of(result, content, started)

    def match(
        self,
        trace: mapmatch.Trace,
        net: RoadNetwork,
        config: MatchConfig,
        overrides: dict[str, object],
        deadline: float,
        **options: Any,
    ) -> mapmatch.MatchResult:
        """
        One match under the service's limits.

        Its estimated memory is held against the budget (413 ``over_budget`` naming the
        options), then it runs :func:`match_within` the time budget.
        """
        cost = match_cost(trace, config, self.networks.density(net.network_id))
        check_budget(cost, self.memory_budget_mb, overrides)
        return match_within(self.runner.budget_s, deadline, trace, net, config, **options)

    def _from_json(
        self, body: bytes, query: MatchQuery
    ) -> tuple[mapmatch.Trace, str | None, float | None, dict[str, object]]:
        doc = parse_json(body)
        if not isinstance(doc, dict):
            msg = (
                'the body must be a JSON object {"points": [{"time", "lat", "lon"}, ...]} '
                f"(got {_shown(doc)})"
            )
            raise RequestFieldError(msg)
        points = doc.pop("points", None)
        try:
            envelope = MatchEnvelope.model_validate(doc)
        except ValidationError as exc:
            raise validation_error(exc.errors(include_url=False)) from None
        if envelope.polyline is not None:
            points = _polyline_points(envelope, points)
        given = envelope.model_fields_set
        for name in ("network", "trace_id", "fused_distance_m", "crs"):
            if name in given and getattr(query, name) is not None:
                msg = f"{name} is given both in the body and in the query; give it once"
                raise RequestFieldError(msg, field=name)
        body_options = envelope.options.overrides() if envelope.options else {}
        query_options = query.options()
        twice = sorted(set(body_options) & set(query_options))
        if twice:
            msg = f"option(s) {twice} given both in the body and in the query; give each once"
            raise OptionError(msg, field=f"options.{twice[0]}")
        _check_points(points, self.max_points)
        trace_id = envelope.trace_id if "trace_id" in given else (query.trace_id or "trace")
        crs = envelope.crs if "crs" in given else (query.crs or "wgs84")
        trace = _trace_from_records(points, trace_id=trace_id, crs=crs)
        network_id = envelope.network if "network" in given else query.network
        fused = envelope.fused_distance_m if "fused_distance_m" in given else query.fused_distance_m
        return trace, network_id, fused, {**body_options, **query_options}

    def _from_file(self, body: bytes, fmt: str, query: MatchQuery) -> mapmatch.Trace:
        if fmt == "geojson":  # parsed here with a bounded parser, then by the reader
            try:
                doc = parse_json(body)
            except InvalidJSONError as exc:
                msg = f"the GeoJSON body cannot be read: {exc}"
                raise TraceFileError(msg, format=fmt) from None
            _check_geojson(doc, self.max_points)
        try:
            traces = mapmatch.read_traces(
                body, format=fmt, default_trace_id=query.trace_id, crs=query.crs or "wgs84"
            )
        except (OverflowError, RecursionError):  # the readers' own parsers, past their limits
            msg = (
                f"the {fmt} body holds a number too large or nesting too deep to read; send "
                "decimal numbers in their units and a flat document"
            )
            raise TraceFileError(msg, format=fmt) from None
        if len(traces) != 1:
            ids = ", ".join(repr(t.trace_id) for t in traces[:_SHOW])
            more = ", ..." if len(traces) > _SHOW else ""
            msg = f"the {fmt} body holds {len(traces)} traces ({ids}{more}); send one per request"
            raise TraceFileError(msg, format=fmt)
        trace = traces[0]
        if trace.report.input_rows > self.max_points:
            raise _too_many(trace.report.input_rows, self.max_points)
        return trace


def _check_geojson(doc: object, limit: int) -> None:
    """
    Refuse a GeoJSON document with more positions than ``limit`` before it is read.

    Counts Point features and the vertices of (Multi)LineStrings; the shape itself is the
    reader's to check.
    """
    features = doc.get("features") if isinstance(doc, dict) else None
    if not isinstance(features, list):
        features = [doc]
    count = 0
    for feature in features:
        geometry = feature.get("geometry") if isinstance(feature, dict) else None
        coords = geometry.get("coordinates") if isinstance(geometry, dict) else None
        kind = geometry.get("type") if isinstance(geometry, dict) else None
        if kind == "LineString" and isinstance(coords, list):
            count += len(coords)
        elif kind == "MultiLineString" and isinstance(coords, list):
            count += sum(len(line) for line in coords if isinstance(line, list))
        else:
            count += 1
    if count > limit:
        raise _too_many(count, limit)


def _too_many(count: int, limit: int) -> TooManyPointsError:
    msg = (
        f"the trace has {count:,} points; this service matches at most {limit:,} per request; "
        "split the trace"
    )
    return TooManyPointsError(msg, field="points")


def _config(overrides: Mapping[str, object]) -> MatchConfig:
    """The server's configuration with the request's overrides, or an :class:`OptionError`."""
    if not overrides:
        return _BASE_CONFIG
    try:
        return _BASE_CONFIG.replace(overrides)
    except ConfigError as exc:
        name = exc.field
        field = f"options.{name}" if name in OVERRIDABLE else None
        raise OptionError(str(exc), field=field) from None


def parse_json(body: bytes) -> object:
    """
    The JSON document of a body, parsed once, in bounded time and depth.

    ``NaN`` and ``Infinity`` are read (as numbers the trace reader then refuses, naming the
    point); nesting deeper than 200 levels and integers of more than 4,300 digits are refused.

    Raises
    ------
    InvalidJSONError
        The body is not JSON, or is nested too deep, or holds a number too long.

    Examples
    --------
    >>> parse_json(b'{"points": [{"lat": NaN}]}')
    {'points': [{'lat': nan}]}
    """
    try:
        return from_json(body, allow_inf_nan=True)
    except ValueError as exc:
        msg = f"the body is not valid JSON: {exc}"
        raise InvalidJSONError(msg) from None


def _polyline_points(envelope: MatchEnvelope, points: object) -> list[dict[str, object]]:
    """The points of a ``polyline`` body (with its ``times``), as the reader takes them."""
    if points is not None:
        msg = 'give the positions once: "points" or "polyline", not both'
        raise RequestFieldError(msg, field="polyline")
    assert envelope.polyline is not None
    try:
        positions = decode(envelope.polyline, envelope.precision)
    except PolylineError as exc:
        msg = f"polyline: {exc}; send Google's encoded polyline format"
        raise RequestFieldError(msg, field="polyline") from None
    times = envelope.times
    if times is not None and len(times) != len(positions):
        msg = (
            f"times has {len(times)} values for the polyline's {len(positions)} positions; "
            "give one per position"
        )
        raise RequestFieldError(msg, field="times")
    out: list[dict[str, object]] = [{"lat": lat, "lon": lon} for lat, lon in positions]
    if times is not None:
        for point, t in zip(out, times, strict=True):
            point["time"] = t
    return out


def _with_polylines(result: mapmatch.MatchResult, precision: int) -> bytes:
    """The GeoJSON answer with each segment's path also as an encoded polyline."""
    doc = result.to_geojson()
    for feature in doc["features"]:
        if feature["properties"].get("kind") == "segment":
            coords = feature["geometry"]["coordinates"]
            feature["properties"]["polyline"] = encode(((y, x) for x, y in coords), precision)
    return json.dumps(doc, allow_nan=False, separators=(",", ":")).encode()


def _check_points(points: object, limit: int) -> None:
    """The ``points`` member is a list of 2 .. ``limit`` items (the items: the reader's job)."""
    if points is None:
        msg = 'the body has no "points": send {"points": [{"time", "lat", "lon"}, ...]}'
        raise InvalidTraceError(msg, field="points")
    if not isinstance(points, list):
        msg = f'"points" must be a list of point objects (got {_shown(points)})'
        raise InvalidTraceError(msg, field="points")
    if len(points) < 2:
        msg = f'"points" holds {len(points)} point(s); a trace needs at least 2'
        raise InvalidTraceError(msg, field="points")
    if len(points) > limit:
        raise _too_many(len(points), limit)


def _trace_from_records(points: list[object], *, trace_id: str, crs: str) -> mapmatch.Trace:
    """
    The JSON points read by the library's own reader, errors naming ``points[i].field``.

    Raises
    ------
    InvalidTraceError
        A point breaks a rule; ``field`` is ``points[i].name`` for the first offending point.
    """
    try:
        return mapmatch.Trace.from_records(points, trace_id=trace_id, crs=crs)  # type: ignore[arg-type]
    except InvalidTraceError as exc:
        field = exc.field
        if exc.rows:
            field = f"points[{exc.rows[0]}]" + (f".{exc.field}" if exc.field else "")
        raise InvalidTraceError(
            str(exc), trace_id=exc.trace_id, field=field, rows=exc.rows
        ) from None
    except TraceFileError as exc:
        raise InvalidTraceError(str(exc), trace_id=trace_id, field="points") from None
    except OverflowError:  # a whole number too large for a float (10**400 as a latitude)
        msg = (
            f"trace {trace_id!r}: a number in the points is too large to be a coordinate, "
            "time or measurement; send decimal numbers in their units"
        )
        raise InvalidTraceError(msg, trace_id=trace_id, field="points") from None


def _where(loc: Iterable[int | str]) -> str:
    """``("points", 3, "lat")`` -> ``"points[3].lat"``."""
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += f".{part}" if out else str(part)
    return out


def _shown(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def validation_error(
    errors: Sequence[ErrorDetails], *, prefix: Sequence[str] = ()
) -> ServiceError | ConfigError | InvalidTraceError:
    """
    One project error for pydantic's validation errors of a request, naming field and rows.

    Errors about ``points`` become :class:`InvalidTraceError` (``invalid_trace``) with the
    offending point indices as rows; about ``options`` (or an option as a query parameter)
    :class:`OptionError`; malformed JSON :class:`InvalidJSONError`; anything else
    :class:`RequestFieldError`. ``prefix`` drops a leading location part (FastAPI's
    ``"query"``) from what is matched, but keeps it in the field name.
    """
    for err in errors:
        if err["type"] == "json_invalid":
            msg = f"the body is not valid JSON: {err['msg']}"
            return InvalidJSONError(msg)
    first = errors[0]
    loc = tuple(first["loc"])
    inner = loc[len(prefix) :] if loc[: len(prefix)] == tuple(prefix) else loc
    lines = []
    for err in errors[:_SHOW]:
        where = _where(err["loc"]) or "body"
        got = f" (got {_shown(err['input'])})" if err["type"] != "missing" else ""
        lines.append(f"{where}: {err['msg']}{got}")
    more = f"; and {len(errors) - _SHOW} more" if len(errors) > _SHOW else ""
    msg = "; ".join(lines) + more
    field = _where(loc) or None
    head = inner[0] if inner else None
    if head == "points":
        rows = sorted(
            {int(e["loc"][1]) for e in errors if len(e["loc"]) > 1 and isinstance(e["loc"][1], int)}
        )
        return InvalidTraceError(msg, field=field, rows=rows)
    if head == "options" or head in OVERRIDABLE:
        return OptionError(msg, field=field)
    if not inner and first["type"] in {"model_type", "model_attributes_type"}:
        msg = (
            'the body must be a JSON object {"points": [{"time", "lat", "lon"}, ...]} '
            f"(got {_shown(first['input'])})"
        )
    return RequestFieldError(msg, field=field)
