"""Live matching (issue 17): fixes matched as they arrive, against the offline match.

Simulated 1 s trips on real extracts (the embedded Monaco and the Melbourne suburb), with the
simulator's realistic noise (correlated errors, outliers, urban canyons, junction stops,
outages) unless said otherwise; fixed seeds.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest

import mapmatch
from mapmatch.errors import InvalidTraceError, NoCandidatesError
from mapmatch.evaluation.scoring import score_geojson
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trips, strip_to_class
from mapmatch.online import OnlineMatcher
from mapmatch.online.matcher import DEFAULT_LAG_S

if TYPE_CHECKING:
    import roadnets
    from mapmatch.online import LiveUpdate

REALISTIC = SimulationConfig.realistic(interval_s=1.0)


def fixes_of(trace: mapmatch.Trace) -> list[dict[str, Any]]:
    """The trace's rows as the fixes a vehicle would send (unknown values left out)."""
    out = []
    for i in range(len(trace.lon)):
        fix: dict[str, Any] = {
            "time": float(trace.time_s[i]),
            "lat": float(trace.lat[i]),
            "lon": float(trace.lon[i]),
        }
        for name, values in (
            ("heading", trace.heading_deg),
            ("speed", trace.speed_mps),
            ("accuracy", trace.accuracy_m),
            ("odometer", trace.odometer_m),
        ):
            if values is not None and np.isfinite(values[i]):
                fix[name] = float(values[i])
        out.append(fix)
    return out


def run_live(
    net: roadnets.RoadNetwork, trace: mapmatch.Trace, **kwargs: Any
) -> tuple[mapmatch.MatchResult, list[LiveUpdate]]:
    live = OnlineMatcher(net, **kwargs)
    updates = [live.push(fix) for fix in fixes_of(trace)]
    return live.close(), updates


def path_of(result: mapmatch.MatchResult) -> list[list[tuple[int, float, float]]]:
    return [
        [
            (int(e), round(float(lo), 6), round(float(hi), 6))
            for e, lo, hi in zip(s.edge, s.start_offset_m, s.end_offset_m, strict=True)
        ]
        for s in result.segments
    ]


def assert_same_points(a: mapmatch.MatchedPoints, b: mapmatch.MatchedPoints) -> None:
    for name in ("matched", "edge", "segment", "outlier", "interpolated"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    for name in ("offset_m", "lon", "lat", "confidence"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), atol=1e-9, err_msg=name)


@pytest.fixture(scope="module")
def monaco_trips(default_net: roadnets.RoadNetwork) -> list[Any]:
    return simulate_trips(default_net, REALISTIC, count=6, seed=11)


@pytest.fixture(scope="module")
def melbourne_trips(melbourne_net: roadnets.RoadNetwork) -> list[Any]:
    return simulate_trips(melbourne_net, REALISTIC, count=6, seed=11)


# --------------------------------------------------------------------- against offline


@pytest.mark.parametrize("input_class", ["odometer", "positions"])
def test_an_unbounded_lag_is_the_offline_match(
    default_net: roadnets.RoadNetwork, monaco_trips: list[Any], input_class: str
) -> None:
    for trip in monaco_trips[:3]:
        trace = strip_to_class(trip.trace, input_class)
        offline = mapmatch.match(trace, default_net)
        online, updates = run_live(default_net, trace, lag=None)
        assert not any(u.settled_fixes for u in updates)  # nothing settles before close
        assert path_of(online) == path_of(offline)
        assert online.matched_length_m == offline.matched_length_m
        assert online.breaks == offline.breaks
        assert_same_points(online.points, offline.points)
        assert online.distance_check == offline.distance_check
        assert online.stats.candidates == offline.stats.candidates
        assert online.stats.model_points == offline.stats.model_points


def test_a_fix_only_a_detour_explains_is_left_out_live_as_offline(
    melbourne_net: roadnets.RoadNetwork,
) -> None:
    from mapmatch.evaluation.accuracy.conditions import condition_config

    # the accuracy matrix's 30 s trip 18 of Melbourne, positions only: one fix thrown onto
    # another road, which the offline match leaves out as an outlier (hmm.detours)
    trip = simulate_trips(melbourne_net, condition_config("30s-20m"), count=1, seed=1018)[0]
    trace = strip_to_class(trip.trace, "positions")
    offline = mapmatch.match(trace, melbourne_net)
    assert offline.points.outlier.any()
    online, _ = run_live(melbourne_net, trace, lag=None)
    assert path_of(online) == path_of(offline)
    assert online.matched_length_m == offline.matched_length_m
    assert_same_points(online.points, offline.points)


