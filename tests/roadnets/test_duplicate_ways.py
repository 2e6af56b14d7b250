"""A road drawn twice by two overlapping ways is one edge per direction."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

import roadnets
from tests.mapmatch.toy import write_osm

if TYPE_CHECKING:
    from pathlib import Path

ONEWAY = {"highway": "primary", "oneway": "yes"}
TWO_WAY = {"highway": "primary"}


def test_overlapping_ways_give_one_edge_per_direction(tmp_path: Path) -> None:
    ways = [
        (1, [(0, 0), (100, 0), (200, 0)], TWO_WAY),
        (2, [(0, 0), (100, 0), (200, 0)], ONEWAY),  # the same road again, one way
        (3, [(200, 0), (100, 0), (0, 0)], ONEWAY),  # and again, the other way round
        (4, [(100, 0), (100, 100)], TWO_WAY),
    ]
    net = roadnets.load(write_osm(tmp_path / "twice.osm", ways), use_cache=False)
    a = net.arrays
    pairs = set(zip(a.edge_u.tolist(), a.edge_v.tolist(), strict=True))
    assert len(pairs) == a.n_edges  # no two edges between the same nodes the same way round
    assert a.n_edges == 6  # way 1: 2 pieces x 2 directions; way 4: 2 directions
    assert set(np.unique(a.edge_way_id).tolist()) == {1, 4}  # the first way drawn is kept
    assert (a.edge_twin >= 0).all()


def test_the_duplicated_melbourne_roads_are_kept_once(data_dir: Path, cache_dir: Path) -> None:
    net = roadnets.load(data_dir / "melbourne-suburb_au.osm.pbf", cache_dir=cache_dir)
    a = net.arrays
    geometry = {}
    for e in range(a.n_edges):
        lo, hi = a.edge_geom_ptr[e], a.edge_geom_ptr[e + 1]
        key = (tuple(np.round(a.geom_x[lo:hi], 3)), tuple(np.round(a.geom_y[lo:hi], 3)))
        assert key not in geometry, (e, geometry.get(key))
        geometry[key] = e
