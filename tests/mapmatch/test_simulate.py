from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest

import mapmatch
import roadnets
from mapmatch.errors import ConfigError
from mapmatch.simulate import SimulationConfig, simulate_trip, simulate_trips, write_trips


def test_truth_is_a_connected_route_of_the_stated_length(default_net: roadnets.RoadNetwork) -> None:
    trip = simulate_trip(default_net, SimulationConfig(), seed=12)
    a = default_net.arrays
    edges = [e.edge for e in trip.edges]
    for first, second in itertools.pairwise(edges):
        assert a.edge_v[first] == a.edge_u[second]
    driven = sum(e.end_offset_m - e.start_offset_m for e in trip.edges)
    assert driven == pytest.approx(trip.length_m, abs=0.01)
    assert set(trip.true_edge.tolist()) <= set(edges)
    assert len(trip.trace) == len(trip.true_edge)


def test_simulated_routes_obey_turn_restrictions(default_net: roadnets.RoadNetwork) -> None:
    a = default_net.arrays
    banned = set(zip(a.banned_in.tolist(), a.banned_out.tolist(), strict=True))
    assert banned
    for trip in simulate_trips(
        default_net, SimulationConfig(route_length_m=3000), count=15, seed=1
    ):
        edges = [e.edge for e in trip.edges]
        assert not banned & set(itertools.pairwise(edges))


def test_the_same_seed_gives_the_same_trip(default_net: roadnets.RoadNetwork) -> None:
    one = simulate_trip(default_net, SimulationConfig(), seed=5)
    two = simulate_trip(default_net, SimulationConfig(), seed=5)
    other = simulate_trip(default_net, SimulationConfig(), seed=6)
    assert np.array_equal(one.trace.lon, two.trace.lon)
    assert not np.array_equal(one.trace.lon[:5], other.trace.lon[:5])


def test_noise_and_odometer_follow_the_settings(default_net: roadnets.RoadNetwork) -> None:
    cfg = SimulationConfig(noise_m=8.0, odometer_scale_error=0.02, route_length_m=4000)
    trip = simulate_trip(default_net, cfg, seed=3)
    x, y = default_net.project(trip.trace.lon, trip.trace.lat)
    tx, ty = default_net.project(trip.true_lon, trip.true_lat)
    for axis_error in (x - tx, y - ty):  # 8 m per axis, no outliers asked for
        assert 7.0 < float(np.sqrt(np.mean(axis_error**2))) < 9.0
    odo = trip.trace.odometer_m
    assert odo[-1] - odo[0] == pytest.approx(trip.length_m * trip.odometer_scale, rel=1e-6)
    assert abs(trip.odometer_scale - 1) <= 0.02


def test_a_small_network_still_gives_trips() -> None:
    net = roadnets.load(Path(__file__).parents[1] / "data" / "west-oakland_us.osm.bz2")
    trips = simulate_trips(net, SimulationConfig(route_length_m=10_000), count=3, seed=0)
    assert all(t.length_m > 200 for t in trips)


def test_bad_settings_are_config_errors() -> None:
    with pytest.raises(ConfigError, match="interval_s must be > 0"):
        SimulationConfig(interval_s=0)
    with pytest.raises(ConfigError, match="route must be"):
        SimulationConfig(route="teleport")


def test_written_files_round_trip(default_net: roadnets.RoadNetwork, tmp_path: Path) -> None:
    trips = simulate_trips(default_net, SimulationConfig(route_length_m=1000), count=2, seed=9)
    traces_csv, truth = write_trips(trips, tmp_path)
    back = {t.trace_id: t for t in mapmatch.read_traces(traces_csv)}
    assert set(back) == {"trip-0000", "trip-0001"}
    assert np.allclose(back["trip-0001"].lat, trips[1].trace.lat, atol=1e-7)
    records = [json.loads(line) for line in truth.read_text().splitlines()]
    assert [r["trace_id"] for r in records] == ["trip-0000", "trip-0001"]
    assert records[0]["geometry"]["type"] == "LineString"
    assert len(records[0]["point_edges"]) == len(trips[0].trace)
