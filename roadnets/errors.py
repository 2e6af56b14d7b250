"""The project's error tree.

The root lives here because every package may import :mod:`roadnets`; :mod:`mapmatch`
re-exports it. Every leaf also subclasses the matching built-in exception, so callers that
catch ``ValueError`` or ``OSError`` keep working.
"""

from __future__ import annotations


class MapMatchError(Exception):
    """Base for every error this project raises on purpose."""


class RoadNetworkError(MapMatchError):
    """A road network could not be loaded, compiled or cached."""


class NetworkSourceNotFoundError(RoadNetworkError, FileNotFoundError):
    """The OSM extract named by the caller does not exist."""

    def __init__(self, path: str) -> None:
        self.path = path
        msg = f"road network source {path!r} does not exist; check the path"
        super().__init__(msg)


class InvalidNetworkSourceError(RoadNetworkError, ValueError):
    """The file is not a readable OSM extract (wrong format, truncated or corrupt)."""

    def __init__(self, path: str, reason: str) -> None:
        self.path, self.reason = path, reason
        msg = f"road network source {path!r} is not a readable OSM extract: {reason}"
        super().__init__(msg)


class NoDrivableRoadsError(RoadNetworkError, ValueError):
    """The extract holds no drivable road."""

    def __init__(self, path: str) -> None:
        self.path = path
        msg = (
            f"road network source {path!r} has no drivable roads "
            "(motorway .. residential, service, *_link); is it the right extract?"
        )
        super().__init__(msg)


class CacheError(RoadNetworkError, OSError):
    """The compiled-network cache folder cannot be used."""

    def __init__(self, cache_dir: str, reason: str) -> None:
        self.cache_dir, self.reason = cache_dir, reason
        msg = (
            f"network cache folder {cache_dir!r} cannot be used: {reason}; "
            "pass cache_dir= or set MAPMATCH_CACHE_DIR to a writable folder"
        )
        super().__init__(msg)


class NetworkTooWideError(RoadNetworkError, ValueError):
    """The network reaches too far east-west for one planar projection to keep distances true."""

    def __init__(
        self,
        path: str,
        *,
        lon_range: tuple[float, float],
        lat_range: tuple[float, float],
        width_km: float,
        scale_error: float,
        limit: float,
        max_width_km: float,
    ) -> None:
        self.path, self.lon_range, self.lat_range = path, lon_range, lat_range
        self.width_km, self.scale_error = width_km, scale_error
        error = "over 100 %" if scale_error > 1.0 else f"{scale_error:.2%}"
        msg = (
            f"road network source {path!r} spans longitudes {lon_range[0]:.4f}..{lon_range[1]:.4f} "
            f"and latitudes {lat_range[0]:.4f}..{lat_range[1]:.4f} (about {width_km:,.0f} km "
            f"east-west): too wide for one planar projection (its scale error would reach {error} "
            f"at the network's east/west ends, more than {limit:.1%}); split the extract into "
            f"parts at most {max_width_km:,.0f} km wide east-west (e.g. `osmium extract --bbox`) "
            "and load each part"
        )
        super().__init__(msg)


class NetworkReopenError(RoadNetworkError, OSError):
    """A pickled network cannot be opened again in this process (its cache entry is gone)."""

    def __init__(self, network_id: str, reason: str) -> None:
        self.network_id, self.reason = network_id, reason
        msg = (
            f"road network {network_id!r} cannot be opened again in this process: {reason}; a "
            "pickled network re-opens from its cache file, so give workers the same cache "
            "folder and source (a shared disk), or load it with use_cache=False to pickle its "
            "arrays instead"
        )
        super().__init__(msg)
