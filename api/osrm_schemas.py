"""
OSRM's match service on this matcher: the request read, the answer written, the documented shapes.

(Over 400 lines on purpose: OSRM's request options and answer shapes are one contract, kept side
by side so that each option's parsing sits beside what it changes in the answer.)

The request is OSRM's ``/match/v1/{profile}/{coordinates}`` with its query options
(project-osrm.org, "Match service"); :func:`parse_request` reads it into an
:class:`OsrmRequest` (refusing what OSRM refuses, with OSRM's codes) and
:func:`build_answer` writes the response from a match. How each option maps onto the matcher:

==================  =============================================================================
OSRM                here
==================  =============================================================================
``coordinates``     the fixes, ``lon,lat;...`` or ``polyline(...)`` / ``polyline6(...)``
``timestamps``      the fixes' times (optional, as in OSRM; non-decreasing); without them the
                    trace is matched by distance only and durations are estimated from the
                    roads' speed limits
``radiuses``        each fix's accuracy (1-sigma, metres): the matcher's sigma for that fix, and
                    its search radius widens to 4 x the accuracy when that is more than the 50 m
                    default (OSRM searches 3 x the radius); empty or ``0`` = unknown
``bearings``        ``value`` is the fix's heading; it counts in proportion to the speed (none
                    when stopped, so none without timestamps). ``range`` is read and checked but
                    not used per fix: the heading's spread is the matcher's ``heading_sigma_deg``
``gaps``            ``split``: a new piece where the time to the next fix is more than 10 x the
                    median interval (OSRM's rule); ``ignore``: no split on time
``tidy``            OSRM's tidy: a fix is dropped unless 15 m and 5 s have passed since the last
                    kept one (the first and last always kept); dropped fixes are ``null``
``waypoints``       the legs run between these coordinates only (first and last required)
``geometries``      ``polyline`` (5 decimals), ``polyline6``, ``geojson``
``overview``        ``full``, ``simplified`` (Douglas-Peucker, 5 m), ``false`` (no geometry)
``annotations``     ``distance``, ``duration``, ``speed``, ``weight``, ``datasources`` per step of
                    the full geometry; ``true`` gives those five. ``nodes`` is refused: the
                    network keeps OSM node ids at intersections only, not at every vertex
``steps``           ``false`` only: no turn-by-turn instructions (``steps=true`` is refused)
``hints``           checked (one per coordinate) and not used: they only speed OSRM up
``generate_hints``  whether tracepoints carry a ``hint`` (an id of the snapped edge and offset)
``skip_waypoints``  leaves out ``tracepoints``
``approaches``      ``unrestricted`` only (a match has no curb side to keep)
``exclude``         refused: the network has no road classes to exclude
``network``         (this service's own) the network to match on; default the first
==================  =============================================================================

In the answer, a matching is one connected piece of the match (a segment) with at least two
tracepoints; ``confidence`` is the mean of its fixes' posterior probabilities, ``weight`` is its
duration (``weight_name`` ``"duration"``); ``duration`` comes from the timestamps where there are
any, else from the speed limits. A tracepoint is ``null`` when its coordinate was dropped by
``tidy``, had no road nearby, was judged an outlier (its place interpolated along the path in
``/v1/match``) or was alone in its piece of the trace; a ``message`` then counts each kind.
``alternatives_count`` counts the fix's other candidates with a posterior of at least 1 %.
"""

from __future__ import annotations

import base64
import itertools
import json
import math
import struct
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Final, Literal
from urllib.parse import parse_qsl

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from api.compat import (
    CompatInput,
    ErrorInfo,
    Matched,
    PathLine,
    finite,
    free_flow_s,
    haversine_m,
    segment_rows,
    shown,
    trace_rows,
)
from api.errors import RequestFieldError, TooManyPointsError
from api.polyline import PolylineError, decode, encode
from mapmatch import InvalidTraceError, Trace
from mapmatch.errors import MapMatchError
from mapmatch.export import edge_table, path_positions

if TYPE_CHECKING:
    from mapmatch import MatchResult
    from mapmatch.export import EdgeTable
    from mapmatch.types import FloatArray, IntArray

__all__ = [
    "ANNOTATIONS",
    "OPTIONS",
    "OsrmAnnotation",
    "OsrmErrorResponse",
    "OsrmLeg",
    "OsrmMatchResponse",
    "OsrmNoMatchError",
    "OsrmRequest",
    "OsrmRequestError",
    "OsrmRoute",
    "OsrmTracepoint",
    "build_answer",
    "osrm_error",
    "parse_form",
    "parse_request",
]

