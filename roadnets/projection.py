"""
WGS84 <-> the network's planar CRS, and true (geodesic) lengths.

Why a transverse Mercator centred on each network, and lengths from the ellipsoid
---------------------------------------------------------------------------------
Every length a user is billed on (edge lengths, offsets along edges, route lengths) is measured
on the WGS84 ellipsoid (:func:`geodesic_steps`, Karney's algorithm through
:class:`pyproj.Geod`), so it is true whatever the projection does.

The plane is still where the spatial work happens: the R-tree, the projection of a fix onto a
road, the distance from a fix to its road and between fixes. Its CRS is a transverse Mercator
with scale 1 on the meridian through the centre of the network (:meth:`Projector.local`),
computed by compiled kernels (:mod:`roadnets.tmerc`, PROJ's algorithm, a tenth of pyproj's
cost for a short trace); any other CRS goes through pyproj. Its
scale error grows with the distance ``x`` east or west of that meridian as about
``x**2 / (2 R**2)``: 3 parts per million 15 km out (a city), 0.03 % at 110 km (a region), 0.1 %
at 285 km. One UTM zone for the whole network (the former choice) errs by -0.04 % on its own
central meridian, by up to 0.1 % at the edge of its zone, and by nearly 10 % thirty degrees of
longitude away at mid latitudes (a 1,000 m drive measured 1,095.6 m on a network spanning 58
degrees); a centred projection is exact where the network is.

A network is refused (:class:`~roadnets.errors.NetworkTooWideError`) when the planar scale
error would pass :data:`MAX_SCALE_ERROR` (0.1 %) anywhere on it, that is when it reaches more
than about 285 km east or west of its centre (about one UTM zone's width at the equator). One
projection per zone or per cluster of edges was the other way: it would cut the R-tree, every
trace and every route at zone borders, for networks that a map matcher, which works in one
city or region at a time, does not need. The error says how wide the network is and to split
the extract.

Offsets along an edge stay consistent with its geodesic length because the distance along an
edge to each vertex (``geom_cum_m``) is the sum of geodesic segment lengths, and a position
inside a segment is placed by its planar fraction of that segment: each segment's planar
offsets are scaled by its own geodesic/planar ratio.
"""

from __future__ import annotations

import functools
import math
import re
import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from pyproj import Geod, Transformer

    from roadnets.tmerc import TransverseMercator

__all__ = [
    "MAX_SCALE_ERROR",
    "Projector",
    "central_longitude",
    "geodesic_steps",
    "tm_scale_error",
]

FloatArray = npt.NDArray[np.float64]

#: Largest planar scale error accepted anywhere on a network (0.1 %).
MAX_SCALE_ERROR = 1e-3

_TMERC = re.compile(r"^\+proj=tmerc \+lat_0=(?P<lat>\S+) \+lon_0=(?P<lon>\S+) \+k_0=1 ")

#: Mean Earth radius (IUGG), metres: for the scale-error estimate only.
EARTH_RADIUS_M = 6_371_008.8


def central_longitude(lon: FloatArray) -> tuple[float, float, float]:
    """
    Centre and ends of the shortest arc of longitudes holding every value, degrees.

    A network across the antimeridian (Fiji, Chukotka) has longitudes near -180 and +180; its
    centre is near 180, not 0.

    Returns
    -------
    centre, west, east
        ``west <= east`` unwrapped (``east`` may pass 180), ``centre`` in [-180, 180).

    Examples
    --------
    >>> central_longitude(np.array([7.40, 7.44]))
    (7.42, 7.4, 7.44)
    >>> central_longitude(np.array([179.0, -179.0]))
    (-180.0, 179.0, 181.0)
    """
    lon = np.asarray(lon, dtype=np.float64)
    west, east = float(lon.min()), float(lon.max())
    shifted = np.where(lon < 0.0, lon + 360.0, lon)
    s_west, s_east = float(shifted.min()), float(shifted.max())
    if s_east - s_west < east - west:
        west, east = s_west, s_east
    centre = (0.5 * (west + east) + 180.0) % 360.0 - 180.0
    return round(centre, 9), west, east


def tm_scale_error(lon: FloatArray, lat: FloatArray, lon_0: float) -> float:
    """
    Largest scale error of a transverse Mercator (scale 1 on ``lon_0``) at the given points.

    Spherical formula ``k = 1 / sqrt(1 - (cos(lat) sin(lon - lon_0))**2)``; the ellipsoidal
    value differs from it by under 1 % of the error itself. ``inf`` at 90 degrees from
    ``lon_0``.

    Examples
    --------
    >>> round(tm_scale_error(np.array([7.42]), np.array([43.73]), 7.42), 12)
    0.0
    >>> 0.0009 < tm_scale_error(np.array([2.55]), np.array([0.0]), 0.0) < 0.0011
    True
    """
    b = np.cos(np.radians(np.asarray(lat, np.float64))) * np.sin(
        np.radians(np.asarray(lon, np.float64) - lon_0)
    )
    worst = float(np.max(np.abs(b), initial=0.0))
    if worst >= 1.0:
        return math.inf
    return 1.0 / math.sqrt(1.0 - worst * worst) - 1.0


