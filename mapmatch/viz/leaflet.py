"""An interactive (folium/Leaflet) map of a match that needs no tile server and no internet.

(Over 400 lines on purpose: each layer is a short function, and the layers share the page's one
canvas, legend and offline assets.)
"""

from __future__ import annotations

import html
import math
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from mapmatch.viz.assets import use_assets
from mapmatch.viz.data import (
    CONFIDENCE_COLOURS,
    MARK_COLOURS,
    SEGMENT_COLOURS,
    break_marks,
    candidate_table,
    confidence_colour,
    direction_arrows,
    edge_line,
    endpoints,
    matched_edge_lines,
    network_lines,
    trace_box_m,
    trace_gaps,
)

if TYPE_CHECKING:
    import folium

    from mapmatch.result import MatchResult
    from mapmatch.viz.assets import AssetMode
    from roadnets import RoadNetwork

__all__ = ["LAYER_NAMES", "match_map"]

#: Names of the map's layers (as the layer switcher shows them), bottom to top.
LAYER_NAMES = (
    "road network",
    "raw points",
    "snapped points",
    "matched path",
    "candidates",
    "gaps",
    "breaks",
    "direction",
    "start / end",
)

_INSTALL_HINT = "mapmatch.viz needs folium and matplotlib: pip install mapmatch[viz]"

# Sizes, in screen pixels, of the marks (the map stays readable at one fix a second).
_RAW_RADIUS = 2.0
_OUTLIER_RADIUS = 3.0
_SNAPPED_RADIUS = 4.0
_PATH_WEIGHT = 4
_ARROW_GAP_PX = 56
_ROAD_WEIGHT = 3

#: A tooltip for every feature that has one, bound when the layer is built.
_BIND_TIP = "function (feature, layer) { layer.bindTooltip(feature.properties.tip); }"


def _import_folium() -> Any:
    try:
        import folium
    except ImportError as exc:
        raise ImportError(_INSTALL_HINT) from exc
    return folium