#: Annotations a request may ask for (``true`` means all of them).
ANNOTATIONS: Final = ("distance", "duration", "speed", "weight", "datasources")
#: The query options read, with what each takes (the error for an unknown one lists them).
OPTIONS: Final = (
    "timestamps",
    "radiuses",
    "bearings",
    "hints",
    "generate_hints",
    "approaches",
    "exclude",
    "gaps",
    "tidy",
    "waypoints",
    "steps",
    "annotations",
    "geometries",
    "overview",
    "skip_waypoints",
    "network",
)
PROFILES: Final = frozenset({"driving", "car"})
TIDY_DISTANCE_M: Final = 15.0
TIDY_DURATION_S: Final = 5.0
GAP_INTERVALS: Final = 10
SIMPLIFY_M: Final = 5.0
ALTERNATIVE_POSTERIOR: Final = 0.01
_DATASOURCES: Final = ["timestamps", "speed limits"]
_NODES_REFUSED: Final = (
    "annotations=nodes is not available: this network keeps OSM node ids at intersections "
    "only, not at every vertex of the geometry; ask for distance,duration,speed,weight,"
    "datasources, or use POST /v1/match, whose edges carry their OSM u and v"
)


# --------------------------------------------------------------------------- errors


class OsrmRequestError(RequestFieldError):
    """A request OSRM itself would refuse; ``osrm_code`` is OSRM's code for it."""

    def __init__(self, msg: str, osrm_code: str, *, field: str | None = None) -> None:
        self.osrm_code = osrm_code
        super().__init__(msg, field=field)


class OsrmNoMatchError(MapMatchError, LookupError):
    """No piece of the trace has two matched tracepoints (OSRM's ``NoMatch``)."""

    osrm_code = "NoMatch"


#: OSRM's code for each of this service's error codes (those OSRM has no name for keep one
#: in OSRM's style).
_CODES: Final = {
    "invalid_json": "InvalidQuery",
    "invalid_request": "InvalidQuery",
    "repeated_parameter": "InvalidQuery",
    "unsupported_media_type": "InvalidQuery",
    "unsupported_encoding": "InvalidQuery",
    "invalid_encoding": "InvalidQuery",
    "incomplete_body": "InvalidQuery",
    "body_timeout": "InvalidQuery",
    "body_too_large": "TooBig",
    "too_many_points": "TooBig",
    "too_many_columns": "TooBig",
    "over_budget": "TooBig",
    "invalid_trace": "InvalidValue",
    "invalid_body": "InvalidValue",
    "unknown_network": "InvalidValue",
    "invalid_options": "InvalidOptions",
    "no_road_nearby": "NoSegment",
    "unauthorized": "Unauthorized",
    "not_ready": "ServiceUnavailable",
    "network_unavailable": "ServiceUnavailable",
    "overloaded": "ServiceUnavailable",
    "timeout": "Timeout",
    "internal_error": "InternalError",
}
#: Statuses kept as they are; every other error answers 400, as OSRM does.
_KEPT_STATUSES: Final = frozenset({401, 408, 415, 500, 503, 504})


def osrm_error(exc: BaseException, info: ErrorInfo) -> tuple[int, dict[str, str]]:
    """The HTTP status and OSRM body ``{"code", "message"}`` of an error."""
    code = getattr(exc, "osrm_code", None) or _CODES.get(info.code, "InvalidValue")
    status = info.status if info.status in _KEPT_STATUSES else 400
    return status, {"code": str(code), "message": info.message}


# --------------------------------------------------------------------------- request


@dataclass(frozen=True, slots=True)
class OsrmRequest:
    """A match request as OSRM reads it; per-coordinate values are NaN where not given."""

    lon: FloatArray
    lat: FloatArray
    timestamps: FloatArray | None = None
    radiuses: FloatArray | None = None
    bearings: FloatArray | None = None
    gaps: Literal["split", "ignore"] = "split"
    tidy: bool = False
    waypoints: IntArray | None = None
    geometries: Literal["polyline", "polyline6", "geojson"] = "polyline"
    overview: Literal["simplified", "full", "false"] = "simplified"
    annotations: frozenset[str] = field(default_factory=frozenset)
    generate_hints: bool = True
    skip_waypoints: bool = False
    network: str | None = None

    def __len__(self) -> int:
        return len(self.lon)


def parse_form(body: bytes) -> list[tuple[str, str]]:
    """
    The options of a ``POST`` body (``application/x-www-form-urlencoded``).

    Raises
    ------
    OsrmRequestError
        ``InvalidQuery`` for a body that is not UTF-8 or not a form.
    """
    try:
        text = body.decode("utf-8")
        return parse_qsl(text, keep_blank_values=True, strict_parsing=bool(text.strip()))
    except (UnicodeDecodeError, ValueError) as exc:
        msg = f"the body is not a form (name=value&...): {exc}"
        raise OsrmRequestError(msg, "InvalidQuery", field="body") from None


