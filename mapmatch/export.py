"""
Every serialised form of a match result, built from its arrays.

(Over 400 lines on purpose: every serialised form is declared here from the same tables of
columns, so that the forms cannot drift apart.)

One module writes what a :class:`~mapmatch.result.MatchResult` becomes outside Python:

- :func:`geojson_bytes`: the GeoJSON FeatureCollection as compact JSON text (what the batch
  writes and the service sends); :func:`geojson_dict` is the same document as Python
  objects (``MatchResult.to_geojson()``). One ``segment`` Feature per connected piece
  (LineString of the driven path and its ``edges``), one ``point`` Feature per fix.
- :func:`points_frame`: one row per fix (``MatchResult.to_dataframe()``).
- :func:`edges_frame`: one row per driven edge.

Each feature's members are declared once (:func:`_point_table`, :func:`_segment_table`) over
the result's feature columns, made by one compiled call (:mod:`mapmatch._features`), and
rendered either as text or as objects (:mod:`mapmatch._jsontext`), so the two always agree;
the text is written by one more compiled call straight from those columns, without a dict
per point or a Python object per column.

Numbers are written as Python writes them, rounded to a fixed number of decimals:
coordinates 7 (about 1 cm, numpy's rounding), metres 3 and confidences 4 (Python's
``round``); times as they are. A missing value is ``null``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from json.encoder import c_make_encoder, encode_basestring_ascii  # type: ignore[attr-defined]
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from mapmatch._features import feature_columns
from mapmatch._jsontext import (
    Bools,
    Choice,
    Const,
    Floats,
    Ints,
    Items,
    Nested,
    Table,
    Tuple,
    Utf8,
    sourced_pieces,
)
from mapmatch._timing import (
    EdgeTimes,
    PathPositions,
    SegmentPaths,
    edge_times,
    path_positions,
    positions_and_times,
    span_times,
    speeds_kph,
)
from mapmatch.result import EdgeAttributes

if TYPE_CHECKING:
    from collections.abc import Callable
    from pathlib import Path

    import geopandas as gpd  # type: ignore[import-untyped]
    import pandas as pd

    from mapmatch.result import MatchResult
    from mapmatch.types import BoolArray, ByteArray, FloatArray, IntArray

__all__ = [
    "COORD_DIGITS",
    "CRS",
    "CSV_TIME_FORMAT",
    "GEO_KINDS",
    "TABLE_FORMATS",
    "EdgeTable",
    "GeoKind",
    "PathPositions",
    "edge_table",
    "edges_frame",
    "geodataframe",
    "geojson_bytes",
    "geojson_dict",
    "path_positions",
    "points_frame",
    "segments_frame",
    "write_geopackage",
    "write_table",
]

#: Decimals of coordinates (degrees) in the GeoJSON: about 1 cm.
COORD_DIGITS = 7
_METRES = 3
_CONFIDENCE = 4
_SECONDS = 3


# --------------------------------------------------------------------------- columns


@dataclass(frozen=True, slots=True)
class EdgeTable:
    """
    Every driven edge of a result, one entry each, segments in order.

    The columns every per-edge output shows (GeoJSON ``edges``, :func:`edges_frame`, the
    batch's edge files), and what the service's peers' formats need (Valhalla's edge
    ``names``, ``speed_limit``, ``road_class``, ``begin_time``/``end_time``).

    Attributes
    ----------
    segment, order
        The edge's segment and its position in the segment's edge list.
    first_point, last_point
        The segment's first and last fix.
    edge
        Index of the edge in the network's arrays.
    u, v, key, way_id
        OSM node ids of its ends, parallel-edge key, OSM way.
    name, road_class, speed_limit_kph
        Street name (``""`` for none), ``highway`` class, ``maxspeed`` (or the class default).
    length_m, start_offset_m, end_offset_m
        The edge's length and the driven stretch on it (metres from the edge's start).
    path_start_m, path_end_m
        Where the stretch starts and ends along the segment's path, metres.
    entry_time_s, exit_time_s
        When the edge was entered and left, epoch seconds, interpolated between the fixes
        around its ends (:mod:`mapmatch._timing`); NaN for a trace without times.
    """

    segment: IntArray
    order: IntArray
    first_point: IntArray
    last_point: IntArray
    edge: IntArray
    u: IntArray
    v: IntArray
    key: IntArray
    way_id: IntArray
    name: tuple[str, ...]
    road_class: tuple[str, ...]
    speed_limit_kph: FloatArray
    length_m: FloatArray
    start_offset_m: FloatArray
    end_offset_m: FloatArray
    path_start_m: FloatArray
    path_end_m: FloatArray
    entry_time_s: FloatArray
    exit_time_s: FloatArray

    def __len__(self) -> int:
        return len(self.edge)

    @property
    def driven_m(self) -> FloatArray:
        """Metres driven on each edge."""
        return self.end_offset_m - self.start_offset_m

    @property
    def duration_s(self) -> FloatArray:
        """Seconds on each edge (NaN without times)."""
        return self.exit_time_s - self.entry_time_s

    @property
    def mean_speed_kph(self) -> FloatArray:
        """Driven metres over seconds on each edge, km/h; NaN where no time passed."""
        speed: FloatArray = speeds_kph(self.driven_m, self.duration_s)
        return speed


def edge_table(result: MatchResult, positions: PathPositions | None = None) -> EdgeTable:
    """
    The columns of every driven edge of ``result`` (see :class:`EdgeTable`).

    The arrays of a one-segment result may be the segment's own: read them, do not write.

    Parameters
    ----------
    result
        A match.
    positions
        Its fixes' places on the path, when already known (:func:`path_positions`).
    """
    paths = SegmentPaths.of(result.segments)
    if positions is None:
        _, times = positions_and_times(result, paths)
    else:
        times = edge_times(result, positions, paths)
    return _edge_table(result, paths, times)


def _edge_table(result: MatchResult, paths: SegmentPaths, times: EdgeTimes) -> EdgeTable:
    """:func:`edge_table` of the result's paths and their times."""
    attrs = EdgeAttributes.joined([s.attributes for s in result.segments])
    sizes = paths.sizes
    return EdgeTable(
        segment=paths.index.repeat(sizes),
        order=np.arange(len(paths.edge), dtype=np.int64) - paths.bounds[:-1].repeat(sizes),
        first_point=paths.first.repeat(sizes),
        last_point=paths.last.repeat(sizes),
        edge=paths.edge,
        u=attrs.u,
        v=attrs.v,
        key=attrs.key,
        way_id=attrs.way_id,
        name=attrs.name,
        road_class=attrs.road_class,
        speed_limit_kph=attrs.speed_limit_kph,
        length_m=attrs.length_m,
        start_offset_m=paths.start_m,
        end_offset_m=paths.end_m,
        path_start_m=times.start_m,
        path_end_m=times.end_m,
        entry_time_s=times.entry_s,
        exit_time_s=times.exit_s,
    )


