"""
Process-level helpers for long-running programs: compile the kernels ahead, freeze the heap.

Kernels
-------
The routers are numba kernels compiled on first use and kept in numba's on-disk cache
(``cache=True``; ``__pycache__`` beside the sources, else ``$NUMBA_CACHE_DIR``). On a fresh
install the first route search therefore spends seconds compiling; later processes load the
machine code from the cache in milliseconds. :func:`warm_kernels` runs every roadnets kernel
once on a tiny network built in memory, with the same argument types a loaded network passes
(its arrays are read-only like every network's, see :class:`~roadnets.arrays.NetworkArrays`),
so that ``mapmatch network build``, ``make demo`` or a service start pays the compilation
instead of the first request, and says so.

Garbage collection
------------------
A loaded network is a few dozen Python objects over numpy arrays (the networkx view is built
only when ``net.graph`` is read), so it adds nothing to a collection's work. What a full
collection does walk are the ~100k objects of the imported libraries (numba, pandas, pyproj,
FastAPI ...): 40-70 ms per full pass, which in a service lands inside a request. Those objects
live as long as the process; :func:`freeze_after_load` moves everything alive into the
permanent generation (:func:`gc.freeze`) so later collections skip it. Call it once, after the
imports and the networks are loaded and the kernels warmed, and before serving:

- the service: at the end of start-up (after its networks are loaded), before accepting
  requests;
- a batch run: in the parent after loading the network and before starting workers (a
  forked worker then also shares the frozen pages instead of touching them), and in each
  worker after its initialiser loaded the network;
- a notebook or a script matching many traces: after ``roadnets.load``.
"""

from __future__ import annotations

import gc
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from roadnets.network import RoadNetwork

__all__ = ["KernelWarmup", "freeze_after_load", "warm_kernels"]


@dataclass(frozen=True, slots=True)
class KernelWarmup:
    """
    What :func:`warm_kernels` did.

    Attributes
    ----------
    seconds
        Time spent, compiling or loading machine code included.
    compiled
        Kernel signatures compiled now (0 once numba's on-disk cache holds them all).
    loaded
        Kernel signatures loaded from numba's on-disk cache.
    """

    seconds: float
    compiled: int
    loaded: int

    def describe(self) -> str:
        """
        One line for a CLI.

        Examples
        --------
        >>> KernelWarmup(4.2, 6, 0).describe()
        'compiled 6 routing kernels in 4.2 s (once per install)'
        >>> KernelWarmup(0.03, 0, 6).describe()
        'routing kernels ready (6 from the compile cache, 0.03 s)'
        """
        if self.compiled:
            return (
                f"compiled {self.compiled} routing kernels in {self.seconds:.1f} s "
                "(once per install)"
            )
        if self.loaded:
            cached = f"{self.loaded} from the compile cache"
            return f"routing kernels ready ({cached}, {self.seconds:.2f} s)"
        return "routing kernels ready (already in this process)"


def _dispatchers() -> list[object]:
    """The kernels called from Python (the others are compiled into them)."""
    from roadnets import names_kernel, record_index, route_search, routing, spatial_kernels

    return [
        names_kernel.gather_names,
        names_kernel.gather_edges,
        record_index._fill,
        routing._bounded_dijkstra_many,
        route_search.search_many,
        route_search.route_pairs_kernel,
        route_search.table_records,
        route_search.gather,
        route_search.table_routes,
        spatial_kernels.nearby_kernel,
        spatial_kernels.path_polyline_kernel,
        spatial_kernels.path_lonlat_kernel,
    ]


def _counts() -> tuple[int, int]:
    misses = hits = 0
    for dispatcher in _dispatchers():
        stats = dispatcher.stats  # type: ignore[attr-defined]
        misses += sum(stats.cache_misses.values())
        hits += sum(stats.cache_hits.values())
    return misses, hits


