from __future__ import annotations

import subprocess
import sys
from typing import Any

import matplotlib
import numpy as np
import pytest

import mapmatch
import roadnets
from mapmatch import viz
from mapmatch.simulate import SimulationConfig, simulate_trip

matplotlib.use("Agg")

import matplotlib.pyplot as plt

FIX = 12  # the fix whose candidates are drawn
SEA_FIXES = slice(30, 34)  # fixes moved 1.5 km south, into the sea off Monaco


@pytest.fixture(scope="module")
def viz_net(tmp_path_factory: pytest.TempPathFactory) -> roadnets.RoadNetwork:
    return roadnets.load(None, cache_dir=tmp_path_factory.mktemp("viz-cache"))


@pytest.fixture(scope="module")
def broken_trace(viz_net: roadnets.RoadNetwork) -> mapmatch.Trace:
    """A simulated trip whose fixes 30-33 lie far out at sea: the match must break there."""
    cfg = SimulationConfig(interval_s=2.0, noise_m=4.0, route_length_m=1500.0)
    trace = simulate_trip(viz_net, cfg, seed=11, trace_id="viz-trip").trace
    lat = trace.lat.copy()
    lat[SEA_FIXES] -= 0.0135
    return mapmatch.Trace(
        time=trace.time_s,
        lon=trace.lon,
        lat=lat,
        heading=trace.heading_deg,
        speed=trace.speed_mps,
        trace_id=trace.trace_id,
    )


@pytest.fixture(scope="module")
def viz_result(viz_net: roadnets.RoadNetwork, broken_trace: mapmatch.Trace) -> mapmatch.MatchResult:
    result = mapmatch.match(broken_trace, viz_net)
    assert result.breaks, "the sea fixes should split the trace"
    assert not result.points.matched[SEA_FIXES].any()
    return result


def _layers(fmap: Any) -> dict[str, list[Any]]:
    """Children of each named FeatureGroup of a folium map."""
    return {
        child.layer_name: list(child._children.values())
        for child in fmap._children.values()
        if type(child).__name__ == "FeatureGroup"
    }


def _kinds(children: list[Any]) -> list[str]:
    return [type(c).__name__ for c in children]


def _tooltip(child: Any) -> str:
    return " ".join(str(t.text) for t in child._children.values() if type(t).__name__ == "Tooltip")


def test_map_has_every_layer_in_its_html(
    viz_result: mapmatch.MatchResult, viz_net: roadnets.RoadNetwork
) -> None:
    html = viz.match_map(viz_result, viz_net, candidates_of=FIX).get_root().render()
    for name in ("road network", "raw points", "snapped points", "matched path", "breaks"):
        assert f'"{name}"' in html
    assert '"candidates"' in html
    assert "confidence" in html  # the colour scale's caption


def test_map_layers_hold_one_mark_per_fix_edge_and_break(
    viz_result: mapmatch.MatchResult, viz_net: roadnets.RoadNetwork
) -> None:
    layers = _layers(viz.match_map(viz_result, viz_net))
    p = viz_result.points
    assert set(layers) == set(viz.LAYER_NAMES) - {"candidates"}
    raw = _kinds(layers["raw points"])
    assert raw.count("CircleMarker") == int(p.matched.sum())
    assert raw.count("RegularPolygonMarker") == int((~p.matched).sum())
    snapped = _kinds(layers["snapped points"])
    assert snapped.count("CircleMarker") == int(p.matched.sum())
    n_edges = sum(len(s.edges) for s in viz_result.segments)
    assert _kinds(layers["matched path"]) == ["PolyLine"] * n_edges
    circles = [c for c in layers["breaks"] if type(c).__name__ == "CircleMarker"]
    assert len(circles) == len(viz_result.breaks)
    assert f"starts at fix {viz_result.breaks[0]}" in _tooltip(circles[0])


def test_map_snapped_points_are_coloured_by_confidence(
    viz_result: mapmatch.MatchResult, viz_net: roadnets.RoadNetwork
) -> None:
    layers = _layers(viz.match_map(viz_result, viz_net))
    markers = [c for c in layers["snapped points"] if type(c).__name__ == "CircleMarker"]
    p = viz_result.points
    expected = [viz.confidence_colour(float(c)) for c in p.confidence[p.matched]]
    assert [m.options["fillColor"] for m in markers] == expected


def test_map_candidates_show_every_candidate_with_scores(
    viz_result: mapmatch.MatchResult, viz_net: roadnets.RoadNetwork
) -> None:
    table = viz.candidate_table(viz_result, viz_net, FIX)
    layers = _layers(viz.match_map(viz_result, viz_net, candidates_of=FIX))
    tips = [_tooltip(c) for c in layers["candidates"]]
    edge_lines = [t for t, c in zip(tips, layers["candidates"], strict=True) if "candidate:" in t]
    # each candidate: its edge line and its projected point carry the scores
    assert len(edge_lines) == 2 * len(table)
    for edge in table["edge"]:
        assert any(f"edge {edge} " in t and "log emission" in t for t in edge_lines)
    assert sum("CHOSEN" in t for t in edge_lines) == 2 * int(table["chosen"].sum())


def test_map_draws_no_tiles_unless_asked(
    viz_result: mapmatch.MatchResult, viz_net: roadnets.RoadNetwork
) -> None:
    offline = viz.match_map(viz_result, viz_net)
    assert not any(type(c).__name__ == "TileLayer" for c in offline._children.values())
    assert "tile.openstreetmap.org" not in offline.get_root().render()
    url = "http://127.0.0.1:8080/tiles/{z}/{x}/{y}.png"
    online = viz.match_map(viz_result, viz_net, tiles=url, attribution="local tiles")
    assert url in online.get_root().render()