# --------------------------------------------------------------------------- GeoJSON


def _feature_tables(c: dict[str, Any], text: ByteArray) -> list[tuple[Table, IntArray]]:
    """
    The segment and the point Features, each with its ``[0, rows]``, of a result's columns.

    ``c`` are :func:`~mapmatch._features.feature_columns`' columns by name, ``text`` the
    names' bytes. Every array here is one of the columns as given: the text is written from
    the packed arrays themselves (:func:`~mapmatch._jsontext.sourced_pieces`).
    """
    return [(_segment_table(c, text), c["segment_rows"]), (_point_table(c), c["point_rows"])]


def _point_table(c: dict[str, Any]) -> Table:
    """The ``point`` Features, one row per fix."""
    n = len(c["time_s"])
    matched = c["matched"]
    properties = Table(
        n,
        [
            ("kind", Const("point")),
            ("index", Ints(c["index"])),
            ("time", Floats(c["time_s"], decimals=_SECONDS)),
            ("matched", Bools(matched)),
            ("u", Ints(c["u"], matched)),
            ("v", Ints(c["v"], matched)),
            ("key", Ints(c["key"], matched)),
            ("offset_m", _rounded(c["offset_m"], _METRES)),
            ("distance_m", _rounded(c["distance_m"], _METRES)),
            ("confidence", _rounded(c["confidence"], _CONFIDENCE)),
            ("interpolated", Bools(c["interpolated"])),
            ("outlier", Bools(c["outlier"])),
            ("segment", Ints(c["segment"], matched)),
            ("edge_index", Ints(c["edge_index"], c["on_path"])),
            ("along_m", _rounded(c["along_m"], _METRES)),
        ],
    )
    position = Tuple((_coordinates(c["lon"]), _coordinates(c["lat"])), matched, "Point")
    return Table(
        n, [("type", Const("Feature")), ("geometry", position), ("properties", Nested(properties))]
    )


