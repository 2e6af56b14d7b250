"""
What the OSRM- and Valhalla-compatible routes share.

(Over 400 lines on purpose: the OSRM and Valhalla routes share this whole answer path.)

- :func:`run_compat`: one match under the service's own limits (the match threads and their
  time budget, the point limit, the memory budget), its metrics and access-log fields, exactly
  as ``POST /v1/match`` has them; the request is parsed and the answer written in the match
  thread too.
- :func:`trace_rows`: each input row's fix in the :class:`~mapmatch.Trace` built from it (the
  trace merges a fix sent twice), so the answers keep one entry per input point.
- :class:`PathLine`: a segment's path as one line with the metres driven at every vertex, cut
  between any two places on it (OSRM's legs and annotations, Valhalla's shape indices).
- :func:`error_info`: status, stable code, message and headers of any raised error, from the
  one table in :mod:`api.errors`; a bug is logged with its traceback and the request id.
"""

from __future__ import annotations

import itertools
import json
import logging
import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final, TypeVar

import numpy as np
from starlette.responses import JSONResponse, Response

from api.deps import get_metrics, get_service
from api.errors import INTERNAL_ERROR, OptionError, error_answer, rule_for
from api.intake import declared_length
from api.middleware import SCOPE_KEY
from api.service import MatchOutcome
from mapmatch import ConfigError, MatchConfig

if TYPE_CHECKING:
    from collections.abc import Awaitable, Callable, Sequence

    from starlette.requests import Request

    from mapmatch import MatchResult, Trace
    from mapmatch.export import EdgeTable
    from mapmatch.types import FloatArray, IntArray
    from roadnets import RoadNetwork

__all__ = [
    "EARTH_RADIUS_M",
    "CompatInput",
    "ErrorInfo",
    "Matched",
    "PathLine",
    "bearing_deg",
    "compat_responses",
    "count_outcome",
    "error_info",
    "finite",
    "free_flow_s",
    "haversine_m",
    "respond",
    "run_compat",
    "segment_rows",
    "shown",
    "trace_rows",
]

R = TypeVar("R")

_log = logging.getLogger("api")
_BASE_CONFIG: Final = MatchConfig()
#: Mean Earth radius of the haversine distances between path vertices, metres.
EARTH_RADIUS_M: Final = 6_371_008.8


@dataclass(frozen=True, slots=True)
class CompatInput:
    """
    A parsed compatible request: the trace to match and how its input rows map onto it.

    Attributes
    ----------
    trace
        The trace built from the rows that were kept.
    rows
        For every input row (coordinate, shape point), its fix in ``trace``; ``-1`` for a row
        left out before the trace was built (OSRM's ``tidy``).
    network
        The network to match on (``None``: the default one).
    overrides
        Matcher options the request sets (``MatchConfig.replace`` takes them).
    diagnostics
        Whether the answer needs the candidates (OSRM's ``alternatives_count``).
    """

    trace: Trace
    rows: IntArray
    network: str | None
    overrides: dict[str, object]
    diagnostics: bool = False


@dataclass(frozen=True, slots=True)
class Matched:
    """A finished match with what its answer is written from."""

    request: CompatInput
    result: MatchResult
    net: RoadNetwork


def trace_rows(trace: Trace, kept: IntArray, columns: Sequence[FloatArray], total: int) -> IntArray:
    """
    Each input row's fix in ``trace``, built from rows ``kept`` (in time order) of ``total``.

    The trace keeps the rows in order (the callers refuse times that go back) but merges a
    row that repeats an earlier one exactly; such a row maps onto the fix it repeats, found by
    its values in ``columns`` (one array per column given to the trace, ``total`` long).

    Raises
    ------
    RuntimeError
        The trace reordered its rows, which the callers' checks rule out (a bug).
    """
    if trace.report.reordered_rows:
        msg = f"the trace reordered {trace.report.reordered_rows} rows after the order check"
        raise RuntimeError(msg)
    out = np.full(total, -1, dtype=np.int64)
    merged = np.zeros(len(kept), dtype=bool)
    merged[list(trace.report.merged_rows)] = True
    given = np.flatnonzero(~merged)
    out[kept[given]] = np.arange(len(given))
    if merged.any():
        seen: dict[tuple[float | None, ...], int] = {}
        for i, row in enumerate(kept.tolist()):
            key = tuple(_key(float(c[row])) for c in columns)
            if merged[i]:
                out[row] = seen[key]
            else:
                seen[key] = int(out[row])
    return out