def _tiny_network() -> RoadNetwork:
    """A 3 x 3 block grid with one-way streets and both kinds of turn restriction."""
    from roadnets.compile import choose_projector, compile_network
    from roadnets.network import RoadNetwork
    from roadnets.osm_reader import OsmExtract, OsmWay, TurnRestriction

    step = 0.001  # degrees, about 100 m
    ways = []
    for k in range(3):
        row = np.array([k * 3 + j + 1 for j in range(3)], dtype=np.int64)
        col = np.array([j * 3 + k + 1 for j in range(3)], dtype=np.int64)
        for way_id, ids in ((10 + k, row), (20 + k, col)):
            lon = 7.42 + step * ((ids - 1) % 3)
            lat = 43.73 + step * ((ids - 1) // 3)
            tags = {"highway": "residential", "name": f"street {way_id}"}
            if way_id == 11:
                tags["oneway"] = "yes"
            ways.append(OsmWay(way_id, ids, lon.astype(float), lat.astype(float), tags))
    restrictions = [
        TurnRestriction(from_way=10, via_node=2, to_way=21, only=False),
        TurnRestriction(from_way=20, via_node=None, to_way=22, only=False, via_ways=(11,)),
    ]
    extract = OsmExtract(ways, restrictions, 0)
    projector = choose_projector(extract, "<warm-up grid>")
    arrays = compile_network(extract, projector)
    return RoadNetwork("warm-up", "<warm-up grid>", "", arrays, projector)


def warm_kernels() -> KernelWarmup:
    """
    Compile (or load from numba's cache) every roadnets kernel, before it is needed.

    Runs the node router, the edge router (pairs and tables, lengths and caller costs), the
    table look-ups, the projection both ways, the R-tree query, the street names' gather and the
    edges' attributes gather once each on a 3 x 3 block network built in memory.
    Cheap when the kernels are already in numba's on-disk cache; seconds on a fresh install.

    Returns
    -------
    KernelWarmup
        Time spent and how many kernel signatures were compiled or loaded.
    """
    from roadnets.names import edge_records

    started = time.perf_counter()
    misses, hits = _counts()
    net = _tiny_network()
    a = net.arrays
    edges = np.arange(a.n_edges)
    net.shortest_paths(np.arange(a.n_nodes), 1000.0)
    routes = net.edge_routes(edges, edges[::-1], 1000.0)
    table = net.route_table(edges[:3], 1000.0)
    table.lookup(edges[:3], edges[-3:])
    net.edge_routes(
        edges,
        edges[::-1],
        1000.0,
        edge_cost=a.edge_length_m / a.edge_speed_mps,
        turn_cost=np.zeros(len(net.turns.trans_to)),
    )
    routes.table.lookup(edges[:2], edges[:2])
    x, y = net.project(np.array([7.4205]), np.array([43.7305]))
    net.unproject(x, y)
    net.nearby_edges(x, y, 50.0)
    net.path_polyline(edges[:2], np.zeros(2), a.edge_length_m[:2])
    net.path_lonlat(edges[:2], np.zeros(2), a.edge_length_m[:2])
    net.way_names.names_of(a.edge_way_id[:2])
    edge_records(a, net.way_names, edges[:2])
    net.precompute_routes(1000.0)
    net.edge_routes(edges, edges[::-1], 500.0)  # answered from the table
    misses_now, hits_now = _counts()
    return KernelWarmup(time.perf_counter() - started, misses_now - misses, hits_now - hits)


def freeze_after_load() -> int:
    """
    Collect once, then move every object alive into the permanent generation.

    Later collections no longer walk the libraries' and the networks' objects (see the module
    docstring for where to call it). Objects created afterwards are collected as usual; the
    frozen ones are never freed (they lived as long as the process anyway).

    Returns
    -------
    int
        Number of objects frozen (``gc.get_freeze_count()``).
    """
    gc.collect()
    gc.freeze()
    return gc.get_freeze_count()
