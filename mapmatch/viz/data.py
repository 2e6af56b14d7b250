"""What the match drawings show, as plain arrays and tables (no plotting library needed).

(Over 400 lines on purpose: one place for what both drawings show, so that they cannot
disagree.)

Both drawings (:mod:`mapmatch.viz.leaflet` and :mod:`mapmatch.viz.static`) take their
geometry from here, so the interactive map and the static figure always show the same thing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from mapmatch.config import MatchConfig
from mapmatch.hmm.candidates import edges_searched

if TYPE_CHECKING:
    import pandas as pd

    from mapmatch.result import MatchResult
    from roadnets import RoadNetwork

__all__ = [
    "CANDIDATE_COLUMNS",
    "MARK_COLOURS",
    "Arrow",
    "BreakMark",
    "Gap",
    "Polyline",
    "break_marks",
    "candidate_table",
    "confidence_colour",
    "direction_arrows",
    "endpoints",
    "matched_edge_lines",
    "network_lines",
    "trace_box_m",
    "trace_gaps",
]

FloatArray = npt.NDArray[np.float64]

#: Columns of :func:`candidate_table` (those of ``result.diagnostics.candidates``).
CANDIDATE_COLUMNS = (
    "fix",
    "edge",
    "u",
    "v",
    "key",
    "lon",
    "lat",
    "distance_m",
    "log_emission",
    "log_transition",
    "posterior",
    "chosen",
)

#: Confidence colour scale, low to high (red, amber, green; colour-blind safe ends).
CONFIDENCE_COLOURS = ("#d7191c", "#fdae61", "#1a9641")

#: Colours of successive segments of a matched path.
SEGMENT_COLOURS = ("#2b83ba", "#7b3294", "#008837", "#e66101", "#5e3c99", "#0571b0")

#: Colours of every other mark, shared by the map, its legend and the static figure.
MARK_COLOURS = {
    "road": "#9e9e9e",
    "raw": "#212121",
    "outlier": "#d7191c",
    "unmatched": "#d7191c",
    "link": "#555555",
    "snapped_edge": "#ffffff",
    "gap": "#e7298a",
    "break": "#d7191c",
    "start": "#1a9641",
    "end": "#252525",
}


@dataclass(frozen=True, slots=True)
class Polyline:
    """
    One line to draw, WGS84 degrees, with a short label for its tooltip.

    ``edge`` is the network edge it shows (-1 when it is not one edge).
    """

    lon: FloatArray
    lat: FloatArray
    label: str
    edge: int = -1


@dataclass(frozen=True, slots=True)
class Arrow:
    """A direction mark on the matched path: where, which way (degrees from north), segment."""

    lon: float
    lat: float
    bearing_deg: float
    segment: int


@dataclass(frozen=True, slots=True)
class Gap:
    """
    A long step between consecutive fixes ``before`` and ``before + 1``: an outage.

    ``seconds`` is NaN for a trace without times (then the step was long in metres).
    """

    before: int
    seconds: float
    metres: float
    lon: tuple[float, float]
    lat: tuple[float, float]
    label: str


@dataclass(frozen=True, slots=True)
class BreakMark:
    """
    Where the match was split: segment ``segment`` starts at fix ``start``.

    ``previous`` is the last fix matched before it (-1 for none) and ``seconds`` the time
    between the two (NaN without times or without a previous fix).
    """

    start: int
    previous: int
    segment: int
    seconds: float
    label: str


def trace_box_m(
    result: MatchResult, net: RoadNetwork, *, margin_m: float = 150.0
) -> tuple[float, float, float, float]:
    """
    Bounding box ``(min_x, min_y, max_x, max_y)`` in metres of the raw and snapped fixes.

    The box is widened by ``margin_m`` on every side.

    Raises
    ------
    ValueError
        No fix has a finite position.
    """
    p = result.points
    lon = np.concatenate((p.raw_lon, p.lon))
    lat = np.concatenate((p.raw_lat, p.lat))
    ok = np.isfinite(lon) & np.isfinite(lat)
    if not ok.any():
        msg = f"trace {result.trace_id!r}: no fix has a finite position to draw"
        raise ValueError(msg)
    x, y = net.project(lon[ok], lat[ok])
    return (
        float(x.min()) - margin_m,
        float(y.min()) - margin_m,
        float(x.max()) + margin_m,
        float(y.max()) + margin_m,
    )


def network_lines(net: RoadNetwork, box_m: tuple[float, float, float, float]) -> list[Polyline]:
    """
    Cut the road network to a box (metres): one line per road geometry, unprojected.

    Both directions of a two-way road share one geometry and are drawn once. An edge is kept
    when its bounding box overlaps ``box_m``.
    """
    a = net.arrays
    ptr = np.asarray(a.edge_geom_ptr)
    starts = ptr[:-1]
    min_x = np.minimum.reduceat(a.geom_x, starts)
    max_x = np.maximum.reduceat(a.geom_x, starts)
    min_y = np.minimum.reduceat(a.geom_y, starts)
    max_y = np.maximum.reduceat(a.geom_y, starts)
    x0, y0, x1, y1 = box_m
    twin = np.asarray(a.edge_twin)
    edges = np.arange(a.n_edges)
    keep = (max_x >= x0) & (min_x <= x1) & (max_y >= y0) & (min_y <= y1)
    keep &= (twin < 0) | (edges < twin)
    chosen = np.flatnonzero(keep)
    if len(chosen) == 0:
        return []
    sizes = ptr[chosen + 1] - ptr[chosen]
    vertex = np.repeat(ptr[chosen] - np.cumsum(sizes) + sizes, sizes) + np.arange(int(sizes.sum()))
    lon, lat = a.geom_lon[vertex], a.geom_lat[vertex]
    bounds = np.concatenate(([0], np.cumsum(sizes)))
    lines = []
    for i, e in enumerate(chosen.tolist()):
        lo, hi = int(bounds[i]), int(bounds[i + 1])
        lines.append(Polyline(lon[lo:hi], lat[lo:hi], _edge_label(net, e), e))
    return lines


def matched_edge_lines(result: MatchResult, net: RoadNetwork) -> list[list[Polyline]]:
    """Return the driven stretch of every matched edge, grouped by segment, unprojected."""
    groups: list[list[Polyline]] = []
    for seg in result.segments:
        lines = []
        for e in seg.edges:
            x, y = net.edge_polyline(e.edge, e.start_offset_m, e.end_offset_m)
            lon, lat = net.unproject(x, y)
            label = (
                f"segment {seg.index} (fixes {seg.first}-{seg.last}): "
                f"{_edge_label(net, e.edge)}, driven {e.driven_m:.0f} m"
            )
            lines.append(Polyline(lon, lat, label, e.edge))
        groups.append(lines)
    return groups


def edge_line(net: RoadNetwork, edge: int) -> tuple[FloatArray, FloatArray]:
    """Return the whole geometry of one edge, WGS84 degrees, in driving order."""
    a = net.arrays
    lo, hi = int(a.edge_geom_ptr[edge]), int(a.edge_geom_ptr[edge + 1])
    return np.asarray(a.geom_lon[lo:hi]), np.asarray(a.geom_lat[lo:hi])


def candidate_table(result: MatchResult, net: RoadNetwork, fix: int) -> pd.DataFrame:
    """
    List the candidates of one fix and their scores, one row per candidate edge.

    With a result of ``mapmatch.match(..., diagnostics=True)`` the rows are the model's own
    (``result.diagnostics.candidates`` for this fix): distance, log emission, log transition
    from the previous model fix's chosen candidate, posterior and whether it was chosen.
    Without diagnostics, or for a fix that did not enter the model, the rows are the directed
    edges the matcher searches around the raw fix (within ``result.config``'s search radius,
    the nearest :func:`~mapmatch.hmm.candidates.edges_searched`) and
    the scores are NaN.

    Parameters
    ----------
    result
        A match result.
    net
        The network it was matched on.
    fix
        Index of the fix in the trace (negative counts from the end).

    Returns
    -------
    pandas.DataFrame
        Columns :data:`CANDIDATE_COLUMNS`, nearest candidate first.

    Raises
    ------
    IndexError
        ``fix`` is outside the trace.
    """
    import pandas as pd

    n = len(result.points.time_s)
    if not -n <= fix < n:
        msg = f"fix {fix} is outside the trace (it has {n} fixes, indices 0..{n - 1})"
        raise IndexError(msg)
    fix = fix % n
    if result.diagnostics is not None:
        table = result.diagnostics.candidates
        rows = table[table["fix"] == fix]
        if len(rows):
            out = rows.loc[:, list(CANDIDATE_COLUMNS)].sort_values("distance_m", kind="stable")
            return out.reset_index(drop=True)
    p = result.points
    config = result.config or MatchConfig()
    x, y = net.project(p.raw_lon[fix : fix + 1], p.raw_lat[fix : fix + 1])
    hits = net.nearby_edges(x, y, config.search_radius_m, max_per_point=edges_searched(config))
    edge = np.asarray(hits.edge, dtype=np.int64)
    u, v, key = net.edge_osm_ids(edge)
    lon, lat = net.unproject(np.asarray(hits.x), np.asarray(hits.y))
    nan = np.full(len(edge), math.nan)
    return pd.DataFrame(
        {
            "fix": np.full(len(edge), fix, dtype=np.int64),
            "edge": edge,
            "u": u,
            "v": v,
            "key": key,
            "lon": lon,
            "lat": lat,
            "distance_m": np.asarray(hits.distance_m),
            "log_emission": nan,
            "log_transition": nan,
            "posterior": nan,
            "chosen": bool(p.matched[fix]) & (edge == p.edge[fix]),
        }
    )


def confidence_colour(confidence: float) -> str:
    """
    Hex colour of a confidence in 0..1 (red, amber, green); grey for NaN.

    Examples
    --------
    >>> confidence_colour(0.0), confidence_colour(1.0), confidence_colour(float("nan"))
    ('#d7191c', '#1a9641', '#808080')
    """
    if not math.isfinite(confidence):
        return "#808080"
    c = min(max(confidence, 0.0), 1.0) * (len(CONFIDENCE_COLOURS) - 1)
    i = min(int(c), len(CONFIDENCE_COLOURS) - 2)
    t = c - i
    lo, hi = _rgb(CONFIDENCE_COLOURS[i]), _rgb(CONFIDENCE_COLOURS[i + 1])
    mixed = (round(a + t * (b - a)) for a, b in zip(lo, hi, strict=True))
    return "#" + "".join(f"{channel:02x}" for channel in mixed)


def _rgb(colour: str) -> tuple[int, int, int]:
    return int(colour[1:3], 16), int(colour[3:5], 16), int(colour[5:7], 16)


def _edge_label(net: RoadNetwork, edge: int) -> str:
    from roadnets import ROAD_CLASSES

    a = net.arrays
    way = int(a.edge_way_id[edge])
    name = net.way_names.get(way, "")
    road_class = ROAD_CLASSES[int(a.edge_class[edge])]
    named = f" {name}" if name else ""
    return f"edge {edge} (way {way}{named}, {road_class})"


def direction_arrows(
    result: MatchResult, net: RoadNetwork, *, spacing_m: float | None = None
) -> list[Arrow]:
    """
    Marks of the driving direction along each segment's path.

    Parameters
    ----------
    result
        A match result.
    net
        The network it was matched on (for metres along the path).
    spacing_m
        Metres between marks; default: the matched length over 60, at least 50 m, so that
        a long trace gets about 60 marks and a short one a mark every 50 m.

    Returns
    -------
    list of Arrow
        One mark half a spacing into every stretch of the path, pointing the way driven.
    """
    if spacing_m is None:
        spacing_m = max(50.0, result.matched_length_m / 60.0)
    if not spacing_m > 0:
        msg = f"spacing_m must be > 0, got {spacing_m}"
        raise ValueError(msg)
    arrows: list[Arrow] = []
    for seg in result.segments:
        if len(seg.lon) < 2:
            continue
        x, y = net.project(np.asarray(seg.lon, dtype=np.float64), np.asarray(seg.lat))
        step = np.hypot(np.diff(x), np.diff(y))
        cum = np.concatenate(([0.0], np.cumsum(step)))
        if cum[-1] <= 0:
            continue
        at = np.arange(0.5 * min(spacing_m, cum[-1]), cum[-1], spacing_m)
        piece = np.clip(np.searchsorted(cum, at, side="right") - 1, 0, len(step) - 1)
        moving = step[piece] > 0
        at, piece = at[moving], piece[moving]
        t = (at - cum[piece]) / step[piece]
        px = x[piece] + t * (x[piece + 1] - x[piece])
        py = y[piece] + t * (y[piece + 1] - y[piece])
        lon, lat = net.unproject(px, py)
        # bearing on the sphere from the piece's own ends: the map's north, not the grid's
        lon0, lat0 = np.asarray(seg.lon)[piece], np.asarray(seg.lat)[piece]
        lon1, lat1 = np.asarray(seg.lon)[piece + 1], np.asarray(seg.lat)[piece + 1]
        east = (lon1 - lon0) * np.cos(np.radians(0.5 * (lat0 + lat1)))
        bearing = np.degrees(np.arctan2(east, lat1 - lat0)) % 360.0
        arrows.extend(
            Arrow(float(a), float(b), float(c), seg.index)
            for a, b, c in zip(lon, lat, bearing, strict=True)
        )
    return arrows


def trace_gaps(
    result: MatchResult, net: RoadNetwork, *, min_gap_s: float | None = None
) -> list[Gap]:
    """
    Long steps between consecutive fixes with positions: outages and dropped stretches.

    With times, a step is a gap when it lasts at least ``min_gap_s`` (default: five times
    the median step, at least 10 s). Without times (``time_s`` all NaN) a step is a gap when
    it is at least five times the median step length and at least 100 m.

    Returns
    -------
    list of Gap
        In trace order, each with a label for a tooltip.
    """
    p = result.points
    ok = np.flatnonzero(np.isfinite(p.raw_lon) & np.isfinite(p.raw_lat))
    if len(ok) < 2:
        return []
    x, y = net.project(p.raw_lon[ok], p.raw_lat[ok])
    metres = np.hypot(np.diff(x), np.diff(y))
    times = p.time_s[ok]
    timed = bool(np.isfinite(times).all())
    if timed:
        seconds = np.diff(times)
        threshold = min_gap_s
        if threshold is None:
            positive = seconds[seconds > 0]
            median = float(np.median(positive)) if len(positive) else 1.0
            threshold = max(10.0, 5.0 * median)
        long_step = seconds >= threshold
    else:
        seconds = np.full(len(metres), math.nan)
        moving = metres[metres > 0]
        median = float(np.median(moving)) if len(moving) else 0.0
        long_step = metres >= max(100.0, 5.0 * median)
    gaps = []
    for k in np.flatnonzero(long_step).tolist():
        i, j = int(ok[k]), int(ok[k + 1])
        what = f"{seconds[k]:.0f} s without a fix" if timed else "a long step (no times)"
        label = f"gap: {what} between fix {i} and fix {j}, {metres[k]:.0f} m apart"
        gaps.append(
            Gap(
                before=i,
                seconds=float(seconds[k]),
                metres=float(metres[k]),
                lon=(float(p.raw_lon[i]), float(p.raw_lon[j])),
                lat=(float(p.raw_lat[i]), float(p.raw_lat[j])),
                label=label,
            )
        )
    return gaps


def break_marks(result: MatchResult) -> list[BreakMark]:
    """
    The breaks of a match, each with the last fix matched before it and the time between.

    The time is left out of the label when it is unknown (a trace without times).
    """
    p = result.points
    matched = np.flatnonzero(p.matched)
    marks = []
    for start in result.breaks:
        earlier = matched[matched < start]
        previous = int(earlier[-1]) if len(earlier) else -1
        label = f"break: segment {int(p.segment[start])} starts at fix {start}"
        seconds = math.nan
        if previous >= 0:
            seconds = float(p.time_s[start] - p.time_s[previous])
            if math.isfinite(seconds):
                label += f" ({seconds:.0f} s after fix {previous}, the last one matched before it)"
            else:
                label += f" (fix {previous} is the last one matched before it)"
        marks.append(BreakMark(start, previous, int(p.segment[start]), seconds, label))
    return marks


def endpoints(result: MatchResult) -> tuple[tuple[float, float, int], tuple[float, float, int]]:
    """
    Where the matched path starts and ends: ``(lon, lat, fix)`` of each.

    The first and last matched fixes' snapped positions; the raw ones when none matched.
    """
    p = result.points
    matched = np.flatnonzero(p.matched)
    if len(matched):
        first, last = int(matched[0]), int(matched[-1])
        return (
            (float(p.lon[first]), float(p.lat[first]), first),
            (float(p.lon[last]), float(p.lat[last]), last),
        )
    ok = np.flatnonzero(np.isfinite(p.raw_lon) & np.isfinite(p.raw_lat))
    if not len(ok):
        msg = f"trace {result.trace_id!r}: no fix has a finite position to draw"
        raise ValueError(msg)
    first, last = int(ok[0]), int(ok[-1])
    return (
        (float(p.raw_lon[first]), float(p.raw_lat[first]), first),
        (float(p.raw_lon[last]), float(p.raw_lat[last]), last),
    )