def _rounded(values: FloatArray, digits: int) -> Floats:
    """Values rounded as Python's ``round(value, digits)`` does, written as ``repr`` does."""
    return Floats(values, decimals=digits, rounding="python")


def _coordinates(degrees: FloatArray) -> Floats:
    """Degrees rounded as ``numpy.round(degrees, COORD_DIGITS)`` does."""
    return Floats(degrees, decimals=COORD_DIGITS, rounding="numpy")


def _edge_json(c: dict[str, Any], text: ByteArray) -> Table:
    """The ``edges`` of the segment Features: one row per driven edge."""
    from roadnets.drivable import ROAD_CLASSES

    return Table(
        len(c["edge_u"]),
        [
            ("u", Ints(c["edge_u"])),
            ("v", Ints(c["edge_v"])),
            ("key", Ints(c["edge_key"])),
            ("osm_way_ids", Tuple((Ints(c["way_id"]),))),
            ("length_m", _rounded(c["edge_length_m"], _METRES)),
            ("start_offset_m", _rounded(c["start_offset_m"], _METRES)),
            ("end_offset_m", _rounded(c["end_offset_m"], _METRES)),
            ("name", Utf8(text, c["name_start"], c["name_stop"])),
            ("road_class", Choice(c["road_class"], ROAD_CLASSES)),
            ("speed_limit_kph", _rounded(c["speed_limit_kph"], 1)),
            ("entry_time", _rounded(c["entry_time_s"], _SECONDS)),
            ("exit_time", _rounded(c["exit_time_s"], _SECONDS)),
            ("duration_s", _rounded(c["duration_s"], _SECONDS)),
            ("mean_speed_kph", _rounded(c["mean_speed_kph"], 2)),
        ],
    )


def _segment_table(c: dict[str, Any], text: ByteArray) -> Table:
    """The ``segment`` Features, one row per segment."""
    count = len(c["segment_index"])
    properties = Table(
        count,
        [
            ("kind", Const("segment")),
            ("segment", Ints(c["segment_index"])),
            ("point_range", Tuple((Ints(c["first_point"]), Ints(c["last_point"])))),
            ("length_m", _rounded(c["segment_length_m"], _METRES)),
            ("edges", Items(_edge_json(c, text), c["edge_bounds"])),
            ("start_time", _rounded(c["segment_start_s"], _SECONDS)),
            ("end_time", _rounded(c["segment_end_s"], _SECONDS)),
        ],
    )
    line = Tuple((_coordinates(c["vertex_lon"]), _coordinates(c["vertex_lat"])))
    return Table(
        count,
        [
            ("type", Const("Feature")),
            ("geometry", Items(line, c["vertex_bounds"], geometry="LineString")),
            ("properties", Nested(properties)),
        ],
    )


def _compact_encoder() -> Callable[[Any], str]:
    """
    ``json.dumps(value, allow_nan=False, separators=(",", ":"))``, the encoder made once.

    The C encoder itself where there is one (``JSONEncoder.encode`` makes a new one every
    call), without the check for circular references: what it encodes is made here.
    """
    encoder = json.JSONEncoder(allow_nan=False, separators=(",", ":"))
    if c_make_encoder is None:  # pragma: no cover  # CPython has it
        return encoder.encode
    chunks = c_make_encoder(
        None, encoder.default, encode_basestring_ascii, None, ":", ",", False, False, False
    )
    return lambda value: "".join(chunks(value, 0))


