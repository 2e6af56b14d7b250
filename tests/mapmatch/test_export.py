"""The export module: one serialiser per output, from arrays, the same bytes as before."""

from __future__ import annotations

import dataclasses
import json
import pickle
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest

import mapmatch
from mapmatch import export
from mapmatch._jsontext import py_round
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trips, with_columns
from mapmatch.viz import candidate_table
from tests.benchmarks.scripts import load_script

if TYPE_CHECKING:
    import roadnets


bench_export = load_script("bench_export.py")


def _legacy_text(result: mapmatch.MatchResult) -> bytes:
    """The legacy serialiser's bytes (what to_geojson + json.dumps wrote before)."""
    return bench_export.legacy_geojson_bytes(result)


def _current_without_new_fields(result: mapmatch.MatchResult) -> bytes:
    """geojson_bytes with the fields added since the legacy serialiser taken out, re-dumped."""
    doc = bench_export._without_new_fields(json.loads(export.geojson_bytes(result)))
    return json.dumps(doc, allow_nan=False, separators=(",", ":")).encode("ascii")


@pytest.fixture(scope="module")
def results(default_net: roadnets.RoadNetwork) -> list[mapmatch.MatchResult]:
    """Matches of many shapes: 1 s and 15 s, outliers, outages, breaks, unmatched, no times."""
    out = []
    for interval, seed in ((1.0, 1), (15.0, 2), (5.0, 3)):
        cfg = SimulationConfig(interval_s=interval, outlier_rate=0.05, outage_rate=0.1)
        for trip in simulate_trips(default_net, cfg, count=3, seed=seed):
            out.append(mapmatch.match(trip.trace, default_net))
    trace = simulate_trips(default_net, SimulationConfig(interval_s=2.0), count=1, seed=9)[0].trace
    lat = trace.lat.copy()
    lat[10:16] -= 0.03  # six fixes 3 km out at sea: unmatched, and a break
    broken = mapmatch.Trace(time=trace.time_s, lon=trace.lon, lat=lat, trace_id="at-sea")
    out.append(mapmatch.match(broken, default_net))
    out.append(mapmatch.match(mapmatch.Trace(lon=trace.lon, lat=trace.lat), default_net))
    still = mapmatch.Trace(time=[0, 1], lon=[trace.lon[0]] * 2, lat=[trace.lat[0]] * 2)
    out.append(mapmatch.match(still, default_net))  # a path of one position
    return out


def test_the_results_cover_the_shapes(results: list[mapmatch.MatchResult]) -> None:
    assert any(len(r.segments) > 1 for r in results)
    assert any(not r.points.matched.all() for r in results)
    assert any(np.isnan(r.points.time_s).all() for r in results)
    assert any(len(s.lon) == 1 for r in results for s in r.segments)


def test_geojson_bytes_keep_every_legacy_field_byte_for_byte(
    results: list[mapmatch.MatchResult],
) -> None:
    for result in results:
        assert _current_without_new_fields(result) == _legacy_text(result), result.trace_id


def test_text_and_dict_are_one_document(results: list[mapmatch.MatchResult]) -> None:
    for result in results:
        text = export.geojson_bytes(result)
        doc = result.to_geojson()
        assert json.loads(text) == doc
        assert json.dumps(doc, allow_nan=False, separators=(",", ":")).encode() == text


def test_a_result_without_segments_writes_its_points_alone(
    results: list[mapmatch.MatchResult],
) -> None:
    result = results[0]
    n = len(result.points.time_s)
    lost = dataclasses.replace(
        result.points, matched=np.zeros(n, dtype=bool), segment=np.full(n, -1)
    )
    empty = dataclasses.replace(result, segments=[], points=lost)
    text = export.geojson_bytes(empty)
    assert json.dumps(empty.to_geojson(), allow_nan=False, separators=(",", ":")).encode() == text
    kinds = [f["properties"]["kind"] for f in json.loads(text)["features"]]
    assert kinds == ["point"] * n
    assert len(export.edge_table(empty)) == 0


def test_the_head_is_what_json_dumps_writes(results: list[mapmatch.MatchResult]) -> None:
    result = dataclasses.replace(results[0], trace_id='bus "7" \\ Straße\n\u2603')
    text = export.geojson_bytes(result)
    assert json.dumps(result.to_geojson(), allow_nan=False, separators=(",", ":")).encode() == text
    assert b'"trace_id":"bus \\"7\\" \\\\ Stra\\u00dfe\\n\\u2603"' in text
    unknown = dataclasses.replace(results[0], matched_length_m=float("nan"))
    with pytest.raises(ValueError, match="not JSON compliant"):
        export.geojson_bytes(unknown)
    with pytest.raises(ValueError, match="not JSON compliant"):
        json.dumps(unknown.to_geojson(), allow_nan=False)


