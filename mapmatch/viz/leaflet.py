"""An interactive (folium/Leaflet) map of a match that needs no tile server."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from mapmatch.viz.data import (
    CONFIDENCE_COLOURS,
    SEGMENT_COLOURS,
    candidate_table,
    confidence_colour,
    edge_line,
    matched_edge_lines,
    network_lines,
    trace_box_m,
)

if TYPE_CHECKING:
    import folium

    from mapmatch.result import MatchResult
    from roadnets import RoadNetwork

__all__ = ["LAYER_NAMES", "match_map"]

#: Names of the map's layers (as the layer switcher shows them), in drawing order.
LAYER_NAMES = (
    "road network",
    "matched path",
    "raw points",
    "snapped points",
    "breaks",
    "candidates",
)

_INSTALL_HINT = "mapmatch.viz needs folium and matplotlib: pip install mapmatch[viz]"


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
) -> folium.Map:
    """
    Draw a match on an interactive Leaflet map: what the matcher saw and what it chose.

    Layers (toggle them in the layer switcher at the top right): ``road network`` (the
    network's own roads around the trace, so the map reads without tiles), ``matched path``
    (each driven edge, coloured by segment), ``raw points`` (the fixes as given; outliers in
    red, fixes left unmatched as crosses), ``snapped points`` (positions on the road, coloured
    by confidence, joined to their raw fix), ``breaks`` (where the trace was split: the gap
    between the last fix before and the first after) and, with ``candidates_of``,
    ``candidates`` (every candidate edge of that fix with its scores in the tooltip).

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

    Returns
    -------
    folium.Map
        Save it with ``.save("match.html")`` or show it as a notebook cell's value.

    Raises
    ------
    ImportError
        folium is not installed (``pip install mapmatch[viz]``).
    """
    fl = _import_folium()
    from branca.colormap import LinearColormap

    box = trace_box_m(result, net, margin_m=margin_m)
    sw_lon, sw_lat = net.unproject(np.array([box[0]]), np.array([box[1]]))
    ne_lon, ne_lat = net.unproject(np.array([box[2]]), np.array([box[3]]))
    fmap = fl.Map(tiles=None, control_scale=True, prefer_canvas=True)
    if tiles is not None:
        fl.TileLayer(tiles=tiles, attr=attribution, name="tiles", overlay=False).add_to(fmap)
    fmap.fit_bounds([[float(sw_lat[0]), float(sw_lon[0])], [float(ne_lat[0]), float(ne_lon[0])]])
    layers = {name: fl.FeatureGroup(name=name) for name in LAYER_NAMES}

    for line in network_lines(net, box):
        fl.PolyLine(
            _latlon(line.lon, line.lat),
            color="#9e9e9e",
            weight=3,
            opacity=0.8,
            tooltip=line.label,
        ).add_to(layers["road network"])

    for s, lines in enumerate(matched_edge_lines(result, net)):
        colour = SEGMENT_COLOURS[s % len(SEGMENT_COLOURS)]
        for line in lines:
            fl.PolyLine(
                _latlon(line.lon, line.lat),
                color=colour,
                weight=6,
                opacity=0.7,
                tooltip=line.label,
            ).add_to(layers["matched path"])

    _add_points(fl, result, layers)
    _add_breaks(fl, result, layers["breaks"])
    if candidates_of is not None:
        _add_candidates(fl, result, net, candidates_of, layers["candidates"])

    for name in LAYER_NAMES:
        if name != "candidates" or candidates_of is not None:
            layers[name].add_to(fmap)
    LinearColormap(list(CONFIDENCE_COLOURS), vmin=0.0, vmax=1.0, caption="confidence").add_to(fmap)
    fl.LayerControl(collapsed=False).add_to(fmap)
    return cast("folium.Map", fmap)


def _latlon(lon: np.ndarray[Any, Any], lat: np.ndarray[Any, Any]) -> list[list[float]]:
    return np.column_stack((lat, lon)).round(7).tolist()  # type: ignore[no-any-return]


def _add_points(folium: Any, result: MatchResult, layers: dict[str, Any]) -> None:
    p = result.points
    for i in range(len(p.time_s)):
        raw = [float(p.raw_lat[i]), float(p.raw_lon[i])]
        flags = [
            name
            for name, on in (("outlier", p.outlier[i]), ("interpolated", p.interpolated[i]))
            if on
        ]
        note = f" ({', '.join(flags)})" if flags else ""
        if p.matched[i]:
            colour = "#d7191c" if p.outlier[i] else "#000000"
            folium.CircleMarker(
                raw,
                radius=3,
                color=colour,
                fill=True,
                fill_opacity=0.9,
                weight=1,
                tooltip=f"fix {i}: raw{note}",
            ).add_to(layers["raw points"])
            snapped = [float(p.lat[i]), float(p.lon[i])]
            confidence = float(p.confidence[i])
            tip = (
                f"fix {i}: snapped to edge {int(p.edge[i])} at {p.offset_m[i]:.1f} m, "
                f"{p.distance_m[i]:.1f} m from the fix, confidence {confidence:.3f}, "
                f"segment {int(p.segment[i])}{note}"
            )
            folium.PolyLine(
                [raw, snapped], color="#555555", weight=1, opacity=0.6, dash_array="2 3"
            ).add_to(layers["snapped points"])
            folium.CircleMarker(
                snapped,
                radius=5,
                color="#333333",
                weight=1,
                fill=True,
                fill_color=confidence_colour(confidence),
                fill_opacity=0.95,
                dash_array="2 2" if p.interpolated[i] else None,
                tooltip=tip,
            ).add_to(layers["snapped points"])
        elif math.isfinite(raw[0]):
            folium.RegularPolygonMarker(
                raw,
                number_of_sides=4,
                radius=5,
                rotation=45,
                color="#d7191c",
                weight=2,
                fill=False,
                tooltip=f"fix {i}: raw, not matched{note}",
            ).add_to(layers["raw points"])


def _add_breaks(folium: Any, result: MatchResult, layer: Any) -> None:
    p = result.points
    for start in result.breaks:
        before = [i for i in range(start - 1, -1, -1) if p.matched[i]]
        tip = f"break: segment {int(p.segment[start])} starts at fix {start}"
        at = [float(p.lat[start]), float(p.lon[start])]
        if before:
            j = before[0]
            gap_s = float(p.time_s[start] - p.time_s[j])
            tip += f" ({gap_s:.0f} s after fix {j}, the last one matched before it)"
            folium.PolyLine(
                [[float(p.lat[j]), float(p.lon[j])], at],
                color="#d7191c",
                weight=4,
                dash_array="8 6",
                tooltip=tip,
            ).add_to(layer)
        folium.CircleMarker(
            at, radius=11, color="#d7191c", weight=3, fill=False, tooltip=tip
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
        tip = (
            f"fix {fix} candidate: edge {row['edge']} "
            f"(u {row['u']} -> v {row['v']}, key {row['key']}), "
            f"{row['distance_m']:.1f} m away, log emission {_fmt(row['log_emission'])}, "
            f"log transition {_fmt(row['log_transition'])}, posterior {_fmt(posterior)}"
            + (", CHOSEN" if chosen else "")
        )
        colour = confidence_colour(posterior)
        lon, lat = edge_line(net, int(row["edge"]))
        folium.PolyLine(
            _latlon(lon, lat), color=colour, weight=9 if chosen else 5, opacity=0.8, tooltip=tip
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


def _fmt(value: float) -> str:
    value = float(value)
    return "n/a" if not math.isfinite(value) else f"{value:.3g}"
