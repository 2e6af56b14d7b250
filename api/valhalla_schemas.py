"""
Valhalla's ``trace_attributes`` on this matcher: the request read, the answer written.

(Over 400 lines on purpose: Valhalla's request and answer shapes are one contract, kept side by
side so that each option's parsing sits beside what it changes in the answer.)

The request is Valhalla's (valhalla.github.io, "Map Matching service API reference");
:func:`parse_request` reads it into a :class:`ValhallaRequest` and :func:`build_answer` writes
the answer. How the request maps onto the matcher:

=========================  =======================================================================
Valhalla                   here
=========================  =======================================================================
``shape``                  the fixes: ``lat``, ``lon``, optional ``time`` (seconds; all points or
                           none, not decreasing) and ``heading``; ``type`` is accepted (it only
                           splits ``trace_route`` legs); a point's ``radius`` is not used (warning)
``encoded_polyline``       the fixes, precision 6; times: ``begin_time`` + ``durations``
``costing``                ``auto`` (or ``auto_shorter``); any other is refused: the network holds
                           drivable roads only
``shape_match``            ``map_snap`` and ``walk_or_snap`` (both map-match); ``edge_walk`` is
                           refused: this service always map-matches
``filters``                ``attributes`` with ``action`` ``include`` / ``exclude`` (default
                           include); attributes this service cannot know: named in ``warnings``
``units``                  ``kilometers`` (default) or ``miles``; or ``directions_options.units``
``use_timestamps``         ``true``: elapsed times and edge speeds from the fixes' times; ``false``
                           (default, as in Valhalla): from the speed limits
``trace_options``          ``gps_accuracy`` -> the matcher's ``sigma_m``, ``search_radius`` ->
                           ``search_radius_m``; ``breakage_distance``,
                           ``interpolation_distance`` and ``turn_penalty_factor`` are not used
                           (warning)
``costing_options``        not used (warning): the matcher has no costing
``id``                     echoed back
``network``                (this service's own) the network to match on; default the first
=========================  =======================================================================

Edges are the driven stretches of every edge, in order, across the pieces of the trace:
``length`` is the length driven (the first and last edges of a piece are partly driven),
``speed`` the speed behind ``end_node.elapsed_time`` (the mean speed driven, or the speed limit),
``speed_limit`` the tagged ``maxspeed`` or the road class's default, ``road_class`` Valhalla's
class of the OSM ``highway`` (links are their road's class with ``use`` ``ramp``), ``id`` the
edge's index in this network, ``traversability`` ``forward`` for a one-way road. Beyond
Valhalla, ``begin_time`` and ``end_time`` (epoch seconds, when the fixes have times) say when
the edge was entered and left (filter keys ``edge.begin_time``, ``edge.end_time``).
``matched_points`` has one entry per input point; ``type`` ``interpolated`` marks fixes placed
along the path rather than matched on their own (a stopped car's repeats, outliers).
"""

from __future__ import annotations

import http
import json
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from api.compat import (
    CompatInput,
    ErrorInfo,
    Matched,
    PathLine,
    bearing_deg,
    finite,
    segment_rows,
    shown,
    trace_rows,
)
from api.errors import RequestFieldError, TooManyPointsError
from api.polyline import PolylineError, decode, encode
from api.service import parse_json
from mapmatch import InvalidTraceError, Trace
from mapmatch.errors import MapMatchError
from mapmatch.export import edge_table, path_positions

if TYPE_CHECKING:
    from mapmatch.export import EdgeTable, PathPositions
    from mapmatch.types import FloatArray, IntArray

__all__ = [
    "ATTRIBUTES",
    "KNOWN_ATTRIBUTES",
    "ValhallaEdge",
    "ValhallaErrorResponse",
    "ValhallaMatchedPoint",
    "ValhallaNoMatchError",
    "ValhallaRequest",
    "ValhallaRequestError",
    "ValhallaResponse",
    "build_answer",
    "build_input",
    "parse_request",
    "valhalla_error",
]