def test_a_pickled_result_writes_the_same_document(results: list[mapmatch.MatchResult]) -> None:
    for result in results[:3]:
        fresh = pickle.loads(pickle.dumps(result))
        assert export.geojson_bytes(fresh) == export.geojson_bytes(result)
        assert fresh.config == result.config
        assert fresh.segments[0]._net is None  # carries its geometry, not the network


def test_segment_attributes_are_read_from_the_network(
    results: list[mapmatch.MatchResult], default_net: roadnets.RoadNetwork
) -> None:
    seg = results[0].segments[0]
    a = default_net.arrays
    edges = seg.edges
    assert [e.edge for e in edges] == seg.edge.tolist()
    e = edges[0]
    assert e.osm_way_ids == (int(a.edge_way_id[e.edge]),)
    assert e.length_m == float(a.edge_length_m[e.edge])
    assert e.speed_limit_kph == pytest.approx(float(a.edge_speed_mps[e.edge]) * 3.6)
    assert e.name == default_net.way_names.get(e.osm_way_ids[0], "")
    assert e.road_class in {"primary", "secondary", "tertiary", "residential", "service"} | {
        "trunk",
        "unclassified",
        "living_street",
        "motorway",
        "primary_link",
        "secondary_link",
        "tertiary_link",
        "trunk_link",
        "motorway_link",
        "road",
    }
    assert seg.length_m == pytest.approx(sum(x.driven_m for x in edges))
    assert repr(seg).startswith(f"<Segment 0: fixes {seg.first}-{seg.last}, {len(edges)} edges")


def test_result_records_its_config_and_candidate_table_uses_it(
    default_net: roadnets.RoadNetwork,
) -> None:
    trace = simulate_trips(default_net, SimulationConfig(interval_s=2.0), count=1, seed=4)[0].trace
    narrow = mapmatch.MatchConfig(search_radius_m=12.0)
    result = mapmatch.match(trace, default_net, narrow)
    assert result.config == narrow
    table = candidate_table(result, default_net, 3)
    assert len(table) > 0
    assert (table["distance_m"] <= 12.0 + 1e-6).all()
    wide = candidate_table(mapmatch.match(trace, default_net), default_net, 3)
    assert len(wide) > len(table)  # the default 50 m finds more edges around the same fix


def test_result_repr_is_one_short_line(results: list[mapmatch.MatchResult]) -> None:
    text = repr(results[0])
    assert "\n" not in text
    assert len(text) < 200
    assert text.startswith(f"<MatchResult {results[0].trace_id!r}: ")


@pytest.mark.parametrize("digits", [0, 3, 4, 7])
def test_py_round_is_pythons_round(digits: int) -> None:
    rng = np.random.default_rng(digits)
    values = np.concatenate(
        (
            rng.uniform(-1e4, 1e4, 20_000),
            np.arange(-2000, 2000) * 0.5 * 10.0**-digits,  # exact and near halves
            np.arange(-2000, 2000) * 0.5 * 10.0**-digits + 1e-17,
            [0.0, -0.0, 1e300, -1e300, 2.675, 1.0005, 0.125, 5e-324],
        )
    )
    expected = [round(v, digits) for v in values.tolist()]
    got = py_round(values, digits).tolist()
    assert got == expected
    assert [repr(v) for v in got] == [repr(v) for v in expected]  # signed zeros too


def test_non_finite_numbers_are_null(results: list[mapmatch.MatchResult]) -> None:
    result = results[-3]  # the one at sea
    doc: dict[str, Any] = json.loads(export.geojson_bytes(result))
    unmatched = [
        f for f in doc["features"] if f["properties"]["kind"] == "point" and not f["geometry"]
    ]
    assert unmatched
    assert {f["properties"]["offset_m"] for f in unmatched} == {None}
    assert {f["properties"]["u"] for f in unmatched} == {None}


# --------------------------------------------------------------------------- issue 16: timing