def _key(value: float) -> float | None:
    return None if math.isnan(value) else value  # NaN never equals itself


async def run_compat(
    request: Request,
    build: Callable[[], tuple[CompatInput, R]],
    answer: Callable[[Matched, R], bytes],
) -> MatchOutcome:
    """
    Parse, match and answer one compatible request in a match thread, under the budget.

    ``build`` parses the request into a :class:`CompatInput` and what else the answer needs
    (the peer's own options); ``answer`` writes the response body from the match and those.
    The networks must be loaded before anything is queued (503 ``not_ready`` otherwise), the
    cost model is held against the memory budget, and the
    request's points, network and trace id go to the access log and the metrics.

    Raises
    ------
    MapMatchError
        Any problem of the request, the service's state or its limits.
    """
    service = get_service(request)
    service.networks.get(None)  # not_ready / network_unavailable before queueing
    deadline = time.monotonic() + service.runner.budget_s

    def job() -> MatchOutcome:
        started = time.perf_counter()
        parsed, options = build()
        net = service.networks.get(parsed.network)
        config = _config(parsed.overrides)
        result = service.match(
            parsed.trace, net, config, parsed.overrides, deadline, diagnostics=parsed.diagnostics
        )
        return MatchOutcome.of(result, answer(Matched(parsed, result, net), options), started)

    # the coordinates come in the URL or a form body: their size picks the runner's lane
    size = len(request.scope.get("query_string", b"")) + (declared_length(request) or 0)
    outcome = await service.runner.run(job, size=size)
    info = request.scope.get(SCOPE_KEY)
    if isinstance(info, dict):
        info.update(points=outcome.points, network=outcome.network, trace_id=outcome.trace_id)
    metrics = get_metrics(request)
    metrics.points.inc(outcome.points)
    metrics.matched_points.inc(outcome.matched_points)
    metrics.breaks.inc(outcome.breaks)
    metrics.match_seconds.observe(outcome.seconds)
    return outcome


def _config(overrides: dict[str, object]) -> MatchConfig:
    if not overrides:
        return _BASE_CONFIG
    try:
        return _BASE_CONFIG.replace(overrides)
    except ConfigError as exc:
        raise OptionError(str(exc), field=exc.field) from None


@dataclass(frozen=True, slots=True)
class ErrorInfo:
    """How one raised error answers, before a peer's format wraps it."""

    status: int
    code: str
    message: str
    headers: dict[str, str]


def error_info(request: Request, exc: BaseException) -> ErrorInfo:
    """
    The answer to ``exc`` from :data:`api.errors.ERROR_TABLE`, noted for logs and metrics.

    A bug (anything the table does not know) is logged with its traceback under the request
    id and answers a message that points to the log. The outcome is counted in
    ``mapmatch_matches`` as for ``POST /v1/match``.
    """
    info = request.scope.get(SCOPE_KEY)
    if rule_for(exc) is INTERNAL_ERROR:
        _log.error(
            "unhandled error in %s %s",
            request.method,
            request.url.path,
            exc_info=exc,
            extra={"request_id": info.get("request_id") if isinstance(info, dict) else None},
        )
    answer = error_answer(exc)
    if isinstance(info, dict):
        info["error"] = answer.code
    message = str(json.loads(answer.body)["error"]["message"])
    return ErrorInfo(answer.status, answer.code, message, dict(answer.headers))