#: The attribute filter keys this service answers.
ATTRIBUTES: Final = (
    "edge.names",
    "edge.length",
    "edge.speed",
    "edge.speed_limit",
    "edge.road_class",
    "edge.use",
    "edge.way_id",
    "edge.id",
    "edge.begin_shape_index",
    "edge.end_shape_index",
    "edge.begin_heading",
    "edge.end_heading",
    "edge.traversability",
    "edge.begin_time",
    "edge.end_time",
    "node.elapsed_time",
    "shape",
    "matched.point",
    "matched.type",
    "matched.edge_index",
    "matched.begin_route_discontinuity",
    "matched.end_route_discontinuity",
    "matched.distance_along_edge",
    "matched.distance_from_trace_point",
)
#: Valhalla's other documented filter keys: accepted, and named in a warning when asked for.
_EDGE_ONLY_VALHALLA: Final = (
    "toll unpaved tunnel bridge roundabout internal_intersection drive_on_right surface "
    "sign.exit_number sign.exit_branch sign.exit_toward sign.exit_name travel_mode "
    "vehicle_type pedestrian_type bicycle_type transit_type indoor weighted_grade "
    "max_upward_grade max_downward_grade mean_elevation lane_count cycle_lane "
    "bicycle_network sac_scale shoulder sidewalk density truck_speed truck_route"
)
_NODE_ONLY_VALHALLA: Final = (
    "intersecting_edge.begin_heading intersecting_edge.from_edge_name_consistency "
    "intersecting_edge.to_edge_name_consistency intersecting_edge.driveability "
    "intersecting_edge.cyclability intersecting_edge.walkability intersecting_edge.use "
    "intersecting_edge.road_class intersecting_edge.lane_count admin_index type fork time_zone"
)
KNOWN_ATTRIBUTES: Final = frozenset(
    [f"edge.{name}" for name in _EDGE_ONLY_VALHALLA.split(" ")]
    + [f"node.{name}" for name in _NODE_ONLY_VALHALLA.split(" ")]
    + ["osm_changeset", "admin.country_code", "admin.country_text", "admin.state_code"]
    + ["admin.state_text"]
)
COSTINGS: Final = frozenset({"auto", "auto_shorter"})
SHAPE_MATCHES: Final = ("map_snap", "walk_or_snap")
_UNITS: Final = {"kilometers": "kilometers", "km": "kilometers", "miles": "miles", "mi": "miles"}
_METRES_PER: Final = {"kilometers": 1000.0, "miles": 1609.344}
#: Valhalla's road class of each OSM ``highway`` value of the network.
ROAD_CLASS: Final = {
    "motorway": "motorway",
    "trunk": "trunk",
    "primary": "primary",
    "secondary": "secondary",
    "tertiary": "tertiary",
    "motorway_link": "motorway",
    "trunk_link": "trunk",
    "primary_link": "primary",
    "secondary_link": "secondary",
    "tertiary_link": "tertiary",
    "unclassified": "unclassified",
    "residential": "residential",
    "living_street": "residential",
    "road": "unclassified",
    "service": "service_other",
}
_READ: Final = frozenset(
    {
        "shape",
        "encoded_polyline",
        "costing",
        "shape_match",
        "filters",
        "units",
        "directions_options",
        "use_timestamps",
        "trace_options",
        "costing_options",
        "id",
        "begin_time",
        "durations",
        "network",
        "action",
        "format",
    }
)
_IGNORED_TRACE_OPTIONS: Final = (
    "breakage_distance",
    "interpolation_distance",
    "turn_penalty_factor",
)
_UNUSED: Final = 299  # the code of this service's warnings: a parameter it does not use


# --------------------------------------------------------------------------- errors


class ValhallaRequestError(RequestFieldError):
    """A request Valhalla would refuse; ``valhalla_code`` is Valhalla's error code."""

    def __init__(self, valhalla_code: int, msg: str, *, field: str | None = None) -> None:
        self.valhalla_code = valhalla_code
        super().__init__(msg, field=field)


class ValhallaNoMatchError(MapMatchError, LookupError):
    """The map matching found no path (Valhalla's 444)."""

    valhalla_code = 444