def match_map(
    result: MatchResult,
    net: RoadNetwork,
    *,
    candidates_of: int | None = None,
    tiles: str | None = None,
    attribution: str | None = None,
    margin_m: float = 150.0,
    assets: AssetMode = "inline",
    min_gap_s: float | None = None,
    arrow_spacing_m: float | None = None,
) -> folium.Map:
    """
    Draw a match on an interactive Leaflet map: what the matcher saw and what it chose.

    Layers, bottom to top (toggle them in the layer switcher at the top right; the legend at
    the bottom right names every mark in the colours drawn):

    - ``road network``: the network's own roads around the trace, so the map reads
      without tiles;
    - ``raw points``: the fixes as given, small dots (outliers larger and red, fixes left
      unmatched as red crosses);
    - ``snapped points``: positions on the road coloured by confidence (dashed outline:
      interpolated), each joined to its raw fix by a dotted line;
    - ``matched path``: each driven edge, coloured by segment, on top of the fixes;
    - ``candidates`` (with ``candidates_of``): every candidate edge of that fix with its
      scores in the tooltip;
    - ``gaps``: long steps between consecutive fixes (outages), dashed;
    - ``breaks``: where the match was split, from the last fix matched before to the first
      after, and a ring at the break;
    - ``direction``: arrows along the path the way it was driven;
    - ``start / end``: the first and last matched positions.

    Works for traces without times: gaps are then long steps in metres and the break
    tooltips say no time.

    Parameters
    ----------
    result
        A match result; from ``mapmatch.match(..., diagnostics=True)`` the candidate
        tooltips carry the model's emission, transition and posterior scores.
    net
        The network the trace was matched on.
    candidates_of
        Index of a fix whose candidates to draw (see :func:`candidate_table`).
    tiles
        A tile URL template (``https://.../{z}/{x}/{y}.png``) or a folium tile name to draw
        under everything; ``None`` (the default) draws no tiles, which works offline.
    attribution
        The tile source's attribution; required by folium for a URL template.
    margin_m
        Metres of road network drawn around the trace's bounding box.
    assets
        How the page gets Leaflet: ``"inline"`` (default) writes the bundled files into
        it, so a saved map or a notebook works offline; ``"cdn"`` links them from a CDN.
    min_gap_s
        Seconds between two fixes that make a gap (default: five times the median step,
        at least 10 s); see :func:`mapmatch.viz.data.trace_gaps`.
    arrow_spacing_m
        Metres between direction arrows (default: about 60 along the path, at least 50 m
        apart); at any zoom, an arrow nearer than 56 px on screen to the last one shown is
        hidden.

    Returns
    -------
    folium.Map
        Save it with ``.save("match.html")`` or show it as a notebook cell's value.

    Raises
    ------
    ImportError
        folium (``pip install mapmatch[viz]``), or for ``assets="inline"`` the bundled
        Leaflet files (``xstatic-leaflet``), are not installed.
    ValueError
        ``assets`` is neither ``"inline"`` nor ``"cdn"``.
    """
    fl = _import_folium()

    box = trace_box_m(result, net, margin_m=margin_m)
    sw_lon, sw_lat = net.unproject(np.array([box[0]]), np.array([box[1]]))
    ne_lon, ne_lat = net.unproject(np.array([box[2]]), np.array([box[3]]))
    fmap = fl.Map(tiles=None, control_scale=True, prefer_canvas=True, zoom_snap=0.25)
    use_assets(fmap, assets)
    if tiles is not None:
        fl.TileLayer(tiles=tiles, attr=attribution, name="tiles", overlay=False).add_to(fmap)
    # the layer switcher (top right) and the legend (bottom right) take a column on the right
    fmap.fit_bounds(
        [[float(sw_lat[0]), float(sw_lon[0])], [float(ne_lat[0]), float(ne_lon[0])]],
        padding_top_left=(10, 10),
        padding_bottom_right=(200, 10),
    )
    layers = {name: fl.FeatureGroup(name=name) for name in LAYER_NAMES}

    roads = [_line(line.lon, line.lat, line.label) for line in network_lines(net, box)]
    _geojson(fl, roads, style=_stroke(MARK_COLOURS["road"], _ROAD_WEIGHT, 0.6)).add_to(
        layers["road network"]
    )
    _add_points(fl, result, layers)
    path = [
        _line(line.lon, line.lat, line.label, {"color": SEGMENT_COLOURS[s % len(SEGMENT_COLOURS)]})
        for s, lines in enumerate(matched_edge_lines(result, net))
        for line in lines
    ]
    _geojson(fl, path, style=_stroke(SEGMENT_COLOURS[0], _PATH_WEIGHT, 0.9)).add_to(
        layers["matched path"]
    )
    if candidates_of is not None:
        _add_candidates(fl, result, net, candidates_of, layers["candidates"])
    gaps = _add_gaps(fl, result, net, min_gap_s, layers["gaps"])
    _add_breaks(fl, result, layers["breaks"])
    for arrow in direction_arrows(result, net, spacing_m=arrow_spacing_m):
        colour = SEGMENT_COLOURS[arrow.segment % len(SEGMENT_COLOURS)]
        fl.Marker(
            [arrow.lat, arrow.lon],
            icon=fl.DivIcon(
                html=_arrow_svg(colour, arrow.bearing_deg),
                icon_size=(14, 14),
                icon_anchor=(7, 7),
                class_name="mm-mark mm-arrow",
            ),
            interactive=False,
        ).add_to(layers["direction"])
    _add_endpoints(fl, result, layers["start / end"])

    shown = [n for n in LAYER_NAMES if n != "candidates" or candidates_of is not None]
    for name in shown:
        layers[name].add_to(fmap)
    fl.LayerControl(collapsed=False).add_to(fmap)
    _legend(result, candidates=candidates_of is not None, gaps=gaps > 0).add_to(fmap)
    _stacking({name: layers[name] for name in shown}).add_to(fmap)
    return cast("folium.Map", fmap)


