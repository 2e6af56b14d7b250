"""
JSON and GeoJSON: the API's body, Point features and LineString features.

The API's body is ``{"points": [...], "trace_id": ...}`` or a list of point objects, its
points grouped like a table's rows. GeoJSON Point features are grouped by their id
properties; each LineString / MultiLineString feature is one trace (per-vertex properties as
lists, ``times`` / ``coordTimes`` for the times; a MultiLineString's lines are segments).
"""

from __future__ import annotations

import json
from collections.abc import Mapping

import numpy as np
import pandas as pd

from mapmatch.trace.columns import id_kind
from mapmatch.trace.readers.grouping import group_rows
from mapmatch.trace.readers.pieces import Piece, pieces_to_traces
from mapmatch.trace.readers.raw import COORD_NAMES, Context, RawTrace

__all__ = ["read_json"]


def read_json(data: bytes, ctx: Context) -> list[RawTrace]:
    """The traces of a JSON body or a GeoJSON document, told apart by content."""
    try:
        doc = json.loads(data)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        msg = f"is not valid JSON: {exc}"
        raise ctx.error(msg) from exc
    if isinstance(doc, Mapping) and doc.get("type") in ("FeatureCollection", "Feature"):
        return _read_geojson(doc, ctx)
    if ctx.fmt == "geojson":
        msg = "is not a GeoJSON Feature or FeatureCollection (no 'type' member)"
        raise ctx.error(msg)
    if isinstance(doc, Mapping) and isinstance(doc.get("points"), list):
        points = doc["points"]
        tid = doc.get("trace_id")
    elif isinstance(doc, list):
        points, tid = doc, None
    else:
        msg = 'expected {"points": [...], "trace_id": ...} or a list of point objects'
        raise ctx.error(msg)
    bad = [i for i, p in enumerate(points) if not isinstance(p, Mapping)]
    if bad:
        msg = f"point {bad[0] + 1} is {type(points[bad[0]]).__name__}, not an object"
        raise ctx.error(msg)
    frame = pd.DataFrame.from_records(points)
    numbers = np.arange(1, len(points) + 1, dtype=np.int64)
    if tid is not None:
        drop = [c for c in frame.columns if id_kind(c) == "trace_id"]
        frame = frame.drop(columns=drop)
        ctx = ctx.renamed(str(tid))
    return group_rows(frame, numbers=numbers, label="point", ctx=ctx)


def _read_geojson(doc: Mapping[str, object], ctx: Context) -> list[RawTrace]:
    features = doc.get("features") if doc.get("type") == "FeatureCollection" else [doc]
    if not isinstance(features, list):
        msg = "'features' is not a list"
        raise ctx.error(msg)
    point_records: list[dict[str, object]] = []
    point_numbers: list[int] = []
    lines: list[Piece] = []
    for k, feat in enumerate(features, start=1):
        if not isinstance(feat, Mapping) or feat.get("type") != "Feature":
            msg = f"feature {k} is not a GeoJSON Feature object"
            raise ctx.error(msg)
        props = feat.get("properties") or {}
        geom = feat.get("geometry")
        if not isinstance(props, Mapping):
            msg = f"feature {k}: 'properties' is not an object"
            raise ctx.error(msg)
        gtype = geom.get("type") if isinstance(geom, Mapping) else None
        coords = geom.get("coordinates") if isinstance(geom, Mapping) else None
        if gtype in ("LineString", "MultiLineString") and isinstance(coords, list):
            parts = [coords] if gtype == "LineString" else coords
            lines.append(_linestring_piece(k, props, parts, ctx))
            continue
        if gtype not in ("Point", None):
            msg = f"feature {k} is a {gtype}; use Point features or one LineString per trace"
            raise ctx.error(msg)
        rec = {key: v for key, v in props.items() if str(key).strip().lower() not in COORD_NAMES}
        lon, lat = lonlat(coords)
        rec["lon"], rec["lat"] = lon, lat
        point_records.append(rec)
        point_numbers.append(k)
    traces: list[RawTrace] = []
    if point_records:
        frame = pd.DataFrame.from_records(point_records)
        numbers = np.asarray(point_numbers, dtype=np.int64)
        traces.extend(group_rows(frame, numbers=numbers, label="feature", ctx=ctx))
    if lines:
        taken = {t.trace_id for t in traces}
        for raw in pieces_to_traces(lines, ctx):
            if raw.trace_id in taken:
                msg = f"trace_id {raw.trace_id!r} is used by Point features and a LineString"
                raise ctx.error(msg)
            traces.append(raw)
    return traces


def lonlat(coords: object) -> tuple[object, object]:
    if isinstance(coords, list | tuple) and len(coords) >= 2:
        return coords[0], coords[1]
    return None, None


def _linestring_piece(
    k: int, props: Mapping[str, object], parts: list[object], ctx: Context
) -> Piece:
    """
    Vertices of a (Multi)LineString feature with per-vertex list properties as columns.

    A MultiLineString's lines are segments; its per-vertex properties are lists of lists
    (one per line, as ``coordTimes`` of togeojson) or one flat list over all vertices.
    """
    lines = [p if isinstance(p, list) else [] for p in parts]
    coords = [c for line in lines for c in line]
    n = len(coords)
    columns: dict[str, list[object]] = {}
    per_vertex: dict[str, object] = dict(props)
    nested = props.get("coordinateProperties")
    if isinstance(nested, Mapping):
        per_vertex.update(nested)
    for key, value in per_vertex.items():
        name = str(key)
        if name.strip().lower() in ("times", "coordtimes"):
            name = "time"
        if not isinstance(value, list):
            continue
        if len(lines) > 1 and len(value) == len(lines) and all(isinstance(v, list) for v in value):
            value = [v for sub in value for v in sub]
        if len(value) != n:
            msg = (
                f"feature {k}: property {key!r} has {len(value)} values for {n} coordinates; "
                "give one value per vertex"
            )
            raise ctx.error(msg)
        if name.strip().lower() not in COORD_NAMES:
            columns[name] = value
    tid = props.get("trace_id")
    piece = Piece("LineString", k, None if tid is None else str(tid), "vertex")
    for i, c in enumerate(coords):
        lon, lat = lonlat(c)
        rec: dict[str, object] = {key: vals[i] for key, vals in columns.items()}
        rec["lon"], rec["lat"] = lon, lat
        piece.records.append(rec)
    piece.segment = [s for s, line in enumerate(lines) for _ in line]
    return piece