_COMPACT = _compact_encoder()


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
    head = _COMPACT(_head(result))
    features = sourced_pieces(feature_columns(result), _feature_tables, "geojson-features")
    return b"".join((head[:-1].encode("ascii"), b',"features":[', *features, b"]}"))


def geojson_dict(result: MatchResult) -> dict[str, Any]:
    """The GeoJSON document of :func:`geojson_bytes` as Python objects."""
    doc = _head(result)
    packed = feature_columns(result)
    tables = _feature_tables(packed.columns(), packed.text)
    doc["features"] = [feature for table, _ in tables for feature in table.objects()]
    return doc


# --------------------------------------------------------------------------- tables

#: What :func:`geodataframe` (``MatchResult.to_geodataframe``) makes one row of.
GeoKind = Literal["segments", "edges", "points"]
GEO_KINDS: tuple[GeoKind, ...] = ("segments", "edges", "points")
#: Formats of :func:`write_table`; ``gpkg`` holds every kind as a layer (:func:`write_geopackage`).
TABLE_FORMATS = ("csv", "parquet", "geoparquet")
#: How CSV files write times: ISO 8601, UTC, to the microsecond.
CSV_TIME_FORMAT = "%Y-%m-%dT%H:%M:%S.%fZ"
#: The coordinate reference system of every geometry written (WGS84 lon/lat).
CRS = "EPSG:4326"


def _utc(epoch_s: FloatArray) -> pd.DatetimeIndex:
    """Epoch seconds as UTC datetimes to the microsecond (NaT for NaN)."""
    import pandas as pd

    return pd.to_datetime(epoch_s, unit="s", utc=True).as_unit("us")


def _nullable(values: IntArray, valid: BoolArray | None = None) -> pd.arrays.IntegerArray:
    """Integers as pandas ``Int64``, null outside ``valid``."""
    import pandas as pd

    mask = np.zeros(len(values), dtype=bool) if valid is None else ~np.asarray(valid, dtype=bool)
    return pd.arrays.IntegerArray(np.asarray(values, dtype=np.int64), mask)


def points_frame(result: MatchResult) -> pd.DataFrame:
    """
    One row per fix: time, raw and snapped position, edge, place on the path, confidence.

    Columns ``trace_id``, ``index``, ``time`` (UTC; null without times), ``raw_lon``,
    ``raw_lat``, ``matched``, ``segment``, ``lon``, ``lat``, ``u``, ``v``, ``key``,
    ``offset_m``, ``distance_m``, ``confidence``, ``interpolated``, ``outlier``,
    ``edge_index`` (the fix's edge in its segment's list: the ``order`` of
    :func:`edges_frame`) and ``along_m`` (metres along the segment's path). ``segment``,
    ``u``, ``v``, ``key`` and ``edge_index`` are ``Int64``, null for an unmatched fix.
    """
    import pandas as pd

    p = result.points
    n = len(p.time_s)
    matched = np.asarray(p.matched, dtype=bool)
    positions = path_positions(result)
    return pd.DataFrame(
        {
            "trace_id": np.full(n, result.trace_id, dtype=object),
            "index": np.arange(n, dtype=np.int64),
            "time": _utc(p.time_s),
            "raw_lon": p.raw_lon,
            "raw_lat": p.raw_lat,
            "matched": matched,
            "segment": _nullable(p.segment, matched),
            "lon": p.lon,
            "lat": p.lat,
            "u": _nullable(p.u, matched),
            "v": _nullable(p.v, matched),
            "key": _nullable(p.key, matched),
            "offset_m": p.offset_m,
            "distance_m": p.distance_m,
            "confidence": p.confidence,
            "interpolated": np.asarray(p.interpolated, dtype=bool),
            "outlier": np.asarray(p.outlier, dtype=bool),
            "edge_index": _nullable(positions.edge_index, positions.edge_index >= 0),
            "along_m": positions.along_m,
        }
    )