def compat_responses(
    ok: type[Any], error: type[Any], answer: str
) -> dict[int | str, dict[str, Any]]:
    """The OpenAPI ``responses`` of a compatible route: ``ok`` on 200, ``error`` otherwise."""
    described = {
        200: answer,
        400: "A bad request, in the peer's own codes.",
        401: "Bearer token missing or wrong.",
        408: "The body arrived too slowly.",
        415: "A body or Content-Encoding this route does not read.",
        500: "A bug; the log has the traceback under the request id.",
        503: "Networks still loading, or every match thread busy.",
        504: "The match ran past the time budget.",
    }
    return {
        status: {"model": ok if status == 200 else error, "description": text}
        for status, text in described.items()
    }


async def respond(
    request: Request,
    work: Callable[[], Awaitable[MatchOutcome]],
    shape: Callable[[BaseException, ErrorInfo], tuple[int, dict[str, Any]]],
) -> Response:
    """
    The answer of a compatible route: the match's JSON, or any error in the peer's ``shape``.

    Both outcomes are counted in ``mapmatch_matches``, as for ``POST /v1/match``.
    """
    try:
        outcome = await work()
    except Exception as exc:  # every error answers in the peer's shape, a bug too
        info = error_info(request, exc)
        count_outcome(request, info.code)
        status, body = shape(exc, info)
        return JSONResponse(body, status_code=status, headers=info.headers)
    count_outcome(request, "ok")
    return Response(outcome.content, media_type="application/json")


def count_outcome(request: Request, code: str) -> None:
    """Count a finished compatible match request in ``mapmatch_matches`` by outcome."""
    get_metrics(request).matches.labels(outcome=code).inc()


# --------------------------------------------------------------------------- paths


def haversine_m(lon: FloatArray, lat: FloatArray) -> FloatArray:
    """Metres between consecutive positions (WGS84 degrees), on a sphere."""
    lam, phi = np.radians(lon), np.radians(lat)
    dphi, dlam = np.diff(phi), np.diff(lam)
    a = np.sin(dphi / 2) ** 2 + np.cos(phi[:-1]) * np.cos(phi[1:]) * np.sin(dlam / 2) ** 2
    out: FloatArray = 2 * EARTH_RADIUS_M * np.arcsin(np.sqrt(np.clip(a, 0.0, 1.0)))
    return out


def bearing_deg(lon: FloatArray, lat: FloatArray) -> FloatArray:
    """Initial bearing of each step between consecutive positions, degrees from north."""
    lam, phi = np.radians(lon), np.radians(lat)
    dlam = np.diff(lam)
    y = np.sin(dlam) * np.cos(phi[1:])
    x = np.cos(phi[:-1]) * np.sin(phi[1:]) - np.sin(phi[:-1]) * np.cos(phi[1:]) * np.cos(dlam)
    out: FloatArray = np.degrees(np.arctan2(y, x)) % 360.0
    return out


