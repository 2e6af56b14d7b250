"""
The networks' transverse Mercator, compiled: WGS84 lon/lat <-> metres, a few hundred ns a call.

A network's plane is a transverse Mercator centred on it (:meth:`Projector.local
<roadnets.projection.Projector.local>`). Every match projects its fixes into it and its
matched positions back, and through pyproj each of those two calls costs 10-13 us whatever
the number of points (its Python glue and PROJ's pipeline set-up), a tenth of a short trace's
whole match. These kernels compute the same projection: Krüger's series in the third
flattening ``n`` to sixth order (Engsager & Poder's formulation, which PROJ's ``tmerc`` uses
by default), summed with Clenshaw's recurrence on the conformal (Gaussian) latitude. It agrees
with PROJ to about a nanometre within the 285 km a network may reach from its central meridian
(``tests/roadnets/test_projection.py``); the series itself is good to a few nanometres up to 4,000
km out (Karney 2011, "Transverse Mercator with an accuracy of a few nanometers").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numba import njit

__all__ = ["TransverseMercator", "inverse_kernel"]

FloatArray = npt.NDArray[np.float64]

#: WGS84 semi-major axis (m) and flattening.
WGS84_A = 6_378_137.0
WGS84_F = 1.0 / 298.257223563


# Each series' k-th coefficient (k = 1 .. 6) is n**k times a polynomial in n, given here by its
# coefficients from the constant term up (Engsager & Poder; Karney 2011, eqs. 35 and 36 for
# the latitudes, 11 and 12 for the northing and easting).
#: Geodetic -> Gaussian (conformal) latitude.
_TO_GAUSS = (
    (-2, 2 / 3, 4 / 3, -82 / 45, 32 / 45, 4642 / 4725),
    (5 / 3, -16 / 15, -13 / 9, 904 / 315, -1522 / 945),
    (-26 / 15, 34 / 21, 8 / 5, -12686 / 2835),
    (1237 / 630, -12 / 5, -24832 / 14175),
    (-734 / 315, 109598 / 31185),
    (444337 / 155925,),
)
#: Gaussian -> geodetic latitude.
_FROM_GAUSS = (
    (2, -2 / 3, -2, 116 / 45, 26 / 45, -2854 / 675),
    (7 / 3, -8 / 5, -227 / 45, 2704 / 315, 2323 / 945),
    (56 / 15, -136 / 35, -1262 / 105, 73814 / 2835),
    (4279 / 630, -332 / 35, -399572 / 14175),
    (4174 / 315, -144838 / 6237),
    (601676 / 22275,),
)
#: Ellipsoidal -> spherical northing and easting.
_TO_SPHERE = (
    (-1 / 2, 2 / 3, -37 / 96, 1 / 360, 81 / 512, -96199 / 604800),
    (-1 / 48, -1 / 15, 437 / 1440, -46 / 105, 1118711 / 3870720),
    (-17 / 480, 37 / 840, 209 / 4480, -5569 / 90720),
    (-4397 / 161280, 11 / 504, 830251 / 7257600),
    (-4583 / 161280, 108847 / 3991680),
    (-20648693 / 638668800,),
)
#: Spherical -> ellipsoidal northing and easting.
_FROM_SPHERE = (
    (1 / 2, -2 / 3, 5 / 16, 41 / 180, -127 / 288, 7891 / 37800),
    (13 / 48, -3 / 5, 557 / 1440, 281 / 630, -1983433 / 1935360),
    (61 / 240, -103 / 140, 15061 / 26880, 167603 / 181440),
    (49561 / 161280, -179 / 168, 6601661 / 7257600),
    (34729 / 80640, -3418889 / 1995840),
    (212378941 / 319334400,),
)


def _coefficients(table: tuple[tuple[float, ...], ...], n: float) -> FloatArray:
    """A series' coefficients for third flattening ``n`` (Horner on each polynomial)."""
    out = np.empty(len(table))
    for k, poly in enumerate(table):
        value = 0.0
        for c in reversed(poly):
            value = value * n + c
        out[k] = n ** (k + 1) * value
    return out


@njit(cache=True, nogil=True, inline="always")
def _clenshaw(coef, angle, cos_2, sin_2):  # type: ignore[no-untyped-def]  # pragma: no cover
    """``angle + sum_k coef[k] sin(2 (k + 1) angle)``, given ``cos(2 angle)``, ``sin(2 angle)``."""
    two_cos = 2.0 * cos_2
    h1 = coef[len(coef) - 1]
    h2 = 0.0
    h = h1
    for k in range(len(coef) - 2, -1, -1):
        h = -h2 + two_cos * h1 + coef[k]
        h2 = h1
        h1 = h
    return angle + h * sin_2


