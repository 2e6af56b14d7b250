"""
The columns a result's GeoJSON features are written from, made by one compiled call.

:func:`feature_columns` gives every array of the segment and point Features
(:mod:`mapmatch.export` declares the members): the fixes' own, their places on the path
and the edges' entry and exit times (:mod:`mapmatch._timing`), each edge's OSM ids, way,
length, speed limit, class and where its name is (read from the network's arrays), each
segment's line in lon/lat and its times. They come packed
(:class:`~mapmatch._jsontext.Packed`), so that :func:`~mapmatch._jsontext.sourced_pieces`
writes the text straight from them: no Python object per column, no array copied again.

A result whose segments all read one network in a local projection, with its way names as
loaded, is read from the network inside the call. Any other (an unpickled result, which
carries its own attributes and lines; a network in another CRS; names edited in this
process) gives the same columns from its segments' attributes and lines.
"""

from __future__ import annotations

import weakref
from typing import TYPE_CHECKING, Any

import numpy as np
from numba import njit

from mapmatch._jsontext import Packed
from mapmatch._sums import path_length_m
from mapmatch._timing import SegmentPaths, place_and_time_kernel, span_times, speeds_kph
from mapmatch.readonly import read_only
from roadnets.names_kernel import edge_records_kernel
from roadnets.spatial_kernels import path_lonlat_kernel

if TYPE_CHECKING:
    from collections.abc import Sequence

    from mapmatch.result import MatchResult, Segment
    from mapmatch.types import ByteArray, FloatArray, IntArray
    from roadnets import RoadNetwork

__all__ = ["BOOL_COLUMNS", "FLOAT_COLUMNS", "INT_COLUMNS", "feature_columns"]

#: The real-valued columns, in the order :func:`_columns` packs them: per fix, per segment,
#: per vertex of the segments' lines, per driven edge.
FLOAT_COLUMNS = (
    "time_s", "lon", "lat", "offset_m", "distance_m", "confidence", "along_m",
    "segment_length_m", "segment_start_s", "segment_end_s",
    "vertex_lon", "vertex_lat",
    "edge_length_m", "start_offset_m", "end_offset_m", "speed_limit_kph",
    "entry_time_s", "exit_time_s", "duration_s", "mean_speed_kph",
)  # fmt: skip
#: The whole-number columns, in the order :func:`_columns` packs them: per fix, per segment
#: (the bounds of each one's edges and vertices: one more), per edge, and ``[0, rows]`` of
#: the segments and of the fixes.
INT_COLUMNS = (
    "index", "matched", "u", "v", "key", "interpolated", "outlier", "segment", "edge_index",
    "on_path",
    "segment_index", "first_point", "last_point", "edge_bounds", "vertex_bounds",
    "edge_u", "edge_v", "edge_key", "way_id", "road_class", "name_start", "name_stop",
    "segment_rows", "point_rows",
)  # fmt: skip
#: The whole-number columns that are flags.
BOOL_COLUMNS = frozenset({"matched", "interpolated", "outlier", "on_path"})


@njit(cache=True, nogil=True)
def _packed(columns):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    The columns (arrays of one type) end to end as one array, and where each one starts.

    A plain loop over the tuple, not an unrolled one: the columns share one type (an
    unrolled loop over columns of mixed types compiles a body per column, about a second
    more for the forty-odd here).
    """
    at = np.zeros(len(columns) + 1, dtype=np.int64)
    for i in range(len(columns)):
        at[i + 1] = at[i] + len(columns[i])
    out = np.empty(at[-1], dtype=columns[0].dtype)
    for i in range(len(columns)):
        out[at[i] : at[i + 1]] = columns[i]
    return out, at


@njit(cache=True, nogil=True)
def _real(values):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """``values`` as a contiguous float64 array (the packed columns share one type)."""
    return np.ascontiguousarray(values)


@njit(cache=True, nogil=True)
def _whole(values):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """``values`` as an int64 array of its own (the packed columns share one type)."""
    return values.astype(np.int64)


@njit(cache=True, nogil=True)
def _lines(vertex_lon, vertex_lat, vertex_bounds):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """The segments' lines with a lone vertex written twice (a LineString needs two)."""
    count = len(vertex_bounds) - 1
    bounds = np.zeros(count + 1, dtype=np.int64)
    for s in range(count):
        size = vertex_bounds[s + 1] - vertex_bounds[s]
        bounds[s + 1] = bounds[s] + (2 if size == 1 else size)
    if bounds[count] == vertex_bounds[count]:
        return vertex_lon, vertex_lat, vertex_bounds
    lon = np.empty(bounds[count])
    lat = np.empty(bounds[count])
    for s in range(count):
        lo, hi = vertex_bounds[s], vertex_bounds[s + 1]
        at = bounds[s]
        lon[at : at + hi - lo] = vertex_lon[lo:hi]
        lat[at : at + hi - lo] = vertex_lat[lo:hi]
        if hi - lo == 1:
            lon[at + 1] = vertex_lon[lo]
            lat[at + 1] = vertex_lat[lo]
    return lon, lat, bounds


