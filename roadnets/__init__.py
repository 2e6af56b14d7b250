"""Road networks: OSM extracts compiled into a routable, R-tree indexed directed graph."""

from __future__ import annotations

from roadnets.errors import (
    CacheError,
    InvalidNetworkSourceError,
    MapMatchError,
    NetworkSourceNotFoundError,
    NoDrivableRoadsError,
    RoadNetworkError,
)

__all__ = [
    "CacheError",
    "InvalidNetworkSourceError",
    "MapMatchError",
    "NetworkSourceNotFoundError",
    "NoDrivableRoadsError",
    "RoadNetworkError",
]
