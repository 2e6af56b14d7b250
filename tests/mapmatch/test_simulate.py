from __future__ import annotations

import dataclasses
import itertools
import json
from pathlib import Path

import numpy as np
import pytest

import mapmatch
import roadnets
from mapmatch.cli import main
from mapmatch.errors import ConfigError
from mapmatch.evaluation.simulate import (
    INPUT_CLASSES,
    TRUE_COLUMNS,
    SimulatedTrip,
    SimulationConfig,
    simulate_trip,
    simulate_trips,
    strip_to_class,
    with_columns,
    write_trips,
)


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
    # offsets stay on their edges, up to the last fix too (the 1 m speed grid overshoots)
    for t in simulate_trips(default_net, SimulationConfig.noise_free(), count=10, seed=40):
        assert all(0 <= e.start_offset_m <= e.end_offset_m <= e.length_m + 1e-6 for e in t.edges)
        assert np.all(t.true_offset_m <= a.edge_length_m[t.true_edge] + 1e-6)


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


# ---------------------------------------------------------------- realistic noise options


def _errors(net: roadnets.RoadNetwork, trip: SimulatedTrip) -> np.ndarray:
    """Observed minus true position of every fix, metres, as (n, 2)."""
    x, y = net.project(trip.trace.lon, trip.trace.lat)
    tx, ty = net.project(trip.true_lon, trip.true_lat)
    return np.column_stack((x - tx, y - ty))


def _lag_correlation(series: list[np.ndarray], lag: int) -> float:
    a = np.concatenate([s[:-lag] for s in series])
    b = np.concatenate([s[lag:] for s in series])
    return float(np.mean(a * b) / np.sqrt(np.mean(a * a) * np.mean(b * b)))


def test_ar1_position_noise_has_the_asked_std_and_correlation(
    default_net: roadnets.RoadNetwork,
) -> None:
    cfg = SimulationConfig(
        noise_m=6.0, noise_correlation_per_s=0.95, stop_probability=0.0, route_length_m=5000
    )
    trips = simulate_trips(default_net, cfg, count=12, seed=30)
    errors = [_errors(default_net, t) for t in trips]
    pooled = np.concatenate(errors)
    assert 5.0 < float(np.sqrt(np.mean(pooled**2))) < 7.0  # stationary 6 m per axis
    per_axis = [e[:, k] for e in errors for k in (0, 1)]
    assert _lag_correlation(per_axis, 1) == pytest.approx(0.95, abs=0.03)
    assert _lag_correlation(per_axis, 10) == pytest.approx(0.95**10, abs=0.12)
    white = simulate_trips(default_net, cfg.replace(noise_correlation_per_s=0.0), count=4, seed=30)
    assert abs(_lag_correlation([_errors(default_net, t)[:, 0] for t in white], 1)) < 0.1
    # the same process as a time constant: rho = exp(-1 / tau)
    tau = SimulationConfig(noise_correlation_s=-1 / np.log(0.95))
    assert tau.correlation_time_s == pytest.approx(cfg.correlation_time_s)


def test_junction_stops_stand_still_with_noisy_fixes(default_net: roadnets.RoadNetwork) -> None:
    cfg = SimulationConfig(
        stop_probability=0.0,
        junction_stop_share=1.0,
        junction_stop_s=(20.0, 20.0),
        speed_noise_mps=0.0,
        noise_m=4.0,
    )
    trip = simulate_trip(default_net, cfg, seed=4)
    assert len(trip.stops) >= 3
    a = default_net.arrays
    x, y = default_net.project(trip.true_lon, trip.true_lat)
    neighbours: dict[int, set[int]] = {}
    for u, v in zip(a.edge_u.tolist(), a.edge_v.tolist(), strict=True):
        neighbours.setdefault(u, set()).add(v)
        neighbours.setdefault(v, set()).add(u)
    junctions = np.array([n for n, near in neighbours.items() if len(near - {n}) >= 3])
    for stop in trip.stops:
        assert stop.duration_s == pytest.approx(20.0)
        standing = np.arange(stop.first_fix, stop.last_fix + 1)
        assert len(standing) >= 19  # a fix every second while standing
        assert np.all(
            (trip.trace.time_s[standing] >= stop.start_s)
            & (trip.trace.time_s[standing] <= stop.end_s)
        )
        assert np.ptp(x[standing]) < 1e-6  # truly standing
        assert np.ptp(y[standing]) < 1e-6
        gap = np.hypot(a.node_x[junctions] - x[standing[0]], a.node_y[junctions] - y[standing[0]])
        assert gap.min() < 0.6  # at a junction (the speed profile's 1 m grid)
        assert np.all(trip.trace.speed_mps[standing] == 0.0)
        spread = _errors(default_net, trip)[standing]
        assert float(np.std(spread)) > 1.0  # the receiver keeps reporting noisy fixes
    # the truth stays one connected route of the stated length
    driven = sum(e.end_offset_m - e.start_offset_m for e in trip.edges)
    assert driven == pytest.approx(trip.length_m, abs=0.01)
    record = trip.truth_record()
    assert [s["fixes"] for s in record["stops"]] == [[s.first_fix, s.last_fix] for s in trip.stops]


