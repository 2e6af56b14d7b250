"""Fixtures shared by the test packages: real networks, loaded once per session."""

from __future__ import annotations

from pathlib import Path

import pytest

import roadnets

DATA = Path(__file__).parent / "data"


@pytest.fixture(scope="session")
def data_dir() -> Path:
    """The folder of small real OSM extracts and hand-checked traces."""
    return DATA


@pytest.fixture(scope="session")
def cache_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A compiled-network cache private to this session."""
    return tmp_path_factory.mktemp("network-cache")


@pytest.fixture(scope="session")
def default_net(cache_dir: Path) -> roadnets.RoadNetwork:
    """The embedded default network (Monaco)."""
    return roadnets.load(cache_dir=cache_dir)


@pytest.fixture(scope="session")
def oakland_net(cache_dir: Path) -> roadnets.RoadNetwork:
    """A few blocks of West Oakland (OSM XML, bz2)."""
    return roadnets.load(DATA / "west-oakland_us.osm.bz2", cache_dir=cache_dir)


@pytest.fixture(scope="session")
def melbourne_net(cache_dir: Path) -> roadnets.RoadNetwork:
    """An outer Melbourne suburb (PBF, clipped ways)."""
    return roadnets.load(DATA / "melbourne-suburb_au.osm.pbf", cache_dir=cache_dir)