def test_a_lag_longer_than_the_trip_is_the_offline_match_on_sparse_fixes(
    melbourne_net: roadnets.RoadNetwork,
) -> None:
    # 15 s fixes without accuracies: the trip's own sigma is estimated, as offline
    cfg = SimulationConfig.realistic(interval_s=15.0, input_class="positions")
    for trip in simulate_trips(melbourne_net, cfg, count=3, seed=5):
        trace = trip.trace
        offline = mapmatch.match(trace, melbourne_net)
        duration = float(trace.time_s[-1] - trace.time_s[0])
        online, updates = run_live(melbourne_net, trace, lag=duration + 1.0)
        assert not any(u.settled_fixes for u in updates)
        assert path_of(online) == path_of(offline)
        assert online.matched_length_m == offline.matched_length_m
        assert_same_points(online.points, offline.points)


@pytest.mark.parametrize("extract", ["monaco", "melbourne"])
@pytest.mark.parametrize("noise", ["plain", "realistic"])
def test_the_default_lag_settles_what_offline_matches(
    request: pytest.FixtureRequest, extract: str, noise: str
) -> None:
    net = request.getfixturevalue("default_net" if extract == "monaco" else "melbourne_net")
    if noise == "realistic":
        trips = request.getfixturevalue(f"{extract}_trips")
    else:
        trips = simulate_trips(net, SimulationConfig(interval_s=1.0), count=6, seed=11)
    online_mismatch, offline_mismatch = [], []
    for trip in trips:
        truth = trip.truth_record()
        offline = mapmatch.match(trip.trace, net)
        online, updates = run_live(net, trip.trace)
        assert sum(u.settled_fixes for u in updates) > 0.5 * len(trip.trace)  # live, not at close
        offline_mismatch.append(score_geojson(offline.to_geojson(), truth).mismatch)
        online_mismatch.append(score_geojson(online.to_geojson(), truth).mismatch)
        assert online.matched_length_m == pytest.approx(offline.matched_length_m, rel=0.005)
    assert np.mean(online_mismatch) <= np.mean(offline_mismatch) + 0.005


# --------------------------------------------------------------------- what settles


def settled_path(updates: list[LiveUpdate]) -> list[tuple[int, int, float, float]]:
    """The settled stretches ``(segment, edge, start, end)``, a carried-on one merged."""
    stretches: list[tuple[int, int, float, float]] = []
    for update in updates:
        for segment, edge in zip(update.segments, update.edges, strict=True):
            if stretches and stretches[-1][:2] == (segment, edge.edge):
                start = stretches.pop()[2]  # the last stretch carried on
                assert start == pytest.approx(edge.start_offset_m)
            stretches.append((segment, edge.edge, edge.start_offset_m, edge.end_offset_m))
    return stretches


def test_what_settles_never_changes(
    melbourne_net: roadnets.RoadNetwork, melbourne_trips: list[Any]
) -> None:
    trip = melbourne_trips[3]
    result, updates = run_live(melbourne_net, trip.trace, lag=20.0)
    points = result.points
    settled_fixes = 0
    for update in updates:
        assert update.first_fix == settled_fixes
        settled_fixes += update.settled_fixes
        assert_same_points(update.points, _rows(points, update.first_fix, settled_fixes))
    stretches = settled_path(updates)
    final = [
        (s.index, int(e), float(lo), float(hi))
        for s in result.segments
        for e, lo, hi in zip(s.edge, s.start_offset_m, s.end_offset_m, strict=True)
    ]
    settled = len(stretches)
    assert 0 < settled <= len(final)
    for got, want in zip(stretches[:-1], final[: settled - 1], strict=True):
        assert got == pytest.approx(want)
    last, want = stretches[-1], final[settled - 1]
    assert last[:3] == pytest.approx(want[:3])
    assert last[3] <= want[3] + 1e-6  # the stretch the last settling cut, grown since


def _rows(points: mapmatch.MatchedPoints, lo: int, hi: int) -> mapmatch.MatchedPoints:
    import dataclasses

    return mapmatch.MatchedPoints(
        **{f.name: getattr(points, f.name)[lo:hi] for f in dataclasses.fields(points)}
    )