_CODES: Final = {
    "invalid_json": 100,
    "invalid_request": 100,
    "unsupported_media_type": 100,
    "unsupported_encoding": 100,
    "invalid_encoding": 100,
    "incomplete_body": 100,
    "body_timeout": 100,
    "body_too_large": 153,
    "too_many_points": 153,
    "too_many_columns": 153,
    "over_budget": 153,
    "invalid_trace": 134,
    "invalid_options": 158,
    "no_road_nearby": 171,
    "unprocessable": 444,
}
_KEPT_STATUSES: Final = frozenset({401, 408, 415, 500, 503, 504})
#: Valhalla's own words for the codes used here; a message starts with them.
_TEXTS: Final = {
    100: "Failed to parse json request",
    134: "Failed to parse shape",
    153: "Too many shape points",
    158: "Input trace option is out of bounds",
    171: "No suitable edges near location",
    444: "Map Match algorithm failed to find path",
}


def valhalla_error(exc: BaseException, info: ErrorInfo) -> tuple[int, dict[str, object]]:
    """The HTTP status and Valhalla's error body ``{error_code, error, status_code, status}``."""
    code = getattr(exc, "valhalla_code", None) or _CODES.get(info.code, 199)
    status = info.status if info.status in _KEPT_STATUSES else 400
    text = _TEXTS.get(int(code))
    message = info.message
    if text and not message.startswith(text):
        message = f"{text}: {message}"
    body: dict[str, object] = {
        "error_code": int(code),
        "error": message,
        "status_code": status,
        "status": http.HTTPStatus(status).phrase,
    }
    return status, body


# --------------------------------------------------------------------------- request


@dataclass(frozen=True, slots=True)
class ValhallaRequest:
    """A ``trace_attributes`` request as read; what it asks for and what it left unused."""

    lon: FloatArray
    lat: FloatArray
    time: FloatArray | None
    heading: FloatArray | None
    units: Literal["kilometers", "miles"]
    use_timestamps: bool
    attributes: frozenset[str]
    overrides: dict[str, object]
    warnings: tuple[str, ...]
    id: object
    network: str | None

    def __len__(self) -> int:
        return len(self.lon)


def parse_request(body: bytes, *, max_points: int) -> ValhallaRequest:
    """
    Read a ``trace_attributes`` request (a JSON object).

    Raises
    ------
    InvalidJSONError
        The body is not JSON (Valhalla's 100).
    ValhallaRequestError
        What Valhalla refuses, with its code (123, 124, 125, 126, 134, 136, 158, 445).
    TooManyPointsError
        More points than the service matches (153).
    """
    doc = parse_json(body)
    if not isinstance(doc, dict):
        msg = f"the request must be a JSON object (got {shown(doc)})"
        raise ValhallaRequestError(100, f"Failed to parse json request: {msg}")
    warnings: list[str] = []
    unread = sorted(set(doc) - _READ)
    if unread:
        warnings.append(f"not read by this service: {', '.join(unread)}")
    costing = doc.get("costing")
    if costing is None:
        msg = "No edge/node costing provided: give costing 'auto'"
        raise ValhallaRequestError(124, msg, field="costing")
    if costing not in COSTINGS:
        msg = (
            f"No costing method found for {shown(costing)}: this service matches drivable "
            "roads only; give costing 'auto'"
        )
        raise ValhallaRequestError(125, msg, field="costing")
    shape_match = doc.get("shape_match", "walk_or_snap")
    if shape_match not in SHAPE_MATCHES:
        why = (
            "edge_walk is not supported: this service always map-matches"
            if shape_match == "edge_walk"
            else f"{shown(shape_match)} is not a shape_match"
        )
        msg = (
            "Shape match algorithm specification in api request is incorrect: "
            f"{why}; give map_snap or walk_or_snap"
        )
        raise ValhallaRequestError(445, msg, field="shape_match")
    lon, lat, time, heading = _positions(doc, max_points, warnings)
    if doc.get("format", "json") != "json":
        msg = f"format {shown(doc['format'])}: this service answers json only"
        raise ValhallaRequestError(164, f"Invalid shape format: {msg}", field="format")
    use_timestamps = doc.get("use_timestamps", False)
    if not isinstance(use_timestamps, bool):
        msg = f"use_timestamps is {shown(use_timestamps)}; give true or false"
        raise ValhallaRequestError(100, msg, field="use_timestamps")
    if use_timestamps and time is None:
        msg = "use_timestamps set with no timestamps present: give every shape point a time"
        raise ValhallaRequestError(159, msg, field="use_timestamps")
    if doc.get("costing_options"):
        warnings.append("costing_options are not used: the matcher has no costing")
    network = doc.get("network")
    if network is not None and not isinstance(network, str):
        msg = f"network is {shown(network)}; give a network id (GET /v1/networks)"
        raise ValhallaRequestError(100, msg, field="network")
    return ValhallaRequest(
        lon=lon,
        lat=lat,
        time=time,
        heading=heading,
        units=_units(doc),
        use_timestamps=use_timestamps,
        attributes=_attributes(doc, warnings),
        overrides=_trace_options(doc, warnings),
        warnings=tuple(warnings),
        id=doc.get("id"),
        network=network,
    )


