"""
Request and response models of the HTTP API; every field is documented in OpenAPI.

(Over 400 lines on purpose: the declarations are the OpenAPI documentation of every field.)

The request envelope and the options are validated with these models (bounds included, so a
sigma of -1 is a 422 naming ``options.sigma_m`` before the matcher sees it); the points are
documented here (:class:`PointIn`) but checked by the trace reader. The response side documents what
``MatchResult.to_geojson()`` produces (docs/DESIGN.md "Output"); the service sends that document as
it is and does not re-validate it, which would cost more than the match for long traces.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Annotated, Any, Literal

from pydantic import (
    AliasChoices,
    BaseModel,
    ConfigDict,
    Field,
    PlainValidator,
    WithJsonSchema,
    create_model,
)

from mapmatch import OVERRIDABLE, parameters
from mapmatch.trace.columns import input_columns

if TYPE_CHECKING:
    from mapmatch.config import Param
    from mapmatch.trace.columns import Column

__all__ = [
    "DistanceCheckOut",
    "EdgeOut",
    "ErrorDetail",
    "ErrorResponse",
    "HealthResponse",
    "MatchEnvelope",
    "MatchOptions",
    "MatchQuery",
    "MatchRequest",
    "MatchResponse",
    "NetworkOut",
    "NetworksResponse",
    "PointFeature",
    "PointIn",
    "ReadyResponse",
    "SegmentFeature",
]


def _time_value(value: object) -> float | str:
    """Epoch seconds (a finite number) or a timestamp string; the trace stage parses it."""
    if isinstance(value, bool) or not isinstance(value, int | float | str):
        msg = "must be epoch seconds (a number) or an ISO-8601 timestamp (a string)"
        raise ValueError(msg)  # pydantic turns a ValueError into a 422
    if isinstance(value, str):
        if len(value) > 64:
            msg = "a timestamp string must be at most 64 characters"
            raise ValueError(msg)
        return value
    if not math.isfinite(value):
        msg = "must be a finite number"
        raise ValueError(msg)
    return float(value)


TimeValue = Annotated[
    float | str,
    PlainValidator(_time_value),
    WithJsonSchema(
        {
            "anyOf": [
                {"type": "number"},
                {"type": "string", "format": "date-time", "maxLength": 64},
            ]
        }
    ),
]


# --------------------------------------------------------------------------- request


def _point_field(col: Column) -> tuple[Any, Any]:
    """The pydantic annotation and field of one input column (:mod:`mapmatch.trace.columns`)."""
    kind: Any = TimeValue if col.kind == "time" else float
    annotation = kind if col.required else kind | None
    return annotation, Field(
        ... if col.required else None,
        validation_alias=AliasChoices(*col.names),
        gt=col.gt,
        ge=col.ge,
        le=col.le,
        allow_inf_nan=None if col.kind == "time" else col.wraps is not None,
        description=col.describe(),
        examples=[col.example] if col.example is not None else None,
    )


class _PointBase(BaseModel):
    """One fix of the trace. Keys not listed here are ignored."""

    model_config = ConfigDict(extra="ignore", populate_by_name=True)


#: One point of a JSON body, generated from the declaration of the input columns
#: (:func:`mapmatch.trace.columns.input_columns`: names, aliases, bounds, descriptions), so the
#: documentation says what the trace reader checks. It documents the points in OpenAPI; the
#: points themselves go to the reader (``Trace.from_records``), which checks them.
PointIn = create_model(
    "PointIn",
    __base__=_PointBase,
    __doc__="One fix of the trace. Keys not listed here are ignored.",
    **{col.name: _point_field(col) for col in input_columns()},  # type: ignore[call-overload]
)


def _option_field(meta: Param, default: object) -> tuple[Any, Any]:
    """The pydantic annotation and field of one overridable matcher parameter."""
    description = meta.describe(default)
    if meta.kind == "bool":
        return bool | None, Field(default=None, description=description)
    if meta.kind == "band":
        band = tuple[
            Annotated[float, Field(gt=-1, le=0, allow_inf_nan=False)],
            Annotated[float, Field(ge=0, lt=10, allow_inf_nan=False)],
        ]
        return band | None, Field(
            default=None,
            description=description + " A pair [low, high]: low in (-1, 0], high in [0, 10).",
        )
    if meta.kind == "int":
        return int | None, Field(default=None, description=description, ge=meta.ge, le=meta.le)
    return float | None, Field(
        default=None,
        description=description,
        gt=meta.gt,
        ge=meta.ge,
        le=meta.le,
        allow_inf_nan=False,
    )


class _OptionsBase(BaseModel):
    """Matcher parameters a request may override; omitted = the server's value."""

    model_config = ConfigDict(extra="forbid")

    def overrides(self) -> dict[str, object]:
        """The options that were given, as ``MatchConfig.replace`` takes them."""
        return self.model_dump(exclude_none=True)