def parse_request(
    version: str,
    profile: str,
    coordinates: str,
    params: list[tuple[str, str]],
    *,
    max_points: int,
) -> OsrmRequest:
    """
    Read an OSRM match request: path parts and options (query and form body together).

    Raises
    ------
    OsrmRequestError
        What OSRM refuses, with its code: ``InvalidVersion``, ``InvalidUrl``, ``InvalidQuery``
        (malformed, unknown or repeated option), ``InvalidOptions`` (a list of the wrong
        length, an unsupported option), ``InvalidValue`` (a coordinate or value out of range,
        timestamps that go back).
    TooManyPointsError
        More coordinates than the service matches (``TooBig``).
    """
    if version != "v1":
        msg = f"version {version!r} is not served; this service speaks OSRM's v1"
        raise OsrmRequestError(msg, "InvalidVersion", field="version")
    if profile not in PROFILES:
        msg = (
            f"profile {profile!r} is not served: this service matches drivable roads only; "
            "use /match/v1/driving/..."
        )
        raise OsrmRequestError(msg, "InvalidOptions", field="profile")
    lon, lat = _coordinates(coordinates, max_points)
    n = len(lon)
    given: dict[str, str] = {}
    for key, value in params:
        if key not in OPTIONS:
            msg = f"unknown option {key!r}; this service reads {', '.join(OPTIONS)}"
            raise OsrmRequestError(msg, "InvalidQuery", field=key)
        if key in given:
            msg = f"option {key!r} is given twice; give it once"
            raise OsrmRequestError(msg, "InvalidQuery", field=key)
        given[key] = value
    timestamps = _timestamps(given.get("timestamps"), n)
    radiuses = _per_point(given.get("radiuses"), n, "radiuses", _radius)
    bearings = _per_point(given.get("bearings"), n, "bearings", _bearing)
    if "hints" in given:
        _elements(given["hints"], n, "hints")
    approaches = _elements(given["approaches"], n, "approaches") if "approaches" in given else []
    for i, approach in enumerate(approaches):
        if approach not in ("", "unrestricted"):
            msg = (
                f"approaches[{i}] is {approach!r}: a match keeps no curb side; give "
                "'unrestricted' or nothing"
            )
            raise OsrmRequestError(msg, "InvalidOptions", field="approaches")
    if given.get("exclude"):
        msg = f"exclude={given['exclude']!r}: this network has no road classes to exclude"
        raise OsrmRequestError(msg, "InvalidOptions", field="exclude")
    if _flag(given, "steps", default=False):
        msg = (
            "steps=true is not supported: this service gives no turn-by-turn instructions; "
            "send steps=false (legs carry empty steps)"
        )
        raise OsrmRequestError(msg, "InvalidOptions", field="steps")
    network = given.get("network") or None
    return OsrmRequest(
        lon=lon,
        lat=lat,
        timestamps=timestamps,
        radiuses=radiuses,
        bearings=bearings,
        gaps=_choice(given, "gaps", ("split", "ignore"), "split"),  # type: ignore[arg-type]
        tidy=_flag(given, "tidy", default=False),
        waypoints=_waypoints(given.get("waypoints"), n),
        geometries=_choice(  # type: ignore[arg-type]
            given, "geometries", ("polyline", "polyline6", "geojson"), "polyline"
        ),
        overview=_choice(  # type: ignore[arg-type]
            given, "overview", ("simplified", "full", "false"), "simplified"
        ),
        annotations=_annotations(given.get("annotations", "false")),
        generate_hints=_flag(given, "generate_hints", default=True),
        skip_waypoints=_flag(given, "skip_waypoints", default=False),
        network=network,
    )


def _coordinates(text: str, max_points: int) -> tuple[FloatArray, FloatArray]:
    if text.endswith(".json"):
        text = text[: -len(".json")]
    for name, precision in (("polyline6", 6), ("polyline", 5)):
        if text.startswith(f"{name}(") and text.endswith(")"):
            try:
                positions = decode(text[len(name) + 1 : -1], precision)
            except PolylineError as exc:
                msg = f"coordinates: {exc}; send Google's encoded polyline format, URL-encoded"
                raise OsrmRequestError(msg, "InvalidQuery", field="coordinates") from None
            lat = np.array([p[0] for p in positions], dtype=np.float64)
            lon = np.array([p[1] for p in positions], dtype=np.float64)
            break
    else:
        pairs = text.split(";")
        if len(pairs) > max_points:
            raise _too_big(len(pairs), max_points)
        lon = np.empty(len(pairs))
        lat = np.empty(len(pairs))
        for i, pair in enumerate(pairs):
            parts = pair.split(",")
            try:
                if len(parts) != 2:
                    raise ValueError
                lon[i], lat[i] = float(parts[0]), float(parts[1])
            except ValueError:
                msg = (
                    f"coordinate {i} is {shown(pair)}; give {{longitude}},{{latitude}} pairs "
                    "separated by ';', or polyline(...)"
                )
                raise OsrmRequestError(msg, "InvalidQuery", field="coordinates") from None
    if len(lon) > max_points:
        raise _too_big(len(lon), max_points)
    if len(lon) < 2:
        msg = f"{len(lon)} coordinate(s) given; a match needs at least two"
        raise OsrmRequestError(msg, "InvalidOptions", field="coordinates")
    bad = np.flatnonzero(
        ~(np.isfinite(lon) & np.isfinite(lat) & (np.abs(lon) <= 180) & (np.abs(lat) <= 90))
    )
    if bad.size:
        i = int(bad[0])
        msg = (
            f"Invalid coordinate value: coordinate {i} is {lon[i]:g},{lat[i]:g}; longitude "
            "must be in [-180, 180] and latitude in [-90, 90], in that order"
        )
        raise OsrmRequestError(msg, "InvalidValue", field=f"coordinates[{i}]")
    return lon, lat