def _positions(
    doc: dict[str, Any], max_points: int, warnings: list[str]
) -> tuple[FloatArray, FloatArray, FloatArray | None, FloatArray | None]:
    shape, polyline = doc.get("shape"), doc.get("encoded_polyline")
    if shape is not None and polyline is not None:
        msg = "Failed to parse shape: give shape or encoded_polyline, not both"
        raise ValhallaRequestError(134, msg, field="shape")
    if shape is None and polyline is None:
        msg = "No shape provided: give shape [{lat, lon, time?}, ...] or encoded_polyline"
        raise ValhallaRequestError(126, msg, field="shape")
    if polyline is not None:
        lon, lat, time = _polyline(doc, polyline, max_points)
        heading = None
    else:
        lon, lat, time, heading = _shape(shape, max_points, warnings)
    if time is not None:
        back = np.flatnonzero(np.diff(time) < 0)
        if back.size:
            i = int(back[0]) + 1
            msg = (
                f"Failed to parse shape: the time of point {i} ({time[i]:g}) comes before "
                f"point {i - 1}'s ({time[i - 1]:g}); times must not decrease"
            )
            raise ValhallaRequestError(134, msg, field=f"shape[{i}].time")
    return lon, lat, time, heading


def _count(n: int, max_points: int) -> None:
    if n > max_points:
        msg = (
            f"Too many shape points: {n:,}; this service matches at most {max_points:,} per "
            "request; split the trace"
        )
        raise TooManyPointsError(msg, field="shape")
    if n < 2:
        msg = f"Insufficient shape provided: {n} point(s); a trace needs at least two"
        raise ValhallaRequestError(123, msg, field="shape")