#: ``mapmatch.OVERRIDABLE`` as a request model: generated from the :class:`MatchConfig`
#: field declarations (description, unit, bounds), so Python, the CLI and HTTP take the same.
MatchOptions = create_model(
    "MatchOptions",
    __base__=_OptionsBase,
    __doc__=(
        "Matcher parameters a request may override (``mapmatch.OVERRIDABLE``); omitted = "
        "default. Descriptions and bounds are the matcher's own (``mapmatch.parameters()``)."
    ),
    **{  # type: ignore[call-overload]
        name: _option_field(meta, default)
        for name, meta, default in parameters(overridable_only=True)
    },
)

_CRS = Literal["wgs84", "gcj02", "bd09"]
_CRS_DESCRIPTION = "Frame of the coordinates; GCJ-02 and BD-09 are converted to WGS84."
_NETWORK_DESCRIPTION = "Id of the network to match on (see GET /v1/networks); default: the first."
_FUSED_DESCRIPTION = (
    "Trip distance the vehicle reported, metres; the distance check uses it when the points "
    "have no odometer."
)


class MatchEnvelope(BaseModel):
    """
    The members of a JSON body other than ``points``: what the HTTP layer validates itself.

    The points go as they are to :meth:`mapmatch.Trace.from_records`, the reader the library
    uses, which checks them (with the same rules for every input format) and names the
    offending point and field.
    """

    model_config = ConfigDict(extra="forbid")

    trace_id: str = Field(
        default="trace", min_length=1, max_length=200, description="Name of the trace."
    )
    fused_distance_m: float | None = Field(
        default=None, ge=0, le=1e8, allow_inf_nan=False, description=_FUSED_DESCRIPTION
    )
    network: str | None = Field(
        default=None, min_length=1, max_length=200, description=_NETWORK_DESCRIPTION
    )
    crs: _CRS = Field(default="wgs84", description=_CRS_DESCRIPTION)
    options: MatchOptions | None = Field(
        default=None, description="Matcher parameters to override for this request."
    )
    polyline: str | None = Field(
        default=None,
        min_length=2,
        description="The positions as an encoded polyline (Google's format, as OSRM and "
        "Valhalla write it) instead of `points`; `precision` says its decimals, `times` may "
        "give one time per position.",
    )
    precision: Literal[5, 6] = Field(
        default=5, description="Decimals of `polyline`: 5, or 6 (OSRM's polyline6, Valhalla)."
    )
    times: list[TimeValue] | None = Field(
        default=None,
        description="With `polyline`: one time per position (epoch seconds or ISO-8601).",
    )


