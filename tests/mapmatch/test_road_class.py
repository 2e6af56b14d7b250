"""A service road within the position noise of the road beside it: speed says which was driven."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pytest

import mapmatch
from tests.mapmatch.toy import drive, load, trace_of, write_osm

if TYPE_CHECKING:
    import roadnets

MAIN = 1
SERVICE = 2
# the main road runs east along y = 0; a service road (a car park's aisle) leaves it at
# x = 100 and joins it again at x = 300, 8 m to the north in between
MAIN_ROAD = [(0.0, 0.0), (100.0, 0.0), (300.0, 0.0), (400.0, 0.0)]
AISLE = [(100.0, 0.0), (110.0, 8.0), (290.0, 8.0), (300.0, 0.0)]


@pytest.fixture(scope="module")
def beside(tmp_path_factory: pytest.TempPathFactory) -> roadnets.RoadNetwork:
    path = tmp_path_factory.mktemp("road_class") / "beside.osm"
    return load(
        write_osm(
            path,
            [
                (MAIN, MAIN_ROAD, {"highway": "tertiary"}),
                (SERVICE, AISLE, {"highway": "service"}),
            ],
        )
    )


def _service_metres(result: mapmatch.MatchResult) -> float:
    """Metres of the matched path on the service road."""
    return sum(
        float(np.sum(s.driven_m[np.asarray(s.attributes.way_id) == SERVICE]))
        for s in result.segments
    )


def _drive_pulled_north(speed_mps: float, pull_m: float) -> tuple[np.ndarray, ...]:
    """The main road driven at ``speed_mps``, every fix ``pull_m`` north (a slow GNSS bias)."""
    x, y, _, t = drive(MAIN_ROAD, speed_mps=speed_mps)
    return x, y + pull_m, t


@pytest.mark.parametrize("columns", ["positions", "speed"])
def test_a_fast_car_pulled_towards_a_service_road_stays_on_the_main_road(
    beside: roadnets.RoadNetwork, columns: str
) -> None:
    # 15 m/s along the main road, the fixes 5 m north: 3 m from the aisle, 5 m from the road
    x, y, t = _drive_pulled_north(15.0, 5.0)
    speed = 15.0 if columns == "speed" else None
    trace = trace_of(x, y, time_s=t, speed=speed)
    assert _service_metres(mapmatch.match(trace, beside)) == 0.0
    # without the prior the nearer aisle wins: the test tells the two apart
    plain = mapmatch.match(trace, beside, mapmatch.MatchConfig(service_penalty=0.0))
    assert _service_metres(plain) > 150.0


def test_a_slow_car_on_the_service_road_keeps_it(beside: roadnets.RoadNetwork) -> None:
    # 4 m/s along the main road, through the aisle and back onto the main road, the fixes on it
    x, y, _, t = drive([MAIN_ROAD[0], *AISLE, MAIN_ROAD[-1]], speed_mps=4.0)
    trace = trace_of(x, y, time_s=t, speed=4.0)
    assert _service_metres(mapmatch.match(trace, beside)) > 180.0
