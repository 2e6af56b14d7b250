from __future__ import annotations

import re
import subprocess
import sys
from typing import Any

import matplotlib
import numpy as np
import pytest

import mapmatch
import roadnets
from mapmatch import viz
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trip
from mapmatch.viz.data import MARK_COLOURS, SEGMENT_COLOURS

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


def _features(children: list[Any], geometry: str | None = None) -> list[dict[str, Any]]:
    """The GeoJSON features of a layer's GeoJson children (of one geometry type)."""
    found = [f for c in children if type(c).__name__ == "GeoJson" for f in c.data["features"]]
    return [f for f in found if geometry is None or f["geometry"]["type"] == geometry]


def _markers(children: list[Any], css_class: str) -> list[Any]:
    """The layer's DivIcon markers of one CSS class."""
    return [
        c
        for c in children
        if type(c).__name__ == "Marker" and css_class in str(c.icon.options.get("class_name"))
    ]


def test_map_has_every_layer_in_its_html(
    viz_result: mapmatch.MatchResult, viz_net: roadnets.RoadNetwork
) -> None:
    html = viz.match_map(viz_result, viz_net, candidates_of=FIX).get_root().render()
    for name in viz.LAYER_NAMES:
        assert f'"{name}"' in html
    assert "mm-legend" in html
    assert "confidence 0" in html  # the legend's colour scale


def test_map_layers_hold_one_mark_per_fix_edge_and_break(
    viz_result: mapmatch.MatchResult, viz_net: roadnets.RoadNetwork
) -> None:
    layers = _layers(viz.match_map(viz_result, viz_net))
    p = viz_result.points
    assert set(layers) == set(viz.LAYER_NAMES) - {"candidates"}
    raw = layers["raw points"]
    assert len(_features(raw, "Point")) == int(p.matched.sum())
    crosses = _markers(raw, "mm-unmatched")
    assert len(crosses) == int((~p.matched).sum())
    assert all("not matched" in _tooltip(c) for c in crosses)
    assert "RegularPolygonMarker" not in _kinds(raw)  # needs an SVG renderer: broke the canvas
    snapped = layers["snapped points"]
    assert len(_features(snapped, "Point")) == int(p.matched.sum())
    assert len(_features(snapped, "LineString")) == int(p.matched.sum())
    n_edges = sum(len(s.edges) for s in viz_result.segments)
    assert len(_features(layers["matched path"], "LineString")) == n_edges
    rings = _features(layers["breaks"], "Point")
    assert len(rings) == len(viz_result.breaks)
    assert f"starts at fix {viz_result.breaks[0]}" in rings[0]["properties"]["tip"]
    assert len(_markers(layers["start / end"], "mm-start")) == 1
    assert len(_markers(layers["start / end"], "mm-end")) == 1
    arrows = viz.data.direction_arrows(viz_result, viz_net)
    assert len(_markers(layers["direction"], "mm-arrow")) == len(arrows) > 0


def test_map_snapped_points_are_coloured_by_confidence(
    viz_result: mapmatch.MatchResult, viz_net: roadnets.RoadNetwork
) -> None:
    layers = _layers(viz.match_map(viz_result, viz_net))
    points = _features(layers["snapped points"], "Point")
    p = viz_result.points
    expected = [viz.confidence_colour(float(c)) for c in p.confidence[p.matched]]
    assert [f["properties"]["style"]["fillColor"] for f in points] == expected


def test_map_path_is_coloured_by_segment(
    viz_result: mapmatch.MatchResult, viz_net: roadnets.RoadNetwork
) -> None:
    path = _features(_layers(viz.match_map(viz_result, viz_net))["matched path"])
    expected = [
        SEGMENT_COLOURS[s.index % len(SEGMENT_COLOURS)]
        for s in viz_result.segments
        for _ in s.edges
    ]
    assert [f["properties"]["style"]["color"] for f in path] == expected


def test_map_legend_names_each_mark_in_its_colour(
    viz_result: mapmatch.MatchResult, viz_net: roadnets.RoadNetwork
) -> None:
    html = viz.match_map(viz_result, viz_net).get_root().render()
    legend = re.findall(r'data-layer=\\"([^"\\]+)\\" data-colour=\\"(#[0-9a-f]{6})\\"', html)
    assert ("raw points", MARK_COLOURS["unmatched"]) in legend
    assert ("breaks", MARK_COLOURS["break"]) in legend
    assert "gaps" not in {layer for layer, _ in legend}  # a trace without gaps
    for s in range(len(viz_result.segments)):
        assert ("matched path", SEGMENT_COLOURS[s]) in legend
    assert {layer for layer, _ in legend} <= set(viz.LAYER_NAMES)


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