class MatchRequest(MatchEnvelope):
    """The JSON body of ``POST /v1/match`` (Content-Type ``application/json``)."""

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={
            "examples": [
                {
                    "trace_id": "monaco-1",
                    "points": [
                        {"time": 1700000000, "lat": 43.7369819, "lon": 7.4231825, "speed": 5.0},
                        {"time": 1700000005, "lat": 43.7369711, "lon": 7.4233494, "speed": 5.2},
                        {"time": 1700000010, "lat": 43.7368906, "lon": 7.4241148},
                    ],
                    "options": {"sigma_m": 6.0},
                }
            ]
        },
    )

    points: list[PointIn] | None = Field(
        default=None,
        min_length=2,
        description=(
            "The fixes, at least 2 with distinct times, at most the server's limit "
            "(MAPMATCH_MAX_POINTS, 100 000 by default; more is a 413). Required unless "
            "`polyline` gives the positions."
        ),
    )


class MatchQuery(MatchOptions):
    """
    Query parameters of ``POST /v1/match``.

    For GPX, CSV and GeoJSON bodies they carry what a JSON body holds in its members; with a
    JSON body they may be used too, but a member given in both places is a 422.
    """

    model_config = ConfigDict(extra="forbid")

    network: str | None = Field(
        default=None, min_length=1, max_length=200, description=_NETWORK_DESCRIPTION
    )
    trace_id: str | None = Field(
        default=None,
        min_length=1,
        max_length=200,
        description="Name of the trace when the body does not name it.",
    )
    fused_distance_m: float | None = Field(
        default=None, ge=0, le=1e8, allow_inf_nan=False, description=_FUSED_DESCRIPTION
    )
    crs: _CRS | None = Field(default=None, description=_CRS_DESCRIPTION + " Default wgs84.")
    polyline: int | None = Field(
        default=None,
        ge=5,
        le=6,
        description="Also give each segment's path as an encoded polyline of this many "
        "decimals (5, or 6 for polyline6), in the segment's `properties.polyline`.",
    )

    def options(self) -> dict[str, object]:
        """The matcher options among the query parameters."""
        return {k: v for k, v in self.model_dump(exclude_none=True).items() if k in OVERRIDABLE}


# --------------------------------------------------------------------------- response


class _Out(BaseModel):
    """
    A part of the match answer, as ``MatchResult.to_geojson()`` writes it.

    Unknown members are refused, so validating a real answer against these models (the test
    suite does) catches a member the output has and the documentation lacks, and a documented
    one the output lost; OpenAPI says ``additionalProperties: false`` accordingly.
    """

    model_config = ConfigDict(extra="forbid")


class EdgeOut(_Out):
    """One directed edge of a matched path and the stretch of it that was driven."""

    u: int = Field(description="OSM node id where the edge starts.")
    v: int = Field(description="OSM node id where the edge ends.")
    key: int = Field(description="Tells parallel edges between u and v apart.")
    osm_way_ids: list[int] = Field(description="OSM way(s) the edge belongs to.")
    length_m: float = Field(description="Length of the whole edge, metres.")
    start_offset_m: float = Field(description="Start of the driven stretch from u, metres.")
    end_offset_m: float = Field(description="End of the driven stretch from u, metres.")
    name: str | None = Field(description="Street name (OSM name or ref); null when unnamed.")
    road_class: str | None = Field(description="OSM highway class (primary, residential ...).")
    speed_limit_kph: float | None = Field(
        description="Posted speed limit (OSM maxspeed), km/h; null when unknown."
    )
    entry_time: float | None = Field(
        description="When the edge was entered, epoch seconds (interpolated between the fixes); "
        "null without times."
    )
    exit_time: float | None = Field(
        description="When the edge was left, epoch seconds; null without times."
    )
    duration_s: float | None = Field(description="Seconds on the edge; null without times.")
    mean_speed_kph: float | None = Field(
        description="Driven length over duration, km/h; null without times or when no time passed."
    )


class LineStringGeometry(_Out):
    """GeoJSON LineString in WGS84 [lon, lat]."""

    type: Literal["LineString"] = Field(description="Always LineString.")
    coordinates: list[list[float]] = Field(description="[lon, lat] pairs in driving order.")


class PointGeometry(_Out):
    """GeoJSON Point in WGS84 [lon, lat]."""

    type: Literal["Point"] = Field(description="Always Point.")
    coordinates: list[float] = Field(description="[lon, lat] of the snapped position.")