def _too_big(count: int, limit: int) -> TooManyPointsError:
    msg = (
        f"Too many trace coordinates: {count:,}; this service matches at most {limit:,} per "
        "request; split the trace"
    )
    return TooManyPointsError(msg, field="coordinates")


def _elements(text: str, n: int, name: str) -> list[str]:
    parts = text.split(";")
    if len(parts) != n:
        msg = (
            f"{name} has {len(parts)} elements for {n} coordinates; give one per coordinate "
            "(an empty element keeps the default)"
        )
        raise OsrmRequestError(msg, "InvalidOptions", field=name)
    return parts


def _number(text: str, name: str, i: int) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        msg = f"{name}[{i}] is {shown(text)}; give a number"
        raise OsrmRequestError(msg, "InvalidQuery", field=f"{name}[{i}]")
    return value


def _timestamps(text: str | None, n: int) -> FloatArray | None:
    if text is None:
        return None
    values = np.array(
        [_number(t, "timestamps", i) for i, t in enumerate(_elements(text, n, "timestamps"))]
    )
    if (values < 0).any():
        i = int(np.flatnonzero(values < 0)[0])
        msg = f"timestamps[{i}] is {values[i]:g}; give seconds since the UNIX epoch (>= 0)"
        raise OsrmRequestError(msg, "InvalidValue", field=f"timestamps[{i}]")
    back = np.flatnonzero(np.diff(values) < 0)
    if back.size:
        i = int(back[0]) + 1
        msg = (
            f"Timestamps need to be monotonically increasing: timestamps[{i}] = "
            f"{values[i]:g} comes before timestamps[{i - 1}] = {values[i - 1]:g}"
        )
        raise OsrmRequestError(msg, "InvalidValue", field=f"timestamps[{i}]")
    return values


def _radius(text: str, i: int) -> float:
    if text == "unlimited":
        msg = (
            f"radiuses[{i}] is 'unlimited': in a match a radius is the fix's standard "
            "deviation; give metres, or nothing for the default"
        )
        raise OsrmRequestError(msg, "InvalidValue", field=f"radiuses[{i}]")
    value = _number(text, "radiuses", i)
    if value < 0:
        msg = f"radiuses[{i}] is {value:g}; a standard deviation is >= 0 metres"
        raise OsrmRequestError(msg, "InvalidValue", field=f"radiuses[{i}]")
    return value if value > 0 else math.nan  # 0: unknown (what Android reports without one)


def _bearing(text: str, i: int) -> float:
    parts = text.split(",")
    if len(parts) != 2:
        msg = f"bearings[{i}] is {shown(text)}; give {{value}},{{range}} (degrees)"
        raise OsrmRequestError(msg, "InvalidQuery", field=f"bearings[{i}]")
    value = _number(parts[0], "bearings", i)
    spread = _number(parts[1], "bearings", i)
    if not (0 <= value <= 360 and 0 <= spread <= 180):
        msg = (
            f"bearings[{i}] is {shown(text)}; the value must be in 0..360 and the range in "
            "0..180 degrees"
        )
        raise OsrmRequestError(msg, "InvalidValue", field=f"bearings[{i}]")
    return value % 360.0


def _per_point(text: str | None, n: int, name: str, read: Any) -> FloatArray | None:
    if text is None:
        return None
    values = [read(t, i) if t else math.nan for i, t in enumerate(_elements(text, n, name))]
    out = np.array(values, dtype=np.float64)
    return out if np.isfinite(out).any() else None


def _flag(given: dict[str, str], name: str, *, default: bool) -> bool:
    value = given.get(name)
    if value is None:
        return default
    if value not in ("true", "false"):
        msg = f"{name} is {shown(value)}; give true or false"
        raise OsrmRequestError(msg, "InvalidQuery", field=name)
    return value == "true"


def _choice(given: dict[str, str], name: str, allowed: tuple[str, ...], default: str) -> str:
    value = given.get(name, default)
    if value not in allowed:
        msg = f"{name} is {shown(value)}; give one of {', '.join(allowed)}"
        raise OsrmRequestError(msg, "InvalidQuery", field=name)
    return value


def _annotations(text: str) -> frozenset[str]:
    if text == "false":
        return frozenset()
    if text == "true":
        return frozenset(ANNOTATIONS)
    asked = text.split(",")
    if "nodes" in asked:
        raise OsrmRequestError(_NODES_REFUSED, "InvalidOptions", field="annotations")
    asked = ["datasources" if a == "datasource" else a for a in asked]
    unknown = [a for a in asked if a not in ANNOTATIONS]
    if unknown:
        msg = (
            f"annotations: {shown(unknown[0])} is not one; give true, false or a list of "
            f"{', '.join(ANNOTATIONS)}"
        )
        raise OsrmRequestError(msg, "InvalidQuery", field="annotations")
    return frozenset(asked)