def test_brief_stops_stand_still_too(default_net: roadnets.RoadNetwork) -> None:
    cfg = SimulationConfig(stop_probability=0.5, stop_s=20.0, speed_noise_mps=0.0)
    trip = simulate_trip(default_net, cfg, seed=2)
    long_stops = [s for s in trip.stops if s.last_fix - s.first_fix >= 3]
    assert long_stops
    for stop in long_stops:
        assert np.all(trip.trace.speed_mps[stop.first_fix : stop.last_fix + 1] == 0.0)


def test_canyon_pulls_fixes_to_one_side_and_the_truth_records_it(
    default_net: roadnets.RoadNetwork,
) -> None:
    cfg = SimulationConfig(noise_m=0.0, canyon_per_km=2.0, canyon_bias_m=20.0, route_length_m=4000)
    trip = simulate_trip(default_net, cfg, seed=8)
    assert len(trip.canyons) >= 2
    offset = np.hypot(*_errors(default_net, trip).T)
    inside = np.zeros(len(offset), dtype=bool)
    for canyon in trip.canyons:
        fixes = slice(canyon.first_fix, canyon.last_fix + 1)
        inside[fixes] = True
        assert np.allclose(offset[fixes], 20.0, atol=1e-3)
        # perpendicular to the driving direction, on the recorded side
        err = _errors(default_net, trip)[fixes]
        heading = np.radians(trip.trace.heading_deg[fixes])  # 5 deg noise on the heading
        along = err[:, 0] * np.sin(heading) + err[:, 1] * np.cos(heading)
        right = err[:, 0] * np.cos(heading) - err[:, 1] * np.sin(heading)
        assert np.median(np.abs(along)) < 3.0
        assert np.all(np.sign(right[np.abs(right) > 10]) == canyon.side)
    assert np.all(offset[~inside] < 1e-3)
    record = trip.truth_record()["canyons"]
    assert {r["side"] for r in record} <= {"left", "right"}
    assert all(r["bias_m"] == 20.0 for r in record)


def test_outages_remove_fixes_and_the_truth_records_the_gaps(
    default_net: roadnets.RoadNetwork,
) -> None:
    cfg = SimulationConfig(outage_per_km=1.0, outage_range_s=(30.0, 30.0), route_length_m=4000)
    trip = simulate_trip(default_net, cfg, seed=5)
    assert trip.outages
    t = trip.trace.time_s
    for outage in trip.outages:
        assert outage.duration_s == pytest.approx(30.0)
        assert not np.any((t > outage.start_s) & (t < outage.end_s))
        assert t[outage.first_fix] <= outage.start_s
        assert t[outage.last_fix] >= outage.end_s
        assert outage.last_fix == outage.first_fix + 1  # nothing seen in between
        assert t[outage.last_fix] - t[outage.first_fix] >= 29.0
    gaps = np.flatnonzero(np.diff(t) > 1.5)
    assert len(gaps) == len(trip.outages)
    # the truth stays consistent: a true edge for every fix that was seen
    assert len(trip.true_edge) == len(trip.trace)
    assert len(trip.truth_record()["outages"]) == len(trip.outages)


def test_heading_noise_grows_as_the_car_slows(default_net: roadnets.RoadNetwork) -> None:
    cfg = SimulationConfig(
        heading_noise_deg=3.0,
        heading_noise_slow_deg=87.0,
        junction_stop_share=0.5,
        stop_probability=0.0,
        route_length_m=5000,
    )
    noisy = simulate_trip(default_net, cfg, seed=6)
    exact = simulate_trip(
        default_net,
        SimulationConfig.noise_free(
            **{"junction_stop_share": 0.5, "stop_probability": 0.0, "route_length_m": 5000}
        ),
        seed=6,
    )
    assert len(noisy.trace) == len(exact.trace)
    diff = (noisy.trace.heading_deg - exact.trace.heading_deg + 180.0) % 360.0 - 180.0
    speed = exact.trace.speed_mps
    standing, fast = speed < 0.05, speed > 8.0
    assert standing.sum() > 30
    assert fast.sum() > 30
    assert float(np.std(diff[standing])) > 45.0  # 90 deg 1-sigma, wrapped
    assert float(np.std(diff[fast])) < 4.0  # 3 deg + 87 exp(-8) deg


