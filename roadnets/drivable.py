"""Which OSM ways a car may drive, in which direction, and how fast.

Pure functions over a way's tag dictionary; the graph builder calls them once per way.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Mapping

__all__ = [
    "DEFAULT_SPEED_KPH",
    "ROAD_CLASSES",
    "direction_flags",
    "is_drivable",
    "parse_maxspeed_kph",
    "road_speed_kph",
]

#: Road classes in descending importance; an edge stores its index into this tuple.
ROAD_CLASSES: tuple[str, ...] = (
    "motorway",
    "trunk",
    "primary",
    "secondary",
    "tertiary",
    "motorway_link",
    "trunk_link",
    "primary_link",
    "secondary_link",
    "tertiary_link",
    "unclassified",
    "residential",
    "living_street",
    "road",
    "service",
)

#: Speed assumed where ``maxspeed`` is not tagged, km/h. Typical urban/rural legal limits of
#: European and North American road classes (the same order of values OSRM's car profile uses).
DEFAULT_SPEED_KPH: dict[str, float] = {
    "motorway": 110.0,
    "trunk": 90.0,
    "primary": 60.0,
    "secondary": 50.0,
    "tertiary": 50.0,
    "motorway_link": 60.0,
    "trunk_link": 50.0,
    "primary_link": 40.0,
    "secondary_link": 40.0,
    "tertiary_link": 30.0,
    "unclassified": 40.0,
    "residential": 30.0,
    "living_street": 10.0,
    "road": 40.0,
    "service": 20.0,
}

#: ``service=*`` values left out: parking aisles and driveways are not through roads, and
#: their dense geometry would only add wrong candidates next to the real street.
_EXCLUDED_SERVICE = frozenset({"parking_aisle", "driveway", "emergency_access", "drive-through"})
_NO_ACCESS = frozenset({"no", "private"})
_MOTOR_ALLOWED = frozenset({"yes", "designated", "permissive", "destination", "delivery"})
_TRUE = frozenset({"yes", "true", "1"})
_FALSE = frozenset({"no", "false", "0"})

#: Zone limits written as ``CC:zone`` (``DE:urban``, ``FR:rural``...), km/h.
_ZONE_SPEED_KPH: dict[str, float] = {
    "urban": 50.0,
    "rural": 90.0,
    "motorway": 130.0,
    "trunk": 110.0,
    "living_street": 10.0,
    "zone20": 20.0,
    "zone30": 30.0,
    "walk": 7.0,
}
_NUMBER = re.compile(r"^\s*(\d+(?:\.\d+)?)\s*(km/h|kmh|kph|mph|knots)?\s*$")


def is_drivable(tags: Mapping[str, str]) -> bool:
    """
    Tell whether a car may use the way with these tags.

    Kept: motorway .. residential, living streets, unclassified, ``road``, ``service`` and every
    ``*_link``. Left out: other highway values (footway, cycleway, path, track...), areas,
    parking aisles and driveways, and ways closed to motor vehicles (``access=no|private`` unless
    ``motor_vehicle``/``motorcar`` allows them, or ``motor_vehicle=no``/``motorcar=no``).

    Examples
    --------
    >>> is_drivable({"highway": "residential"})
    True
    >>> is_drivable({"highway": "footway"})
    False
    >>> is_drivable({"highway": "service", "access": "private"})
    False
    """
    highway = tags.get("highway")
    if highway not in DEFAULT_SPEED_KPH:
        return False
    if tags.get("area") == "yes":
        return False
    if highway == "service" and tags.get("service") in _EXCLUDED_SERVICE:
        return False
    motor = tags.get("motor_vehicle", tags.get("motorcar"))
    if motor in _FALSE or motor in _NO_ACCESS:
        return False
    return not (tags.get("access") in _NO_ACCESS and motor not in _MOTOR_ALLOWED)


def direction_flags(tags: Mapping[str, str]) -> tuple[bool, bool]:
    """
    Directions a car may drive a way in: ``(along the node order, against it)``.

    Follows OSM's rules: ``oneway=yes|true|1`` forward only, ``oneway=-1|reverse`` backward only,
    ``oneway=no|false|0`` both ways; ``junction=roundabout|circular`` and ``highway=motorway`` are
    one-way unless tagged otherwise. ``oneway=reversible|alternating`` roads change direction
    by time of day, so both directions stay possible. ``oneway:motor_vehicle`` overrides
    ``oneway`` when present.

    Examples
    --------
    >>> direction_flags({"highway": "primary", "oneway": "-1"})
    (False, True)
    >>> direction_flags({"highway": "motorway"})
    (True, False)
    """
    value = tags.get("oneway:motor_vehicle", tags.get("oneway"))
    if value is not None:
        value = value.strip().lower()
        if value in _TRUE:
            return True, False
        if value in {"-1", "reverse"}:
            return False, True
        if value in _FALSE or value in {"reversible", "alternating"}:
            return True, True
    implied = tags.get("junction") in {"roundabout", "circular"} or tags.get("highway") == (
        "motorway"
    )
    return (True, False) if implied else (True, True)


def parse_maxspeed_kph(value: str | None) -> float | None:
    """
    Parse an OSM ``maxspeed`` value into km/h, or ``None`` when it gives no number.

    Numbers with or without a unit (``50``, ``50 km/h``, ``30 mph``, ``10 knots``), country zone
    codes (``DE:urban``, ``FR:zone30``), ``walk``, and lists (``50;30``: the highest, as the
    limit a vehicle may legally reach on the way). ``none``, ``signals`` and ``variable`` give
    ``None`` so the class default applies.

    Examples
    --------
    >>> parse_maxspeed_kph("30 mph")
    48.28032
    >>> parse_maxspeed_kph("DE:urban")
    50.0
    >>> parse_maxspeed_kph("50;70")
    70.0
    >>> parse_maxspeed_kph("signals") is None
    True
    """
    if not value:
        return None
    speeds: list[float] = []
    for part in value.split(";"):
        part = part.strip().lower()
        match = _NUMBER.match(part)
        if match:
            number = float(match.group(1))
            unit = match.group(2)
            if unit == "mph":
                number *= 1.609344
            elif unit == "knots":
                number *= 1.852
            if number > 0:
                speeds.append(number)
            continue
        zone = part.split(":", 1)[-1]
        if zone in _ZONE_SPEED_KPH:
            speeds.append(_ZONE_SPEED_KPH[zone])
    return max(speeds) if speeds else None


def road_speed_kph(tags: Mapping[str, str], *, forward: bool) -> float:
    """
    Speed limit of a way in one direction, km/h.

    ``maxspeed:forward``/``:backward`` first, then ``maxspeed``, then the class default of
    :data:`DEFAULT_SPEED_KPH`.

    Examples
    --------
    >>> road_speed_kph({"highway": "residential"}, forward=True)
    30.0
    >>> road_speed_kph({"highway": "primary", "maxspeed": "70", "maxspeed:backward": "50"},
    ...                forward=False)
    50.0
    """
    directional = tags.get("maxspeed:forward" if forward else "maxspeed:backward")
    parsed = parse_maxspeed_kph(directional) or parse_maxspeed_kph(tags.get("maxspeed"))
    if parsed is not None:
        return parsed
    return DEFAULT_SPEED_KPH[tags.get("highway", "road")]