def test_road_network_layer_is_clipped_to_the_trace(
    viz_result: mapmatch.MatchResult, viz_net: roadnets.RoadNetwork
) -> None:
    roads = _layers(viz.match_map(viz_result, viz_net, margin_m=100.0))["road network"]
    a = viz_net.arrays
    geometries = int(((a.edge_twin < 0) | (np.arange(a.n_edges) < a.edge_twin)).sum())
    assert 0 < len(roads) < geometries
    p = viz_result.points
    ok = np.isfinite(p.raw_lon)
    lon = np.concatenate([np.asarray(r.locations)[:, 1] for r in roads])
    # margin 100 m is about 0.0013 deg of longitude and 0.0009 deg of latitude at Monaco
    assert lon.min() > min(p.raw_lon[ok].min(), np.nanmin(p.lon)) - 0.01
    assert lon.max() < max(p.raw_lon[ok].max(), np.nanmax(p.lon)) + 0.01


def test_figure_has_the_expected_artists(
    viz_result: mapmatch.MatchResult, viz_net: roadnets.RoadNetwork
) -> None:
    fig = viz.match_figure(viz_result, viz_net, candidates_of=FIX)
    try:
        ax = fig.axes[0]
        labels = {c.get_label(): c for c in ax.collections}
        segments = {f"matched path, segment {s.index}" for s in viz_result.segments}
        assert len(segments) >= 2
        expected = {"road network", "raw points", "snapped points", "breaks", "candidates"}
        assert expected | segments <= set(labels)
        p = viz_result.points
        assert len(labels["snapped points"].get_offsets()) == int(p.matched.sum())
        colours = np.asarray(labels["snapped points"].get_array())
        np.testing.assert_allclose(colours, p.confidence[p.matched])
        assert len(labels["breaks"].get_offsets()) == len(viz_result.breaks)
        table = viz.candidate_table(viz_result, viz_net, FIX)
        assert len(labels["candidates"].get_segments()) == len(table)
        assert len(fig.axes) == 2  # the map and its confidence colour bar
        assert fig.axes[1].get_ylabel() == "confidence"
    finally:
        plt.close(fig)


def test_figure_draws_on_given_axes(
    viz_result: mapmatch.MatchResult, viz_net: roadnets.RoadNetwork
) -> None:
    fig, (left, right) = plt.subplots(1, 2)
    try:
        assert viz.match_figure(viz_result, viz_net, ax=right) is fig
        assert not left.collections
        assert right.collections
    finally:
        plt.close(fig)


def test_candidate_table_without_diagnostics_lists_nearby_edges(
    viz_result: mapmatch.MatchResult, viz_net: roadnets.RoadNetwork
) -> None:
    table = viz.candidate_table(viz_result, viz_net, FIX)
    assert tuple(table.columns) == viz.CANDIDATE_COLUMNS
    assert len(table) >= 2
    assert (table["fix"] == FIX).all()
    assert table["distance_m"].is_monotonic_increasing
    assert table["distance_m"].max() <= mapmatch.MatchConfig().search_radius_m
    chosen = table[table["chosen"]]
    assert chosen["edge"].tolist() == [int(viz_result.points.edge[FIX])]


def test_candidate_table_rejects_a_fix_outside_the_trace(
    viz_result: mapmatch.MatchResult, viz_net: roadnets.RoadNetwork
) -> None:
    n = len(viz_result.points.time_s)
    with pytest.raises(IndexError, match=f"fix {n} is outside the trace"):
        viz.candidate_table(viz_result, viz_net, n)


def test_candidate_table_uses_the_model_scores_with_diagnostics(
    viz_net: roadnets.RoadNetwork, broken_trace: mapmatch.Trace
) -> None:
    result = mapmatch.match(broken_trace, viz_net, diagnostics=True)
    assert result.diagnostics is not None
    fix = int(result.diagnostics.candidates["fix"].iloc[-1])
    table = viz.candidate_table(result, viz_net, fix)
    assert np.isfinite(table["log_emission"]).all()
    assert table["posterior"].sum() == pytest.approx(1.0, abs=1e-6)
    (chosen,) = table.loc[table["chosen"], "edge"].tolist()
    placed = int(result.points.edge[fix])
    # the point is on the chosen edge, or at the junction it starts at when the chosen
    # candidate was a sliver past it (the path does not end on a road it never drove)
    a = viz_net.arrays
    assert placed == chosen or (
        a.edge_v[placed] == a.edge_u[chosen]
        and result.points.offset_m[fix] == pytest.approx(a.edge_length_m[placed])
    )


def test_import_mapmatch_loads_no_plotting_library() -> None:
    code = (
        "import sys, mapmatch, mapmatch.viz; "
        "print(sorted(m for m in ('folium', 'matplotlib', 'branca') if m in sys.modules))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    assert out.stdout.strip() == "[]"


def test_missing_folium_names_the_extra(
    viz_result: mapmatch.MatchResult,
    viz_net: roadnets.RoadNetwork,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setitem(sys.modules, "folium", None)
    with pytest.raises(ImportError, match=r"pip install mapmatch\[viz\]"):
        viz.match_map(viz_result, viz_net)


def test_missing_matplotlib_names_the_extra(
    viz_result: mapmatch.MatchResult,
    viz_net: roadnets.RoadNetwork,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setitem(sys.modules, "matplotlib.pyplot", None)
    with pytest.raises(ImportError, match=r"pip install mapmatch\[viz\]"):
        viz.match_figure(viz_result, viz_net)