# ----------------------------------------------------------------------------- features


def _round(values: Any) -> list[float]:
    return [round(float(v), 7) for v in values]


def _line(lon: Any, lat: Any, tip: str, style: dict[str, Any] | None = None) -> dict[str, Any]:
    props: dict[str, Any] = {"tip": html.escape(tip)}
    if style:
        props["style"] = style
    coords = [list(pair) for pair in zip(_round(lon), _round(lat), strict=True)]
    return {
        "type": "Feature",
        "geometry": {"type": "LineString", "coordinates": coords},
        "properties": props,
    }


def _point(lon: float, lat: float, tip: str, style: dict[str, Any] | None = None) -> dict[str, Any]:
    props: dict[str, Any] = {"tip": html.escape(tip)}
    if style:
        props["style"] = style
    geometry = {"type": "Point", "coordinates": _round((lon, lat))}
    return {"type": "Feature", "geometry": geometry, "properties": props}


def _stroke(colour: str, weight: float, opacity: float, **more: Any) -> dict[str, Any]:
    return {"color": colour, "weight": weight, "opacity": opacity, **more}


def _geojson(
    folium: Any,
    features: list[dict[str, Any]],
    *,
    style: dict[str, Any],
    marker: Any = None,
) -> Any:
    """One GeoJSON layer: a shared style, per-feature ``style`` overrides, and tooltips."""
    from folium.utilities import JsCode

    return folium.GeoJson(
        {"type": "FeatureCollection", "features": features},
        marker=marker,
        control=False,
        on_each_feature=JsCode(_BIND_TIP),
        style=style,
    )


def _circles(folium: Any, features: list[dict[str, Any]], style: dict[str, Any]) -> Any:
    """Points drawn as canvas circles (``style`` includes the radius)."""
    marker = folium.CircleMarker(radius=style["radius"])
    return _geojson(folium, features, style=style, marker=marker)


def _add_points(folium: Any, result: MatchResult, layers: dict[str, Any]) -> None:
    p = result.points
    t0 = _first_time(result)
    raw: list[dict[str, Any]] = []
    links: list[dict[str, Any]] = []
    snapped: list[dict[str, Any]] = []
    for i in range(len(p.time_s)):
        flags = [
            name
            for name, on in (("outlier", p.outlier[i]), ("interpolated", p.interpolated[i]))
            if on
        ]
        note = f" ({', '.join(flags)})" if flags else ""
        raw_lon, raw_lat = float(p.raw_lon[i]), float(p.raw_lat[i])
        if not (math.isfinite(raw_lon) and math.isfinite(raw_lat)):
            continue
        when = _when(p.time_s[i], t0)
        if not p.matched[i]:
            folium.Marker(
                [raw_lat, raw_lon],
                icon=folium.DivIcon(
                    html=_cross_svg(MARK_COLOURS["unmatched"]),
                    icon_size=(12, 12),
                    icon_anchor=(6, 6),
                    class_name="mm-mark mm-unmatched",
                ),
                tooltip=html.escape(f"fix {i}{when}: raw, not matched{note}"),
            ).add_to(layers["raw points"])
            continue
        outlier_style = None
        if p.outlier[i]:
            outlier_style = {
                "radius": _OUTLIER_RADIUS,
                "color": MARK_COLOURS["outlier"],
                "fillColor": MARK_COLOURS["outlier"],
            }
        raw.append(_point(raw_lon, raw_lat, f"fix {i}{when}: raw{note}", outlier_style))
        lon, lat = float(p.lon[i]), float(p.lat[i])
        links.append(_line([raw_lon, lon], [raw_lat, lat], f"fix {i}: raw to snapped"))
        confidence = float(p.confidence[i])
        tip = (
            f"fix {i}{when}: snapped to edge {int(p.edge[i])} at {p.offset_m[i]:.1f} m, "
            f"{p.distance_m[i]:.1f} m from the fix, confidence {confidence:.3f}, "
            f"segment {int(p.segment[i])}{note}"
        )
        style: dict[str, Any] = {"fillColor": confidence_colour(confidence)}
        if p.interpolated[i]:
            style["dashArray"] = "2 2"
        snapped.append(_point(lon, lat, tip, style))
    raw_style = {
        "radius": _RAW_RADIUS,
        "color": MARK_COLOURS["raw"],
        "weight": 1,
        "fill": True,
        "fillColor": MARK_COLOURS["raw"],
        "fillOpacity": 0.8,
    }
    _circles(folium, raw, raw_style).add_to(layers["raw points"])
    link_style = _stroke(MARK_COLOURS["link"], 1, 0.6, dashArray="2 3")
    _geojson(folium, links, style=link_style).add_to(layers["snapped points"])
    snapped_style = {
        "radius": _SNAPPED_RADIUS,
        "color": MARK_COLOURS["snapped_edge"],
        "weight": 1,
        "fill": True,
        "fillOpacity": 0.95,
    }
    _circles(folium, snapped, snapped_style).add_to(layers["snapped points"])