def _polyline(
    doc: dict[str, Any], text: object, max_points: int
) -> tuple[FloatArray, FloatArray, FloatArray | None]:
    if not isinstance(text, str):
        msg = f"Failed to parse shape: encoded_polyline is {shown(text)}, not a string"
        raise ValhallaRequestError(134, msg, field="encoded_polyline")
    try:
        positions = decode(text, 6)
    except PolylineError as exc:
        msg = f"Failed to parse shape: encoded_polyline: {exc} (precision 6)"
        raise ValhallaRequestError(134, msg, field="encoded_polyline") from None
    _count(len(positions), max_points)
    lat = np.array([q[0] for q in positions], dtype=np.float64)
    lon = np.array([q[1] for q in positions], dtype=np.float64)
    durations = doc.get("durations")
    if durations is None:
        return lon, lat, None
    begin = doc.get("begin_time", 0)
    ok = isinstance(durations, list) and all(_is_number(d) and d >= 0 for d in durations)
    if not ok or not _is_number(begin):
        msg = (
            "durations must be a list of seconds >= 0 between successive points and "
            f"begin_time a number (got {shown(durations)}, {shown(begin)})"
        )
        raise ValhallaRequestError(136, msg, field="durations")
    if len(durations) != len(positions) - 1:
        msg = (
            f"durations size not compatible with trace size: {len(durations)} durations for "
            f"{len(positions)} points; give one per pair of successive points"
        )
        raise ValhallaRequestError(136, msg, field="durations")
    time = float(begin) + np.concatenate(([0.0], np.cumsum(np.array(durations, float))))
    return lon, lat, time


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _shape(
    shape: object, max_points: int, warnings: list[str]
) -> tuple[FloatArray, FloatArray, FloatArray | None, FloatArray | None]:
    if not isinstance(shape, list):
        msg = f"Failed to parse shape: shape must be a list of points (got {shown(shape)})"
        raise ValhallaRequestError(134, msg, field="shape")
    _count(len(shape), max_points)
    n = len(shape)
    lon, lat = np.empty(n), np.empty(n)
    time, heading = np.full(n, np.nan), np.full(n, np.nan)
    radius = 0
    for i, point in enumerate(shape):
        if not isinstance(point, dict):
            msg = f"Failed to parse shape: point {i} is {shown(point)}, not {{lat, lon}}"
            raise ValhallaRequestError(134, msg, field=f"shape[{i}]")
        for name, out in (("lat", lat), ("lon", lon), ("time", time), ("heading", heading)):
            value = point.get(name)
            if value is None and name in ("time", "heading"):
                continue
            if not isinstance(value, int | float) or not _is_number(value):
                msg = f"Failed to parse shape: point {i} has {name} {shown(value)}, not a number"
                raise ValhallaRequestError(134, msg, field=f"shape[{i}].{name}")
            out[i] = float(value)
        radius += "radius" in point
    bad = np.flatnonzero((np.abs(lat) > 90) | (np.abs(lon) > 180))
    if bad.size:
        i = int(bad[0])
        msg = (
            f"Failed to parse shape: point {i} has lat {lat[i]:g}, lon {lon[i]:g}; lat must be "
            "in [-90, 90] and lon in [-180, 180]"
        )
        raise ValhallaRequestError(134, msg, field=f"shape[{i}]")
    timed = np.isfinite(time)
    if timed.any() and not timed.all():
        i = int(np.flatnonzero(~timed)[0])
        msg = (
            f"Failed to parse shape: {int(timed.sum())} of {n} points have a time (point {i} "
            "has none); give every point a time, or none"
        )
        raise ValhallaRequestError(134, msg, field=f"shape[{i}].time")
    if radius:
        warnings.append(
            f"the radius of {radius} shape point(s) is not used: set "
            "trace_options.search_radius for the whole trace"
        )
    return (
        lon,
        lat,
        time if timed.all() else None,
        heading if np.isfinite(heading).any() else None,
    )


def _units(doc: dict[str, Any]) -> Literal["kilometers", "miles"]:
    options = doc.get("directions_options")
    value = doc.get("units")
    if value is None and isinstance(options, dict):
        value = options.get("units")
    value = "kilometers" if value is None else value
    if value not in _UNITS:
        msg = f"units is {shown(value)}; give kilometers or miles"
        raise ValhallaRequestError(100, msg, field="units")
    return _UNITS[value]  # type: ignore[return-value]


def _attributes(doc: dict[str, Any], warnings: list[str]) -> frozenset[str]:
    filters = doc.get("filters")
    if filters is None:
        return frozenset(ATTRIBUTES)
    if not isinstance(filters, dict) or not isinstance(filters.get("attributes", []), list):
        msg = f"filters must be {{attributes: [...], action}} (got {shown(filters)})"
        raise ValhallaRequestError(100, msg, field="filters")
    keys = [str(k) for k in filters.get("attributes", [])]
    action: object = filters.get("action", doc.get("action", "include"))
    if action not in ("include", "exclude"):
        msg = f"filters.action is {shown(action)}; give include or exclude"
        raise ValhallaRequestError(100, msg, field="filters.action")
    unavailable = [k for k in keys if k in KNOWN_ATTRIBUTES]
    unknown = [k for k in keys if k not in KNOWN_ATTRIBUTES and k not in ATTRIBUTES]
    if unavailable and action == "include":
        warnings.append(f"not known to this service, left out: {', '.join(unavailable)}")
    if unknown:
        warnings.append(f"not trace_attributes filter keys, ignored: {', '.join(unknown)}")
    if action == "include":
        return frozenset(k for k in ATTRIBUTES if k in keys)
    return frozenset(k for k in ATTRIBUTES if k not in keys)


