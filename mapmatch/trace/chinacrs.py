"""
Conversions between WGS84 and the Chinese map frames GCJ-02 and BD-09.

Traces from Chinese map SDKs (AMap/Gaode, Tencent: GCJ-02; Baidu: BD-09) are offset by
a deliberately obfuscated, position-dependent shift of typically 100-700 m from the WGS84
coordinates that OpenStreetMap uses. Before matching they must be brought back to WGS84.

The forward GCJ-02 transform is the widely reproduced public formula (Krasovsky 1940
ellipsoid, ``a = 6378245 m``, ``e^2 = 0.00669342162296594323``); the BD-09 step is Baidu's
published rotation/shift of GCJ-02. The inverses have no closed form: they are computed by
fixed-point iteration on the forward transform until the residual is below 1e-9 degrees
(about 0.1 mm), so ``wgs84_to_gcj02(*gcj02_to_wgs84(lon, lat))`` reproduces the input to far
better than the 1e-6 degree the callers need.

Bounding rule
-------------
A point is treated as *outside China* when ``lon < 72.004`` or ``lon > 137.8347`` or
``lat < 0.8293`` or ``lat > 55.8271`` (the coarse rectangle used by the common open-source
implementations). Outside it all three frames coincide with WGS84 and every function here
returns the input unchanged. The rectangle is coarse: parts of neighbouring countries inside it
are shifted too, as the Chinese SDKs themselves do; it is applied to the *input* coordinates
of each function.

All functions take scalars or numpy arrays (broadcast together) and return ``(lon, lat)`` as
float64 numpy arrays (0-d for scalar input).

Examples
--------
>>> lon, lat = wgs84_to_gcj02(116.404, 39.915)
>>> print(f"{float(lon):.6f} {float(lat):.6f}")
116.410244 39.916404
>>> lon, lat = gcj02_to_wgs84(lon, lat)
>>> print(f"{float(lon):.6f} {float(lat):.6f}")
116.404000 39.915000
>>> lon, lat = wgs84_to_gcj02(2.35, 48.85)  # Paris: outside China, unchanged
>>> print(float(lon), float(lat))
2.35 48.85
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import numpy.typing as npt

    from mapmatch.types import BoolArray, FloatArray

    ArrayLike = npt.ArrayLike

__all__ = [
    "bd09_to_gcj02",
    "bd09_to_wgs84",
    "gcj02_to_bd09",
    "gcj02_to_wgs84",
    "in_china",
    "wgs84_to_bd09",
    "wgs84_to_gcj02",
]

_A = 6378245.0  # Krasovsky 1940 semi-major axis, metres
_EE = 0.00669342162296594323  # Krasovsky 1940 first eccentricity squared
_X_PI = math.pi * 3000.0 / 180.0  # Baidu's BD-09 rotation constant
_LON_MIN, _LON_MAX = 72.004, 137.8347
_LAT_MIN, _LAT_MAX = 0.8293, 55.8271
_TOL_DEG = 1e-9
_MAX_ITER = 30


def _as_arrays(lon: ArrayLike, lat: ArrayLike) -> tuple[FloatArray, FloatArray]:
    lon_a, lat_a = np.broadcast_arrays(
        np.asarray(lon, dtype=np.float64), np.asarray(lat, dtype=np.float64)
    )
    return lon_a.astype(np.float64, copy=True), lat_a.astype(np.float64, copy=True)


def in_china(lon: ArrayLike, lat: ArrayLike) -> BoolArray:
    """
    Whether points fall inside the rectangle where the Chinese offsets apply.

    Parameters
    ----------
    lon, lat
        Longitude and latitude in degrees (any of the three frames; the offsets are far
        smaller than the rectangle's precision).

    Returns
    -------
    numpy.ndarray of bool
        True inside ``72.004 <= lon <= 137.8347`` and ``0.8293 <= lat <= 55.8271``.

    Examples
    --------
    >>> in_china([116.4, -0.12], [39.9, 51.5]).tolist()
    [True, False]
    """
    lon_a, lat_a = _as_arrays(lon, lat)
    return (lon_a >= _LON_MIN) & (lon_a <= _LON_MAX) & (lat_a >= _LAT_MIN) & (lat_a <= _LAT_MAX)


def _gcj_delta(lon: FloatArray, lat: FloatArray) -> tuple[FloatArray, FloatArray]:
    """GCJ-02 minus WGS84 offset (degrees) at WGS84 point ``(lon, lat)``."""
    x = lon - 105.0
    y = lat - 35.0
    sqrt_abs_x = np.sqrt(np.abs(x))
    common = (20.0 * np.sin(6.0 * x * math.pi) + 20.0 * np.sin(2.0 * x * math.pi)) * 2.0 / 3.0
    t_lat = -100.0 + 2.0 * x + 3.0 * y + 0.2 * y * y + 0.1 * x * y + 0.2 * sqrt_abs_x + common
    t_lat += (20.0 * np.sin(y * math.pi) + 40.0 * np.sin(y / 3.0 * math.pi)) * 2.0 / 3.0
    t_lat += (160.0 * np.sin(y / 12.0 * math.pi) + 320.0 * np.sin(y * math.pi / 30.0)) * 2.0 / 3.0
    t_lon = 300.0 + x + 2.0 * y + 0.1 * x * x + 0.1 * x * y + 0.1 * sqrt_abs_x + common
    t_lon += (20.0 * np.sin(x * math.pi) + 40.0 * np.sin(x / 3.0 * math.pi)) * 2.0 / 3.0
    t_lon += (150.0 * np.sin(x / 12.0 * math.pi) + 300.0 * np.sin(x / 30.0 * math.pi)) * 2.0 / 3.0
    rad_lat = np.radians(lat)
    magic = 1.0 - _EE * np.sin(rad_lat) ** 2
    sqrt_magic = np.sqrt(magic)
    d_lat = t_lat * 180.0 / ((_A * (1.0 - _EE)) / (magic * sqrt_magic) * math.pi)
    d_lon = t_lon * 180.0 / (_A / sqrt_magic * np.cos(rad_lat) * math.pi)
    return d_lon, d_lat


def _gcj_to_bd_raw(lon: FloatArray, lat: FloatArray) -> tuple[FloatArray, FloatArray]:
    z = np.hypot(lon, lat) + 0.00002 * np.sin(lat * _X_PI)
    theta = np.arctan2(lat, lon) + 0.000003 * np.cos(lon * _X_PI)
    return z * np.cos(theta) + 0.0065, z * np.sin(theta) + 0.006


def _bd_to_gcj_closed(lon: FloatArray, lat: FloatArray) -> tuple[FloatArray, FloatArray]:
    x = lon - 0.0065
    y = lat - 0.006
    z = np.hypot(x, y) - 0.00002 * np.sin(y * _X_PI)
    theta = np.arctan2(y, x) - 0.000003 * np.cos(x * _X_PI)
    return z * np.cos(theta), z * np.sin(theta)


def wgs84_to_gcj02(lon: ArrayLike, lat: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """
    Convert WGS84 to GCJ-02 ("Mars coordinates", used by AMap/Gaode and Tencent maps).

    Parameters
    ----------
    lon, lat
        WGS84 longitude and latitude in degrees; scalars or arrays.

    Returns
    -------
    tuple of numpy.ndarray
        GCJ-02 ``(lon, lat)`` in degrees; points outside China unchanged.

    Examples
    --------
    >>> lon, lat = wgs84_to_gcj02(116.404, 39.915)
    >>> print(round(float(lon), 9), round(float(lat), 9))
    116.410244499 39.916404282
    """
    lon_a, lat_a = _as_arrays(lon, lat)
    inside = in_china(lon_a, lat_a)
    d_lon, d_lat = _gcj_delta(lon_a, lat_a)
    return np.where(inside, lon_a + d_lon, lon_a), np.where(inside, lat_a + d_lat, lat_a)


def gcj02_to_wgs84(lon: ArrayLike, lat: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """
    Convert GCJ-02 to WGS84 by iterating the forward transform (residual < 1e-9 degrees).

    Parameters
    ----------
    lon, lat
        GCJ-02 longitude and latitude in degrees; scalars or arrays.

    Returns
    -------
    tuple of numpy.ndarray
        WGS84 ``(lon, lat)`` in degrees; points outside China unchanged.

    Examples
    --------
    >>> lon, lat = gcj02_to_wgs84(116.404, 39.915)
    >>> print(f"{float(lon):.6f} {float(lat):.6f}")
    116.397756 39.913596
    """
    g_lon, g_lat = _as_arrays(lon, lat)
    inside = in_china(g_lon, g_lat)
    w_lon, w_lat = g_lon.copy(), g_lat.copy()
    for _ in range(_MAX_ITER):
        d_lon, d_lat = _gcj_delta(w_lon, w_lat)
        r_lon = g_lon - (w_lon + d_lon)
        r_lat = g_lat - (w_lat + d_lat)
        w_lon += r_lon
        w_lat += r_lat
        if float(np.max(np.abs(r_lon), initial=0.0)) < _TOL_DEG and (
            float(np.max(np.abs(r_lat), initial=0.0)) < _TOL_DEG
        ):
            break
    return np.where(inside, w_lon, g_lon), np.where(inside, w_lat, g_lat)


def gcj02_to_bd09(lon: ArrayLike, lat: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """
    Convert GCJ-02 to BD-09 (Baidu maps).

    Parameters
    ----------
    lon, lat
        GCJ-02 longitude and latitude in degrees; scalars or arrays.

    Returns
    -------
    tuple of numpy.ndarray
        BD-09 ``(lon, lat)`` in degrees; points outside China unchanged.

    Examples
    --------
    >>> lon, lat = gcj02_to_bd09(116.404, 39.915)
    >>> print(round(float(lon), 9), round(float(lat), 9))
    116.410369494 39.921336994
    """
    lon_a, lat_a = _as_arrays(lon, lat)
    inside = in_china(lon_a, lat_a)
    b_lon, b_lat = _gcj_to_bd_raw(lon_a, lat_a)
    return np.where(inside, b_lon, lon_a), np.where(inside, b_lat, lat_a)


def bd09_to_gcj02(lon: ArrayLike, lat: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """
    Convert BD-09 to GCJ-02: Baidu's closed-form inverse, refined by iteration (< 1e-9 deg).

    Parameters
    ----------
    lon, lat
        BD-09 longitude and latitude in degrees; scalars or arrays.

    Returns
    -------
    tuple of numpy.ndarray
        GCJ-02 ``(lon, lat)`` in degrees; points outside China unchanged.

    Examples
    --------
    >>> lon, lat = bd09_to_gcj02(116.404, 39.915)
    >>> print(f"{float(lon):.6f} {float(lat):.6f}")
    116.397627 39.908656
    """
    b_lon, b_lat = _as_arrays(lon, lat)
    inside = in_china(b_lon, b_lat)
    g_lon, g_lat = _bd_to_gcj_closed(b_lon, b_lat)
    for _ in range(_MAX_ITER):
        f_lon, f_lat = _gcj_to_bd_raw(g_lon, g_lat)
        r_lon = b_lon - f_lon
        r_lat = b_lat - f_lat
        g_lon += r_lon
        g_lat += r_lat
        if float(np.max(np.abs(r_lon), initial=0.0)) < _TOL_DEG and (
            float(np.max(np.abs(r_lat), initial=0.0)) < _TOL_DEG
        ):
            break
    return np.where(inside, g_lon, b_lon), np.where(inside, g_lat, b_lat)


def wgs84_to_bd09(lon: ArrayLike, lat: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """
    Convert WGS84 to BD-09 (via GCJ-02).

    Parameters
    ----------
    lon, lat
        WGS84 longitude and latitude in degrees; scalars or arrays.

    Returns
    -------
    tuple of numpy.ndarray
        BD-09 ``(lon, lat)`` in degrees; points outside China unchanged.

    Examples
    --------
    >>> lon, lat = wgs84_to_bd09(116.404, 39.915)
    >>> print(round(float(lon), 9), round(float(lat), 9))
    116.416627244 39.922699552
    """
    lon_a, lat_a = _as_arrays(lon, lat)
    inside = in_china(lon_a, lat_a)
    g_lon, g_lat = wgs84_to_gcj02(lon_a, lat_a)
    b_lon, b_lat = _gcj_to_bd_raw(g_lon, g_lat)
    return np.where(inside, b_lon, lon_a), np.where(inside, b_lat, lat_a)


def bd09_to_wgs84(lon: ArrayLike, lat: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """
    Convert BD-09 to WGS84 (via GCJ-02; both inverses iterated).

    Parameters
    ----------
    lon, lat
        BD-09 longitude and latitude in degrees; scalars or arrays.

    Returns
    -------
    tuple of numpy.ndarray
        WGS84 ``(lon, lat)`` in degrees; points outside China unchanged.

    Examples
    --------
    >>> lon, lat = bd09_to_wgs84(*wgs84_to_bd09(121.4737, 31.2304))
    >>> print(f"{float(lon):.7f} {float(lat):.7f}")
    121.4737000 31.2304000
    """
    lon_a, lat_a = _as_arrays(lon, lat)
    inside = in_china(lon_a, lat_a)
    g_lon, g_lat = bd09_to_gcj02(lon_a, lat_a)
    w_lon, w_lat = gcj02_to_wgs84(g_lon, g_lat)
    return np.where(inside, w_lon, lon_a), np.where(inside, w_lat, lat_a)