def _waypoints(text: str | None, n: int) -> IntArray | None:
    if text is None:
        return None
    try:
        values = [int(t) for t in text.split(";")]
    except ValueError:
        msg = f"waypoints is {shown(text)}; give coordinate indices separated by ';'"
        raise OsrmRequestError(msg, "InvalidQuery", field="waypoints") from None
    if len(values) < 2 or any(not 0 <= v < n for v in values):
        msg = (
            f"waypoints {shown(values)}: give at least two indices of input coordinates "
            f"(0 .. {n - 1})"
        )
        raise OsrmRequestError(msg, "InvalidOptions", field="waypoints")
    if values[0] != 0 or values[-1] != n - 1 or any(b <= a for a, b in itertools.pairwise(values)):
        msg = (
            "First and last coordinates must be specified as waypoints, in increasing order "
            f"(got {shown(values)} for {n} coordinates)"
        )
        raise OsrmRequestError(msg, "InvalidValue", field="waypoints")
    return np.array(values, dtype=np.int64)


# --------------------------------------------------------------------------- trace


def tidy_kept(req: OsrmRequest) -> IntArray:
    """
    The coordinates OSRM's ``tidy`` keeps (all of them without it).

    Walking the trace, a coordinate is kept once the distance and the time since the last
    kept one have reached 15 m and 5 s (the time only when there are timestamps); the first
    and the last are always kept.
    """
    n = len(req)
    if not req.tidy:
        return np.arange(n, dtype=np.int64)
    steps = haversine_m(req.lon, req.lat)
    dts = np.diff(req.timestamps) if req.timestamps is not None else None
    kept = [0]
    run_m = run_s = 0.0
    for nxt in range(1, n - 1):
        run_m += float(steps[nxt - 1])
        enough = run_m >= TIDY_DISTANCE_M
        if dts is not None:
            run_s += float(dts[nxt - 1])
            enough = enough and run_s >= TIDY_DURATION_S
        if enough:
            kept.append(nxt)
            run_m = run_s = 0.0
    kept.append(n - 1)
    return np.array(kept, dtype=np.int64)


def build_input(req: OsrmRequest) -> tuple[CompatInput, OsrmRequest]:
    """
    The trace to match: the kept coordinates with their times, accuracies and headings.

    With ``gaps=split`` a new piece of the trace starts where the time to the next kept
    coordinate is more than 10 x the median interval.

    Raises
    ------
    OsrmRequestError
        A value the trace refuses (``InvalidValue``).
    """
    kept = tidy_kept(req)
    time = req.timestamps[kept] if req.timestamps is not None else None
    segment = None
    if time is not None and req.gaps == "split" and len(kept) > 1:
        dt = np.diff(time)
        limit = GAP_INTERVALS * max(1.0, float(np.median(dt)))
        segment = np.concatenate(([0], np.cumsum(dt > limit)))
    columns: dict[str, FloatArray | None] = {
        "time": time,
        "accuracy": req.radiuses[kept] if req.radiuses is not None else None,
        "heading": req.bearings[kept] if req.bearings is not None else None,
    }
    try:
        trace = Trace(
            lon=req.lon[kept],
            lat=req.lat[kept],
            segment=segment,
            trace_id="osrm",
            **columns,  # type: ignore[arg-type]
        )
    except InvalidTraceError as exc:
        raise OsrmRequestError(str(exc), "InvalidValue", field="coordinates") from None
    values = [req.lon, req.lat] + [
        full for full in (req.timestamps, req.radiuses, req.bearings) if full is not None
    ]
    rows = trace_rows(trace, kept, values, len(req))
    compat = CompatInput(
        trace=trace, rows=rows, network=req.network, overrides={}, diagnostics=True
    )
    return compat, req


# --------------------------------------------------------------------------- answer


def _alternatives(result: MatchResult) -> IntArray:
    """Each fix's candidates other than the chosen one with a posterior of at least 1 %."""
    n = len(result.points.time_s)
    d = result.diagnostics
    if d is None or len(d.model_fixes) == 0:
        return np.zeros(n, dtype=np.int64)
    other = (~d.chosen) & (d.posterior >= ALTERNATIVE_POSTERIOR)
    order = np.argsort(d.model_fixes, kind="stable")
    model = d.model_fixes[order]
    counts = np.bincount(np.searchsorted(model, d.fix[other]), minlength=len(model))
    # a fix left out of the model (a stopped car's repeat) takes its nearest model fix's count
    at = np.clip(np.searchsorted(model, np.arange(n)), 0, len(model) - 1)
    before = np.clip(at - 1, 0, len(model) - 1)
    nearer = np.where(np.abs(model[before] - np.arange(n)) < np.abs(model[at] - np.arange(n)))
    at[nearer] = before[nearer]
    return np.asarray(counts[at], dtype=np.int64)


