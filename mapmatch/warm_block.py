"""
What the warm-ups match on: a block of four streets built in memory, and a drive around it.

numba compiles the matcher's kernels per install, not per network, so a tiny network will
do: the whole-trace warm-up (:mod:`mapmatch.batch.warm`, run by ``mapmatch network build``
and the batch's fork server) and the live one (:mod:`mapmatch.online.warm`) both drive here.
"""

from __future__ import annotations

import contextlib
import logging
import time
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Callable

    from roadnets import RoadNetwork

__all__ = ["BLOCK_FIXES", "OPTIONAL_COLUMNS", "block_graph", "block_network", "timed_quietly"]

#: The optional columns of a fix, each on or off in one of the warm-ups' matches.
OPTIONAL_COLUMNS = ("heading", "speed", "accuracy", "odometer")

#: A 20 s drive along two sides of :func:`block_graph`, every column given.
BLOCK_FIXES: tuple[dict[str, float], ...] = tuple(
    {"time": 5.0 * i, "lon": lon, "lat": lat, "heading": heading, "speed": 4.0,
     "accuracy": 4.0, "odometer": odometer}
    for i, (lon, lat, heading, odometer) in enumerate((
        (7.4201, 43.73001, 90.0, 0.0),
        (7.4206, 43.73002, 90.0, 40.0),
        (7.4211, 43.73001, 90.0, 80.0),
        (7.4212, 43.7304, 0.0, 110.0),
        (7.4212, 43.7308, 0.0, 150.0),
    ))
)  # fmt: skip


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


def block_network() -> RoadNetwork:
    """:func:`block_graph` as a road network (id ``warm-up``)."""
    import roadnets

    return roadnets.from_graph(block_graph(), network_id="warm-up")


def timed_quietly(warm_up: Callable[[], object]) -> float:
    """
    Run ``warm_up`` with the matcher's warnings off; the seconds it took, 0 when it raised.

    A failed warm-up changes nothing but the time of the first real match (which then
    compiles), so it is never an error; the distance check's warnings about the block's
    made-up odometers are of no interest.
    """
    started = time.perf_counter()
    quiet = logging.getLogger("mapmatch")
    level = quiet.level
    quiet.setLevel(logging.ERROR)
    try:
        with contextlib.suppress(Exception):
            warm_up()
            return time.perf_counter() - started
        return 0.0
    finally:
        quiet.setLevel(level)
