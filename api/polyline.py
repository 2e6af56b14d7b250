"""
Google's encoded polyline format (as OSRM, Valhalla and map SDKs use it), both ways.

A polyline is the text of a list of ``(lat, lon)`` positions: each coordinate rounded to
``precision`` decimals (5, or 6 for OSRM's ``polyline6`` and Valhalla), as the difference from
the previous one, zig-zag encoded and written 5 bits per character from ``?`` (63).

Examples
--------
>>> encode([(38.5, -120.2), (40.7, -120.95), (43.252, -126.453)])
'_p~iF~ps|U_ulLnnqC_mqNvxq`@'
>>> decode('_p~iF~ps|U_ulLnnqC_mqNvxq`@')
[(38.5, -120.2), (40.7, -120.95), (43.252, -126.453)]
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Final

if TYPE_CHECKING:
    from collections.abc import Iterable

__all__ = ["PRECISIONS", "PolylineError", "decode", "encode"]

#: Decimals a polyline may carry: 5 (Google, OSRM's ``polyline``) or 6 (``polyline6``).
PRECISIONS: Final = (5, 6)
_MAX_CHARS: Final = 10_000_000


class PolylineError(ValueError):
    """The text is not an encoded polyline (names the offending character)."""


def _chunks(value: int) -> str:
    value = ~(value << 1) if value < 0 else value << 1
    out = []
    while value >= 0x20:
        out.append(chr((0x20 | (value & 0x1F)) + 63))
        value >>= 5
    out.append(chr(value + 63))
    return "".join(out)


def encode(positions: Iterable[tuple[float, float]], precision: int = 5) -> str:
    """The polyline of ``(lat, lon)`` positions (WGS84 degrees) at ``precision`` decimals."""
    factor = 10**precision
    out: list[str] = []
    last_lat = last_lon = 0
    for lat, lon in positions:
        ilat, ilon = round(lat * factor), round(lon * factor)
        out.append(_chunks(ilat - last_lat))
        out.append(_chunks(ilon - last_lon))
        last_lat, last_lon = ilat, ilon
    return "".join(out)


def decode(text: str, precision: int = 5) -> list[tuple[float, float]]:
    """
    The ``(lat, lon)`` positions of a polyline.

    Raises
    ------
    PolylineError
        A character outside ``?`` .. ``~``, a coordinate cut off at the end, or a latitude
        without its longitude.
    """
    if len(text) > _MAX_CHARS:
        msg = f"the polyline is longer than {_MAX_CHARS:,} characters"
        raise PolylineError(msg)
    factor = 10**precision
    values: list[int] = []
    value = shift = 0
    for i, char in enumerate(text):
        code = ord(char) - 63
        if not 0 <= code < 64:
            msg = f"character {i} ({char!r}) is not part of an encoded polyline"
            raise PolylineError(msg)
        value |= (code & 0x1F) << shift
        shift += 5
        if code < 0x20:
            values.append(~(value >> 1) if value & 1 else value >> 1)
            value = shift = 0
        elif shift > 60:
            msg = f"character {i}: a coordinate longer than any latitude or longitude"
            raise PolylineError(msg)
    if shift:
        msg = "the polyline ends in the middle of a coordinate"
        raise PolylineError(msg)
    if len(values) % 2:
        msg = "the polyline has a latitude without its longitude at the end"
        raise PolylineError(msg)
    out: list[tuple[float, float]] = []
    lat = lon = 0
    for k in range(0, len(values), 2):
        lat += values[k]
        lon += values[k + 1]
        out.append((lat / factor, lon / factor))
    return out
