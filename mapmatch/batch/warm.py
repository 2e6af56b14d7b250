"""
Load the compiled kernels once in the local pool's fork server, before any worker is forked.

The first match of a fresh process loads (or compiles) the matcher's and the router's
kernels: about a second, more when several workers do it at once. The pool's fork server
imports this module (``set_forkserver_preload``): :func:`warm_up` matches a short trace on a
block of four streets built in memory and writes its GeoJSON, so every worker forked from
the server starts with the kernels loaded. A failed warm-up changes nothing (the workers
load them themselves).
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import pickle
import time

__all__ = ["WARMUP_S", "block_graph", "warm_up"]


def block_graph() -> object:
    """A square block of two-way residential streets, about 100 m a side (a networkx graph)."""
    import networkx as nx

    G: nx.MultiDiGraph[int] = nx.MultiDiGraph(crs="EPSG:4326", name="warm-up block")
    corners = {
        1: (7.4200, 43.7300),
        2: (7.4212, 43.7300),
        3: (7.4212, 43.7309),
        4: (7.4200, 43.7309),
    }
    for node, (x, y) in corners.items():
        G.add_node(node, x=x, y=y)
    for u, v in ((1, 2), (2, 3), (3, 4), (4, 1)):
        G.add_edge(u, v, highway="residential")
        G.add_edge(v, u, highway="residential")
    return G


def warm_up() -> float:
    """Match a short trace on an in-memory block once; the seconds it took (0 on failure)."""
    started = time.perf_counter()
    quiet = logging.getLogger("mapmatch")
    level = quiet.level
    quiet.setLevel(logging.ERROR)  # the warm-up's distance check is of no interest
    try:
        with contextlib.suppress(Exception):
            import roadnets
            from mapmatch.export import geojson_bytes
            from mapmatch.matcher import match
            from mapmatch.trace import Trace

            net = roadnets.from_graph(block_graph(), network_id="warm-up")
            lon = [7.4201, 7.4206, 7.4211, 7.4212, 7.4212]
            lat = [43.73001, 43.73002, 43.73001, 43.7304, 43.7308]
            trace = Trace(time=[0, 5, 10, 15, 20], lon=lon, lat=lat, heading=[90, 90, 90, 0, 0])
            result = match(trace, net)
            geojson_bytes(result)  # the writer's number kernel too
            # a result sent back by a worker process carries its segments' attributes and
            # lines, not the network: its GeoJSON columns come from a kernel of their own
            geojson_bytes(pickle.loads(pickle.dumps(result)))
            # every set of optional columns, and no times: numba compiles a variant of some
            # kernels for each (the travel terms, per-fix accuracy, a file with no time
            # column), the assembly's taking a minute on a slow machine
            columns: dict[str, list[float]] = {
                "heading": [90.0, 90.0, 90.0, 0.0, 0.0],
                "speed": [4.0, 4.0, 4.0, 4.0, 4.0],
                "accuracy": [4.0, 4.0, 4.0, 4.0, 4.0],
                "odometer": [0.0, 40.0, 80.0, 110.0, 150.0],
            }
            for given in itertools.product((False, True), repeat=len(columns)):
                chosen = {k: v for (k, v), on in zip(columns.items(), given, strict=True) if on}
                given_trace = Trace(
                    time=[0, 5, 10, 15, 20],
                    lon=lon,
                    lat=lat,
                    heading=chosen.get("heading"),
                    speed=chosen.get("speed"),
                    accuracy=chosen.get("accuracy"),
                    odometer=chosen.get("odometer"),
                )
                geojson_bytes(match(given_trace, net))
            geojson_bytes(match(Trace(lon=lon, lat=lat), net))
            return time.perf_counter() - started
        return 0.0
    finally:
        quiet.setLevel(level)


#: Seconds the warm-up took when this module was imported.
WARMUP_S = warm_up()