def test_a_fixed_odometer_bias(default_net: roadnets.RoadNetwork) -> None:
    cfg = SimulationConfig(odometer_bias=0.02, odometer_scale_error=0.0)
    trip = simulate_trip(default_net, cfg, seed=3)
    assert trip.odometer_scale == 1.02
    odo = trip.trace.odometer_m
    assert odo[-1] - odo[0] == pytest.approx(1.02 * trip.length_m, rel=1e-9)
    spread = SimulationConfig(odometer_bias=0.02, odometer_scale_error=0.005)
    scales = [t.odometer_scale for t in simulate_trips(default_net, spread, count=6, seed=0)]
    assert all(1.015 <= s <= 1.025 for s in scales)


@pytest.mark.parametrize("interval_s", [0.1, 1.0, 15.0])
def test_noise_free_traces_are_the_truth(
    default_net: roadnets.RoadNetwork, interval_s: float
) -> None:
    trip = simulate_trip(default_net, SimulationConfig.noise_free(interval_s=interval_s), seed=11)
    assert np.abs(_errors(default_net, trip)).max() < 1e-6
    assert np.allclose(np.diff(trip.trace.time_s), interval_s)
    odo = trip.trace.odometer_m
    assert odo[-1] - odo[0] == pytest.approx(trip.length_m, rel=1e-12)
    assert np.allclose(
        trip.trace.speed_mps, np.interp(trip.trace.time_s, trip.dense_time_s, trip.dense_speed_mps)
    )
    if interval_s == 0.1:  # the 10 Hz truth the fusion front-end starts from
        assert len(trip.trace) == pytest.approx(len(trip.dense_time_s), abs=1)


def test_input_classes_strip_columns(default_net: roadnets.RoadNetwork, tmp_path: Path) -> None:
    full = simulate_trip(default_net, SimulationConfig(), seed=1)
    for name, kept in INPUT_CLASSES.items():
        trip = simulate_trip(default_net, SimulationConfig(input_class=name), seed=1)
        assert np.array_equal(trip.trace.lon, full.trace.lon)  # same fixes, fewer columns
        present = {
            c
            for c, v in (
                ("heading", trip.trace.heading_deg),
                ("speed", trip.trace.speed_mps),
                ("accuracy", trip.trace.accuracy_m),
                ("odometer", trip.trace.odometer_m),
            )
            if v is not None
        }
        assert present == set(kept)
        assert trip.truth_record()["columns"] == [c for c in TRUE_COLUMNS if c in kept]
        assert strip_to_class(full.trace, name).to_dataframe().columns.tolist() == (
            trip.trace.to_dataframe().columns.tolist()
        )
    plain = simulate_trips(default_net, SimulationConfig(input_class="positions"), count=2, seed=1)
    traces_csv, _ = write_trips(plain, tmp_path)
    assert traces_csv.read_text().splitlines()[0] == "trace_id,time,lon,lat"
    only_speed = with_columns(full.trace, ["speed"])
    assert only_speed.speed_mps is not None
    assert only_speed.heading_deg is None
    with pytest.raises(ConfigError, match="unknown column"):
        with_columns(full.trace, ["altitude"])
    with pytest.raises(ConfigError, match="input class must be one of"):
        strip_to_class(full.trace, "lidar")


@pytest.mark.parametrize("fixture", ["default_net", "melbourne_net"])
def test_fastest_routes_turn_back_only_at_dead_ends(
    fixture: str, request: pytest.FixtureRequest
) -> None:
    net: roadnets.RoadNetwork = request.getfixturevalue(fixture)
    a = net.arrays
    banned = set(zip(a.banned_in.tolist(), a.banned_out.tolist(), strict=True))
    for trip in simulate_trips(net, SimulationConfig(), count=20, seed=70):
        edges = [e.edge for e in trip.edges]
        assert trip.loops == 0  # a fastest route never drives a directed edge twice
        turns = [
            (first, second)
            for first, second in itertools.pairwise(edges)
            if a.edge_twin[first] == second
        ]
        assert trip.uturns == len(turns)
        for first, _ in turns:
            node = int(a.edge_v[first])
            ahead = [
                int(e)
                for e in a.out_edge[a.out_ptr[node] : a.out_ptr[node + 1]]
                if int(e) != a.edge_twin[first] and (first, int(e)) not in banned
            ]
            assert not ahead, "a U-turn where the road went on"


