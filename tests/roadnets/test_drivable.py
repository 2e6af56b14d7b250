from __future__ import annotations

import pytest

from roadnets.drivable import direction_flags, is_drivable, parse_maxspeed_kph, road_speed_kph


@pytest.mark.parametrize(
    ("tags", "expected"),
    [
        ({"highway": "primary"}, True),
        ({"highway": "motorway_link"}, True),
        ({"highway": "living_street"}, True),
        ({"highway": "service"}, True),
        ({"highway": "service", "service": "parking_aisle"}, False),
        ({"highway": "service", "service": "driveway"}, False),
        ({"highway": "footway"}, False),
        ({"highway": "cycleway"}, False),
        ({"highway": "path"}, False),
        ({"highway": "pedestrian"}, False),
        ({"highway": "track"}, False),
        ({"highway": "residential", "access": "private"}, False),
        ({"highway": "residential", "access": "no", "motor_vehicle": "yes"}, True),
        ({"highway": "residential", "motor_vehicle": "no"}, False),
        ({"highway": "residential", "area": "yes"}, False),
        ({"building": "yes"}, False),
    ],
)
def test_drivable_filter(tags: dict[str, str], expected: bool) -> None:
    assert is_drivable(tags) is expected


@pytest.mark.parametrize(
    ("tags", "expected"),
    [
        ({"highway": "residential"}, (True, True)),
        ({"highway": "residential", "oneway": "yes"}, (True, False)),
        ({"highway": "residential", "oneway": "true"}, (True, False)),
        ({"highway": "residential", "oneway": "1"}, (True, False)),
        ({"highway": "residential", "oneway": "-1"}, (False, True)),
        ({"highway": "residential", "oneway": "reverse"}, (False, True)),
        ({"highway": "residential", "oneway": "no"}, (True, True)),
        ({"highway": "residential", "oneway": "reversible"}, (True, True)),
        ({"highway": "primary", "junction": "roundabout"}, (True, False)),
        ({"highway": "primary", "junction": "circular"}, (True, False)),
        ({"highway": "primary", "junction": "roundabout", "oneway": "no"}, (True, True)),
        ({"highway": "motorway"}, (True, False)),
        ({"highway": "motorway", "oneway": "no"}, (True, True)),
        ({"highway": "primary", "oneway": "yes", "oneway:motor_vehicle": "no"}, (True, True)),
    ],
)
def test_oneway_rules(tags: dict[str, str], expected: tuple[bool, bool]) -> None:
    assert direction_flags(tags) == expected


@pytest.mark.parametrize(
    ("value", "kph"),
    [
        ("50", 50.0),
        ("50 km/h", 50.0),
        ("30 mph", 48.28032),
        ("30mph", 48.28032),
        ("10 knots", 18.52),
        ("DE:urban", 50.0),
        ("FR:rural", 90.0),
        ("RU:living_street", 10.0),
        ("walk", 7.0),
        ("50;70", 70.0),
        ("none", None),
        ("signals", None),
        ("", None),
        (None, None),
        ("fast", None),
    ],
)
def test_maxspeed_parsing(value: str | None, kph: float | None) -> None:
    parsed = parse_maxspeed_kph(value)
    if kph is None:
        assert parsed is None
    else:
        assert parsed == pytest.approx(kph)


def test_speed_falls_back_to_class_default_and_honours_direction() -> None:
    assert road_speed_kph({"highway": "motorway"}, forward=True) == 110.0
    assert road_speed_kph({"highway": "residential", "maxspeed": "signals"}, forward=True) == 30.0
    tags = {"highway": "primary", "maxspeed": "70", "maxspeed:forward": "90"}
    assert road_speed_kph(tags, forward=True) == 90.0
    assert road_speed_kph(tags, forward=False) == 70.0
