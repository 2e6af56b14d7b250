"""The compiled road network: flat numpy arrays the matcher's hot path works on.

Everything is indexed by position: nodes ``0..N-1``, directed edges ``0..E-1``. Metric
coordinates are in the network's projected CRS. The arrays are written to and read from disk
as ``.npy`` files so that several processes can memory-map one copy.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from roadnets.pages import advise_huge_pages

if TYPE_CHECKING:
    from pathlib import Path

__all__ = ["NetworkArrays"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
Int32Array = npt.NDArray[np.int32]


@dataclass(frozen=True, slots=True)
class NetworkArrays:
    """
    Flat arrays of a compiled directed road network.

    Attributes
    ----------
    node_osm_id
        OSM node id of each graph node.
    node_x, node_y
        Node position, metres in the projected CRS.
    edge_u, edge_v
        Start and end node (indices) of each directed edge.
    edge_key
        Key distinguishing parallel edges between the same ``u`` and ``v`` (networkx style).
    edge_way_id
        OSM way id each edge comes from.
    edge_length_m
        Length along the geometry, metres, measured on the WGS84 ellipsoid (geodesic).
    edge_speed_mps
        Speed limit (tagged ``maxspeed`` or the class default), metres per second.
    edge_class
        Index into :data:`roadnets.drivable.ROAD_CLASSES`.
    edge_oneway
        Whether the road is one-way (no twin in the other direction).
    edge_twin
        The edge running the same geometry the other way, or -1.
    edge_geom_ptr
        Edge ``e``'s vertices are ``geom_*[edge_geom_ptr[e]:edge_geom_ptr[e + 1]]``.
    geom_x, geom_y
        Vertex positions, metres, in driving order for each edge.
    geom_cum_m
        Distance along the edge from its start to each vertex, metres (geodesic: the sum of
        the geodesic lengths of the segments before it).
    geom_lon, geom_lat
        The vertices in WGS84 degrees: ``geom_x``/``geom_y`` unprojected once, so that a
        path's geometry is read, not unprojected again, for every result.
    out_ptr, out_edge
        CSR adjacency: edges leaving node ``n`` are ``out_edge[out_ptr[n]:out_ptr[n + 1]]``.
    seg_start, seg_edge
        Segments in the spatial index: segment ``s`` runs from vertex ``seg_start[s]`` to the
        next one and belongs to edge ``seg_edge[s]`` (one per geometry; twins share it).
    banned_in, banned_out
        Turn restrictions: the move from edge ``banned_in[i]`` onto ``banned_out[i]`` is banned.
    banned_seq_ptr, banned_seq_edge
        Via-way turn restrictions: driving the edges
        ``banned_seq_edge[banned_seq_ptr[i]:banned_seq_ptr[i + 1]]`` one right after the other
        is banned (at least three edges: from, via..., to).
    name_way_id, name_ptr, name_utf8
        Way names (``name``, else ``ref``): way ``name_way_id[i]`` (sorted) is named by the
        UTF-8 bytes ``name_utf8[name_ptr[i]:name_ptr[i + 1]]``; read them through
        :class:`roadnets.names.WayNames` (``RoadNetwork.way_names``).

    Every array is read-only, whether compiled in this process or memory-mapped from the
    cache: the compiled kernels then see one type of array and are compiled once, not once
    for writable and once more for read-only arrays.
    """

    node_osm_id: IntArray
    node_x: FloatArray
    node_y: FloatArray
    edge_u: Int32Array
    edge_v: Int32Array
    edge_key: Int32Array
    edge_way_id: IntArray
    edge_length_m: FloatArray
    edge_speed_mps: FloatArray
    edge_class: npt.NDArray[np.int8]
    edge_oneway: npt.NDArray[np.bool_]
    edge_twin: Int32Array
    edge_geom_ptr: IntArray
    geom_x: FloatArray
    geom_y: FloatArray
    geom_cum_m: FloatArray
    geom_lon: FloatArray
    geom_lat: FloatArray
    out_ptr: IntArray
    out_edge: Int32Array
    seg_start: IntArray
    seg_edge: Int32Array
    banned_in: Int32Array
    banned_out: Int32Array
    banned_seq_ptr: IntArray
    banned_seq_edge: Int32Array
    name_way_id: IntArray
    name_ptr: IntArray
    name_utf8: npt.NDArray[np.uint8]

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            getattr(self, field.name).flags.writeable = False

    def __reduce__(self) -> tuple[type[NetworkArrays], tuple[npt.NDArray[Any], ...]]:
        # through the constructor, so that unpickled arrays are read-only too
        return NetworkArrays, tuple(getattr(self, f.name) for f in dataclasses.fields(self))

    @property
    def n_nodes(self) -> int:
        """Number of graph nodes."""
        return len(self.node_osm_id)

    @property
    def n_edges(self) -> int:
        """Number of directed edges."""
        return len(self.edge_u)

    def save(self, path: Path) -> dict[str, list[Any]]:
        """
        Write every array into one binary file; return its layout.

        The layout maps each array's name to ``[dtype, shape, byte offset]``; arrays start on
        64-byte boundaries so that :meth:`load` can hand out aligned views of one mapping.
        """
        layout: dict[str, list[Any]] = {}
        offset = 0
        with path.open("wb") as handle:
            for field in dataclasses.fields(self):
                array = np.ascontiguousarray(getattr(self, field.name))
                pad = -offset % 64
                handle.write(b"\0" * pad)
                offset += pad
                layout[field.name] = [array.dtype.str, list(array.shape), offset]
                handle.write(array.tobytes())
                offset += array.nbytes
        return layout

    @classmethod
    def load(cls, path: Path, layout: dict[str, list[Any]], *, mmap: bool = True) -> NetworkArrays:
        """
        Read the arrays written by :meth:`save`: views of one read-only memory mapping.

        Raises
        ------
        ValueError
            The layout does not describe this class's arrays, or the file is too short.
        """
        names = {field.name for field in dataclasses.fields(cls)}
        if set(layout) != names:
            msg = f"layout lists {sorted(set(layout) ^ names)} wrongly"
            raise ValueError(msg)
        buffer: np.ndarray = (
            np.memmap(path, dtype=np.uint8, mode="r") if mmap else np.fromfile(path, dtype=np.uint8)
        )
        advise_huge_pages(buffer)  # 2 MB pages where possible (not a mapping: nothing)
        values = {}
        for name, (dtype, shape, offset) in layout.items():
            dt = np.dtype(dtype)
            count = int(np.prod(shape))
            if offset + count * dt.itemsize > len(buffer):
                msg = f"array {name} runs past the end of {path.name}"
                raise ValueError(msg)
            values[name] = np.ndarray(tuple(shape), dtype=dt, buffer=buffer, offset=offset)
        return cls(**values)
