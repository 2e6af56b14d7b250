"""Saved match maps opened in a real headless Chromium, offline: nothing may fail to draw.

The trip is simulated at 1 Hz on the embedded network, with four fixes moved out to sea (they
stay unmatched: the case that used to stop the page with ``this._renderer._setPath is not a
function``) and a 30 s outage (a gap). Each map is saved to a file and opened from disk with
name resolution switched off; the test fails on any console error, failed request or
request leaving the page, then reads Leaflet's own objects to check that every layer drew
what the match holds, in the right order, and that the legend's colours are the drawn ones.
"""

from __future__ import annotations

import json
import re
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest

import mapmatch
import roadnets
from mapmatch import viz
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trip
from mapmatch.viz.data import (
    CONFIDENCE_COLOURS,
    MARK_COLOURS,
    SEGMENT_COLOURS,
    confidence_colour,
    direction_arrows,
    trace_gaps,
)

if TYPE_CHECKING:
    from collections.abc import Callable
    from pathlib import Path

SEA = slice(40, 44)  # fixes moved 1.5 km south, into the sea off Monaco
OUTAGE = slice(100, 130)  # fixes removed: 30 s without a fix

#: Everything the test reads from the page, in one pass (the map is the page's only L.Map).
SUMMARY_JS = """
(() => {
  const maps = Object.values(window).filter((v) => v instanceof L.Map);
  const map = maps[0];
  const leaves = (layer) => (layer.getLayers ? layer.getLayers().flatMap(leaves) : [layer]);
  const kind = (l) => l instanceof L.CircleMarker ? "circle"
    : l instanceof L.Polyline ? "line" : l instanceof L.Marker ? "marker" : "other";
  const owner = new Map();
  const layers = {};
  for (const [name, group] of Object.entries(map.mapmatch.layers)) {
    const all = leaves(group);
    all.forEach((l) => owner.set(l, name));
    const drawn = all.filter((l) => map.hasLayer(l) && (
      (l._renderer instanceof L.Canvas && l._order !== undefined)
      || (l._icon && document.body.contains(l._icon))));
    const counts = {};
    drawn.forEach((l) => { counts[kind(l)] = (counts[kind(l)] || 0) + 1; });
    const colours = new Set();
    all.forEach((l) => {
      if (l.options.color) colours.add(l.options.color);
      if (l.options.fill && l.options.fillColor) colours.add(l.options.fillColor);
      const html = l.options.icon && l.options.icon.options.html;
      if (html) (html.match(/#[0-9a-f]{6}/g) || []).forEach((c) => colours.add(c));
    });
    layers[name] = {
      total: all.length, drawn: drawn.length, counts: counts, colours: [...colours],
      icons: all.filter((l) => l._icon).map((l) => l._icon.className),
      visible_icons: all.filter((l) => l._icon && l._icon.style.opacity !== "0").length,
      tooltips: all.filter((l) => l.getTooltip && l.getTooltip()).map(
        (l) => l.getTooltip().getContent()),
    };
  }
  // canvas drawing order, bottom to top, as layer names
  const order = [];
  const renderers = new Set([...owner.keys()].map((l) => l._renderer).filter(Boolean));
  renderers.forEach((r) => {
    for (let o = r._drawFirst; o; o = o.next) order.push(owner.get(o.layer) || "?");
  });
  const painted = [...document.querySelectorAll(".leaflet-pane canvas")].map((c) => {
    const d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
    let n = 0;
    for (let i = 3; i < d.length; i += 4) if (d[i]) n++;
    return n;
  });
  return {
    maps: maps.length,
    renderers: [...renderers].map((r) => r.constructor === L.Canvas ? "canvas" : "svg"),
    layers: layers,
    order: order,
    painted: painted,
    control: [...document.querySelectorAll(".leaflet-control-layers-overlays label")].map(
      (e) => e.textContent.trim()),
    legend: [...document.querySelectorAll(".mm-legend-item")].map((e) => ({
      layer: e.dataset.layer, colour: e.dataset.colour, label: e.textContent.trim()})),
  };
})()
"""


@pytest.fixture(scope="module")
def net(tmp_path_factory: pytest.TempPathFactory) -> roadnets.RoadNetwork:
    return roadnets.load(None, cache_dir=tmp_path_factory.mktemp("browser-cache"))


def _one_hz_trip(net: roadnets.RoadNetwork, *, times: bool) -> mapmatch.Trace:
    cfg = SimulationConfig(interval_s=1.0, noise_m=4.0, outlier_rate=0.02, route_length_m=1800.0)
    trip = simulate_trip(net, cfg, seed=3, trace_id="one-hz").trace
    keep = np.ones(len(trip), dtype=bool)
    keep[OUTAGE] = False
    lat = trip.lat.copy()
    lat[SEA] -= 0.0135
    return mapmatch.Trace(
        time=trip.time_s[keep] if times else None,
        lon=trip.lon[keep],
        lat=lat[keep],
        trace_id="one-hz" if times else "one-hz-no-times",
    )