def _add_gaps(
    folium: Any, result: MatchResult, net: RoadNetwork, min_gap_s: float | None, layer: Any
) -> int:
    gaps = trace_gaps(result, net, min_gap_s=min_gap_s)
    lines = [_line(g.lon, g.lat, g.label) for g in gaps]
    style = _stroke(MARK_COLOURS["gap"], 3, 0.9, dashArray="6 6")
    _geojson(folium, lines, style=style).add_to(layer)
    return len(gaps)


def _add_breaks(folium: Any, result: MatchResult, layer: Any) -> None:
    p = result.points
    lines, rings = [], []
    for mark in break_marks(result):
        at_lon, at_lat = float(p.lon[mark.start]), float(p.lat[mark.start])
        if mark.previous >= 0:
            j = mark.previous
            lons, lats = [float(p.lon[j]), at_lon], [float(p.lat[j]), at_lat]
            lines.append(_line(lons, lats, mark.label))
        rings.append(_point(at_lon, at_lat, mark.label))
    _geojson(folium, lines, style=_stroke(MARK_COLOURS["break"], 4, 0.9, dashArray="8 6")).add_to(
        layer
    )
    ring_style = {"radius": 10.0, "color": MARK_COLOURS["break"], "weight": 3, "fill": False}
    _circles(folium, rings, ring_style).add_to(layer)


def _add_endpoints(folium: Any, result: MatchResult, layer: Any) -> None:
    start, end = endpoints(result)
    p = result.points
    t0 = _first_time(result)
    for (lon, lat, fix), kind in ((start, "start"), (end, "end")):
        when = _when(p.time_s[fix], t0)
        folium.Marker(
            [lat, lon],
            icon=folium.DivIcon(
                html=_endpoint_svg(kind),
                icon_size=(20, 20),
                icon_anchor=(10, 10),
                class_name=f"mm-mark mm-{kind}",
            ),
            tooltip=html.escape(f"{kind}: fix {fix}{when}"),
        ).add_to(layer)