@njit(cache=True, nogil=True, inline="always")
def _clenshaw_complex(coef, sin_r, cos_r, sinh_i, cosh_i):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Real and imaginary parts of ``sum_k coef[k] sin(2 (k + 1) w)``, ``w = r + i i``.

    Given ``sin(2 r)``, ``cos(2 r)``, ``sinh(2 i)`` and ``cosh(2 i)``.
    """
    r = 2.0 * cos_r * cosh_i
    i = -2.0 * sin_r * sinh_i
    hr, hi = coef[len(coef) - 1], 0.0
    hr1, hi1 = 0.0, 0.0
    for k in range(len(coef) - 2, -1, -1):
        hr2, hi2 = hr1, hi1
        hr1, hi1 = hr, hi
        hr = -hr2 + r * hr1 - i * hi1 + coef[k]
        hi = -hi2 + i * hr1 + r * hi1
    r = sin_r * cosh_i
    i = cos_r * sinh_i
    return r * hr - i * hi, r * hi + i * hr


@njit(cache=True, nogil=True)
def _forward(lon, lat, lon_0, northing_0, scale, to_gauss, from_sphere):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Degrees to metres east/north of the origin (see :class:`TransverseMercator`)."""
    n = len(lon)
    x, y = np.empty(n), np.empty(n)
    for k in range(n):
        phi = math.radians(lat[k])
        lam = math.radians(lon[k] - lon_0)
        lam = (lam + math.pi) % (2.0 * math.pi) - math.pi
        gauss = _clenshaw(to_gauss, phi, math.cos(2.0 * phi), math.sin(2.0 * phi))
        sin_g, cos_g = math.sin(gauss), math.cos(gauss)
        sin_l, cos_l = math.sin(lam), math.cos(lam)
        north = math.atan2(sin_g, cos_g * cos_l)
        east = math.asinh(sin_l * cos_g / math.hypot(sin_g, cos_g * cos_l))
        d_north, d_east = _clenshaw_complex(
            from_sphere,
            math.sin(2.0 * north),
            math.cos(2.0 * north),
            math.sinh(2.0 * east),
            math.cosh(2.0 * east),
        )
        x[k] = scale * (east + d_east)
        y[k] = scale * (north + d_north) - northing_0
    return x, y


@njit(cache=True, nogil=True)
def inverse_kernel(x, y, lon_0, northing_0, scale, from_gauss, to_sphere):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Metres east/north of the origin to degrees (see :class:`TransverseMercator`)."""
    n = len(x)
    lon, lat = np.empty(n), np.empty(n)
    for k in range(n):
        north = (y[k] + northing_0) / scale
        east = x[k] / scale
        d_north, d_east = _clenshaw_complex(
            to_sphere,
            math.sin(2.0 * north),
            math.cos(2.0 * north),
            math.sinh(2.0 * east),
            math.cosh(2.0 * east),
        )
        north += d_north
        east += d_east
        sin_n, cos_n = math.sin(north), math.cos(north)
        sinh_e = math.sinh(east)
        lam = math.atan2(sinh_e, cos_n)
        gauss = math.atan2(sin_n, math.hypot(sinh_e, cos_n))
        phi = _clenshaw(from_gauss, gauss, math.cos(2.0 * gauss), math.sin(2.0 * gauss))
        lat[k] = math.degrees(phi)
        lon[k] = (math.degrees(lam) + lon_0 + 180.0) % 360.0 - 180.0
    return lon, lat


@dataclass(frozen=True, slots=True)
class TransverseMercator:
    """
    The WGS84 transverse Mercator with scale 1 on meridian ``lon_0``, origin ``(lon_0, lat_0)``.

    The same plane as PROJ's ``+proj=tmerc +lat_0=.. +lon_0=.. +k_0=1 +x_0=0 +y_0=0
    +ellps=WGS84``.

    Examples
    --------
    >>> tm = TransverseMercator.of(7.42, 43.73)
    >>> x, y = tm.forward(np.array([7.42, 7.43]), np.array([43.73, 43.74]))
    >>> [round(float(v), 3) for v in (x[0], y[0], x[1], y[1])]
    [0.0, 0.0, 805.556, 1111.119]
    >>> lon, lat = tm.inverse(x, y)
    >>> bool(np.allclose(lon, [7.42, 7.43], atol=1e-12) and np.allclose(lat, [43.73, 43.74]))
    True
    """

    lon_0: float
    scale: float
    northing_0: float
    to_gauss: FloatArray
    from_gauss: FloatArray
    to_sphere: FloatArray
    from_sphere: FloatArray

    @classmethod
    def of(cls, lon_0: float, lat_0: float) -> TransverseMercator:
        """The projection centred on ``(lon_0, lat_0)`` (degrees)."""
        n = WGS84_F / (2.0 - WGS84_F)
        to_gauss, from_gauss = _coefficients(_TO_GAUSS, n), _coefficients(_FROM_GAUSS, n)
        to_sphere, from_sphere = _coefficients(_TO_SPHERE, n), _coefficients(_FROM_SPHERE, n)
        # the rectifying radius: a meridian quadrant is pi / 2 of it
        scale = WGS84_A * (1 + n**2 * (1 / 4 + n**2 * (1 / 64 + n**2 / 256))) / (1 + n)
        phi_0 = math.radians(lat_0)
        gauss_0 = float(_clenshaw(to_gauss, phi_0, math.cos(2 * phi_0), math.sin(2 * phi_0)))
        d_north, _ = _clenshaw_complex(
            from_sphere, math.sin(2 * gauss_0), math.cos(2 * gauss_0), 0.0, 1.0
        )
        northing_0 = scale * (gauss_0 + float(d_north))
        return cls(float(lon_0), scale, northing_0, to_gauss, from_gauss, to_sphere, from_sphere)

    def forward(self, lon: FloatArray, lat: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Project lon/lat degrees to x/y metres."""
        x, y = _forward(
            np.ascontiguousarray(lon, np.float64),
            np.ascontiguousarray(lat, np.float64),
            self.lon_0,
            self.northing_0,
            self.scale,
            self.to_gauss,
            self.from_sphere,
        )
        return x, y

    def inverse(self, x: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Unproject x/y metres to lon/lat degrees."""
        lon, lat = inverse_kernel(
            np.ascontiguousarray(x, np.float64),
            np.ascontiguousarray(y, np.float64),
            *self.inverse_parameters,
        )
        return lon, lat

    @property
    def inverse_parameters(self) -> tuple[float, float, float, FloatArray, FloatArray]:
        """What the compiled inverse (:func:`inverse_kernel`) takes after ``x`` and ``y``."""
        return self.lon_0, self.northing_0, self.scale, self.from_gauss, self.to_sphere
