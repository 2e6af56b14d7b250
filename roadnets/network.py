"""The road network object users hold: arrays, spatial index, routing, geometry, graph view.

(Over 400 lines on purpose: it is the object users hold; its methods are thin and delegate to
the modules beside it.)
"""

from __future__ import annotations

import dataclasses
import threading
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from roadnets.drivable import ROAD_CLASSES
from roadnets.names import WayNames
from roadnets.route_store import DEFAULT_BUDGET_MB, TableKeeper
from roadnets.spatial import (
    EdgeHits,
    PackedTree,
    build_packed_tree,
    build_rtree,
    query_packed,
    rtree_rank,
)
from roadnets.turns import DEFAULT_UTURN_COST_M, TurnGraph, build_turn_graph

if TYPE_CHECKING:
    from collections.abc import Callable

    import networkx as nx
    from rtree.index import Index

    from roadnets.arrays import NetworkArrays
    from roadnets.projection import Projector
    from roadnets.routes import EdgeRoutes, RouteTable
    from roadnets.routing import PathTable

# The routers (numba), networkx and shapely are imported where they are first used: loading a
# cached network and matching on it needs none of them but the routers.

__all__ = ["NetworkInfo", "RoadNetwork"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


@dataclass(frozen=True, slots=True)
class NetworkInfo:
    """Summary figures of a network (what ``mapmatch network info`` prints)."""

    network_id: str
    source: str
    crs: str
    nodes: int
    edges: int
    road_km_by_class: dict[str, float]
    oneway_share: float
    bbox: tuple[float, float, float, float]
    turn_restrictions: int
    clipped_ways: int
    from_cache: bool
    load_s: float
    #: Banned edge sequences of via-way restrictions (``turn_restrictions`` counts banned pairs).
    banned_sequences: int = 0

    @property
    def road_km(self) -> float:
        """Length of road, each two-way road counted once, km."""
        return sum(self.road_km_by_class.values())


@dataclass(eq=False, repr=False)
class RoadNetwork:
    """
    A compiled, routable, spatially indexed directed road network.

    Safe to share between threads: the R-tree (libspatialindex, not thread-safe itself) is
    queried under a lock; :meth:`nearby_edges` uses the packed tree (:attr:`segment_tree`,
    read-only arrays, no lock); everything else is read-only arrays.

    Build one with :func:`roadnets.load`. Planar work happens in :attr:`crs` (a transverse
    Mercator centred on the network, see :mod:`roadnets.projection`); lengths and offsets along
    edges are geodesic; positions given to and returned from users are WGS84 lon/lat.

    Pickling (``multiprocessing``, ``joblib``, ``dask.distributed``): a network that has a cache
    entry (every :func:`roadnets.load` with ``use_cache=True``) pickles as its id, source, digest
    and cache entry path, a few hundred bytes; unpickling re-opens (memory-maps) the entry, so
    every worker on the machine shares one copy of the arrays through the page cache, and the
    R-tree, turn graph and locks are built again there on first use. Where the entry is gone
    the worker compiles the unchanged source again into the same cache folder
    (:func:`roadnets.loader.reopen`; :class:`~roadnets.errors.NetworkReopenError` when it cannot).
    A network without an entry (``use_cache=False``, :func:`roadnets.from_graph`) pickles its
    arrays instead (about the size of its cache entry). Tables made by :meth:`precompute_paths`
    and :meth:`precompute_routes` travel with the pickle.
    """

    network_id: str
    source: str
    source_sha256: str
    arrays: NetworkArrays
    projector: Projector
    clipped_ways: int = 0
    from_cache: bool = False
    load_s: float = 0.0
    #: The cache entry folder the arrays were read from or written to (``None``: not cached).
    cache_entry: str | None = None
    precomputed: PathTable | None = None
    precomputed_bound_m: float = 0.0
    precomputed_routes: RouteTable | None = None
    #: Largest route table for sparse traces made without being asked, MB (0: never); see
    #: :meth:`sparse_route_table`.
    route_table_budget_mb: float = DEFAULT_BUDGET_MB
    _rtree_lock: threading.Lock = field(default_factory=threading.Lock)
    _route_keeper: TableKeeper = field(default_factory=TableKeeper)

    def __repr__(self) -> str:
        a = self.arrays
        lon0, lat0, lon1, lat1 = self.bbox
        return (
            f"<RoadNetwork {self.network_id!r} from {Path(self.source).name!r}: "
            f"{a.n_nodes:,} nodes, {a.n_edges:,} edges, crs {self.projector.label}, "
            f"bbox ({lon0:.5f}, {lat0:.5f}, {lon1:.5f}, {lat1:.5f})"
            f"{', cached' if self.cache_entry else ''}>"
        )

    def __reduce__(self) -> tuple[Callable[[dict[str, Any]], RoadNetwork], tuple[dict[str, Any]]]:
        keep: tuple[str, ...] = (
            "precomputed",
            "precomputed_bound_m",
            "precomputed_routes",
            "route_table_budget_mb",
        )
        if self.cache_entry is not None:
            keep = ("network_id", "source", "source_sha256", "cache_entry", *keep)
        else:
            keep = tuple(f.name for f in dataclasses.fields(self) if not f.name.startswith("_"))
        state = {name: getattr(self, name) for name in keep}
        if self._route_keeper.stored:  # the other process maps the cache entry's own file
            state["precomputed_routes"] = None
        return _unpickle, (state,)

    @cached_property
    def way_names(self) -> WayNames:
        """``{way id: name}`` (``name``, else ``ref``), read from the arrays like a dict."""
        a = self.arrays
        return WayNames(a.name_way_id, a.name_ptr, a.name_utf8)

    @property
    def crs(self) -> str:
        """The projected CRS of the arrays (a PROJ string pyproj reads)."""
        return self.projector.crs

    @cached_property
    def rtree(self) -> Index:
        """R-tree over the segments of every road geometry (bulk loaded on first use)."""
        return build_rtree(self.arrays)

    @cached_property
    def segment_tree(self) -> PackedTree:
        """
        The same segments in a packed R-tree queried from compiled code (the matcher's index).

        Built on first use, with :attr:`rtree`'s order of the segments for ties (see
        :mod:`roadnets.spatial`), so both give the same hits.
        """
        with self._rtree_lock:
            rank = rtree_rank(self.rtree, len(self.arrays.seg_start))
        return build_packed_tree(self.arrays, rank)

    def project(self, lon: FloatArray, lat: FloatArray) -> tuple[FloatArray, FloatArray]:
        """WGS84 lon/lat degrees to x/y metres in :attr:`crs`."""
        return self.projector.forward(lon, lat)

    def unproject(self, x: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray]:
        """x/y metres in :attr:`crs` to WGS84 lon/lat degrees."""
        return self.projector.inverse(x, y)

    def nearby_edges(
        self,
        x: FloatArray,
        y: FloatArray,
        radius_m: float | FloatArray,
        *,
        max_per_point: int | None = None,
    ) -> EdgeHits:
        """
        Directed edges within ``radius_m`` of each point, projected, nearest first.

        Parameters
        ----------
        x, y
            Points in metres (:attr:`crs`).
        radius_m
            One radius, or one per point, metres.
        max_per_point
            Keep at most this many directed edges per point.
        """
        radius = np.asarray(radius_m, dtype=np.float64)
        return query_packed(
            self.segment_tree, self.arrays, x, y, radius, max_per_point=max_per_point
        )

    def shortest_paths(
        self, sources: npt.NDArray[np.integer[Any]], bounds_m: float | FloatArray
    ) -> PathTable:
        """
        Bounded shortest paths from each source node (see :func:`shortest_path_table`).

        Answered from the table of :meth:`precompute_paths` when every bound fits in it.
        """
        from roadnets.routing import shortest_path_table

        bounds = np.asarray(bounds_m, dtype=np.float64)
        if self.precomputed is not None and bool(np.all(bounds <= self.precomputed_bound_m)):
            return self.precomputed
        return shortest_path_table(self.arrays, sources, bounds)

    def precompute_paths(self, bound_m: float) -> PathTable:
        """
        Shortest paths from every node to every node within ``bound_m``, kept for reuse.

        An upper-bounded origin-destination table, as FMM's UBODT; :meth:`shortest_paths`
        answers from it whenever the bounds asked for fit.

        Worth it for batch matching of sparse traces on a small network; its size grows with
        the number of nodes times the nodes within reach, so measure first
        (``benchmarks/bench_match.py`` reports both ways).
        """
        from roadnets.routing import shortest_path_table

        table = shortest_path_table(
            self.arrays, np.arange(self.arrays.n_nodes), np.asarray(bound_m, dtype=np.float64)
        )
        self.precomputed, self.precomputed_bound_m = table, float(bound_m)
        return table

    @cached_property
    def turns(self) -> TurnGraph:
        """The turn graph: legal moves between edges, every turn restriction compiled in."""
        return build_turn_graph(self.arrays)

    def edge_routes(
        self,
        from_edges: npt.NDArray[np.integer[Any]],
        to_edges: npt.NDArray[np.integer[Any]],
        bounds_m: float | FloatArray,
        *,
        uturn_cost_m: float = DEFAULT_UTURN_COST_M,
        edge_cost: FloatArray | None = None,
        turn_cost: FloatArray | None = None,
    ) -> EdgeRoutes:
        """
        Shortest legal route from the end of each ``from`` edge to the start of its ``to`` edge.

        Edge-based, obeying every turn restriction; U-turns at nodes allowed but each one
        costs ``uturn_cost_m`` in the search (see :mod:`roadnets.routes`). One search per
        distinct ``from`` edge with the largest bound of its pairs, stopping once its ``to``
        edges are reached; answered from the table of :meth:`precompute_routes` instead when
        it was built with the same U-turn cost and every bound fits in it.

        Parameters
        ----------
        from_edges, to_edges
            Edge pairs (same length).
        bounds_m
            One bound or one per pair: metres of route length plus U-turn costs.
        uturn_cost_m
            Search-key cost of a U-turn, metres (not added to the reported length).
        edge_cost, turn_cost
            Search costs other than lengths (see :func:`roadnets.routes.route_pairs`).
        """
        from roadnets.routes import route_pairs

        table = self.precomputed_routes
        bounds = np.asarray(bounds_m, dtype=np.float64)
        usable = (
            table is not None
            and not table.weighted
            and edge_cost is None
            and turn_cost is None
            and table.uturn_cost_m == uturn_cost_m
            and bool(np.all(bounds <= table.bounds_m.min(initial=np.inf)))
        )
        return route_pairs(
            self.arrays,
            self.turns,
            from_edges,
            to_edges,
            bounds,
            uturn_cost_m=uturn_cost_m,
            edge_cost=edge_cost,
            turn_cost=turn_cost,
            table=table if usable else None,
        )

    def route_table(
        self,
        sources: npt.NDArray[np.integer[Any]],
        bounds_m: float | FloatArray,
        *,
        uturn_cost_m: float = DEFAULT_UTURN_COST_M,
        edge_cost: FloatArray | None = None,
        turn_cost: FloatArray | None = None,
    ) -> RouteTable:
        """
        Every best legal route from each source edge within its bound (complete searches).

        See :func:`roadnets.routes.route_table`; ``edge_cost`` and ``turn_cost`` replace the
        lengths as search costs (for a fastest route with turn penalties, say).
        """
        from roadnets.routes import route_table

        return route_table(
            self.arrays,
            self.turns,
            sources,
            bounds_m,
            uturn_cost_m=uturn_cost_m,
            edge_cost=edge_cost,
            turn_cost=turn_cost,
        )

    def precompute_routes(
        self, bound_m: float, *, uturn_cost_m: float = DEFAULT_UTURN_COST_M
    ) -> RouteTable:
        """
        Shortest legal routes from every edge to every edge within ``bound_m``, kept for reuse.

        The edge-based counterpart of :meth:`precompute_paths` (restrictions obeyed, U-turns
        counted); :meth:`edge_routes` answers from it whenever the bounds asked for fit.
        Its size grows with the edges times the edges within reach: measure first
        (``benchmarks/bench_routing.py`` reports it).
        """
        from roadnets.route_store import build_table

        table = build_table(self.arrays, self.turns, float(bound_m), uturn_cost_m=uturn_cost_m)
        self.precomputed_routes = table
        return table

    def sparse_route_table(self) -> RouteTable | None:
        """
        The route table sparse traces are matched with, looked for once per process.

        The one :meth:`precompute_routes` made; else the one stored in the cache entry
        (memory-mapped); else one of every edge's routes within
        :data:`~roadnets.route_store.ROUTE_TABLE_BOUND_M` is built when its estimated size
        fits :attr:`route_table_budget_mb`, or within the longest shorter bound that fits
        (:func:`~roadnets.route_store.fitted_bound`), and stored in the cache entry. ``None``
        when not even the shortest fits; :attr:`route_table_note` says why. The matcher asks
        for it in the background (:meth:`request_route_table`) on its first sparse trace;
        ``mapmatch network build`` asks here, so that the first sparse match finds it ready.
        """
        return self._route_keeper.ensure(self)

    def request_route_table(self) -> None:
        """Start :meth:`sparse_route_table` in a background thread (once) and return."""
        self._route_keeper.request(self)

    @property
    def route_table_requested(self) -> bool:
        """Whether this process has looked for the sparse-trace route table (or is looking)."""
        return self._route_keeper.started

    @property
    def route_table_note(self) -> str:
        """What became of the sparse-trace route table (read, built, too large ...)."""
        return self._route_keeper.note

    @cached_property
    def kernel_geometry(self) -> tuple[FloatArray | IntArray, ...]:
        """
        The arrays the compiled path kernels read, in their order.

        ``(edge_len, geom_ptr, geom_x, geom_y, geom_cum, vertex_pos)``, what
        :func:`~roadnets.spatial_kernels.point_on_edge` and the kernels built on it take
        (``vertex_pos``: each vertex's distance along the concatenation of all edges).
        """
        a = self.arrays
        return (
            a.edge_length_m,
            a.edge_geom_ptr,
            a.geom_x,
            a.geom_y,
            a.geom_cum_m,
            self._vertex_position,
        )

    @cached_property
    def _vertex_position(self) -> FloatArray:
        """Each vertex's distance along the concatenation of all edges (a monotone key)."""
        a = self.arrays
        base = np.concatenate(([0.0], np.cumsum(a.edge_length_m + 1.0)[:-1]))
        sizes = np.diff(a.edge_geom_ptr)
        return np.asarray(a.geom_cum_m + np.repeat(base, sizes), dtype=np.float64)

    def segment_at(self, edge: IntArray, offset_m: FloatArray) -> IntArray:
        """
        Index of the first vertex of the geometry segment holding each offset, vectorised.

        Offsets are clipped to their edge, so the segment is always one of the edge's own.
        """
        a = self.arrays
        edge = np.asarray(edge, dtype=np.int64)
        offset = np.clip(np.asarray(offset_m, dtype=np.float64), 0.0, a.edge_length_m[edge])
        base = self._vertex_position[a.edge_geom_ptr[edge]]
        i = np.searchsorted(self._vertex_position, base + offset, side="right") - 1
        return np.asarray(
            np.clip(i, a.edge_geom_ptr[edge], a.edge_geom_ptr[edge + 1] - 2), dtype=np.int64
        )

    def point_on_edge(self, edge: IntArray, offset_m: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Positions (metres) at ``offset_m`` along each ``edge`` (clipped to it), vectorised."""
        from roadnets.spatial_kernels import points_on_edges

        edges, offsets = np.broadcast_arrays(
            np.asarray(edge, dtype=np.int64), np.asarray(offset_m, dtype=np.float64)
        )
        edge = np.ascontiguousarray(edges).ravel()
        offset = np.ascontiguousarray(offsets).ravel()
        if len(edge) and (edge.min() < 0 or edge.max() >= self.arrays.n_edges):
            bad = int(edge[(edge < 0) | (edge >= self.arrays.n_edges)][0])
            msg = f"edge {bad} is out of range for a network of {self.arrays.n_edges:,} edges"
            raise IndexError(msg)
        x, y = points_on_edges(edge, offset, *self.kernel_geometry)
        return np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)

    def edge_polyline(
        self, edge: int, start_m: float, end_m: float
    ) -> tuple[FloatArray, FloatArray]:
        """Vertices (metres) of ``edge`` between two offsets along it, ends interpolated."""
        a = self.arrays
        lo, hi = int(a.edge_geom_ptr[edge]), int(a.edge_geom_ptr[edge + 1])
        cum = a.geom_cum_m[lo:hi]
        inner = np.flatnonzero((cum > start_m) & (cum < end_m)) + lo
        ends_x, ends_y = self.point_on_edge(np.array([edge, edge]), np.array([start_m, end_m]))
        x = np.concatenate(([ends_x[0]], a.geom_x[inner], [ends_x[1]]))
        y = np.concatenate(([ends_y[0]], a.geom_y[inner], [ends_y[1]]))
        return x, y

    def path_polyline(
        self, edge: IntArray, start_m: FloatArray, end_m: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """
        Vertices (metres) of a path of edge stretches, in order, joints not repeated.

        Stretch ``i`` runs along ``edge[i]`` from ``start_m[i]`` to ``end_m[i]``; its ends are
        interpolated, the edge's vertices between them kept. One compiled pass
        (:func:`~roadnets.spatial_kernels.path_polyline_kernel`).
        """
        from roadnets.spatial_kernels import path_polyline_kernel

        x, y = path_polyline_kernel(
            np.ascontiguousarray(edge, dtype=np.int64),
            np.ascontiguousarray(start_m, dtype=np.float64),
            np.ascontiguousarray(end_m, dtype=np.float64),
            self.kernel_geometry,
        )
        return np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)

    def path_lonlat(
        self, edge: IntArray, start_m: FloatArray, end_m: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """
        :meth:`path_polyline`'s vertices in WGS84 lon/lat degrees (:meth:`unproject`).

        One compiled call for a network in a :meth:`~roadnets.projection.Projector.local` CRS
        (:func:`~roadnets.spatial_kernels.path_lonlat_kernel`), the same numbers: the network's
        vertices are read from ``geom_lon``/``geom_lat``, only the points between them
        unprojected.
        """
        compiled = self.projector.compiled
        if compiled is None:
            return self.unproject(*self.path_polyline(edge, start_m, end_m))
        from roadnets.spatial_kernels import path_lonlat_kernel

        a = self.arrays
        lon, lat = path_lonlat_kernel(
            np.ascontiguousarray(edge, dtype=np.int64),
            np.ascontiguousarray(start_m, dtype=np.float64),
            np.ascontiguousarray(end_m, dtype=np.float64),
            self.kernel_geometry,
            (a.geom_lon, a.geom_lat),
            compiled.inverse_parameters,
        )
        return lon, lat

    def edge_osm_ids(self, edge: IntArray) -> tuple[IntArray, IntArray, IntArray]:
        """OSM ``(u, v, key)`` of each edge (u and v are OSM node ids)."""
        a = self.arrays
        edge = np.asarray(edge, dtype=np.int64)
        key = a.edge_key[edge].astype(np.int64)
        return a.node_osm_id[a.edge_u[edge]], a.node_osm_id[a.edge_v[edge]], key

    @cached_property
    def bbox(self) -> tuple[float, float, float, float]:
        """``(min_lon, min_lat, max_lon, max_lat)`` of the road geometry (every vertex)."""
        a = self.arrays
        lon, lat = a.geom_lon, a.geom_lat
        return float(lon.min()), float(lat.min()), float(lon.max()), float(lat.max())

    def info(self) -> NetworkInfo:
        """Counts, km of road by class, one-way share, bounding box."""
        a = self.arrays
        once = (a.edge_twin < 0) | (np.arange(a.n_edges) < a.edge_twin)
        km = np.bincount(
            a.edge_class[once], weights=a.edge_length_m[once], minlength=len(ROAD_CLASSES)
        )
        by_class = {
            name: round(float(k) / 1000.0, 3) for name, k in zip(ROAD_CLASSES, km, strict=True) if k
        }
        total = float(a.edge_length_m[once].sum())
        oneway = float(a.edge_length_m[once & a.edge_oneway].sum())
        return NetworkInfo(
            network_id=self.network_id,
            source=self.source,
            crs=self.crs,
            nodes=a.n_nodes,
            edges=a.n_edges,
            road_km_by_class=by_class,
            oneway_share=oneway / total if total else 0.0,
            bbox=self.bbox,
            turn_restrictions=len(a.banned_in),
            clipped_ways=self.clipped_ways,
            from_cache=self.from_cache,
            load_s=self.load_s,
            banned_sequences=len(a.banned_seq_ptr) - 1,
        )

    @cached_property
    def graph(self) -> nx.MultiDiGraph:  # type: ignore[type-arg]
        """
        The network as a networkx ``MultiDiGraph`` in osmnx's conventions.

        Node ids are OSM node ids with ``x``/``y`` (metres, :attr:`crs`) and ``lon``/``lat``;
        edges ``(u, v, key)`` carry ``osmid`` (way id), ``length`` (m), ``highway``,
        ``oneway``, ``speed_kph``, ``name``, ``geometry`` (shapely, metres) and ``index``
        (the edge's position in :attr:`arrays`). Built on first use.
        """
        import networkx as nx
        from shapely.geometry import LineString

        a = self.arrays
        G: nx.MultiDiGraph = nx.MultiDiGraph(crs=self.crs, name=self.network_id)  # type: ignore[type-arg]
        lon, lat = self.unproject(a.node_x, a.node_y)
        for i, osm in enumerate(a.node_osm_id.tolist()):
            G.add_node(osm, x=float(a.node_x[i]), y=float(a.node_y[i]), lon=lon[i], lat=lat[i])
        u, v, key = self.edge_osm_ids(np.arange(a.n_edges))
        for e in range(a.n_edges):
            lo, hi = a.edge_geom_ptr[e], a.edge_geom_ptr[e + 1]
            way = int(a.edge_way_id[e])
            G.add_edge(
                int(u[e]),
                int(v[e]),
                key=int(key[e]),
                index=e,
                osmid=way,
                length=float(a.edge_length_m[e]),
                highway=ROAD_CLASSES[a.edge_class[e]],
                oneway=bool(a.edge_oneway[e]),
                speed_kph=float(a.edge_speed_mps[e] * 3.6),
                name=self.way_names.get(way, ""),
                geometry=LineString(np.column_stack((a.geom_x[lo:hi], a.geom_y[lo:hi]))),
            )
        return G


def _unpickle(state: dict[str, Any]) -> RoadNetwork:
    """Rebuild a pickled :class:`RoadNetwork` (see its docstring)."""
    if "arrays" in state:
        return RoadNetwork(**state)
    from roadnets.loader import reopen

    net = reopen(state["network_id"], state["source"], state["source_sha256"], state["cache_entry"])
    net.precomputed, net.precomputed_bound_m = state["precomputed"], state["precomputed_bound_m"]
    net.precomputed_routes = state["precomputed_routes"]
    net.route_table_budget_mb = state["route_table_budget_mb"]
    return net