def test_map_is_self_contained_by_default(
    viz_result: mapmatch.MatchResult, viz_net: roadnets.RoadNetwork
) -> None:
    html = viz.match_map(viz_result, viz_net).get_root().render()
    # no script or style sheet from anywhere: Leaflet itself is written into the page
    assert re.findall(r"<script[^>]+src=", html) == []
    assert re.findall(r"<link[^>]+stylesheet", html) == []
    js, _ = viz.assets.leaflet_files()
    assert js.read_text()[:2000] in html
    assert "url(images/" not in html  # the style sheet's images are inlined as data: URIs
    assert "url(data:image/png;base64," in html


def test_cdn_map_links_leaflet_alone(
    viz_result: mapmatch.MatchResult, viz_net: roadnets.RoadNetwork
) -> None:
    html = viz.match_map(viz_result, viz_net, assets="cdn").get_root().render()
    version = viz.assets.leaflet_version()
    scripts = re.findall(r'<script[^>]+src="([^"]+)"', html)
    sheets = re.findall(r'<link[^>]+href="([^"]+)"', html)
    assert scripts == [f"https://cdn.jsdelivr.net/npm/leaflet@{version}/dist/leaflet.js"]
    assert sheets == [f"https://cdn.jsdelivr.net/npm/leaflet@{version}/dist/leaflet.css"]
    assert len(html) < 0.8 * len(viz.match_map(viz_result, viz_net).get_root().render())


def test_map_rejects_an_unknown_asset_mode(
    viz_result: mapmatch.MatchResult, viz_net: roadnets.RoadNetwork
) -> None:
    with pytest.raises(ValueError, match=r"assets must be one of 'inline', 'cdn', got 'local'"):
        viz.match_map(viz_result, viz_net, assets="local")  # type: ignore[arg-type]


def test_missing_leaflet_package_names_it(
    viz_result: mapmatch.MatchResult,
    viz_net: roadnets.RoadNetwork,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import importlib.metadata

    real = importlib.metadata.distribution

    def distribution(name: str) -> Any:
        if name == "XStatic-Leaflet":
            raise importlib.metadata.PackageNotFoundError(name)
        return real(name)

    monkeypatch.setattr(importlib.metadata, "distribution", distribution)
    with pytest.raises(ImportError, match=r"xstatic-leaflet.*assets='cdn'"):
        viz.match_map(viz_result, viz_net)
    viz.match_map(viz_result, viz_net, assets="cdn")  # the CDN needs no package


def test_tooltips_escape_html(
    viz_result: mapmatch.MatchResult, viz_net: roadnets.RoadNetwork, monkeypatch: pytest.MonkeyPatch
) -> None:
    way = int(viz_net.arrays.edge_way_id[viz_result.segments[0].edges[0].edge])
    monkeypatch.setitem(viz_net.way_names, way, "<img src=x onerror=alert(1)>")
    path = _features(_layers(viz.match_map(viz_result, viz_net))["matched path"])
    tips = [f["properties"]["tip"] for f in path]
    assert any("&lt;img src=x onerror=alert(1)&gt;" in t for t in tips)
    assert not any("<img" in t for t in tips)


def test_road_network_layer_is_clipped_to_the_trace(
    viz_result: mapmatch.MatchResult, viz_net: roadnets.RoadNetwork
) -> None:
    roads = _features(_layers(viz.match_map(viz_result, viz_net, margin_m=100.0))["road network"])
    a = viz_net.arrays
    geometries = int(((a.edge_twin < 0) | (np.arange(a.n_edges) < a.edge_twin)).sum())
    assert 0 < len(roads) < geometries
    p = viz_result.points
    ok = np.isfinite(p.raw_lon)
    lon = np.concatenate([np.asarray(r["geometry"]["coordinates"])[:, 0] for r in roads])
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
        expected |= {"start", "end", "direction"}
        assert expected | segments <= set(labels)
        arrows = [c for c in ax.collections if c.get_label().endswith("direction")]
        assert len(arrows) == len(viz.data.direction_arrows(viz_result, viz_net))
        path_z = {labels[s].get_zorder() for s in segments}
        assert min(path_z) > labels["snapped points"].get_zorder()  # the path over the fixes
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


# ----------------------------------------------------------------------------- marks


@pytest.fixture(scope="module")
def one_hz(viz_net: roadnets.RoadNetwork) -> mapmatch.Trace:
    """A 1 Hz trip with fixes 100-129 removed: a 30 s outage."""
    cfg = SimulationConfig(interval_s=1.0, noise_m=3.0, route_length_m=1500.0)
    trace = simulate_trip(viz_net, cfg, seed=2, trace_id="one-hz").trace
    keep = np.ones(len(trace), dtype=bool)
    keep[100:130] = False
    return mapmatch.Trace(
        time=trace.time_s[keep], lon=trace.lon[keep], lat=trace.lat[keep], trace_id="one-hz"
    )


def _untimed(trace: mapmatch.Trace) -> mapmatch.Trace:
    return mapmatch.Trace(time=None, lon=trace.lon, lat=trace.lat, trace_id=trace.trace_id)


def test_direction_arrows_sit_on_the_path_and_point_the_way_driven(
    viz_result: mapmatch.MatchResult, viz_net: roadnets.RoadNetwork
) -> None:
    from pyproj import Geod
    from shapely.geometry import LineString, Point

    arrows = viz.data.direction_arrows(viz_result, viz_net, spacing_m=60.0)
    assert {a.segment for a in arrows} == {s.index for s in viz_result.segments}
    geod = Geod(ellps="WGS84")
    for seg in viz_result.segments:
        mine = [a for a in arrows if a.segment == seg.index]
        x, y = viz_net.project(seg.lon, seg.lat)
        line = LineString(np.column_stack((x, y)))
        cum = np.concatenate(([0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))))
        # one arrow 30 m in, then every 60 m
        assert len(mine) == int(np.ceil((line.length - 30.0) / 60.0))
        for k, arrow in enumerate(mine):
            ax, ay = viz_net.project(np.array([arrow.lon]), np.array([arrow.lat]))
            at = Point(float(ax[0]), float(ay[0]))
            assert line.distance(at) < 0.01  # on the path
            along = line.project(at)
            assert along == pytest.approx(30.0 + 60.0 * k, abs=0.01)
            piece = int(np.searchsorted(cum, along, side="right") - 1)
            # the geodesic azimuth of the path piece it sits on, from pyproj
            azimuth, _, _ = geod.inv(
                seg.lon[piece], seg.lat[piece], seg.lon[piece + 1], seg.lat[piece + 1]
            )
            assert abs((arrow.bearing_deg - azimuth + 180.0) % 360.0 - 180.0) < 0.5


