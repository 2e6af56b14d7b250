"""
Local tangent-plane (east/north metres) conversion for a vehicle's working area.

The fusion filter works in metres east (``x``) and north (``y``) of an origin. For the few
kilometres a trip covers, a tangent plane with the WGS84 meridional and prime-vertical radii of
curvature at the origin is accurate to better than 1e-3 relative and is exactly invertible,
which is all the filter and the simulator need (both use this same conversion).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import numpy.typing as npt

    FloatArray = npt.NDArray[np.float64]

__all__ = ["LocalTangentPlane"]

_WGS84_A = 6378137.0
_WGS84_E2 = 6.69437999014e-3


@dataclass(frozen=True, slots=True)
class LocalTangentPlane:
    """
    East/north metres around an origin ``(lon0, lat0)`` in degrees (WGS84).

    Examples
    --------
    >>> ltp = LocalTangentPlane(116.4, 39.9)
    >>> x, y = ltp.to_xy(116.401, 39.901)
    >>> print(f"{float(x):.2f} {float(y):.2f}")
    85.52 111.03
    >>> lon, lat = ltp.to_lonlat(x, y)
    >>> print(f"{float(lon):.6f} {float(lat):.6f}")
    116.401000 39.901000
    """

    lon0: float
    lat0: float

    @property
    def _radii(self) -> tuple[float, float]:
        s = math.sin(math.radians(self.lat0))
        w = math.sqrt(1.0 - _WGS84_E2 * s * s)
        meridional = _WGS84_A * (1.0 - _WGS84_E2) / w**3
        prime_vertical = _WGS84_A / w
        return meridional, prime_vertical * math.cos(math.radians(self.lat0))

    def to_xy(self, lon: npt.ArrayLike, lat: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
        """
        Convert ``(lon, lat)`` degrees to ``(x, y)`` metres east/north of the origin.

        Parameters
        ----------
        lon, lat
            WGS84 degrees; scalars or arrays.
        """
        m, n_cos = self._radii
        lon_a = np.asarray(lon, dtype=np.float64)
        lat_a = np.asarray(lat, dtype=np.float64)
        x = np.radians(lon_a - self.lon0) * n_cos
        y = np.radians(lat_a - self.lat0) * m
        return x, y

    def to_lonlat(self, x: npt.ArrayLike, y: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
        """
        Convert ``(x, y)`` metres east/north of the origin to ``(lon, lat)`` degrees.

        Parameters
        ----------
        x, y
            Metres east and north; scalars or arrays.
        """
        m, n_cos = self._radii
        lon = self.lon0 + np.degrees(np.asarray(x, dtype=np.float64) / n_cos)
        lat = self.lat0 + np.degrees(np.asarray(y, dtype=np.float64) / m)
        return lon, lat