def _add_candidates(
    folium: Any, result: MatchResult, net: RoadNetwork, fix: int, layer: Any
) -> None:
    table = candidate_table(result, net, fix)
    p = result.points
    fix = int(table["fix"].iloc[0]) if len(table) else fix % len(p.time_s)
    raw = [float(p.raw_lat[fix]), float(p.raw_lon[fix])]
    for row in table.to_dict("records"):
        posterior = float(row["posterior"])
        chosen = bool(row["chosen"])
        tip = html.escape(
            f"fix {fix} candidate: edge {row['edge']} "
            f"(u {row['u']} -> v {row['v']}, key {row['key']}), "
            f"{row['distance_m']:.1f} m away, log emission {_fmt(row['log_emission'])}, "
            f"log transition {_fmt(row['log_transition'])}, posterior {_fmt(posterior)}"
            + (", CHOSEN" if chosen else "")
        )
        colour = confidence_colour(posterior)
        lon, lat = edge_line(net, int(row["edge"]))
        folium.PolyLine(
            np.column_stack((lat, lon)).round(7).tolist(),
            color=colour,
            weight=9 if chosen else 5,
            opacity=0.8,
            tooltip=tip,
        ).add_to(layer)
        position = [float(row["lat"]), float(row["lon"])]
        folium.PolyLine([raw, position], color=colour, weight=2, dash_array="4 4").add_to(layer)
        folium.CircleMarker(
            position, radius=4, color=colour, fill=True, fill_opacity=1.0, tooltip=tip
        ).add_to(layer)
    folium.CircleMarker(
        raw,
        radius=8,
        color="#000000",
        weight=3,
        fill=False,
        tooltip=f"fix {fix}: {len(table)} candidates",
    ).add_to(layer)


def _first_time(result: MatchResult) -> float:
    times = result.points.time_s
    finite = times[np.isfinite(times)]
    return float(finite[0]) if len(finite) else math.nan


def _when(time_s: float, t0: float) -> str:
    """`` at t+12 s`` (seconds since the first fix), or nothing for a trace without times."""
    return f" at t+{time_s - t0:.0f} s" if math.isfinite(time_s - t0) else ""


def _fmt(value: float) -> str:
    value = float(value)
    return "n/a" if not math.isfinite(value) else f"{value:.3g}"


# ----------------------------------------------------------------------------- marks


def _cross_svg(colour: str) -> str:
    return (
        '<svg width="12" height="12" viewBox="0 0 12 12">'
        '<path d="M2 2L10 10M10 2L2 10" stroke="#ffffff" stroke-width="4.5"/>'
        f'<path d="M2 2L10 10M10 2L2 10" stroke="{colour}" stroke-width="2.5"/></svg>'
    )


def _arrow_svg(colour: str, bearing_deg: float) -> str:
    return (
        '<svg width="14" height="14" viewBox="-7 -7 14 14">'
        f'<g transform="rotate({bearing_deg:.0f})">'
        f'<path d="M0 -6L5 5L0 2L-5 5Z" fill="{colour}" stroke="#ffffff" '
        'stroke-width="1.5" stroke-linejoin="round"/></g></svg>'
    )


def _endpoint_svg(kind: str) -> str:
    colour = MARK_COLOURS[kind]
    inner = (
        '<path d="M-3 -4.5L5 0L-3 4.5Z" fill="#ffffff"/>'
        if kind == "start"
        else '<rect x="-3.5" y="-3.5" width="7" height="7" fill="#ffffff"/>'
    )
    return (
        '<svg width="20" height="20" viewBox="-10 -10 20 20">'
        f'<circle r="8.5" fill="{colour}" stroke="#ffffff" stroke-width="2"/>{inner}</svg>'
    )


def _swatch_line(colour: str, dash: str | None = None, width: float = 4) -> str:
    dashed = f' stroke-dasharray="{dash}"' if dash else ""
    return (
        '<svg width="26" height="12"><line x1="1" y1="6" x2="25" y2="6" '
        f'stroke="{colour}" stroke-width="{width}"{dashed}/></svg>'
    )


def _swatch_dot(fill: str, radius: float, stroke: str | None = None) -> str:
    edge = f' stroke="{stroke}" stroke-width="1"' if stroke else ""
    return (
        f'<svg width="26" height="12"><circle cx="13" cy="6" r="{radius}" '
        f'fill="{fill}"{edge}/></svg>'
    )