def test_gaps_mark_an_outage_with_times_and_a_long_step_without(
    viz_net: roadnets.RoadNetwork, one_hz: mapmatch.Trace
) -> None:
    timed = mapmatch.match(one_hz, viz_net)
    gaps = viz.data.trace_gaps(timed, viz_net)
    assert [g.before for g in gaps] == [99]
    assert gaps[0].seconds == pytest.approx(31.0)
    assert "31 s without a fix between fix 99 and fix 100" in gaps[0].label
    assert viz.data.trace_gaps(timed, viz_net, min_gap_s=40.0) == []
    fig = viz.match_figure(timed, viz_net)
    try:
        drawn = [c for c in fig.axes[0].collections if c.get_label() == "gaps"]
        assert [len(c.get_segments()) for c in drawn] == [1]
    finally:
        plt.close(fig)
    untimed = mapmatch.match(_untimed(one_hz), viz_net)
    gaps = viz.data.trace_gaps(untimed, viz_net)
    assert [g.before for g in gaps] == [99]
    assert np.isnan(gaps[0].seconds)
    assert gaps[0].metres > 100.0
    assert "no times" in gaps[0].label


def test_break_labels_say_the_time_only_when_there_is_one(
    viz_net: roadnets.RoadNetwork, broken_trace: mapmatch.Trace
) -> None:
    timed = mapmatch.match(broken_trace, viz_net)
    marks = viz.data.break_marks(timed)
    assert [m.start for m in marks] == timed.breaks
    assert all(m.previous < m.start for m in marks)
    assert all(f" s after fix {m.previous}" in m.label for m in marks)
    untimed = mapmatch.match(_untimed(broken_trace), viz_net)
    marks = viz.data.break_marks(untimed)
    assert marks
    assert all(np.isnan(m.seconds) for m in marks)
    assert all("nan" not in m.label and " s after" not in m.label for m in marks)
    assert all(f"fix {m.previous} is the last one matched" in m.label for m in marks)
    html = viz.match_map(untimed, viz_net).get_root().render()
    assert not re.search(r"\bnan\b", html.replace("NaN", ""))


def test_endpoints_are_the_first_and_last_matched_positions(
    viz_result: mapmatch.MatchResult,
) -> None:
    (lon0, lat0, first), (lon1, lat1, last) = viz.data.endpoints(viz_result)
    matched = np.flatnonzero(viz_result.points.matched)
    assert (first, last) == (int(matched[0]), int(matched[-1]))
    assert (lon0, lat0) == (viz_result.points.lon[first], viz_result.points.lat[first])
    assert (lon1, lat1) == (viz_result.points.lon[last], viz_result.points.lat[last])