def _trace_options(doc: dict[str, Any], warnings: list[str]) -> dict[str, object]:
    options = doc.get("trace_options") or {}
    if not isinstance(options, dict):
        msg = f"trace_options must be an object (got {shown(options)})"
        raise ValhallaRequestError(100, msg, field="trace_options")
    out: dict[str, object] = {}
    for name, option in (("gps_accuracy", "sigma_m"), ("search_radius", "search_radius_m")):
        if name in options:
            value = options[name]
            if not _is_number(value):
                msg = f"Input trace option is out of bounds: {name} is {shown(value)}"
                raise ValhallaRequestError(158, msg, field=f"trace_options.{name}")
            out[option] = float(value)
    ignored = [name for name in _IGNORED_TRACE_OPTIONS if name in options]
    if ignored:
        warnings.append(f"trace_options not used by this matcher: {', '.join(ignored)}")
    return out


def build_input(req: ValhallaRequest) -> tuple[CompatInput, ValhallaRequest]:
    """
    The trace to match.

    Raises
    ------
    ValhallaRequestError
        A value the trace refuses (134).
    """
    try:
        trace = Trace(
            lon=req.lon, lat=req.lat, time=req.time, heading=req.heading, trace_id="valhalla"
        )
    except InvalidTraceError as exc:
        raise ValhallaRequestError(134, f"Failed to parse shape: {exc}", field="shape") from None
    n = len(req)
    columns = [c for c in (req.lon, req.lat, req.time, req.heading) if c is not None]
    rows = trace_rows(trace, np.arange(n, dtype=np.int64), columns, n)
    compat = CompatInput(trace=trace, rows=rows, network=req.network, overrides=req.overrides)
    return compat, req


# --------------------------------------------------------------------------- answer


def build_answer(matched: Matched, req: ValhallaRequest) -> bytes:
    """
    The ``trace_attributes`` response of a finished match (see the module docstring).

    Raises
    ------
    ValhallaNoMatchError
        No fix was matched.
    """
    result = matched.result
    if not result.segments:
        msg = "Map Match algorithm failed to find path: no fix could be placed on a road"
        raise ValhallaNoMatchError(msg)
    positions = path_positions(result)
    edges = edge_table(result, positions)
    per_segment = segment_rows(edges, len(result.segments))
    want = req.attributes
    shape_lon: list[FloatArray] = []
    shape_lat: list[FloatArray] = []
    begin = np.zeros(len(edges), dtype=np.int64)
    end = np.zeros(len(edges), dtype=np.int64)
    offset = 0
    for seg, rows in zip(result.segments, per_segment, strict=True):
        line = PathLine.of_segment(result, seg.index, rows)
        begin[rows] = offset + line.first_vertex
        end[rows] = offset + line.last_vertex
        shape_lon.append(line.lon)
        shape_lat.append(line.lat)
        offset += len(line.lon)
    lon = np.concatenate(shape_lon)
    lat = np.concatenate(shape_lat)
    doc: dict[str, Any] = {}
    if req.id is not None:
        doc["id"] = req.id
    doc["edges"] = _edges(matched, req, edges, begin, end, lon, lat)
    if "shape" in want:
        doc["shape"] = encode(zip(lat.tolist(), lon.tolist(), strict=True), 6)
    if any(k.startswith("matched.") for k in want):
        doc["matched_points"] = _matched_points(matched, req, positions, per_segment, edges)
    doc["units"] = req.units
    if req.warnings:
        doc["warnings"] = [{"code": _UNUSED, "text": text} for text in req.warnings]
    return json.dumps(doc, separators=(",", ":"), allow_nan=False).encode()


