"""The export module: one serialiser per output, from arrays, the same bytes as before."""

from __future__ import annotations

import importlib.util
import json
import pickle
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest

import mapmatch
from mapmatch import export
from mapmatch._jsontext import py_round
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trips
from mapmatch.viz import candidate_table

if TYPE_CHECKING:
    import roadnets

ROOT = Path(__file__).resolve().parents[2]

_spec = importlib.util.spec_from_file_location(
    "bench_export", ROOT / "benchmarks" / "bench_export.py"
)
assert _spec is not None
assert _spec.loader is not None
bench_export = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = bench_export
_spec.loader.exec_module(bench_export)


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