@functools.cache
def _geod() -> Geod:
    from pyproj import Geod

    return Geod(ellps="WGS84")


def geodesic_steps(lon: FloatArray, lat: FloatArray) -> FloatArray:
    """
    Geodesic length of each step between consecutive points on the WGS84 ellipsoid, metres.

    Vectorised (one call for a whole array of vertices; ``len(lon) - 1`` steps).

    Examples
    --------
    >>> steps = geodesic_steps(np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 1.0]))
    >>> [round(float(s), 1) for s in steps]
    [110574.4, 111302.6]
    """
    lon = np.asarray(lon, dtype=np.float64)
    lat = np.asarray(lat, dtype=np.float64)
    if len(lon) < 2:
        return np.zeros(0, dtype=np.float64)
    _, _, dist = _geod().inv(lon[:-1], lat[:-1], lon[1:], lat[1:])
    return np.asarray(dist, dtype=np.float64)


@functools.lru_cache(maxsize=64)
def _transformers(crs: str, thread: int) -> tuple[Transformer, Transformer, str]:
    """
    Make the transformers to and from a CRS, once per thread (they are not thread-safe).

    Returns them and the direction that unprojects with the second. Only CRSs that are not
    :meth:`Projector.local` ones come here (those are projected by :func:`_local`).
    """
    from pyproj import Transformer

    del thread  # part of the cache key only
    to_metric = Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    return to_metric, Transformer.from_crs(crs, "EPSG:4326", always_xy=True), "FORWARD"


@functools.lru_cache(maxsize=64)
def _local(crs: str) -> TransverseMercator | None:
    """The compiled projection of a :meth:`Projector.local` CRS; ``None`` for any other."""
    from roadnets.tmerc import TransverseMercator  # numba: not at import

    found = _TMERC.match(crs)
    if found is None:
        return None
    return TransverseMercator.of(float(found["lon"]), float(found["lat"]))


@dataclass(frozen=True, slots=True)
class Projector:
    """
    Vectorised conversion between WGS84 lon/lat (degrees) and a projected CRS (metres).

    ``crs`` is anything pyproj reads (``"EPSG:32632"``, a PROJ string); networks use
    :meth:`local`.

    Examples
    --------
    >>> p = Projector.local(7.42, 43.73)
    >>> x, y = p.forward(np.array([7.42, 7.43]), np.array([43.73, 43.73]))
    >>> [round(float(v), 3) for v in (x[0], y[0])]
    [0.0, 0.0]
    >>> lon, lat = p.inverse(x, y)
    >>> bool(abs(lon[1] - 7.43) < 1e-9 and abs(lat[1] - 43.73) < 1e-9)
    True
    """

    crs: str

    @classmethod
    def local(cls, lon_0: float, lat_0: float) -> Projector:
        """
        The transverse Mercator with scale 1 on meridian ``lon_0``, origin ``(lon_0, lat_0)``.

        Coordinates are metres east and north of the origin on the WGS84 ellipsoid.
        """
        definition = (
            f"+proj=tmerc +lat_0={lat_0:.6f} +lon_0={lon_0:.6f} +k_0=1 +x_0=0 +y_0=0 "
            "+ellps=WGS84 +units=m +no_defs +type=crs"
        )
        return cls(definition)

    @property
    def label(self) -> str:
        """
        A short name of the CRS: ``tmerc(lon_0, lat_0)`` for :meth:`local` ones.

        Examples
        --------
        >>> Projector.local(7.42, 43.73).label
        'tmerc(7.420000, 43.730000)'
        >>> Projector("EPSG:32632").label
        'EPSG:32632'
        """
        found = _TMERC.match(self.crs)
        return f"tmerc({found['lon']}, {found['lat']})" if found else self.crs

    @property
    def compiled(self) -> TransverseMercator | None:
        """The compiled projection of a :meth:`local` CRS (:mod:`roadnets.tmerc`), else ``None``."""
        return _local(self.crs)

    def forward(self, lon: FloatArray, lat: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Project lon/lat degrees to x/y metres."""
        local = _local(self.crs)
        if local is not None:
            return local.forward(lon, lat)
        to_metric, _, _ = _transformers(self.crs, threading.get_ident())
        x, y = to_metric.transform(np.asarray(lon, float), np.asarray(lat, float))
        return np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)

    def inverse(self, x: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Unproject x/y metres to lon/lat degrees."""
        local = _local(self.crs)
        if local is not None:
            return local.inverse(x, y)
        _, to_wgs84, direction = _transformers(self.crs, threading.get_ident())
        lon, lat = to_wgs84.transform(
            np.asarray(x, float), np.asarray(y, float), direction=direction
        )
        return np.asarray(lon, dtype=np.float64), np.asarray(lat, dtype=np.float64)