def _hint(edge: int, offset_m: float) -> str:
    """An opaque id of the snapped place (edge index and offset), as OSRM's hint is."""
    return base64.urlsafe_b64encode(struct.pack("<qd", edge, offset_m)).decode("ascii")


def _simplify(lon: FloatArray, lat: FloatArray, tolerance_m: float) -> IntArray:
    """Douglas-Peucker: the vertices to keep so that none is farther than the tolerance."""
    n = len(lon)
    if n <= 2:
        return np.arange(n)
    scale = math.cos(math.radians(float(np.mean(lat))))
    x = np.radians(lon) * scale * 6_371_008.8
    y = np.radians(lat) * 6_371_008.8
    keep = np.zeros(n, dtype=bool)
    keep[[0, -1]] = True
    stack = [(0, n - 1)]
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            continue
        dx, dy = x[b] - x[a], y[b] - y[a]
        px, py = x[a + 1 : b] - x[a], y[a + 1 : b] - y[a]
        length = math.hypot(dx, dy)
        dist = np.abs(px * dy - py * dx) / length if length > 0 else np.hypot(px, py)
        k = int(np.argmax(dist))
        if dist[k] > tolerance_m:
            mid = a + 1 + k
            keep[mid] = True
            stack += [(a, mid), (mid, b)]
    return np.flatnonzero(keep)


def _geometry(lon: FloatArray, lat: FloatArray, req: OsrmRequest) -> object:
    if len(lon) == 1:
        lon, lat = np.repeat(lon, 2), np.repeat(lat, 2)
    if req.overview == "simplified":
        keep = _simplify(lon, lat, SIMPLIFY_M)
        lon, lat = lon[keep], lat[keep]
    if req.geometries == "geojson":
        coords = np.round(np.column_stack((lon, lat)), 6).tolist()
        return {"type": "LineString", "coordinates": coords}
    precision = 6 if req.geometries == "polyline6" else 5
    return encode(zip(lat.tolist(), lon.tolist(), strict=True), precision)


def _summary(names: list[str], metres: FloatArray) -> str:
    """OSRM's leg summary: the names of the two roads driven longest, in driving order."""
    totals: dict[str, float] = {}
    for name, m in zip(names, metres.tolist(), strict=True):
        if name:
            totals[name] = totals.get(name, 0.0) + m
    top = sorted(totals, key=lambda k: -totals[k])[:2]
    return ", ".join(name for name in dict.fromkeys(names) if name in top)


@dataclass
class _Nulls:
    tidy: int = 0
    unmatched: int = 0
    outliers: int = 0
    alone: int = 0

    def message(self, total: int) -> str | None:
        parts = [
            (self.tidy, "removed by tidy"),
            (self.unmatched, "with no road nearby"),
            (self.outliers, "judged outliers"),
            (self.alone, "alone in their piece of the trace"),
        ]
        said = [f"{count} {why}" for count, why in parts if count]
        if not said:
            return None
        nulls = sum(count for count, _ in parts)
        return f"{nulls} of {total} tracepoints are null: {', '.join(said)}"


def build_answer(matched: Matched, req: OsrmRequest) -> bytes:
    """
    The OSRM match response of a finished match (see the module docstring).

    Raises
    ------
    OsrmNoMatchError
        No piece of the trace has two matched tracepoints; or ``waypoints`` were given and
        the trace split, or a waypoint is not matched.
    """
    result = matched.result
    p = result.points
    rows = matched.request.rows
    n = len(rows)
    positions = path_positions(result)
    edges = edge_table(result, positions)
    per_segment = segment_rows(edges, len(result.segments))
    alternatives = _alternatives(result)
    usable = np.asarray(p.matched, dtype=bool) & ~np.asarray(p.outlier, dtype=bool)
    usable &= np.isfinite(positions.along_m) & (positions.edge_index >= 0)
    nulls = _Nulls()
    fix = np.where(rows >= 0, rows, 0)
    row_ok = (rows >= 0) & usable[fix]
    nulls.tidy = int(np.count_nonzero(rows < 0))
    nulls.unmatched = int(np.count_nonzero((rows >= 0) & ~np.asarray(p.matched, bool)[fix]))
    nulls.outliers = int(np.count_nonzero((rows >= 0) & np.asarray(p.outlier, bool)[fix]))
    segment_of_row = np.where(row_ok, p.segment[fix], -1)
    pieces: list[tuple[int, IntArray]] = []
    tracepoints: list[dict[str, Any] | None] = [None] * n
    for seg in result.segments:
        members = np.flatnonzero(segment_of_row == seg.index)
        if len(np.unique(rows[members])) < 2:
            nulls.alone += len(members)
            continue
        for k, r in enumerate(members.tolist()):
            i = int(rows[r])
            tracepoints[r] = {
                "alternatives_count": int(alternatives[i]),
                "waypoint_index": k,
                "matchings_index": len(pieces),
                "location": [round(float(p.lon[i]), 6), round(float(p.lat[i]), 6)],
                "name": edges.name[per_segment[seg.index].start + int(positions.edge_index[i])],
                "distance": round(float(p.distance_m[i]), 3),
                "hint": _hint(int(p.edge[i]), float(p.offset_m[i])),
            }
        pieces.append((seg.index, members))
    if not pieces:
        msg = "Could not match the trace: no piece of it has two matched coordinates"
        detail = nulls.message(n)
        raise OsrmNoMatchError(f"{msg} ({detail})" if detail else msg)
    if req.waypoints is not None:
        _number_waypoints(tracepoints, req, matched.request.rows, len(pieces))
    matchings = [
        _matching(
            result, index, members, per_segment[index], edges, matched, req, positions.along_m
        )
        for index, members in pieces
    ]
    doc: dict[str, Any] = {"code": "Ok"}
    message = nulls.message(n)
    if message:
        doc["message"] = message
    doc["matchings"] = matchings
    if not req.skip_waypoints:
        if not req.generate_hints:
            for tp in tracepoints:
                if tp is not None:
                    del tp["hint"]
        doc["tracepoints"] = tracepoints
    return json.dumps(doc, separators=(",", ":"), allow_nan=False).encode()