@pytest.fixture(scope="module")
def result(net: roadnets.RoadNetwork) -> mapmatch.MatchResult:
    res = mapmatch.match(_one_hz_trip(net, times=True), net, diagnostics=True)
    assert res.breaks, "the sea fixes should split the trace"
    assert not res.points.matched[SEA].any()
    return res


@pytest.fixture(scope="module")
def untimed(net: roadnets.RoadNetwork) -> mapmatch.MatchResult:
    res = mapmatch.match(_one_hz_trip(net, times=False), net)
    assert np.isnan(res.points.time_s).all()
    assert res.breaks
    return res


@pytest.fixture(scope="module")
def saved(tmp_path_factory: pytest.TempPathFactory) -> Callable[..., Path]:
    folder = tmp_path_factory.mktemp("maps")

    def save(result: mapmatch.MatchResult, net: roadnets.RoadNetwork, **kw: Any) -> Path:
        path = folder / f"{result.trace_id}-{len(list(folder.iterdir()))}.html"
        viz.match_map(result, net, **kw).save(str(path))
        return path

    return save


def _open(page: Any, path: Path) -> dict[str, Any]:
    page.goto(path.as_uri())
    page.wait_for("window.L && Object.values(window).some((v) => v instanceof L.Map)")
    page.browser.pump(0.3)  # late console messages and requests
    problems = page.problems()
    assert problems == [], "\n".join(problems)
    # offline: the page asks for nothing but itself (and data: URIs inside it)
    others = [u for u in page.requests() if u != path.as_uri() and not u.startswith("data:")]
    assert others == []
    summary: dict[str, Any] = page.evaluate(SUMMARY_JS)
    return summary


def _check_layers(
    summary: dict[str, Any], result: mapmatch.MatchResult, net: roadnets.RoadNetwork
) -> None:
    p = result.points
    matched = int(p.matched.sum())
    finite = np.isfinite(p.raw_lon) & np.isfinite(p.raw_lat)
    unmatched = int((~p.matched & finite).sum())
    edges = sum(len(s.edges) for s in result.segments)
    layers = summary["layers"]
    assert summary["maps"] == 1
    assert set(summary["renderers"]) == {"canvas"}
    # every mark drawn: canvas paths registered with the canvas, markers in the document
    for name, layer in layers.items():
        assert layer["drawn"] == layer["total"], name
    assert layers["raw points"]["counts"] == {"circle": matched, "marker": unmatched}
    assert all("mm-unmatched" in c for c in layers["raw points"]["icons"])
    assert layers["snapped points"]["counts"] == {"circle": matched, "line": matched}
    assert layers["matched path"]["counts"] == {"line": edges}
    segment_colours = {
        SEGMENT_COLOURS[s % len(SEGMENT_COLOURS)] for s in range(len(result.segments))
    }
    assert set(layers["matched path"]["colours"]) == segment_colours
    breaks = layers["breaks"]["counts"]
    assert breaks["circle"] == len(result.breaks)
    assert 1 <= breaks.get("line", 0) <= len(result.breaks)
    gaps = trace_gaps(result, net)
    assert len(gaps) >= 1
    assert layers["gaps"]["counts"] == {"line": len(gaps)}
    arrows = direction_arrows(result, net)
    assert layers["direction"]["counts"] == {"marker": len(arrows)}
    assert 1 <= layers["direction"]["visible_icons"] <= len(arrows)
    assert layers["start / end"]["counts"] == {"marker": 2}
    # the path is drawn over the fixes: canvas order follows the layer order, bottom to top
    rank = {name: i for i, name in enumerate(viz.LAYER_NAMES)}
    ranks = [rank[name] for name in summary["order"]]
    assert ranks == sorted(ranks)
    assert max(summary["painted"]) > 1000  # pixels actually painted on the canvas
    # the layer switcher lists every layer; the legend's colours are the drawn ones
    assert summary["control"] == list(layers)
    assert summary["legend"]
    for entry in summary["legend"]:
        if entry["layer"] == "snapped points":  # a scale: its ends are the scale's ends
            assert entry["colour"] == CONFIDENCE_COLOURS[-1]
            continue
        assert entry["colour"] in layers[entry["layer"]]["colours"], entry
    # snapped points are drawn in the colour of their confidence, and only those colours
    confidence = {confidence_colour(float(c)) for c in p.confidence[p.matched]}
    other = {MARK_COLOURS["link"], MARK_COLOURS["snapped_edge"]}
    assert set(layers["snapped points"]["colours"]) == confidence | other
    labels = " ".join(e["label"] for e in summary["legend"])
    assert "fix not matched" in labels
    assert "gap" in labels
    assert "break" in labels
    # tooltips: one per fix drawn, none of them reporting a NaN
    tips = [t for layer in layers.values() for t in layer["tooltips"]]
    assert sum("raw, not matched" in t for t in tips) == unmatched
    assert not [t for t in tips if re.search(r"\bnan\b", t, re.IGNORECASE)]