@pytest.fixture(scope="module")
def steady(default_net: roadnets.RoadNetwork) -> list[tuple[Any, mapmatch.MatchResult]]:
    """1 Hz trips without stops (the truth's time at each place is unambiguous), matched."""
    cfg = SimulationConfig(interval_s=1.0, noise_m=4.0, stop_probability=0.0)
    trips = simulate_trips(default_net, cfg, count=4, seed=21)
    return [(trip, mapmatch.match(trip.trace, default_net)) for trip in trips]


def test_edges_are_entered_when_the_truth_says(
    steady: list[tuple[Any, mapmatch.MatchResult]],
) -> None:
    errors = []
    for trip, result in steady:
        table = export.edge_table(result)
        driven = np.array([e.end_offset_m - e.start_offset_m for e in trip.edges])
        true_start = np.concatenate(([0.0], np.cumsum(driven)[:-1]))
        true_entry = np.interp(true_start, trip.dense_distance_m, trip.dense_time_s)
        place: dict[int, int] = {}
        for k, e in enumerate(trip.edges):
            place.setdefault(e.edge, k)
        for i in range(1, len(table)):
            k = place.get(int(table.edge[i]), 0)
            if k > 0 and abs(table.path_start_m[i] - true_start[k]) < 5.0:
                errors.append(table.entry_time_s[i] - true_entry[k])
    errors_s = np.abs(np.array(errors))
    assert len(errors_s) > 20
    assert np.median(errors_s) < 1.0  # 4 m of noise at about 10 m/s
    assert np.percentile(errors_s, 90) < 2.5


def test_edge_times_tile_each_segment(results: list[mapmatch.MatchResult]) -> None:
    timed = [r for r in results if np.isfinite(r.points.time_s).all()]
    assert len(timed) >= 5
    for result in timed:
        table = export.edge_table(result)
        p = result.points
        for seg in result.segments:
            rows = table.segment == seg.index
            entry, exit_ = table.entry_time_s[rows], table.exit_time_s[rows]
            fixes = np.flatnonzero((p.segment == seg.index) & p.matched)
            assert entry[0] == p.time_s[fixes[0]]
            assert exit_[-1] == p.time_s[fixes[-1]]
            assert (np.diff(entry) >= 0).all()
            assert (exit_ >= entry).all()
            np.testing.assert_array_equal(exit_[:-1], entry[1:])  # one edge left, next entered
        speed = table.mean_speed_kph
        moving = table.duration_s > 0
        np.testing.assert_allclose(
            speed[moving], 3.6 * table.driven_m[moving] / table.duration_s[moving]
        )
        assert np.isnan(speed[~moving]).all()


def test_without_times_every_time_is_null(results: list[mapmatch.MatchResult]) -> None:
    result = next(r for r in results if np.isnan(r.points.time_s).all())
    doc = result.to_geojson()
    edges = [
        e
        for f in doc["features"]
        if f["properties"]["kind"] == "segment"
        for e in f["properties"]["edges"]
    ]
    assert edges
    for name in ("entry_time", "exit_time", "duration_s", "mean_speed_kph"):
        assert {e[name] for e in edges} == {None}
    frame = export.edges_frame(result)
    assert frame["entry_time"].isna().all()
    assert str(frame["entry_time"].dtype) == "datetime64[us, UTC]"


def test_edges_carry_street_name_class_and_limit(
    results: list[mapmatch.MatchResult], default_net: roadnets.RoadNetwork
) -> None:
    from roadnets.drivable import ROAD_CLASSES

    a = default_net.arrays
    for result in results[:4]:
        table = export.edge_table(result)
        assert list(table.name) == default_net.way_names.names_of(table.way_id)
        assert set(table.road_class) <= set(ROAD_CLASSES)
        assert list(table.road_class) == [ROAD_CLASSES[c] for c in a.edge_class[table.edge]]
        np.testing.assert_allclose(table.speed_limit_kph, a.edge_speed_mps[table.edge] * 3.6)
        doc = result.to_geojson()
        edges = [
            e
            for f in doc["features"]
            if f["properties"]["kind"] == "segment"
            for e in f["properties"]["edges"]
        ]
        assert [e["name"] for e in edges] == [n or None for n in table.name]
        assert any(e["name"] for e in edges)  # Monaco's streets have names
        frame = export.edges_frame(result)
        assert frame["name"].fillna("").tolist() == list(table.name)
        assert frame["name"].isna().tolist() == [not n for n in table.name]