def test_the_running_distance_check_follows_the_odometer(
    default_net: roadnets.RoadNetwork,
) -> None:
    cfg = SimulationConfig(interval_s=1.0, odometer_bias=0.03, odometer_scale_error=0.0)
    trip = simulate_trips(default_net, cfg, count=1, seed=21)[0]
    trace = trip.trace
    live = OnlineMatcher(default_net, trip_id="cab-7")
    until, checked = [], 0
    updates = []
    for i, fix in enumerate(fixes_of(trace)):
        update = live.push(fix)
        updates.append(update)
        distance = update.distance
        until.append(distance.settled_until_s)
        assert 0.0 <= distance.coverage <= 1.0
        assert distance.fixes == i + 1
        settled_m = sum(hi - lo for _, _, lo, hi in settled_path(updates))
        assert distance.check.matched_length_m == pytest.approx(settled_m)
        if update.settled_fixes:
            # the fused distance so far is the odometer's increase to the last settled fixes
            last = update.first_fix + update.settled_fixes - 1
            odo = trace.odometer_m
            assert odo is not None
            assert distance.check.source == "odometer"
            assert distance.check.fused_length_m == pytest.approx(odo[last] - odo[0], abs=40.0)
            if distance.check.matched_length_m > 500:
                # a meter 3 % high is caught while the trip runs
                assert distance.check.verdict == "over"
                checked += 1
    assert checked > 0
    settled = [t for t in until if not math.isnan(t)]
    assert settled == sorted(settled)  # the settled part only grows
    assert 0.5 < live.distance().coverage < 1.0  # the lag's end is still open
    result = live.close()
    assert result.distance_check.verdict == "over"
    assert live.distance().coverage == 1.0


def test_the_provisional_position_is_on_the_road_near_the_newest_fix(
    default_net: roadnets.RoadNetwork,
) -> None:
    trip = simulate_trips(default_net, SimulationConfig(interval_s=1.0), count=1, seed=4)[0]
    live = OnlineMatcher(default_net)
    assert live.position() is None
    fixes = fixes_of(trip.trace)
    for i, fix in enumerate(fixes):
        live.push(fix)
        if i % 25 == 5:
            where = live.position()
            assert where is not None
            assert where.fix <= i
            assert i - where.fix <= 3  # the newest fixes, not the settled ones
            assert 0.0 <= where.confidence <= 1.0
            assert where.distance_m <= 50.0
            true_edge = int(trip.true_edge[where.fix])
            assert where.edge == true_edge or _adjacent(default_net, where.edge, true_edge)


def _adjacent(net: roadnets.RoadNetwork, a: int, b: int) -> bool:
    arrays = net.arrays
    ends = {int(arrays.edge_u[a]), int(arrays.edge_v[a])}
    return bool(ends & {int(arrays.edge_u[b]), int(arrays.edge_v[b])})


# --------------------------------------------------------------------- bad input, memory


def test_a_live_trip_survives_bad_fixes(default_net: roadnets.RoadNetwork) -> None:
    trip = simulate_trips(default_net, SimulationConfig(interval_s=1.0), count=1, seed=2)[0]
    good = fixes_of(trip.trace)
    live = OnlineMatcher(default_net, trip_id="bus-12")
    bad: list[tuple[Any, str | None, str]] = [
        ({**good[0], "lat": 95.0}, "lat", "out of range"),
        ({k: v for k, v in good[0].items() if k != "time"}, "time", "time is missing"),
        ({**good[0], "speed": -2.0}, "speed", "must be >= 0"),
        ({**good[0], "time": good[0]["time"] * 1000}, "time", "milliseconds"),
        ({**good[0], "lon": "east"}, "lon", "not a number"),
        ({**good[0], "accuracy": 0}, "accuracy", "must be > 0"),
        (["not", "a", "fix"], None, "not an object"),
        ({**good[0], "Lat": 43.7, "latitude": 43.7}, "lat", "both give lat"),
    ]
    for i, fix in enumerate(good):
        if i == 40:
            for wrong, field, words in bad:
                with pytest.raises(InvalidTraceError) as caught:
                    live.push(wrong)
                assert caught.value.field == field
                assert words in str(caught.value)
                assert "'bus-12'" in str(caught.value)
            older = {**fix, "time": fix["time"] - 5.0}
            with pytest.raises(InvalidTraceError, match="before the fix before it"):
                live.push(older)
        live.push(fix)
        if i == 41:
            assert live.push(fix).merged == 1  # the same fix sent twice
    result = live.close()
    clean = mapmatch.match(trip.trace, default_net)
    assert result.matched_length_m == pytest.approx(clean.matched_length_m, rel=1e-9)
    assert result.stats.points == len(good)
    assert result.stats.merged_rows == 1
    with pytest.raises(RuntimeError, match="closed"):
        live.push(good[-1])