def _waypoint_rows(req: OsrmRequest, rows: IntArray) -> list[int]:
    """The input rows the legs end at: the waypoints, a tidied-away one moved back to a kept one."""
    assert req.waypoints is not None
    out: list[int] = []
    for w in req.waypoints.tolist():
        r = w
        while rows[r] < 0:
            r -= 1
        if not out or out[-1] != r:
            out.append(r)
    return out


def _number_waypoints(
    tracepoints: list[dict[str, Any] | None], req: OsrmRequest, rows: IntArray, count: int
) -> None:
    if count > 1:
        msg = "Could not match the trace with the given waypoints: it splits into pieces"
        raise OsrmNoMatchError(msg)
    ends = _waypoint_rows(req, rows)
    if any(tracepoints[r] is None for r in ends):
        missing = [r for r in ends if tracepoints[r] is None]
        msg = f"Requested waypoint parameter could not be matched: coordinate(s) {missing}"
        raise OsrmNoMatchError(msg)
    rank = {r: k for k, r in enumerate(ends)}
    for r, tp in enumerate(tracepoints):
        if tp is not None:
            tp["waypoint_index"] = rank.get(r)


def _matching(
    result: MatchResult,
    index: int,
    members: IntArray,
    rows: slice,
    edges: EdgeTable,
    matched: Matched,
    req: OsrmRequest,
    along_m: FloatArray,
) -> dict[str, Any]:
    """One matching: segment ``index`` between its tracepoints (input rows ``members``)."""
    p = result.points
    fixes = matched.request.rows[members]
    along = np.maximum.accumulate(along_m[fixes])
    times = p.time_s[fixes]
    timed = bool(np.isfinite(times).all())
    if req.waypoints is not None:
        inside = set(members.tolist())
        ends = [r for r in _waypoint_rows(req, matched.request.rows) if r in inside]
        cut = [int(np.flatnonzero(members == r)[0]) for r in ends]
    else:
        cut = list(range(len(members)))
    line = PathLine.of_segment(result, index, rows)
    knots = free_flow_s(edges, rows)
    legs: list[dict[str, Any]] = []
    lon_all: list[FloatArray] = []
    lat_all: list[FloatArray] = []
    for a, b in itertools.pairwise(cut):
        lon, lat, at, stretch = line.cut(float(along[a]), float(along[b]))
        legs.append(_leg(lon, lat, at, stretch, times[a], times[b], timed, knots, edges, req))
        lon_all.append(lon if not lon_all else lon[1:])
        lat_all.append(lat if not lat_all else lat[1:])
    distance = float(along[cut[-1]] - along[cut[0]])
    duration = float(sum(leg["duration"] for leg in legs))
    route: dict[str, Any] = {
        "confidence": round(float(np.mean(p.confidence[np.unique(fixes)])), 6),
        "distance": round(distance, 1),
        "duration": round(duration, 1),
        "weight": round(duration, 1),
        "weight_name": "duration",
    }
    if req.overview != "false":
        route["geometry"] = _geometry(np.concatenate(lon_all), np.concatenate(lat_all), req)
    route["legs"] = legs
    return route