def test_random_walks_record_their_own_loops(default_net: roadnets.RoadNetwork) -> None:
    cfg = SimulationConfig(route="random_walk", route_length_m=8000)
    trips = simulate_trips(default_net, cfg, count=6, seed=3)
    for trip in trips:
        edges = [e.edge for e in trip.edges]
        repeats = len(edges) - len(set(edges))
        assert trip.loops == repeats
        assert trip.truth_record()["loops"] == repeats
    assert any(t.loops for t in trips)


def test_the_realistic_options_keep_the_route_and_the_older_draws(
    default_net: roadnets.RoadNetwork,
) -> None:
    plain = simulate_trip(default_net, SimulationConfig(noise_m=3.0), seed=9)
    canyon = simulate_trip(default_net, SimulationConfig(noise_m=3.0, canyon_per_km=1.0), seed=9)
    assert [e.edge for e in plain.edges] == [e.edge for e in canyon.edges]
    outside = np.ones(len(plain.trace), dtype=bool)
    for c in canyon.canyons:
        outside[c.first_fix : c.last_fix + 1] = False
    assert np.array_equal(plain.trace.lon[outside], canyon.trace.lon[outside])
    real = SimulationConfig.realistic(interval_s=15.0)
    assert simulate_trip(default_net, real, seed=9).trace.lon.tolist() == (
        simulate_trip(default_net, real, seed=9).trace.lon.tolist()
    )


def test_bad_realistic_settings_are_config_errors() -> None:
    with pytest.raises(ConfigError, match="not both"):
        SimulationConfig(noise_correlation_per_s=0.9, noise_correlation_s=5.0)
    with pytest.raises(ConfigError, match=r"noise_correlation_per_s must be within 0\.\.1"):
        SimulationConfig(noise_correlation_per_s=1.0)
    with pytest.raises(ConfigError, match="canyon_s must be a range"):
        SimulationConfig(canyon_s=(30.0, 10.0))
    with pytest.raises(ConfigError, match="input_class must be one of"):
        SimulationConfig(input_class="gps")
    with pytest.raises(ConfigError, match=r"junction_stop_share must be within 0\.\.1"):
        SimulationConfig(junction_stop_share=1.5)


def test_cli_writes_realistic_plain_gps_traces(tmp_path: Path) -> None:
    code = main(
        [
            "simulate",
            "--out",
            str(tmp_path),
            "--traces",
            "2",
            "--seed",
            "3",
            "--realistic",
            "--plain-gps",
            "--interval-s",
            "15",
            "--outage-per-km",
            "1",
        ]
    )
    assert code == 0
    assert (tmp_path / "traces.csv").read_text().splitlines()[0] == "trace_id,time,lon,lat"
    records = [json.loads(line) for line in (tmp_path / "truth.jsonl").read_text().splitlines()]
    assert all(r["columns"] == [] and r["odometer_scale"] == 1.02 for r in records)
    assert any(r["outages"] for r in records)
    assert any(r["stops"] for r in records)
    assert main(["simulate", "--out", str(tmp_path), "--canyon-s", "9", "3"]) != 0


def test_ends_error_is_what_the_end_fixes_noise_moves_the_length_by(
    default_net: roadnets.RoadNetwork,
) -> None:
    clean = simulate_trip(default_net, SimulationConfig.noise_free(), seed=8)
    assert clean.ends_error() == pytest.approx(0.0, abs=1e-6)
    # the last fix moved 20 m ahead along the true heading: the length grows by 20 m
    last = len(clean.trace) - 1
    j = int(np.argmin(np.abs(clean.dense_time_s - clean.trace.time_s[last])))
    heading = np.radians(clean.dense_heading_deg[j])
    lon, lat = clean.trace.lon.copy(), clean.trace.lat.copy()
    metres_per_deg = 6_371_008.8 * np.pi / 180
    lat[last] += 20.0 * np.cos(heading) / metres_per_deg
    lon[last] += 20.0 * np.sin(heading) / (metres_per_deg * np.cos(np.radians(lat[last])))
    moved = mapmatch.Trace.from_records(
        [
            {"time": t, "lon": x, "lat": y}
            for t, x, y in zip(clean.trace.time_s, lon, lat, strict=True)
        ]
    )
    shifted = dataclasses.replace(clean, trace=moved)
    assert shifted.ends_error() * clean.length_m == pytest.approx(20.0, abs=0.05)