def test_fixes_know_their_place_on_the_path(results: list[mapmatch.MatchResult]) -> None:
    for result in results:
        p = result.points
        pos = export.path_positions(result)
        table = export.edge_table(result, pos)
        matched = p.matched
        assert (pos.edge_index[matched] >= 0).all()
        assert (pos.edge_index[~matched] == -1).all()
        assert np.isnan(pos.along_m[~matched]).all()
        for seg in result.segments:
            fixes = np.flatnonzero((p.segment == seg.index) & matched)
            k = pos.edge_index[fixes]
            assert (seg.edge[k] == p.edge[fixes]).all()  # the fix's own edge
            rows = np.flatnonzero(table.segment == seg.index)[k]
            start = table.path_start_m[rows] + p.offset_m[fixes] - table.start_offset_m[rows]
            np.testing.assert_allclose(pos.along_m[fixes], start, atol=1e-6)
            assert (pos.along_m[fixes] <= seg.length_m + 1e-6).all()
        frame = result.to_dataframe()
        assert frame["edge_index"].tolist()[:3] == pos.edge_index.tolist()[:3]


def test_an_edge_driven_twice_is_told_apart_by_the_order_of_the_fixes(
    default_net: roadnets.RoadNetwork,
) -> None:
    from mapmatch._timing import _stretch_of

    a = default_net.arrays
    e, f = 3, int(a.out_edge[a.out_ptr[a.edge_v[3]]])
    length = float(a.edge_length_m[e])
    seg = mapmatch.Segment(
        0,
        0,
        5,
        np.array([e, f, e, f]),
        np.zeros(4),
        np.array([length, float(a.edge_length_m[f]), length, float(a.edge_length_m[f])]),
        net=default_net,
    )
    fix_edge = np.array([e, e, f, e, e, f])
    other = float(a.edge_length_m[f])
    offset = np.array([0.1, 0.6, 0.5, 0.2, 0.7, 0.5]) * np.array(
        [length] * 2 + [other] + [length] * 2 + [other]
    )
    assert _stretch_of(seg, fix_edge, offset).tolist() == [0, 0, 1, 2, 2, 3]


@pytest.mark.parametrize("decimals", [0, 1, 3, 4, 7, 9])
def test_the_number_kernel_writes_what_repr_writes(decimals: int) -> None:
    from mapmatch._jsontext import Floats

    rng = np.random.default_rng(decimals)
    values = np.concatenate(
        (
            py_round(rng.uniform(-5000, 5000, 5000), decimals),
            np.round(rng.uniform(-180, 180, 5000), decimals),
            py_round(rng.uniform(-1, 1, 5000), decimals),
            1.7e9 + py_round(rng.uniform(0, 1000, 500), 3),  # epoch times
            rng.uniform(-1e6, 1e6, 500),  # more decimals than the column's: repr's job
            [0.0, -0.0, 1e-5, 5e-5, 1e-4, 1.2e-4, 1e14, 999999999999999.0, 1e15, 1e16],
            [2.5, 10.0, 100.0, 0.1, 0.2, 0.3, 7e-4, np.nan, np.inf, -np.inf],
        )
    )
    cells = Floats(values, decimals=decimals).cells(len(values))
    assert cells == [repr(v) if np.isfinite(v) else "null" for v in values.tolist()]


#: Street names that are easy to write wrong: quotes, backslashes, accents, an emoji, controls.
_AWKWARD_NAMES = ('Rue "Grimaldi"', "C:\\Voie", "Straße\tNord\x7f", "\U0001f697 Lane")


def _named_block() -> roadnets.RoadNetwork:
    """The warm-up's block of two-way streets, about 100 m a side, each side an awkward name."""
    import roadnets
    from mapmatch.warm_block import block_graph

    G: Any = block_graph()
    sides = sorted({tuple(sorted((u, v))) for u, v in G.edges()})
    for u, v, data in G.edges(data=True):
        way = sides.index(tuple(sorted((u, v))))
        data.update(osmid=100 + way, name=_AWKWARD_NAMES[way])
    return roadnets.from_graph(G, network_id="named block")


def _around_the_block(net: roadnets.RoadNetwork) -> mapmatch.MatchResult:
    """Once around the block, along every side."""
    lon = [7.4201, 7.4206, 7.4211, 7.4212, 7.4212, 7.4206, 7.4201, 7.42, 7.42]
    lat = [43.73001, 43.73002, 43.73001, 43.7304, 43.7308, 43.73089, 43.73089, 43.7305, 43.7302]
    trace = mapmatch.Trace(time=np.arange(len(lon)) * 5.0, lon=lon, lat=lat)
    return mapmatch.match(trace, net)