def test_map_with_unmatched_fixes_draws_every_layer_offline(
    page: Any,
    result: mapmatch.MatchResult,
    net: roadnets.RoadNetwork,
    saved: Callable[..., Path],
    tmp_path: Path,
) -> None:
    summary = _open(page, saved(result, net))
    _check_layers(summary, result, net)
    assert "candidates" not in summary["layers"]
    assert page.screenshot(tmp_path / "map.png").stat().st_size > 10_000


def test_map_of_a_trace_without_times_draws_every_layer(
    page: Any, untimed: mapmatch.MatchResult, net: roadnets.RoadNetwork, saved: Callable[..., Path]
) -> None:
    summary = _open(page, saved(untimed, net))
    _check_layers(summary, untimed, net)
    breaks = summary["layers"]["breaks"]["tooltips"]
    assert breaks
    assert all(" s after fix" not in t for t in breaks)
    assert all("(no times)" in t for t in summary["layers"]["gaps"]["tooltips"])


def test_candidates_layer_draws_with_its_scores(
    page: Any, result: mapmatch.MatchResult, net: roadnets.RoadNetwork, saved: Callable[..., Path]
) -> None:
    fix = int(np.flatnonzero(result.points.matched)[20])
    table = viz.candidate_table(result, net, fix)
    summary = _open(page, saved(result, net, candidates_of=fix))
    layer = summary["layers"]["candidates"]
    assert layer["drawn"] == layer["total"]
    # each candidate: its edge, a line to it and its point; plus a ring round the fix
    assert layer["counts"] == {"line": 2 * len(table), "circle": len(table) + 1}
    assert sum("CHOSEN" in t for t in layer["tooltips"]) == 2 * int(table["chosen"].sum())
    assert "candidates" in summary["control"]


def test_switching_a_layer_off_and_on_keeps_the_path_on_top(
    page: Any, result: mapmatch.MatchResult, net: roadnets.RoadNetwork, saved: Callable[..., Path]
) -> None:
    _open(page, saved(result, net))
    # a person clicking the layer switcher's check boxes
    for name in ("raw points", "road network"):
        for _ in range(2):
            page.evaluate(
                "[...document.querySelectorAll('.leaflet-control-layers-overlays label')]"
                f".find((e) => e.textContent.trim() === {json.dumps(name)})"
                ".querySelector('input').click()"
            )
    summary = page.evaluate(SUMMARY_JS)
    rank = {name: i for i, name in enumerate(viz.LAYER_NAMES)}
    ranks = [rank[name] for name in summary["order"]]
    assert ranks == sorted(ranks)
    assert summary["layers"]["raw points"]["drawn"] == summary["layers"]["raw points"]["total"]
    assert page.problems() == []


def test_hovering_an_unmatched_fix_shows_its_tooltip(
    page: Any, result: mapmatch.MatchResult, net: roadnets.RoadNetwork, saved: Callable[..., Path]
) -> None:
    _open(page, saved(result, net))
    fix = SEA.start
    lat, lon = float(result.points.raw_lat[fix]), float(result.points.raw_lon[fix])
    x, y = page.evaluate(
        "(() => { const m = Object.values(window).find((v) => v instanceof L.Map);"
        f" const p = m.latLngToContainerPoint([{lat}, {lon}]);"
        " const r = m.getContainer().getBoundingClientRect();"
        " return [p.x + r.left, p.y + r.top]; })()"
    )
    page.call("Input.dispatchMouseEvent", {"type": "mouseMoved", "x": x, "y": y})
    text = page.wait_for(
        "(document.querySelector('.leaflet-tooltip') || {}).textContent", timeout_s=10
    )
    # the four sea fixes lie a few pixels apart: the one under the pointer is one of them
    shown = re.search(r"fix (\d+)", text)
    assert shown is not None
    assert int(shown.group(1)) in range(SEA.start, SEA.stop)
    assert "not matched" in text


def test_screenshot_writes_a_png_of_a_saved_map(
    browser: Any,  # only for its skip when there is no Chromium
    result: mapmatch.MatchResult,
    net: roadnets.RoadNetwork,
    saved: Callable[..., Path],
    tmp_path: Path,
) -> None:
    from mapmatch.viz.browser import screenshot

    out = screenshot(saved(result, net), tmp_path / "map.png", size=(640, 480))
    header = out.read_bytes()[:24]
    assert header[:8] == b"\x89PNG\r\n\x1a\n"
    assert (int.from_bytes(header[16:20], "big"), int.from_bytes(header[20:24], "big")) == (
        640,
        480,
    )


def test_screenshot_without_chromium_says_how_to_get_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from mapmatch.viz.browser import find_chromium, screenshot

    monkeypatch.setenv("MAPMATCH_CHROMIUM", str(tmp_path / "no-such-chromium"))
    assert find_chromium() is None
    page = tmp_path / "page.html"
    page.write_text("<html></html>")
    with pytest.raises(FileNotFoundError, match="apt-get install -y chromium"):
        screenshot(page, tmp_path / "out.png")
