"""Road networks: OSM extracts compiled into a routable, R-tree indexed directed graph."""

from __future__ import annotations

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
from roadnets.graph_import import from_graph
from roadnets.loader import DEFAULT_NETWORK, default_network_path, load
from roadnets.network import NetworkInfo, RoadNetwork
from roadnets.routes import DEFAULT_UTURN_COST_M, EdgeRoutes, RouteTable
from roadnets.routing import PathTable
from roadnets.spatial import EdgeHits
from roadnets.turns import TurnGraph

__all__ = [
    "DEFAULT_NETWORK",
    "DEFAULT_UTURN_COST_M",
    "ROAD_CLASSES",
    "CacheError",
    "EdgeHits",
    "EdgeRoutes",
    "InvalidNetworkSourceError",
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
    "default_network_path",
    "from_graph",
    "load",
]