class SegmentProperties(_Out):
    """Properties of a segment Feature."""

    kind: Literal["segment"] = Field(description="Marks a segment Feature.")
    segment: int = Field(description="0-based index of the segment.")
    point_range: list[int] = Field(description="[first, last] point indices it covers.")
    length_m: float = Field(description="Driven length, metres.")
    edges: list[EdgeOut] = Field(description="Edges driven, in order.")
    polyline: str | None = Field(
        default=None,
        description="The path as an encoded polyline, only when the request asks "
        "(`?polyline=5` or `6`).",
    )
    start_time: float | None = Field(
        description="When the segment starts, epoch seconds; null without times."
    )
    end_time: float | None = Field(
        description="When the segment ends, epoch seconds; null without times."
    )


class SegmentFeature(_Out):
    """A connected matched piece of the trace; a break starts a new one."""

    type: Literal["Feature"] = Field(description="Always Feature.")
    geometry: LineStringGeometry = Field(description="The driven path.")
    properties: SegmentProperties = Field(description="What the segment covers and drove.")


class PointProperties(_Out):
    """Properties of a point Feature (one per point, after sorting by time)."""

    kind: Literal["point"] = Field(description="Marks a point Feature.")
    index: int = Field(description="0-based index of the point after sorting.")
    time: float | None = Field(description="Epoch seconds; null when the trace has no times.")
    matched: bool = Field(description="Whether the point was placed on a road.")
    u: int | None = Field(description="OSM node id where the matched edge starts.")
    v: int | None = Field(description="OSM node id where the matched edge ends.")
    key: int | None = Field(description="Parallel-edge key of the matched edge.")
    offset_m: float | None = Field(description="Position along the matched edge, metres.")
    distance_m: float | None = Field(description="Raw point to its road position, metres.")
    confidence: float = Field(description="Posterior probability of the chosen road, 0..1.")
    interpolated: bool = Field(
        description="Left out of the model (outlier, stopped car) and placed by time."
    )
    outlier: bool = Field(description="Judged an outlier.")
    segment: int | None = Field(description="Segment the point lies on; null if unmatched.")
    edge_index: int | None = Field(
        description="Index of its edge in the segment's `edges`; null when not on the path."
    )
    along_m: float | None = Field(
        description="Metres along the segment's path to the point; null when not on the path."
    )


class PointFeature(_Out):
    """One input point at its snapped position (null geometry when unmatched)."""

    type: Literal["Feature"] = Field(description="Always Feature.")
    geometry: PointGeometry | None = Field(description="Snapped position; null if unmatched.")
    properties: PointProperties = Field(description="How the point was matched.")


class DistanceCheckOut(_Out):
    """The fused trip distance held against the matched road length."""

    matched_length_m: float = Field(description="Road distance along the matched path, m.")
    fused_length_m: float = Field(description="Trip distance the vehicle reported, m.")
    source: Literal["odometer", "caller", "chord"] = Field(
        description="odometer (last - first), caller (fused_distance_m) or chord (raw positions)."
    )
    relative_error: float | None = Field(
        description="(fused - matched) / matched; null when the matched length is 0."
    )
    band: list[float] = Field(description="[low, high] pass band of relative errors.")
    verdict: Literal["pass", "over", "under", "incomplete"] = Field(
        description="pass inside the band; over/under outside; incomplete with breaks or gaps."
    )
    evidence: Literal["positions", "heading", "odometer"] = Field(
        description="What the matched length rests on, the strongest of: positions only, the "
        "heading at speed, the odometer between fixes."
    )
    uturns: int = Field(description="U-turns on the matched path.")