def edges_frame(result: MatchResult, table: EdgeTable | None = None) -> pd.DataFrame:
    """
    One row per driven edge, segments in order (the columns of :class:`EdgeTable`).

    Columns ``trace_id``, ``segment``, ``order``, ``first_point``, ``last_point``, ``u``,
    ``v``, ``key``, ``osm_way_id`` (``Int64``), ``name`` (null for an unnamed road),
    ``road_class``, ``speed_limit_kph``, ``length_m``, ``start_offset_m``,
    ``end_offset_m``, ``entry_time`` / ``exit_time`` (UTC; null without times),
    ``duration_s`` and ``mean_speed_kph``.
    """
    import pandas as pd

    t = table if table is not None else edge_table(result)
    return pd.DataFrame(
        {
            "trace_id": np.full(len(t), result.trace_id, dtype=object),
            "segment": t.segment,
            "order": t.order,
            "first_point": t.first_point,
            "last_point": t.last_point,
            "u": _nullable(t.u),
            "v": _nullable(t.v),
            "key": _nullable(t.key),
            "osm_way_id": _nullable(t.way_id),
            "name": np.array([n or None for n in t.name], dtype=object),
            "road_class": np.array(t.road_class, dtype=object),
            "speed_limit_kph": t.speed_limit_kph,
            "length_m": t.length_m,
            "start_offset_m": t.start_offset_m,
            "end_offset_m": t.end_offset_m,
            "entry_time": _utc(t.entry_time_s),
            "exit_time": _utc(t.exit_time_s),
            "duration_s": t.duration_s,
            "mean_speed_kph": t.mean_speed_kph,
        }
    )


def segments_frame(result: MatchResult, table: EdgeTable | None = None) -> pd.DataFrame:
    """
    One row per segment: its fixes, edges, length, start and end time, mean speed.

    Columns ``trace_id``, ``segment``, ``first_point``, ``last_point``, ``edges`` (how
    many), ``length_m``, ``start_time`` / ``end_time`` (UTC; null without times),
    ``duration_s`` and ``mean_speed_kph``.
    """
    import pandas as pd

    t = table if table is not None else edge_table(result)
    segs = result.segments
    bounds = np.concatenate(([0], np.cumsum([len(s.edge) for s in segs], dtype=np.int64)))
    start, end = span_times(t.entry_time_s, t.exit_time_s, bounds)
    length = np.array([s.length_m for s in segs], dtype=np.float64)
    duration = end - start
    return pd.DataFrame(
        {
            "trace_id": np.full(len(segs), result.trace_id, dtype=object),
            "segment": np.array([s.index for s in segs], dtype=np.int64),
            "first_point": np.array([s.first for s in segs], dtype=np.int64),
            "last_point": np.array([s.last for s in segs], dtype=np.int64),
            "edges": np.diff(bounds),
            "length_m": length,
            "start_time": _utc(start),
            "end_time": _utc(end),
            "duration_s": duration,
            "mean_speed_kph": speeds_kph(length, duration),
        }
    )


def geodataframe(result: MatchResult, kind: GeoKind = "segments") -> gpd.GeoDataFrame:
    """
    A table of the result with geometries, WGS84 (:data:`CRS`).

    Parameters
    ----------
    result
        A match.
    kind
        ``"segments"``: :func:`segments_frame` with each segment's LineString;
        ``"edges"``: :func:`edges_frame` with the LineString of each driven stretch;
        ``"points"``: :func:`points_frame` with each fix's snapped Point (none when
        unmatched).

    Raises
    ------
    ValueError
        ``kind`` is none of those.
    """
    import geopandas as gpd
    import shapely

    if kind == "points":
        frame = points_frame(result)
        p = result.points
        geometry = np.asarray(shapely.points(np.column_stack((p.lon, p.lat))), dtype=object)
        geometry[~np.asarray(p.matched, dtype=bool)] = None
    elif kind == "edges":
        frame = edges_frame(result)
        parts = [s.stretches for s in result.segments]
        geometry = _lines(
            [st.lon for st in parts], [st.lat for st in parts], [np.diff(st.ptr) for st in parts]
        )
    elif kind == "segments":
        frame = segments_frame(result)
        lons = [s.lon if len(s.lon) > 1 else np.repeat(s.lon, 2) for s in result.segments]
        lats = [s.lat if len(s.lat) > 1 else np.repeat(s.lat, 2) for s in result.segments]
        geometry = _lines(lons, lats, [np.array([len(x)]) for x in lons])
    else:
        msg = f"unknown kind {kind!r}; use one of {', '.join(GEO_KINDS)}"
        raise ValueError(msg)
    return gpd.GeoDataFrame(frame, geometry=geometry, crs=CRS)