def _swatch_ring(colour: str) -> str:
    return (
        '<svg width="26" height="16"><circle cx="13" cy="8" r="6" fill="none" '
        f'stroke="{colour}" stroke-width="2.5"/></svg>'
    )


def _swatch_gradient() -> str:
    stops = "".join(
        f'<stop offset="{i / (len(CONFIDENCE_COLOURS) - 1):.2f}" stop-color="{c}"/>'
        for i, c in enumerate(CONFIDENCE_COLOURS)
    )
    return (
        '<svg width="26" height="12"><defs><linearGradient id="mm-confidence">'
        f'{stops}</linearGradient></defs><rect x="1" y="2" width="24" height="8" '
        f'fill="url(#mm-confidence)" stroke="{MARK_COLOURS["road"]}" '
        'stroke-width="0.5"/></svg>'
    )


def _legend_entries(
    result: MatchResult, *, candidates: bool, gaps: bool
) -> list[tuple[str, str, str, str]]:
    """``(layer, colour, swatch html, label)`` for every kind of mark the map shows."""
    p = result.points
    segments = max(1, len(result.segments))
    entries = []
    for s in range(min(segments, len(SEGMENT_COLOURS))):
        colour = SEGMENT_COLOURS[s]
        label = "matched path" if segments == 1 else f"matched path, segment {s}"
        if s == len(SEGMENT_COLOURS) - 1 and segments > len(SEGMENT_COLOURS):
            label += f" (colours repeat: {segments} segments)"
        entries.append(("matched path", colour, _swatch_line(colour), label))
    entries.append(
        ("direction", SEGMENT_COLOURS[0], _arrow_svg(SEGMENT_COLOURS[0], 90), "direction driven")
    )
    entries.append(("start / end", MARK_COLOURS["start"], _endpoint_svg("start"), "start"))
    entries.append(("start / end", MARK_COLOURS["end"], _endpoint_svg("end"), "end"))
    raw = _swatch_dot(MARK_COLOURS["raw"], _RAW_RADIUS + 0.5)
    entries.append(("raw points", MARK_COLOURS["raw"], raw, "raw fix"))
    if p.outlier.any():
        dot = _swatch_dot(MARK_COLOURS["outlier"], _OUTLIER_RADIUS + 0.5)
        entries.append(("raw points", MARK_COLOURS["outlier"], dot, "raw fix, outlier"))
    finite = np.isfinite(p.raw_lon) & np.isfinite(p.raw_lat)
    if (~p.matched & finite).any():
        cross = _cross_svg(MARK_COLOURS["unmatched"])
        entries.append(("raw points", MARK_COLOURS["unmatched"], cross, "fix not matched"))
    entries.append(
        (
            "snapped points",
            CONFIDENCE_COLOURS[-1],
            _swatch_gradient(),
            "snapped fix, confidence 0 → 1",
        )
    )
    if gaps:
        gap = _swatch_line(MARK_COLOURS["gap"], "6 4", 3)
        entries.append(("gaps", MARK_COLOURS["gap"], gap, "gap (outage)"))
    if result.breaks:
        entries.append(
            ("breaks", MARK_COLOURS["break"], _swatch_ring(MARK_COLOURS["break"]), "break")
        )
    entries.append(
        ("road network", MARK_COLOURS["road"], _swatch_line(MARK_COLOURS["road"], None, 3), "road")
    )
    if candidates:
        entries.append(
            (
                "candidates",
                CONFIDENCE_COLOURS[-1],
                _swatch_line(CONFIDENCE_COLOURS[-1]),
                "candidate edge, by posterior",
            )
        )
    return entries


def _template(text: str) -> Any:
    from folium.template import Template

    return Template(text)


