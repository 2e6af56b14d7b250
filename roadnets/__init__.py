"""
Road networks: OSM extracts compiled into a routable, R-tree indexed directed graph.

``import roadnets`` loads only what opening a cached network needs (numpy and this package);
libosmium, pyproj, libspatialindex, the numba routers, networkx and shapely are imported when
first used (:func:`from_graph`, the router classes and the CRS work import theirs on access).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from roadnets.arrays import NetworkArrays
from roadnets.drivable import ROAD_CLASSES
from roadnets.errors import (
    CacheError,
    InvalidNetworkSourceError,
    MapMatchError,
    NetworkReopenError,
    NetworkSourceNotFoundError,
    NetworkTooWideError,
    NoDrivableRoadsError,
    RoadNetworkError,
)
from roadnets.loader import DEFAULT_NETWORK, default_network_path, load
from roadnets.names import WayNames
from roadnets.network import NetworkInfo, RoadNetwork
from roadnets.runtime import KernelWarmup, freeze_after_load, warm_kernels
from roadnets.spatial import EdgeHits
from roadnets.turns import DEFAULT_UTURN_COST_M, TurnGraph

if TYPE_CHECKING:
    from roadnets.graph_import import from_graph
    from roadnets.routes import EdgeRoutes, RouteTable
    from roadnets.routing import PathTable

#: Public names whose modules import heavy libraries, imported on first access.
_LAZY = {
    "from_graph": "roadnets.graph_import",
    "EdgeRoutes": "roadnets.routes",
    "RouteTable": "roadnets.routes",
    "PathTable": "roadnets.routing",
}

__all__ = [
    "DEFAULT_NETWORK",
    "DEFAULT_UTURN_COST_M",
    "ROAD_CLASSES",
    "CacheError",
    "EdgeHits",
    "EdgeRoutes",
    "InvalidNetworkSourceError",
    "KernelWarmup",
    "MapMatchError",
    "NetworkArrays",
    "NetworkInfo",
    "NetworkReopenError",
    "NetworkSourceNotFoundError",
    "NetworkTooWideError",
    "NoDrivableRoadsError",
    "PathTable",
    "RoadNetwork",
    "RoadNetworkError",
    "RouteTable",
    "TurnGraph",
    "WayNames",
    "default_network_path",
    "freeze_after_load",
    "from_graph",
    "load",
    "warm_kernels",
]


def __getattr__(name: str) -> object:
    module = _LAZY.get(name)
    if module is None:
        msg = f"module 'roadnets' has no attribute {name!r}"
        raise AttributeError(msg)
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value