def test_a_batch_refuses_its_bad_fixes_and_keeps_the_rest(
    default_net: roadnets.RoadNetwork,
) -> None:
    trip = simulate_trips(default_net, SimulationConfig(interval_s=1.0), count=1, seed=2)[0]
    fixes = fixes_of(trip.trace)
    live = OnlineMatcher(default_net)
    batch = [*fixes[:10], {**fixes[10], "odometer": 0.0}, {"lat": 1.0}, *fixes[10:60]]
    update = live.push_many(batch)
    assert update.accepted == 60
    assert [(r.index, r.field) for r in update.rejected] == [(10, "odometer"), (11, "time")]
    assert "less than the trip's last reading" in update.rejected[0].message
    for start in range(60, len(fixes), 50):
        live.push_many(fixes[start : start + 50])
    result = live.close()
    assert result.stats.dropped_rows == 2
    assert len(result.points.time_s) == len(fixes)
    assert any("2 fix(es) were refused" in w for w in result.stats.warnings)


def test_a_long_trip_holds_a_bounded_tail(default_net: roadnets.RoadNetwork) -> None:
    cfg = SimulationConfig(interval_s=1.0, route="random_walk", route_length_m=12_000.0)
    trip = simulate_trips(default_net, cfg, count=1, seed=8)[0]
    live = OnlineMatcher(default_net, lag=20.0)
    held = []
    for fix in fixes_of(trip.trace):
        live.push(fix)
        held.append(live.tail_fixes)
    n = len(trip.trace)
    assert n > 1000
    # the lag's fixes, the look-ahead and the context before them: not the trip
    assert max(held) < 200
    assert live.close().stats.points == n


def test_a_parked_car_reporting_for_an_hour_holds_a_bounded_tail(
    default_net: roadnets.RoadNetwork,
) -> None:
    trip = simulate_trips(default_net, SimulationConfig(interval_s=1.0), count=1, seed=3)[0]
    drive = [{"time": f["time"], "lat": f["lat"], "lon": f["lon"]} for f in fixes_of(trip.trace)]
    rng = np.random.default_rng(0)
    last = drive[-1]
    parked = [
        {
            "time": last["time"] + 1.0 + k,
            "lat": last["lat"] + rng.normal(0.0, 3e-5),
            "lon": last["lon"] + rng.normal(0.0, 3e-5),
        }
        for k in range(3600)
    ]
    live = OnlineMatcher(default_net, lag=30.0)
    held = []
    for fix in drive + parked:
        live.push(fix)
        held.append(live.tail_fixes)
    # the stop is cut every ten minutes (one observation of a parked car otherwise)
    assert max(held) < 900
    result = live.close()
    offline = mapmatch.match(mapmatch.Trace.from_records(drive + parked), default_net)
    assert len(result.segments) == len(offline.segments) == 1
    assert result.matched_length_m == pytest.approx(offline.matched_length_m, abs=10.0)


def test_closing_a_trip(default_net: roadnets.RoadNetwork) -> None:
    live = OnlineMatcher(default_net, trip_id="t1")
    with pytest.raises(InvalidTraceError, match="at least 2"):
        live.close()
    far = OnlineMatcher(default_net, trip_id="t2")  # in the sea, kilometres from a road
    far.push_many([{"time": 1.7e9 + k, "lat": 43.60 + 1e-5 * k, "lon": 7.50} for k in range(5)])
    with pytest.raises(NoCandidatesError):
        far.close()
    with pytest.raises(NoCandidatesError):
        far.close()  # the same answer again


def test_the_lag_is_validated(default_net: roadnets.RoadNetwork) -> None:
    with pytest.raises(mapmatch.ConfigError, match="lag must be >= 0"):
        OnlineMatcher(default_net, lag=-1.0)
    with pytest.raises(mapmatch.ConfigError, match="at least lag"):
        OnlineMatcher(default_net, lag=30.0, max_lag=10.0)
    with pytest.raises(TypeError, match="number of seconds"):
        OnlineMatcher(default_net, lag="30")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="RoadNetwork"):
        OnlineMatcher("monaco.osm.pbf")  # type: ignore[arg-type]
    assert OnlineMatcher(default_net).lag_s == DEFAULT_LAG_S
    assert OnlineMatcher(default_net, lag=math.inf).lag_s is None
