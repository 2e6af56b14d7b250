"""What a match returns: segments of driven edges, snapped points, length and its check.

(Over 400 lines on purpose: the result's value objects (segments, edges, points, stats, check)
are one public contract, documented together.)

The result holds arrays; every serialised form of it (GeoJSON, tables, GeoDataFrames, the
batch's files) is made by :mod:`mapmatch.export` when asked for. A segment's per-edge objects,
road attributes and geometry are read from the network on first use, so a match that only
needs its length or its points never builds them.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from mapmatch.frozen import quick_init
from roadnets.names import edge_records

if TYPE_CHECKING:
    from collections.abc import Sequence

    import geopandas as gpd  # type: ignore[import-untyped]
    import numpy.typing as npt
    import pandas as pd

    from mapmatch._timing import SegmentPaths
    from mapmatch.config import MatchConfig
    from mapmatch.distance import DistanceCheck
    from mapmatch.export import GeoKind
    from mapmatch.types import BoolArray, FloatArray, IntArray
    from roadnets import RoadNetwork

__all__ = [
    "Diagnostics",
    "EdgeAttributes",
    "MatchResult",
    "MatchStats",
    "MatchedEdge",
    "MatchedPoints",
    "PlacedArrays",
    "Segment",
    "Stretches",
]


@dataclass(frozen=True, slots=True)
class MatchedEdge:
    """
    One directed edge of a matched path, and the part of it that was driven.

    ``u``/``v`` are OSM node ids and ``key`` tells parallel edges apart; ``edge`` is the
    edge's index in the network's arrays. ``start_offset_m``/``end_offset_m`` bound the
    driven stretch, metres from the edge's start. ``name`` is the street's ``name`` (else its
    ``ref``; empty when the way has neither), ``road_class`` its OSM ``highway`` value and
    ``speed_limit_kph`` its ``maxspeed`` (the road class's default where it is not tagged).
    """

    edge: int
    u: int
    v: int
    key: int
    osm_way_ids: tuple[int, ...]
    length_m: float
    start_offset_m: float
    end_offset_m: float
    name: str = ""
    road_class: str = ""
    speed_limit_kph: float = float("nan")

    @property
    def driven_m(self) -> float:
        """Metres driven on this edge."""
        return self.end_offset_m - self.start_offset_m

    def to_dict(self) -> dict[str, Any]:
        """The edge's fields as plain Python values (``osm_way_ids`` a list)."""
        return {
            "edge": self.edge,
            "u": self.u,
            "v": self.v,
            "key": self.key,
            "osm_way_ids": list(self.osm_way_ids),
            "length_m": self.length_m,
            "start_offset_m": self.start_offset_m,
            "end_offset_m": self.end_offset_m,
            "name": self.name,
            "road_class": self.road_class,
            "speed_limit_kph": self.speed_limit_kph,
        }


@dataclass(frozen=True, slots=True)
class EdgeAttributes:
    """
    What the network says about each edge of a segment's path, one entry per stretch.

    ``u``/``v``/``key`` are the OSM ids of the edge, ``way_id`` its OSM way, ``length_m``
    its whole length, ``speed_limit_kph`` the ``maxspeed`` (or the class default),
    ``road_class`` the ``highway`` value and ``name`` the street name (``""`` for none).
    """

    u: IntArray
    v: IntArray
    key: IntArray
    way_id: IntArray
    length_m: FloatArray
    speed_limit_kph: FloatArray
    road_class: tuple[str, ...]
    name: tuple[str, ...]

    @classmethod
    def of_edges(cls, net: RoadNetwork, edge: IntArray) -> EdgeAttributes:
        """Read the attributes of network edges ``edge`` (array of edge indices)."""
        u, v, key, way, length, speed, road_class, name = edge_records(
            net.arrays, net.way_names, edge
        )
        return cls(
            u=u,
            v=v,
            key=key,
            way_id=way,
            length_m=length,
            speed_limit_kph=speed,
            road_class=tuple(_road_classes()[road_class].tolist()),
            name=tuple(name),
        )

    @classmethod
    def joined(cls, parts: Sequence[EdgeAttributes]) -> EdgeAttributes:
        """The attributes of several paths end to end (one path's as they are, not copied)."""
        if len(parts) == 1:
            return parts[0]

        def cat(values: list[Any], dtype: type) -> Any:
            return np.concatenate(values, dtype=dtype) if values else np.zeros(0, dtype=dtype)

        return cls(
            u=cat([a.u for a in parts], np.int64),
            v=cat([a.v for a in parts], np.int64),
            key=cat([a.key for a in parts], np.int64),
            way_id=cat([a.way_id for a in parts], np.int64),
            length_m=cat([a.length_m for a in parts], np.float64),
            speed_limit_kph=cat([a.speed_limit_kph for a in parts], np.float64),
            road_class=tuple(c for a in parts for c in a.road_class),
            name=tuple(n for a in parts for n in a.name),
        )


@functools.cache
def _road_classes() -> npt.NDArray[np.object_]:
    """``roadnets.drivable.ROAD_CLASSES`` as an array to index with edge classes (made once)."""
    from roadnets.drivable import ROAD_CLASSES

    return np.asarray(ROAD_CLASSES, dtype=object)


class Segment:
    """
    A connected matched piece of the trace: fixes ``first..last`` and the path driven.

    The path is held as arrays: stretch ``i`` runs along network edge ``edge[i]`` from
    ``start_offset_m[i]`` to ``end_offset_m[i]`` (metres from the edge's start). The
    per-edge objects (:attr:`edges`), the road attributes (:attr:`attributes`) and the
    geometry (:attr:`lon`/:attr:`lat`, WGS84, driving order) are read from the network on
    first use. A pickled segment carries them, not the network.

    Parameters
    ----------
    index, first, last
        Position of the segment in the result, and its first and last fix.
    edge, start_offset_m, end_offset_m
        The stretches of the path.
    net
        The network matched on; ``None`` only when ``attributes``, ``lon`` and ``lat`` are
        given.
    attributes, lon, lat
        Already known attributes and geometry (an unpickled segment).
    length_m
        The path's length where already added (by the assembly; :attr:`length_m` to the bit).
    """

    __slots__ = (
        "_attributes",
        "_edges",
        "_lat",
        "_length_m",
        "_lon",
        "_net",
        "_stretches",
        "edge",
        "end_offset_m",
        "first",
        "index",
        "last",
        "start_offset_m",
    )

    def __init__(
        self,
        index: int,
        first: int,
        last: int,
        edge: IntArray,
        start_offset_m: FloatArray,
        end_offset_m: FloatArray,
        *,
        net: RoadNetwork | None = None,
        attributes: EdgeAttributes | None = None,
        lon: FloatArray | None = None,
        lat: FloatArray | None = None,
        stretches: Stretches | None = None,
        length_m: float | None = None,
    ) -> None:
        if net is None and (attributes is None or lon is None or lat is None or stretches is None):
            msg = "Segment needs the network, or its attributes and geometry"
            raise ValueError(msg)
        self.index, self.first, self.last = int(index), int(first), int(last)
        self.edge = np.asarray(edge, dtype=np.int64)
        self.start_offset_m = np.asarray(start_offset_m, dtype=np.float64)
        self.end_offset_m = np.asarray(end_offset_m, dtype=np.float64)
        self._net = net
        self._attributes = attributes
        self._lon, self._lat = lon, lat
        self._stretches = stretches
        self._edges: list[MatchedEdge] | None = None
        self._length_m = length_m

    def __repr__(self) -> str:
        return (
            f"<Segment {self.index}: fixes {self.first}-{self.last}, {len(self.edge)} edges, "
            f"{self.length_m:,.1f} m>"
        )

    def __reduce__(self) -> tuple[Any, ...]:
        path = (
            self.index,
            self.first,
            self.last,
            self.edge,
            self.start_offset_m,
            self.end_offset_m,
        )
        known = {
            "attributes": self.attributes,
            "lon": self.lon,
            "lat": self.lat,
            "stretches": self.stretches,
        }
        return (_restore_segment, (path, known))

    @property
    def net(self) -> RoadNetwork | None:
        """The network matched on (``None`` for an unpickled segment, which carries its own)."""
        return self._net

    @property
    def length_m(self) -> float:
        """Metres along the path, from the first fix's place to the last's."""
        if self._length_m is None:
            from mapmatch._sums import path_length_m  # compiled: imported when first asked for

            length = path_length_m(self.start_offset_m, self.end_offset_m, 0, len(self.edge))
            self._length_m = float(length)
        return self._length_m

    @property
    def driven_m(self) -> FloatArray:
        """Metres driven on each edge of the path."""
        return self.end_offset_m - self.start_offset_m

    @property
    def attributes(self) -> EdgeAttributes:
        """OSM ids, way, length, speed limit, road class and name of each edge."""
        if self._attributes is None:
            assert self._net is not None  # checked in __init__
            self._attributes = EdgeAttributes.of_edges(self._net, self.edge)
        return self._attributes

    @property
    def edges(self) -> list[MatchedEdge]:
        """The driven edges as objects, in driving order."""
        if self._edges is None:
            a = self.attributes
            self._edges = [
                MatchedEdge(
                    edge=e,
                    u=u,
                    v=v,
                    key=k,
                    osm_way_ids=(w,),
                    length_m=length,
                    start_offset_m=lo,
                    end_offset_m=hi,
                    name=name,
                    road_class=cls,
                    speed_limit_kph=limit,
                )
                for e, u, v, k, w, length, lo, hi, name, cls, limit in zip(
                    self.edge.tolist(),
                    a.u.tolist(),
                    a.v.tolist(),
                    a.key.tolist(),
                    a.way_id.tolist(),
                    a.length_m.tolist(),
                    self.start_offset_m.tolist(),
                    self.end_offset_m.tolist(),
                    a.name,
                    a.road_class,
                    a.speed_limit_kph.tolist(),
                    strict=True,
                )
            ]
        return self._edges

    def _geometry(self) -> tuple[FloatArray, FloatArray]:
        if self._lon is None or self._lat is None:
            net = self._net
            assert net is not None  # checked in __init__
            self._lon, self._lat = net.path_lonlat(
                self.edge, self.start_offset_m, self.end_offset_m
            )
        return self._lon, self._lat

    @property
    def lon(self) -> FloatArray:
        """Longitudes of the path's vertices, WGS84 degrees, in driving order."""
        return self._geometry()[0]

    @property
    def lat(self) -> FloatArray:
        """Latitudes of the path's vertices, WGS84 degrees, in driving order."""
        return self._geometry()[1]

    @property
    def stretches(self) -> Stretches:
        """The line of each driven stretch on its own (one per edge), WGS84."""
        if self._stretches is None:
            assert self._net is not None  # checked in __init__
            self._stretches = Stretches.of_path(
                self._net, self.edge, self.start_offset_m, self.end_offset_m
            )
        return self._stretches


@dataclass(frozen=True, slots=True)
class Stretches:
    """
    The lines of the stretches of a path, one per edge.

    Stretch ``i`` has the vertices ``lon[ptr[i]:ptr[i + 1]]``, ``lat[ptr[i]:ptr[i + 1]]``
    (WGS84 degrees, driving order, at least two: the ends).
    """

    lon: FloatArray
    lat: FloatArray
    ptr: IntArray

    @classmethod
    def of_path(
        cls, net: RoadNetwork, edge: IntArray, start_m: FloatArray, end_m: FloatArray
    ) -> Stretches:
        """
        Cut the network's geometry: each edge between its two offsets, ends interpolated.

        Vectorised over the stretches (the edge's vertices strictly between the offsets are
        kept, in order, in the network's own degrees; only the ends are unprojected).
        """
        a = net.arrays
        n = len(edge)
        sizes = a.edge_geom_ptr[edge + 1] - a.edge_geom_ptr[edge]
        owner = np.repeat(np.arange(n), sizes)
        first = np.repeat(a.edge_geom_ptr[edge] - np.cumsum(sizes) + sizes, sizes)
        vertex = first + np.arange(int(sizes.sum()))
        along = a.geom_cum_m[vertex]
        inner = (along > start_m[owner]) & (along < end_m[owner])
        ends_x, ends_y = net.point_on_edge(
            np.concatenate((edge, edge)), np.concatenate((start_m, end_m))
        )
        ends_lon, ends_lat = net.unproject(ends_x, ends_y)
        lon = np.concatenate((ends_lon[:n], a.geom_lon[vertex[inner]], ends_lon[n:]))
        lat = np.concatenate((ends_lat[:n], a.geom_lat[vertex[inner]], ends_lat[n:]))
        key_owner = np.concatenate((np.arange(n), owner[inner], np.arange(n)))
        key_along = np.concatenate((start_m - 1.0, along[inner], end_m + 1.0))
        order = np.lexsort((key_along, key_owner))
        lon, lat = lon[order], lat[order]
        ptr = np.concatenate(([0], np.cumsum(np.bincount(key_owner, minlength=n))))
        return cls(lon=lon, lat=lat, ptr=np.asarray(ptr, dtype=np.int64))


def _restore_segment(args: tuple[Any, ...], known: dict[str, Any]) -> Segment:
    """Rebuild a pickled :class:`Segment` (its attributes and geometry made already)."""
    return Segment(*args, **known)


@quick_init
@dataclass(frozen=True, slots=True)
class MatchedPoints:
    """
    Per-fix outcome, one array entry per input fix (after sorting).

    Unmatched fixes have ``matched`` False, ``edge``/``u``/``v``/``key`` -1 and NaN
    positions; ``confidence`` is the posterior probability of the chosen candidate.
    ``interpolated`` marks fixes left out of the model (outliers, a stopped car's repeats)
    whose position was interpolated along the path; ``outlier`` those judged outliers.
    """

    time_s: FloatArray
    raw_lon: FloatArray
    raw_lat: FloatArray
    matched: BoolArray
    edge: IntArray
    u: IntArray
    v: IntArray
    key: IntArray
    offset_m: FloatArray
    distance_m: FloatArray
    lon: FloatArray
    lat: FloatArray
    confidence: FloatArray
    segment: IntArray
    interpolated: BoolArray
    outlier: BoolArray


@quick_init
@dataclass(frozen=True, slots=True)
class MatchStats:
    """
    Counts and timings of one match.

    ``input_rows``, ``reordered_rows``, ``merged_rows`` (true duplicates merged),
    ``shared_time_rows`` (points kept that share the previous point's time),
    ``dropped_rows`` (source records the reader could not use) and ``time_source``
    (``"ok"``, ``"absent"``, ``"implausible"``: only ``"ok"`` times entered the model) repeat
    the trace's :class:`~mapmatch.trace.TraceReport`, and ``warnings`` its sentences.
    """

    points: int
    matched_points: int
    candidates: int
    reordered_rows: int
    timings_s: dict[str, float]
    warnings: tuple[str, ...]
    model_points: int
    outliers: int
    break_repairs: int
    input_rows: int = 0
    merged_rows: int = 0
    shared_time_rows: int = 0
    dropped_rows: int = 0
    time_source: str = "ok"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return {
            "points": self.points,
            "matched_points": self.matched_points,
            "candidates": self.candidates,
            "input_rows": self.input_rows,
            "reordered_rows": self.reordered_rows,
            "merged_rows": self.merged_rows,
            "shared_time_rows": self.shared_time_rows,
            "dropped_rows": self.dropped_rows,
            "time_source": self.time_source,
            "model_points": self.model_points,
            "outliers": self.outliers,
            "break_repairs": self.break_repairs,
            "timings_s": {k: round(v, 6) for k, v in self.timings_s.items()},
            "warnings": list(self.warnings),
        }


@dataclass(frozen=True, slots=True)
class Diagnostics:
    """
    The model's inside view, for inspecting a match (``match(..., diagnostics=True)``).

    One entry per candidate of every fix that entered the model: ``fix`` (trace index),
    ``edge`` (network edge index), ``u``/``v``/``key`` (OSM), ``lon``/``lat`` (projection),
    ``distance_m``, ``log_emission``, ``log_transition`` (from the previous model fix's chosen
    candidate; NaN at the first fix of a segment), ``posterior`` and ``chosen``.
    ``model_fixes`` lists the trace indices that entered the model.
    """

    model_fixes: IntArray
    fix: IntArray
    edge: IntArray
    u: IntArray
    v: IntArray
    key: IntArray
    lon: FloatArray
    lat: FloatArray
    distance_m: FloatArray
    log_emission: FloatArray
    log_transition: FloatArray
    posterior: FloatArray
    chosen: BoolArray

    @property
    def candidates(self) -> pd.DataFrame:
        """The candidates as a table, one row each."""
        import pandas as pd

        names = ("fix", "edge", "u", "v", "key", "lon", "lat", "distance_m", "log_emission")
        columns = {name: getattr(self, name) for name in names}
        columns.update(
            log_transition=self.log_transition, posterior=self.posterior, chosen=self.chosen
        )
        return pd.DataFrame(columns)


class PlacedArrays:
    """
    A match's segments as the assembly's arrays: the :class:`Segment` objects made when read.

    A :class:`MatchResult` holds one until its :attr:`~MatchResult.segments` are first read,
    so that a caller who only writes the document (:func:`mapmatch.export.geojson_bytes`, the
    batch's and the service's GeoJSON) never makes them: the document is written from these
    arrays, the same values.

    Attributes
    ----------
    paths
        Every segment's path end to end (:class:`~mapmatch._timing.SegmentPaths`).
    lengths
        Each segment's :attr:`Segment.length_m`, added as it adds it.
    net
        The network matched on.
    """

    __slots__ = ("_segments", "lengths", "net", "paths")

    def __init__(self, paths: SegmentPaths, lengths: FloatArray, net: RoadNetwork) -> None:
        self.paths, self.lengths, self.net = paths, lengths, net
        self._segments: list[Segment] | None = None

    def segments(self) -> list[Segment]:
        """The paths as :class:`Segment` objects (their stretches: views of the arrays), once."""
        if self._segments is None:
            p = self.paths
            bounds, first, last = p.bounds.tolist(), p.first.tolist(), p.last.tolist()
            index, lengths = p.index.tolist(), self.lengths.tolist()
            self._segments = [
                Segment(
                    index[s], first[s], last[s], p.edge[bounds[s] : bounds[s + 1]],
                    p.start_m[bounds[s] : bounds[s + 1]], p.end_m[bounds[s] : bounds[s + 1]],
                    net=self.net, length_m=lengths[s],
                )
                for s in range(len(index))
            ]  # fmt: skip
        return self._segments


@quick_init
@dataclass(frozen=True)
class MatchResult:
    """
    The outcome of matching one trace.

    Attributes
    ----------
    trace_id
        The trace's id.
    network
        ``{"id", "source", "crs"}`` of the network matched on.
    segments
        Connected matched pieces in order; a break starts a new one.
    points
        Per-fix outcome.
    breaks
        Fix indices where the trace was split (the first fix of every segment but the first).
    matched_length_m
        Metres along the matched edges, from the first fix's projection to the last's
        (with an odometer, from where the fixes' readings put them: :mod:`mapmatch.hmm.ends`),
        summed over segments.
    distance_check
        The fused trip distance against :attr:`matched_length_m`.
    stats
        Counts and timings.
    diagnostics
        The model's candidates and scores when asked for (``match(..., diagnostics=True)``).

    A result made by :func:`mapmatch.match` makes its ``segments`` when they are first read
    (:class:`PlacedArrays`); pickled, it carries them made.
    """

    trace_id: str
    network: dict[str, str]
    segments: list[Segment]
    points: MatchedPoints
    breaks: list[int]
    matched_length_m: float
    distance_check: DistanceCheck
    stats: MatchStats
    diagnostics: Diagnostics | None = None
    config: MatchConfig | None = field(default=None, repr=False)

    def defer_segments(self, placed: PlacedArrays) -> None:
        """
        Make this new result's ``segments`` from ``placed`` when they are first read.

        For :func:`mapmatch.match`, which makes the result with no segments and hands it the
        assembly's arrays: the segments given to the constructor are dropped.
        """
        values = self.__dict__
        del values["segments"]
        values["_placed"] = placed

    def __getattr__(self, name: str) -> Any:
        """The ``segments`` of a result that still holds them as arrays: made now."""
        values = self.__dict__
        placed = values.get("_placed")
        if placed is None or name != "segments":
            msg = f"{type(self).__name__!r} object has no attribute {name!r}"
            raise AttributeError(msg)
        segments: list[Segment] = values.setdefault("segments", placed.segments())
        values.pop("_placed", None)  # another thread may have read them at the same time
        return segments

    def __getstate__(self) -> dict[str, Any]:
        """Pickled with its segments made (the arrays' network stays behind)."""
        if "_placed" in self.__dict__:
            self.__getattr__("segments")
        return self.__dict__

    @property
    def placed(self) -> PlacedArrays | None:
        """The arrays its segments are still to be made from (``None`` once made)."""
        placed: PlacedArrays | None = self.__dict__.get("_placed")
        return placed

    def __repr__(self) -> str:
        p = self.points
        return (
            f"<MatchResult {self.trace_id!r}: {int(p.matched.sum())}/{len(p.matched)} fixes "
            f"matched, {len(self.segments)} segment(s), {self.matched_length_m:,.1f} m, "
            f"verdict {self.distance_check.verdict}>"
        )

    def way_ids(self) -> list[int]:
        """OSM way ids driven, in order, consecutive repeats collapsed."""
        ways: list[int] = []
        for segment in self.segments:
            for way in segment.attributes.way_id.tolist():
                if not ways or ways[-1] != way:
                    ways.append(way)
        return ways

    def to_geojson(self) -> dict[str, Any]:
        """
        The result as a GeoJSON FeatureCollection (docs/DESIGN.md's output schema).

        One ``segment`` Feature per segment (LineString of the driven path) and one ``point``
        Feature per fix (snapped Point, or null geometry when unmatched). The same document
        as text is :func:`mapmatch.export.geojson_bytes` (what the batch and the service
        write).
        """
        from mapmatch.export import geojson_dict

        return geojson_dict(self)

    def to_dataframe(self) -> pd.DataFrame:
        """The per-fix table: time, raw and snapped position, edge, offset, confidence."""
        from mapmatch.export import points_frame

        return points_frame(self)

    def to_geodataframe(self, kind: GeoKind = "segments") -> gpd.GeoDataFrame:
        """
        The result as a GeoPandas table in WGS84 (EPSG:4326), one row per ``kind``.

        Parameters
        ----------
        kind
            ``"segments"`` (LineString of each connected piece; the default), ``"edges"``
            (LineString of each driven stretch, with street, class, speed limit, entry and
            exit time) or ``"points"`` (the snapped Point of each fix; none when unmatched).

        Returns
        -------
        geopandas.GeoDataFrame
            OSM ids as nullable integers (``Int64``, null where unmatched), flags as bools,
            times as ``datetime64[us, UTC]``; see :func:`mapmatch.export.geodataframe`.
        """
        from mapmatch.export import geodataframe

        return geodataframe(self, kind)