def _edges(
    matched: Matched,
    req: ValhallaRequest,
    edges: EdgeTable,
    begin: IntArray,
    end: IntArray,
    lon: FloatArray,
    lat: FloatArray,
) -> list[dict[str, Any]]:
    want = req.attributes
    unit_m = _METRES_PER[req.units]
    per_hour = 1000.0 / unit_m  # km/h -> units per hour
    driven = edges.driven_m
    if req.use_timestamps:
        first = float(edges.entry_time_s[0]) if len(edges) else 0.0
        elapsed = edges.exit_time_s - first
        speed_kph = edges.mean_speed_kph
    else:  # at the speed limits, one piece of the trace after the other
        elapsed = np.cumsum(driven / np.maximum(edges.speed_limit_kph / 3.6, 0.1))
        speed_kph = edges.speed_limit_kph
    speed_kph = np.where(np.isfinite(speed_kph), speed_kph, edges.speed_limit_kph)
    oneway = np.asarray(matched.net.arrays.edge_oneway, dtype=bool)[edges.edge]
    heading = bearing_deg(lon, lat) if len(lon) > 1 else np.zeros(0)
    out: list[dict[str, Any]] = []
    for k in range(len(edges)):
        e: dict[str, Any] = {}
        if "edge.names" in want and edges.name[k]:
            e["names"] = [edges.name[k]]
        if "edge.length" in want:
            e["length"] = round(float(driven[k]) / unit_m, 3)
        if "edge.speed" in want:
            e["speed"] = round(float(speed_kph[k]) * per_hour)
        if "edge.speed_limit" in want:
            e["speed_limit"] = round(float(edges.speed_limit_kph[k]) * per_hour)
        if "edge.road_class" in want:
            e["road_class"] = ROAD_CLASS.get(edges.road_class[k], "service_other")
        if "edge.use" in want:
            e["use"] = "ramp" if edges.road_class[k].endswith("_link") else "road"
        if "edge.way_id" in want:
            e["way_id"] = int(edges.way_id[k])
        if "edge.id" in want:
            e["id"] = int(edges.edge[k])
        if "edge.begin_shape_index" in want:
            e["begin_shape_index"] = int(begin[k])
        if "edge.end_shape_index" in want:
            e["end_shape_index"] = int(end[k])
        if "edge.begin_heading" in want and end[k] > begin[k]:
            e["begin_heading"] = round(float(heading[begin[k]])) % 360
        if "edge.end_heading" in want and end[k] > begin[k]:
            e["end_heading"] = round(float(heading[end[k] - 1])) % 360
        if "edge.traversability" in want:
            e["traversability"] = "forward" if oneway[k] else "both"
        if "edge.begin_time" in want and math.isfinite(edges.entry_time_s[k]):
            e["begin_time"] = round(float(edges.entry_time_s[k]), 3)
        if "edge.end_time" in want and math.isfinite(edges.exit_time_s[k]):
            e["end_time"] = round(float(edges.exit_time_s[k]), 3)
        if "node.elapsed_time" in want:
            e["end_node"] = {"elapsed_time": finite(float(elapsed[k]), 3)}
        out.append(e)
    return out


def _matched_points(
    matched: Matched,
    req: ValhallaRequest,
    positions: PathPositions,
    per_segment: list[slice],
    edges: EdgeTable,
) -> list[dict[str, Any]]:
    want = req.attributes
    p = matched.result.points
    seg_of = np.asarray(p.segment)
    is_matched = np.asarray(p.matched, dtype=bool)
    first_of = {s.index: s.first for s in matched.result.segments}
    last_of = {s.index: s.last for s in matched.result.segments}
    count = len(matched.result.segments)
    out: list[dict[str, Any]] = []
    for r, i in enumerate(matched.request.rows.tolist()):
        point: dict[str, Any] = {}
        on = bool(is_matched[i]) and int(positions.edge_index[i]) >= 0
        if "matched.point" in want:
            point["lat"] = round(float(p.lat[i] if on else req.lat[r]), 6)
            point["lon"] = round(float(p.lon[i] if on else req.lon[r]), 6)
        if "matched.type" in want:
            point["type"] = (
                "unmatched" if not on else "interpolated" if p.interpolated[i] else "matched"
            )
        if on:
            s = int(seg_of[i])
            row = per_segment[s].start + int(positions.edge_index[i])
            if "matched.edge_index" in want:
                point["edge_index"] = row
            if "matched.begin_route_discontinuity" in want and i == last_of[s] and s < count - 1:
                point["begin_route_discontinuity"] = True
            if "matched.end_route_discontinuity" in want and i == first_of[s] and s > 0:
                point["end_route_discontinuity"] = True
            if "matched.distance_along_edge" in want:
                length = float(edges.length_m[row])
                fraction = float(p.offset_m[i]) / length if length > 0 else 0.0
                point["distance_along_edge"] = round(min(max(fraction, 0.0), 1.0), 3)
            if "matched.distance_from_trace_point" in want:
                point["distance_from_trace_point"] = round(float(p.distance_m[i]), 3)
        out.append(point)
    return out