@dataclass(frozen=True, slots=True)
class PathLine:
    """
    One segment's path as a line: its vertices and the metres driven to each.

    Attributes
    ----------
    lon, lat
        Vertices, WGS84 degrees, in driving order; where one stretch ends and the next begins
        there is one vertex.
    along_m
        Metres along the path to each vertex (non-decreasing; the driven length of a stretch
        spread over its vertices in proportion to their great-circle steps).
    stretch
        Row of the result's :class:`~mapmatch.export.EdgeTable` of the stretch each step
        (vertex ``i`` to ``i + 1``) runs on; one shorter than the vertices.
    first_vertex, last_vertex
        Index of the first and last vertex of every stretch of the segment.
    """

    lon: FloatArray
    lat: FloatArray
    along_m: FloatArray
    stretch: IntArray
    first_vertex: IntArray
    last_vertex: IntArray

    @classmethod
    def of_segment(cls, result: MatchResult, index: int, rows: slice) -> PathLine:
        """The line of segment ``index``, whose stretches are rows ``rows`` of the edge table."""
        seg = result.segments[index]
        st = seg.stretches
        driven = seg.driven_m
        start = np.concatenate(([0.0], np.cumsum(driven)[:-1]))
        lon: list[float] = []
        lat: list[float] = []
        along: list[float] = []
        stretch: list[int] = []
        first = np.zeros(len(driven), dtype=np.int64)
        last = np.zeros(len(driven), dtype=np.int64)
        for k in range(len(driven)):
            x = st.lon[st.ptr[k] : st.ptr[k + 1]]
            y = st.lat[st.ptr[k] : st.ptr[k + 1]]
            steps = haversine_m(x, y)
            total = float(steps.sum())
            share = np.cumsum(steps) / total if total > 0 else np.linspace(0, 1, len(steps) + 1)[1:]
            at = start[k] + driven[k] * np.concatenate(([0.0], share))
            skip = 1 if lon else 0  # the stretch begins where the previous one ended
            first[k] = len(lon) - skip
            lon.extend(x[skip:].tolist())
            lat.extend(y[skip:].tolist())
            along.extend(at[skip:].tolist())
            stretch.extend([rows.start + k] * (len(x) - 1))
            last[k] = len(lon) - 1
        along_m = np.maximum.accumulate(np.asarray(along, dtype=np.float64))
        return cls(
            lon=np.asarray(lon, dtype=np.float64),
            lat=np.asarray(lat, dtype=np.float64),
            along_m=along_m,
            stretch=np.asarray(stretch, dtype=np.int64),
            first_vertex=first,
            last_vertex=last,
        )

    def cut(
        self, from_m: float, to_m: float
    ) -> tuple[FloatArray, FloatArray, FloatArray, IntArray]:
        """
        The line between two places on the path (metres along it, ``from_m <= to_m``).

        Returns the vertices' ``lon``, ``lat`` and ``along_m`` (the ends interpolated, the
        vertices strictly between kept) and the stretch of each step.
        """
        a = self.along_m
        inner = np.flatnonzero((a > from_m) & (a < to_m))
        ends = np.array([from_m, to_m])
        lon = np.interp(ends, a, self.lon)
        lat = np.interp(ends, a, self.lat)
        steps = len(self.stretch)
        first_step = min(max(int(np.searchsorted(a, from_m, side="right")) - 1, 0), steps - 1)
        step = np.concatenate(([first_step], np.minimum(inner, steps - 1)))
        return (
            np.concatenate(([lon[0]], self.lon[inner], [lon[1]])),
            np.concatenate(([lat[0]], self.lat[inner], [lat[1]])),
            np.concatenate(([from_m], a[inner], [to_m])),
            self.stretch[step],
        )


def free_flow_s(edges: EdgeTable, rows: slice) -> tuple[FloatArray, FloatArray]:
    """
    Seconds to drive a segment's path at the speed limits: ``(at_m, seconds)`` knots.

    The piecewise-linear time at every metre along the path of the segment whose stretches
    are rows ``rows`` of ``edges``, driving each at its speed limit (the estimate OSRM and
    Valhalla give without timestamps); ``np.interp(d, *knots)`` reads it anywhere.
    """
    start = edges.path_start_m[rows]
    end = edges.path_end_m[rows]
    speed_mps = np.maximum(edges.speed_limit_kph[rows] / 3.6, 0.1)
    seconds = np.cumsum((end - start) / speed_mps)
    at = np.concatenate((start[:1], end))
    return at, np.concatenate(([0.0], seconds))


def finite(value: float, digits: int) -> float | None:
    """``value`` rounded, or ``None`` when it is not a finite number."""
    return round(value, digits) if math.isfinite(value) else None


def segment_rows(edges: EdgeTable, segments: int) -> list[slice]:
    """The rows of ``edges`` of each of the result's ``segments``, in order."""
    counts = np.bincount(edges.segment, minlength=segments)
    bounds = np.concatenate(([0], np.cumsum(counts))).tolist()
    return [slice(int(a), int(b)) for a, b in itertools.pairwise(bounds)]


def shown(value: Any) -> str:
    """A value for a message, cut to 60 characters."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."