def _edge_names(doc: dict[str, Any]) -> list[str | None]:
    return [
        e["name"]
        for f in doc["features"]
        if f["properties"]["kind"] == "segment"
        for e in f["properties"]["edges"]
    ]


def test_street_names_are_written_as_json_dumps_writes_them() -> None:
    from mapmatch import _features

    net = _named_block()
    assert _features._network_inputs(net) is not None  # read inside the compiled call
    result = _around_the_block(net)
    text = export.geojson_bytes(result)
    doc = result.to_geojson()
    assert json.dumps(doc, allow_nan=False, separators=(",", ":")).encode() == text
    names = _edge_names(json.loads(text))
    assert set(names) == set(_AWKWARD_NAMES)
    assert names == [e.name or None for s in result.segments for e in s.edges]
    for escaped in (b'"Rue \\"Grimaldi\\""', b'"C:\\\\Voie"', b'"Stra\\u00dfe\\tNord\\u007f"',
                    b'"\\ud83d\\ude97 Lane"'):  # fmt: skip
        assert escaped in text


def test_an_edited_street_name_is_written_as_edited() -> None:
    from mapmatch import _features

    net = _named_block()
    net.way_names[100] = 'Avenue "Nouvelle"'  # this process only; read through the edit
    assert _features._network_inputs(net) is None
    edited = _around_the_block(net)
    text = export.geojson_bytes(edited)
    assert json.dumps(edited.to_geojson(), allow_nan=False, separators=(",", ":")).encode() == text
    assert set(_edge_names(json.loads(text))) == {'Avenue "Nouvelle"', *_AWKWARD_NAMES[1:]}


def test_a_result_makes_its_segments_when_read_and_writes_its_document_without_them(
    default_net: roadnets.RoadNetwork,
) -> None:
    cfg = SimulationConfig(interval_s=15.0, outlier_rate=0.05, outage_rate=0.1)
    for trip in simulate_trips(default_net, cfg, count=4, seed=5):
        trace = with_columns(trip.trace, ("heading", "speed"))  # no odometer to move the ends
        result = mapmatch.match(trace, default_net)
        assert result.placed is not None  # the assembly's arrays, no Segment made yet
        from_arrays = export.geojson_bytes(result)
        assert result.placed is not None  # the document did not need them
        segments = result.segments  # read: made now, and kept
        assert result.placed is None
        assert result.segments is segments
        assert export.geojson_bytes(result) == from_arrays  # the objects' document is the same
        for s in segments:  # the assembly added each length as the segment adds it
            again = mapmatch.Segment(
                s.index, s.first, s.last, s.edge, s.start_offset_m, s.end_offset_m, net=default_net
            )
            assert again.length_m == s.length_m
        assert sum(s.length_m for s in segments) == result.matched_length_m
        assert result.breaks == [s.first for s in segments[1:]]


def test_a_result_not_read_yet_pickles_copies_and_replaces_with_its_segments(
    default_net: roadnets.RoadNetwork,
) -> None:
    trip = simulate_trips(default_net, SimulationConfig(interval_s=15.0), count=1, seed=6)[0]
    trace = with_columns(trip.trace, ())
    result = mapmatch.match(trace, default_net)
    document = export.geojson_bytes(result)
    fresh = pickle.loads(pickle.dumps(mapmatch.match(trace, default_net)))
    assert fresh.placed is None
    assert fresh.segments[0]._net is None  # carries its geometry, not the network
    assert len(fresh.segments) == len(result.segments)
    renamed = dataclasses.replace(mapmatch.match(trace, default_net), trace_id="renamed")
    assert renamed.placed is None
    assert [s.edge.tolist() for s in renamed.segments] == [s.edge.tolist() for s in result.segments]
    assert export.geojson_bytes(result) == document
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        _ = result.nothing


def test_moved_ends_make_the_segments_at_once(default_net: roadnets.RoadNetwork) -> None:
    trip = simulate_trips(default_net, SimulationConfig(interval_s=15.0), count=1, seed=7)[0]
    assert trip.trace.odometer_m is not None
    result = mapmatch.match(trip.trace, default_net)
    assert result.placed is None  # the odometer moved the ends: segments made as moved
    off = mapmatch.match(trip.trace, default_net, mapmatch.MatchConfig(odometer_end_sigmas=0))
    assert off.placed is not None
    assert sum(s.length_m for s in result.segments) == result.matched_length_m