def _leg(
    lon: FloatArray,
    lat: FloatArray,
    at: FloatArray,
    stretch: IntArray,
    t0: float,
    t1: float,
    timed: bool,
    knots: tuple[FloatArray, FloatArray],
    edges: EdgeTable,
    req: OsrmRequest,
) -> dict[str, Any]:
    step_m = np.diff(at)
    distance = float(at[-1] - at[0])
    if timed:
        duration = float(t1 - t0)
        share = step_m / distance if distance > 0 else np.full(len(step_m), 1 / len(step_m))
        step_s = duration * share
    else:
        clock = np.interp(at, *knots)
        step_s = np.diff(clock)
        duration = float(clock[-1] - clock[0])
    leg: dict[str, Any] = {
        "distance": round(distance, 1),
        "duration": round(duration, 1),
        "weight": round(duration, 1),
        "summary": _summary([edges.name[s] for s in stretch.tolist()], step_m),
        "steps": [],
    }
    if req.annotations:
        note: dict[str, Any] = {}
        if "distance" in req.annotations:
            note["distance"] = np.round(step_m, 6).tolist()
        if "duration" in req.annotations:
            note["duration"] = np.round(step_s, 1).tolist()
        if "weight" in req.annotations:
            note["weight"] = np.round(step_s, 1).tolist()
        if "speed" in req.annotations:
            with np.errstate(invalid="ignore", divide="ignore"):
                speed = np.where(step_s > 0, np.round(step_m / step_s, 1), np.nan)
            note["speed"] = [finite(float(v), 1) for v in speed]
        if "datasources" in req.annotations:
            note["datasources"] = [0 if timed else 1] * len(step_m)
            note["metadata"] = {"datasource_names": _DATASOURCES}
        leg["annotation"] = note
    return leg


# --------------------------------------------------------------------------- documented shapes


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class OsrmAnnotation(_Strict):
    """Per step of the leg's geometry (pairs of consecutive coordinates), as asked for."""

    distance: list[float] | None = Field(default=None, description="Metres of each step.")
    duration: list[float] | None = Field(default=None, description="Seconds of each step.")
    weight: list[float] | None = Field(default=None, description="Weight (= seconds) of each step.")
    speed: list[float | None] | None = Field(
        default=None, description="distance / duration of each step, m/s, one decimal."
    )
    datasources: list[int] | None = Field(
        default=None,
        description="Where each step's duration comes from: 0 timestamps, 1 speed limits.",
    )
    metadata: dict[str, list[str]] | None = Field(
        default=None, description="`datasource_names`: the names of the datasources."
    )


class OsrmLeg(_Strict):
    """The route between two consecutive tracepoints (or waypoints)."""

    distance: float = Field(description="Metres along the matched roads.")
    duration: float = Field(description="Seconds: from the timestamps, else the speed limits.")
    weight: float = Field(description="Equal to the duration.")
    summary: str = Field(description="Names of the two roads driven longest on the leg.")
    steps: list[dict[str, Any]] = Field(description="Always empty: steps are not supported.")
    annotation: OsrmAnnotation | None = Field(default=None, description="When asked for.")


class OsrmLineString(_Strict):
    """A GeoJSON LineString (``geometries=geojson``)."""

    type: Literal["LineString"] = Field(description="Always LineString.")
    coordinates: list[list[float]] = Field(description="[lon, lat] positions, WGS84.")


class OsrmRoute(_Strict):
    """One matching: a connected piece of the matched trace."""

    confidence: float = Field(description="Mean posterior probability of its fixes, 0..1.")
    distance: float = Field(description="Metres from its first to its last tracepoint.")
    duration: float = Field(description="Seconds: from the timestamps, else the speed limits.")
    weight: float = Field(description="Equal to the duration.")
    weight_name: str = Field(description="Always `duration`.")
    geometry: str | OsrmLineString | None = Field(
        default=None, description="Polyline (5 or 6 decimals) or GeoJSON; absent: overview=false."
    )
    legs: list[OsrmLeg] = Field(description="One per pair of consecutive tracepoints.")


class OsrmTracepoint(_Strict):
    """Where an input coordinate was matched."""

    alternatives_count: int = Field(description="Other candidates with posterior >= 1 %.")
    waypoint_index: int | None = Field(description="Index among its matching's waypoints.")
    matchings_index: int = Field(description="Index of its matching.")
    location: list[float] = Field(description="[lon, lat] of the snapped position.")
    name: str = Field(description="Name of the street snapped to ('' for none).")
    distance: float = Field(description="Metres from the input coordinate to the snapped one.")
    hint: str | None = Field(default=None, description="Opaque id of the snapped edge place.")


class OsrmMatchResponse(_Strict):
    """OSRM's match response."""

    code: Literal["Ok"] = Field(description="`Ok`.")
    message: str | None = Field(default=None, description="Why some tracepoints are null.")
    matchings: list[OsrmRoute] = Field(description="The matched pieces of the trace.")
    tracepoints: list[OsrmTracepoint | None] | None = Field(
        default=None, description="One per input coordinate; null where not matched."
    )


class OsrmErrorResponse(_Strict):
    """OSRM's error response."""

    code: str = Field(
        description="InvalidUrl, InvalidVersion, InvalidQuery, InvalidOptions, InvalidValue, "
        "NoSegment, NoMatch, TooBig; and Unauthorized, ServiceUnavailable, Timeout, "
        "InternalError for this service's own states."
    )
    message: str = Field(description="What is wrong, with the offending value.")