def _lines(lons: list[FloatArray], lats: list[FloatArray], sizes: list[IntArray]) -> Any:
    """LineStrings of consecutive runs (``sizes`` long) of the vertices, vectorised."""
    import shapely

    counts = np.concatenate(sizes) if sizes else np.zeros(0, dtype=np.int64)
    if len(counts) == 0:
        return np.array([], dtype=object)
    coords = np.column_stack((np.concatenate(lons), np.concatenate(lats)))
    return shapely.linestrings(coords, indices=np.repeat(np.arange(len(counts)), counts))


def write_table(result: MatchResult, kind: GeoKind, path: Path, fmt: str) -> None:
    """
    Write one table of a result to a file.

    Parameters
    ----------
    result
        A match.
    kind
        ``"segments"``, ``"edges"`` or ``"points"``.
    path
        The file (created or replaced).
    fmt
        ``"csv"`` (times ISO 8601 UTC, :data:`CSV_TIME_FORMAT`; nulls empty), ``"parquet"``
        (the dtypes kept) or ``"geoparquet"`` (with geometry and GeoParquet metadata, read
        back by ``geopandas.read_parquet``).

    Raises
    ------
    ValueError
        ``kind`` or ``fmt`` is not one of those, before anything is written.
    """
    if kind not in GEO_KINDS:
        msg = f"unknown table kind {kind!r}; use one of {', '.join(GEO_KINDS)}"
        raise ValueError(msg)
    if fmt not in TABLE_FORMATS:
        msg = f"unknown table format {fmt!r}; use one of {', '.join(TABLE_FORMATS)}"
        raise ValueError(msg)
    if fmt == "geoparquet":
        geodataframe(result, kind).to_parquet(path, index=False)
        return
    frames = {"segments": segments_frame, "edges": edges_frame, "points": points_frame}
    frame = frames[kind](result)
    if fmt == "csv":
        _iso_times(frame).to_csv(path, index=False)
    else:
        frame.to_parquet(path, index=False)


def _iso_times(frame: pd.DataFrame) -> pd.DataFrame:
    """The frame with its UTC datetime columns as ISO 8601 text (:data:`CSV_TIME_FORMAT`)."""
    import pandas as pd

    out = frame.copy()
    for name in frame.columns:
        column = frame[name]
        if isinstance(column.dtype, pd.DatetimeTZDtype):
            naive = column.dt.tz_convert(None).to_numpy().astype("datetime64[us]")
            text = np.char.add(np.datetime_as_string(naive, unit="us"), "Z").astype(object)
            text[np.isnat(naive)] = None
            out[name] = text
    return out


def write_geopackage(result: MatchResult, path: Path) -> None:
    """
    Write every table of a result into one GeoPackage, a layer each (segments, edges, points).

    ``geopandas.read_file(path, layer="edges")`` reads a layer back; integer columns with
    nulls read as floats unless read through Arrow with nullable types (``use_arrow=True,
    arrow_to_pandas_kwargs={"types_mapper": ...}``), the file itself keeps them integers.
    """
    if path.exists() and path.stat().st_size == 0:
        path.unlink()  # a placeholder (atomic writes make one): GDAL wants no file or a GeoPackage
    for kind in GEO_KINDS:
        geodataframe(result, kind).to_file(path, layer=kind, driver="GPKG", engine="pyogrio")