@njit(cache=True, nogil=True)
def _columns(paths, points, whole, real, vertices):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    Every feature column, packed (:data:`FLOAT_COLUMNS`, :data:`INT_COLUMNS`).

    ``paths`` are :class:`~mapmatch._timing.SegmentPaths`' arrays (each segment's length
    added from them as :attr:`~mapmatch.result.Segment.length_m` adds it), ``points`` the
    fixes' arrays, ``whole`` and ``real`` the edges' records
    (:func:`~roadnets.names_kernel.edge_records_kernel`'s), ``vertices`` the segments' lines
    end to end and their bounds.
    """
    seg_index, first, last, bounds, seg_edge, start_m, end_m = paths
    lengths = np.empty(len(seg_index))
    for s in range(len(seg_index)):
        lengths[s] = path_length_m(start_m, end_m, bounds[s], bounds[s + 1])
    (segment, matched, edge, offset_m, time_s, lon, lat, distance_m, confidence, u, v, key,
     interpolated, outlier) = points  # fmt: skip
    edge_index, along, times = place_and_time_kernel(
        seg_index, bounds, seg_edge, start_m, end_m, segment, matched, edge, offset_m, time_s
    )
    entry, exit_ = times[2], times[3]
    duration = exit_ - entry
    segment_start, segment_end = span_times(entry, exit_, bounds)
    vertex_lon, vertex_lat, vertex_bounds = _lines(*vertices)
    floats, floats_at = _packed(
        (_real(time_s), _real(lon), _real(lat), _real(offset_m), _real(distance_m),
         _real(confidence), along,
         lengths, segment_start, segment_end,
         _real(vertex_lon), _real(vertex_lat),
         _real(real[0]), _real(start_m), _real(end_m), _real(real[1]), entry, exit_, duration,
         speeds_kph(end_m - start_m, duration)),
    )  # fmt: skip
    ints, ints_at = _packed(
        (np.arange(len(time_s)), _whole(matched), _whole(u), _whole(v), _whole(key),
         _whole(interpolated), _whole(outlier), _whole(segment), edge_index,
         _whole(edge_index >= 0),
         _whole(seg_index), _whole(first), _whole(last), _whole(bounds), vertex_bounds,
         _whole(whole[0]), _whole(whole[1]), _whole(whole[2]), _whole(whole[3]),
         _whole(whole[4]), _whole(whole[5]), whole[5] + whole[6],
         np.array([0, len(seg_index)]), np.array([0, len(time_s)])),
    )  # fmt: skip
    return floats, floats_at, ints, ints_at


@njit(cache=True, nogil=True)
def _from_network(paths, points, network):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """:func:`_columns`, the edges' records and the segments' lines read from ``network``."""
    records, names, geom, vertex_lonlat, inverse = network
    _, _, _, bounds, seg_edge, start_m, end_m = paths
    whole, real, _ = edge_records_kernel(seg_edge, *records, *names)
    count = len(bounds) - 1
    lines = [
        path_lonlat_kernel(
            seg_edge[bounds[s] : bounds[s + 1]], start_m[bounds[s] : bounds[s + 1]],
            end_m[bounds[s] : bounds[s + 1]], geom, vertex_lonlat, inverse,
        )
        for s in range(count)
    ]  # fmt: skip
    vertex_bounds = np.zeros(count + 1, dtype=np.int64)
    for s in range(count):
        vertex_bounds[s + 1] = vertex_bounds[s] + len(lines[s][0])
    vertex_lon = np.empty(vertex_bounds[count])
    vertex_lat = np.empty(vertex_bounds[count])
    for s in range(count):
        vertex_lon[vertex_bounds[s] : vertex_bounds[s + 1]] = lines[s][0]
        vertex_lat[vertex_bounds[s] : vertex_bounds[s + 1]] = lines[s][1]
    return _columns(paths, points, whole, real, (vertex_lon, vertex_lat, vertex_bounds))


@njit(cache=True, nogil=True)
def _from_segments(paths, points, whole, real, vertices):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """:func:`_columns` of records and lines already known."""
    return _columns(paths, points, whole, real, vertices)


def feature_columns(result: MatchResult) -> Packed:
    """
    The columns of ``result``'s GeoJSON features (see the module docstring).

    Parameters
    ----------
    result
        A match.

    Returns
    -------
    Packed
        :data:`FLOAT_COLUMNS` and :data:`INT_COLUMNS` (:data:`BOOL_COLUMNS` read as flags);
        the edges' names are UTF-8 in its ``text``, from ``name_start`` to ``name_stop``.
    """
    placed = result.placed  # the assembly's arrays, where the result was not read yet
    paths = SegmentPaths.of(result.segments) if placed is None else placed.paths
    path_arrays = (paths.index, paths.first, paths.last, paths.bounds, paths.edge, paths.start_m,
                   paths.end_m)  # fmt: skip
    p = result.points
    # the points' times are the trace's read-only column, or a copy of them (an unpickled
    # result, a live trip): read-only either way, so that the kernel has one variant
    points = (
        p.segment, p.matched, p.edge, p.offset_m, read_only(p.time_s), p.lon, p.lat, p.distance_m,
        p.confidence, p.u, p.v, p.key, p.interpolated, p.outlier,
    )  # fmt: skip
    net = _one_network(result.segments) if placed is None else placed.net
    inputs = None if net is None else _network_inputs(net)
    if inputs is not None:
        text, network = inputs
        floats, floats_at, ints, ints_at = _from_network(path_arrays, points, network)
    else:
        text, whole, real, vertices = _known(result.segments)
        floats, floats_at, ints, ints_at = _from_segments(
            path_arrays, points, whole, real, vertices
        )
    return Packed(floats, floats_at, ints, ints_at, text, FLOAT_COLUMNS, INT_COLUMNS, BOOL_COLUMNS)


def _one_network(segs: Sequence[Segment]) -> RoadNetwork | None:
    """The network every segment reads, if there is one."""
    if not segs:
        return None
    net = segs[0].net
    return net if all(s.net is net for s in segs) else None


#: The last network's :func:`_network_inputs` (a network is matched on for many results).
_last: tuple[weakref.ref[RoadNetwork], tuple[ByteArray, tuple[Any, ...]]] | None = None


def _network_inputs(net: RoadNetwork) -> tuple[ByteArray, tuple[Any, ...]] | None:
    """
    What :func:`_from_network` reads of ``net``, and its names' bytes; made once per network.

    ``None`` where the network cannot be read inside the call: its way names edited in this
    process, or a CRS without a compiled projection.
    """
    global _last  # one slot, replaced whole
    names = net.way_names.arrays()
    compiled = net.projector.compiled
    if names is None or compiled is None:
        return None
    last = _last
    if last is not None and last[0]() is net and last[1][0] is names[2]:
        return last[1]
    a = net.arrays
    records = (a.node_osm_id, a.edge_u, a.edge_v, a.edge_key, a.edge_way_id, a.edge_length_m,
               a.edge_speed_mps, a.edge_class)  # fmt: skip
    network = (records, names[:2], net.kernel_geometry, (a.geom_lon, a.geom_lat),
               compiled.inverse_parameters)  # fmt: skip
    made = (names[2], network)
    _last = (weakref.ref(net), made)
    return made


def _known(
    segs: Sequence[Segment],
) -> tuple[ByteArray, IntArray, FloatArray, tuple[FloatArray, FloatArray, IntArray]]:
    """The names' bytes, the edges' records and the lines, from the segments' own."""
    from mapmatch.result import EdgeAttributes
    from roadnets.drivable import ROAD_CLASSES

    attrs = EdgeAttributes.joined([s.attributes for s in segs])
    encoded = [name.encode("utf-8") for name in attrs.name]
    size = np.array([len(e) for e in encoded], dtype=np.int64)
    classes = {name: i for i, name in enumerate(ROAD_CLASSES)}
    road_class = np.array([classes[c] for c in attrs.road_class], dtype=np.int64)
    whole = np.array(
        (attrs.u, attrs.v, attrs.key, attrs.way_id, road_class, np.cumsum(size) - size, size),
        dtype=np.int64,
    )
    real = np.array((attrs.length_m, attrs.speed_limit_kph), dtype=np.float64)
    vertex_bounds = np.zeros(len(segs) + 1, dtype=np.int64)
    np.cumsum([len(s.lon) for s in segs], out=vertex_bounds[1:])
    lon = np.concatenate([s.lon for s in segs], dtype=np.float64) if segs else np.zeros(0)
    lat = np.concatenate([s.lat for s in segs], dtype=np.float64) if segs else np.zeros(0)
    text = np.frombuffer(b"".join(encoded), dtype=np.uint8)
    return text, whole, real, (lon, lat, vertex_bounds)