_LEGEND_TEMPLATE = """
{% macro header(this, kwargs) %}
<style>
  .mm-legend { background: rgba(255,255,255,0.92); padding: 6px 8px;
    font: 12px/1.35 sans-serif; border-radius: 4px;
    box-shadow: 0 1px 4px rgba(0,0,0,0.35); max-width: 260px; }
  .mm-legend-title { font-weight: bold; margin-bottom: 2px; }
  .mm-legend-item { display: flex; align-items: center; gap: 6px; }
  .mm-swatch { flex: none; width: 26px; display: flex; justify-content: center; }
  .mm-mark { background: none; border: none; }
</style>
{% endmacro %}
{% macro script(this, kwargs) %}
(function () {
  var legend = L.control({position: "bottomright"});
  legend.onAdd = function () {
    var div = L.DomUtil.create("div", "mm-legend");
    div.innerHTML = {{ this.html|tojson }};
    L.DomEvent.disableClickPropagation(div);
    return div;
  };
  legend.addTo({{ this._parent.get_name() }});
})();
{% endmacro %}
"""

_STACKING_TEMPLATE = """
{% macro script(this, kwargs) %}
(function () {
  var map = {{ this._parent.get_name() }};
  var layers = {
    {%- for name, layer in this.layers.items() %}
    {{ name|tojson }}: {{ layer.get_name() }},
    {%- endfor %}
  };
  map.mapmatch = {layers: layers};
  map.on("overlayadd", function () {
    Object.keys(layers).forEach(function (name) {
      var layer = layers[name];
      if (map.hasLayer(layer) && layer.bringToFront) { layer.bringToFront(); }
    });
  });
  // direction arrows: at most one per {{ this.arrow_gap_px }} px at any zoom
  var arrows = layers["direction"];
  function thin() {
    if (!arrows || !map.hasLayer(arrows)) { return; }
    var last = null;
    arrows.eachLayer(function (marker) {
      var at = map.latLngToLayerPoint(marker.getLatLng());
      var show = last === null || at.distanceTo(last) >= {{ this.arrow_gap_px }};
      if (show) { last = at; }
      marker.setOpacity(show ? 1 : 0);
    });
  }
  map.on("zoomend overlayadd", thin);
  map.whenReady(thin);
})();
{% endmacro %}
"""


def _element(name: str, template: str, **attributes: Any) -> Any:
    """A branca element rendering ``template`` (``this`` is the element) under the map."""
    from branca.element import MacroElement
    from folium.template import Template

    element = MacroElement()  # type: ignore[no-untyped-call]
    element._name = name
    element._template = Template(template)
    for key, value in attributes.items():
        setattr(element, key, value)
    return element


def _legend(result: MatchResult, *, candidates: bool, gaps: bool) -> Any:
    """The legend: one row per kind of mark shown, its swatch in the colour drawn."""
    rows = "".join(
        f'<div class="mm-legend-item" data-layer="{layer}" data-colour="{colour}">'
        f'<span class="mm-swatch">{swatch}</span><span>{html.escape(label)}</span></div>'
        for layer, colour, swatch, label in _legend_entries(
            result, candidates=candidates, gaps=gaps
        )
    )
    title = html.escape(str(result.trace_id))
    legend_html = f'<div class="mm-legend-title">{title}</div>{rows}'
    return _element("MapmatchLegend", _LEGEND_TEMPLATE, html=legend_html)


def _stacking(layers: dict[str, Any]) -> Any:
    """
    Keep the layers in drawing order when one is switched off and on again; thin arrows.

    One canvas draws every vector layer in the order it was added, and the layer switcher
    re-adds a layer on top; this brings the ones meant to be above it back up. Direction
    arrows nearer than ``_ARROW_GAP_PX`` on screen to the previous one shown are hidden at
    each zoom. The map object also gets ``mapmatch.layers`` (name to layer), for scripts
    and tests.
    """
    return _element(
        "MapmatchStacking", _STACKING_TEMPLATE, layers=layers, arrow_gap_px=_ARROW_GAP_PX
    )