class StatsOut(_Out):
    """Counts and timings of the match."""

    points: int = Field(description="Points after sorting and merging true duplicates.")
    matched_points: int = Field(description="Points placed on a road.")
    candidates: int = Field(description="Candidate road positions considered.")
    input_rows: int = Field(description="Input points (or file rows) given.")
    reordered_rows: int = Field(description="Input points that were out of time order.")
    merged_rows: int = Field(
        description="Input points merged into an earlier one they repeat exactly (same time, "
        "position and fields)."
    )
    shared_time_rows: int = Field(
        description="Points kept whose time equals the previous point's (matched by distance)."
    )
    dropped_rows: int = Field(
        description="Source records the reader could not use (NMEA checksum, no fix)."
    )
    time_source: Literal["ok", "absent", "implausible"] = Field(
        description="ok: times used; absent: no times; implausible: the times imply "
        "impossible speeds between most points. Both of the latter match by distance only."
    )
    model_points: int = Field(description="Points that entered the HMM.")
    outliers: int = Field(description="Points judged outliers.")
    break_repairs: int = Field(description="Breaks repaired by leaving a point out.")
    timings_s: dict[str, float] = Field(description="Seconds per matching stage.")
    warnings: list[str] = Field(description="What validation did to the input, one sentence each.")


class NetworkRef(_Out):
    """The network matched on."""

    id: str = Field(description="Network id.")
    source: str = Field(description="OSM extract it was compiled from.")
    crs: str = Field(description="Metric CRS used internally (EPSG code).")


class MatchResponse(_Out):
    """A GeoJSON FeatureCollection: one Feature per segment, then one per point."""

    type: Literal["FeatureCollection"] = Field(description="Always FeatureCollection.")
    trace_id: str = Field(description="Name of the trace.")
    network: NetworkRef = Field(description="The network matched on.")
    matched_length_m: float = Field(description="Metres along the matched path, all segments.")
    distance_check: DistanceCheckOut = Field(
        description="The fused trip distance against the matched length."
    )
    breaks: list[int] = Field(description="Point indices where the trace was split.")
    stats: StatsOut = Field(description="Counts and timings.")
    features: list[SegmentFeature | PointFeature] = Field(
        description="Segment Features first, then one point Feature per point."
    )


class ErrorDetail(BaseModel):
    """What went wrong."""

    code: str = Field(description="Stable machine-readable code (see the error table).")
    message: str = Field(description="What is wrong, the offending value, and how to fix it.")
    field: str | None = Field(
        default=None, description="Offending field, e.g. points[3].lat, options.sigma_m."
    )
    rows: list[int] | None = Field(
        default=None,
        description="Offending 0-based points (JSON) or data rows (files); the first 100.",
    )
    rows_total: int | None = Field(
        default=None, description="How many rows are at fault, when more than `rows` lists."
    )


class ErrorResponse(BaseModel):
    """Every 4xx/5xx answer."""

    error: ErrorDetail = Field(description="What went wrong.")


class NetworkOut(BaseModel):
    """A network this service matches on."""

    id: str = Field(description="Id to pass as `network`.")
    source: str = Field(description="File name of the OSM extract.")
    crs: str = Field(description="Metric CRS used internally.")
    bbox: list[float] = Field(description="[min_lon, min_lat, max_lon, max_lat], WGS84.")
    nodes: int = Field(description="Graph nodes.")
    edges: int = Field(description="Directed edges.")
    road_km: float = Field(description="Road length, each two-way road counted once, km.")
    route_table: str = Field(
        description="What became of its route table for sparse traces (read from the cache, "
        "built, or none and why; `MAPMATCH_ROUTE_TABLE_MB`)."
    )
    default: bool = Field(description="Used when a request names no network.")


class NetworksResponse(BaseModel):
    """The networks this service matches on."""

    networks: list[NetworkOut] = Field(description="Every network, the default first.")


class HealthResponse(BaseModel):
    """The process is alive."""

    status: Literal["alive"] = Field(description="Always alive.")


class ReadyResponse(BaseModel):
    """Every network is loaded; matches can be served."""

    status: Literal["ready"] = Field(description="Always ready (503 otherwise).")
    networks: list[str] = Field(description="Ids of the loaded networks.")
