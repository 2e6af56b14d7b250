"""
Every serialised form of a match result, built from its arrays.

One module writes what a :class:`~mapmatch.result.MatchResult` becomes outside Python:

- :func:`geojson_bytes`: the GeoJSON FeatureCollection as compact JSON text (what the batch
  writes and the service sends); :func:`geojson_dict` is the same document as Python
  objects (``MatchResult.to_geojson()``). One ``segment`` Feature per connected piece
  (LineString of the driven path and its ``edges``), one ``point`` Feature per fix.
- :func:`points_frame`: one row per fix (``MatchResult.to_dataframe()``).
- :func:`edges_frame`: one row per driven edge.

Each feature's members are declared once (:func:`_point_table`, :func:`_segment_table`) and
rendered either as text or as objects (:mod:`mapmatch._jsontext`), so the two always agree;
the text is written from the arrays, column by column, without a dict per point.

Numbers are written as Python writes them, rounded to a fixed number of decimals:
coordinates 7 (about 1 cm, numpy's rounding), metres 3 and confidences 4 (Python's
``round``); times as they are. A missing value is ``null``.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

import numpy as np

from mapmatch._jsontext import (
    Bools,
    Const,
    Floats,
    Ints,
    Items,
    Nested,
    Table,
    Tuple,
    Values,
    py_round,
)

if TYPE_CHECKING:
    import pandas as pd

    from mapmatch.result import MatchResult, Segment
    from mapmatch.types import FloatArray

__all__ = [
    "COORD_DIGITS",
    "edges_frame",
    "geojson_bytes",
    "geojson_dict",
    "points_frame",
]

#: Decimals of coordinates (degrees) in the GeoJSON: about 1 cm.
COORD_DIGITS = 7
_METRES = 3
_CONFIDENCE = 4


# --------------------------------------------------------------------------- GeoJSON


def _point_table(result: MatchResult) -> Table:
    """The ``point`` Features, one row per fix."""
    p = result.points
    n = len(p.time_s)
    matched = np.asarray(p.matched, dtype=bool)
    properties = Table(
        n,
        [
            ("kind", Const("point")),
            ("index", Ints(np.arange(n))),
            ("time", Floats(p.time_s)),
            ("matched", Bools(matched)),
            ("u", Ints(p.u, matched)),
            ("v", Ints(p.v, matched)),
            ("key", Ints(p.key, matched)),
            ("offset_m", Floats(py_round(p.offset_m, _METRES))),
            ("distance_m", Floats(py_round(p.distance_m, _METRES))),
            ("confidence", Floats(py_round(p.confidence, _CONFIDENCE))),
            ("interpolated", Bools(p.interpolated)),
            ("outlier", Bools(p.outlier)),
        ],
    )
    position = Tuple((_coordinates(p.lon), _coordinates(p.lat)), matched, "Point")
    return Table(
        n,
        [("type", Const("Feature")), ("geometry", position), ("properties", Nested(properties))],
    )


def _coordinates(degrees: FloatArray) -> Floats:
    rounded: FloatArray = np.round(degrees, COORD_DIGITS)
    return Floats(rounded)


def _edge_table(seg: Segment) -> Table:
    """The ``edges`` of a segment Feature, one row per driven edge."""
    a = seg.attributes
    return Table(
        len(seg.edge),
        [
            ("u", Ints(a.u)),
            ("v", Ints(a.v)),
            ("key", Ints(a.key)),
            ("osm_way_ids", Tuple((Ints(a.way_id),))),
            ("length_m", Floats(py_round(a.length_m, _METRES))),
            ("start_offset_m", Floats(py_round(seg.start_offset_m, _METRES))),
            ("end_offset_m", Floats(py_round(seg.end_offset_m, _METRES))),
        ],
    )


def _path(seg: Segment) -> Values:
    lon, lat = seg.lon, seg.lat
    if len(lon) == 1:  # a LineString needs two positions
        lon, lat = np.repeat(lon, 2), np.repeat(lat, 2)
    return Values(Tuple((_coordinates(lon), _coordinates(lat))), len(lon))


def _segment_table(result: MatchResult) -> Table:
    """The ``segment`` Features, one row per segment."""
    segs = result.segments
    count = len(segs)
    lengths = np.array([s.length_m for s in segs], dtype=np.float64)
    properties = Table(
        count,
        [
            ("kind", Const("segment")),
            ("segment", Ints(np.array([s.index for s in segs], dtype=np.int64))),
            (
                "point_range",
                Tuple(
                    (
                        Ints(np.array([s.first for s in segs], dtype=np.int64)),
                        Ints(np.array([s.last for s in segs], dtype=np.int64)),
                    )
                ),
            ),
            ("length_m", Floats(py_round(lengths, _METRES))),
            ("edges", Items([_edge_table(s) for s in segs])),
        ],
    )
    return Table(
        count,
        [
            ("type", Const("Feature")),
            ("geometry", Items([_path(s) for s in segs], geometry="LineString")),
            ("properties", Nested(properties)),
        ],
    )


def _head(result: MatchResult) -> dict[str, Any]:
    return {
        "type": "FeatureCollection",
        "trace_id": result.trace_id,
        "network": dict(result.network),
        "matched_length_m": round(result.matched_length_m, _METRES),
        "distance_check": result.distance_check.to_dict(),
        "breaks": list(result.breaks),
        "stats": result.stats.to_dict(),
    }


def geojson_bytes(result: MatchResult) -> bytes:
    """
    The result as a GeoJSON FeatureCollection: compact JSON text, ASCII.

    The same document as :func:`geojson_dict` (``json.loads(geojson_bytes(r)) ==
    geojson_dict(r)``), equal to ``json.dumps(geojson_dict(r), separators=(",", ":"),
    allow_nan=False)``, written from the arrays. What the batch writes and the service sends.

    Parameters
    ----------
    result
        A match.

    Returns
    -------
    bytes
        Top-level members ``type``, ``trace_id``, ``network``, ``matched_length_m``,
        ``distance_check``, ``breaks``, ``stats`` and ``features`` (the segments, then the
        points).
    """
    head = json.dumps(_head(result), allow_nan=False, separators=(",", ":"))
    parts = [t.text() for t in (_segment_table(result), _point_table(result)) if t.rows]
    return f'{head[:-1]},"features":[{",".join(parts)}]}}'.encode("ascii")


def geojson_dict(result: MatchResult) -> dict[str, Any]:
    """The GeoJSON document of :func:`geojson_bytes` as Python objects."""
    doc = _head(result)
    doc["features"] = _segment_table(result).objects() + _point_table(result).objects()
    return doc


# --------------------------------------------------------------------------- tables


def points_frame(result: MatchResult) -> pd.DataFrame:
    """
    One row per fix: time, raw and snapped position, edge, offset, confidence.

    Columns ``trace_id``, ``index``, ``time``, ``raw_lon``, ``raw_lat``, ``matched``,
    ``segment``, ``lon``, ``lat``, ``u``, ``v``, ``key``, ``offset_m``, ``distance_m``,
    ``confidence``, ``interpolated``, ``outlier``.
    """
    import pandas as pd

    p = result.points
    return pd.DataFrame(
        {
            "trace_id": result.trace_id,
            "index": np.arange(len(p.time_s)),
            "time": p.time_s,
            "raw_lon": p.raw_lon,
            "raw_lat": p.raw_lat,
            "matched": p.matched,
            "segment": p.segment,
            "lon": p.lon,
            "lat": p.lat,
            "u": p.u,
            "v": p.v,
            "key": p.key,
            "offset_m": p.offset_m,
            "distance_m": p.distance_m,
            "confidence": p.confidence,
            "interpolated": p.interpolated,
            "outlier": p.outlier,
        }
    )


_EDGE_COLUMNS = (
    "trace_id",
    "segment",
    "order",
    "first_point",
    "last_point",
    "u",
    "v",
    "key",
    "osm_way_ids",
    "length_m",
    "start_offset_m",
    "end_offset_m",
)


def edges_frame(result: MatchResult) -> pd.DataFrame:
    """
    One row per driven edge: trace, segment, order, OSM ids, length and offsets.

    ``osm_way_ids`` holds the way ids joined by ``;``.
    """
    import pandas as pd

    parts: list[dict[str, Any]] = []
    for seg in result.segments:
        a = seg.attributes
        m = len(seg.edge)
        parts.append(
            {
                "segment": np.full(m, seg.index, dtype=np.int64),
                "order": np.arange(m, dtype=np.int64),
                "first_point": np.full(m, seg.first, dtype=np.int64),
                "last_point": np.full(m, seg.last, dtype=np.int64),
                "u": a.u,
                "v": a.v,
                "key": a.key,
                "osm_way_ids": np.asarray(a.way_id.astype(str), dtype=object),
                "length_m": a.length_m,
                "start_offset_m": seg.start_offset_m,
                "end_offset_m": seg.end_offset_m,
            }
        )
    if not parts:
        return pd.DataFrame({name: [] for name in _EDGE_COLUMNS})
    columns = {k: np.concatenate([part[k] for part in parts]) for k in parts[0]}
    return pd.DataFrame({"trace_id": result.trace_id, **columns}).loc[:, list(_EDGE_COLUMNS)]