# --------------------------------------------------------------------------- documented shapes


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class ValhallaEndNode(_Strict):
    """The node at the end of an edge."""

    elapsed_time: float | None = Field(
        default=None, description="Seconds from the start of the path to this node."
    )


class ValhallaEdge(_Strict):
    """One driven edge (the attributes the filters let through)."""

    names: list[str] | None = Field(default=None, description="Street names (absent: none).")
    length: float | None = Field(default=None, description="Length driven, in `units`.")
    speed: int | None = Field(
        default=None, description="Speed behind the elapsed times, km/h or mph."
    )
    speed_limit: int | None = Field(
        default=None, description="maxspeed, or the road class's default; km/h or mph."
    )
    road_class: str | None = Field(default=None, description="Valhalla's road class.")
    use: str | None = Field(default=None, description="`road`, or `ramp` for a link.")
    way_id: int | None = Field(default=None, description="OSM way id.")
    id: int | None = Field(default=None, description="Index of the edge in this network.")
    begin_shape_index: int | None = Field(default=None, description="First vertex in `shape`.")
    end_shape_index: int | None = Field(default=None, description="Last vertex in `shape`.")
    begin_heading: int | None = Field(default=None, description="Heading at the start, deg.")
    end_heading: int | None = Field(default=None, description="Heading at the end, deg.")
    traversability: str | None = Field(default=None, description="`forward` or `both`.")
    begin_time: float | None = Field(default=None, description="Entered, epoch seconds.")
    end_time: float | None = Field(default=None, description="Left, epoch seconds.")
    end_node: ValhallaEndNode | None = Field(default=None, description="The edge's end node.")


class ValhallaMatchedPoint(_Strict):
    """Where one input point was matched."""

    lat: float | None = Field(default=None, description="Matched (or input) latitude.")
    lon: float | None = Field(default=None, description="Matched (or input) longitude.")
    type: Literal["matched", "interpolated", "unmatched"] | None = Field(
        default=None, description="How the point was placed."
    )
    edge_index: int | None = Field(default=None, description="Its edge in `edges`.")
    begin_route_discontinuity: bool | None = Field(
        default=None, description="True at the last point before a break."
    )
    end_route_discontinuity: bool | None = Field(
        default=None, description="True at the first point after a break."
    )
    distance_along_edge: float | None = Field(
        default=None, description="Fraction of its edge's length, 0..1."
    )
    distance_from_trace_point: float | None = Field(
        default=None, description="Metres from the input point."
    )


class ValhallaWarning(_Strict):
    """Something the request asked for that this service does not use."""

    code: int = Field(description="299: a parameter not used.")
    text: str = Field(description="What was not used, and why.")


class ValhallaResponse(_Strict):
    """Valhalla's ``trace_attributes`` response."""

    id: Any = Field(default=None, description="The request's `id`, echoed.")
    edges: list[ValhallaEdge] = Field(description="Every driven edge, in order.")
    shape: str | None = Field(default=None, description="The matched path, polyline6.")
    matched_points: list[ValhallaMatchedPoint] | None = Field(
        default=None, description="One per input point."
    )
    units: Literal["kilometers", "miles"] = Field(description="Units of lengths and speeds.")
    warnings: list[ValhallaWarning] | None = Field(default=None, description="Unused input.")


class ValhallaErrorResponse(_Strict):
    """Valhalla's error response."""

    error_code: int = Field(description="Valhalla's error code (171: no road nearby ...).")
    error: str = Field(description="What is wrong, with the offending value.")
    status_code: int = Field(description="The HTTP status.")
    status: str = Field(description="Its reason phrase.")
