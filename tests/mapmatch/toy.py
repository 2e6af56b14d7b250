"""Hand-made road networks written as real OSM XML and loaded through roadnets.load."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

import mapmatch
import roadnets

if TYPE_CHECKING:
    from pathlib import Path

LON0, LAT0 = 8.0, 45.0
_M_PER_DEG_LAT = 111_132.0
_M_PER_DEG_LON = 111_320.0 * np.cos(np.radians(LAT0))


def lonlat(x: np.ndarray | float, y: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """Local metres east/north of (LON0, LAT0) to lon/lat (a tangent plane, good to cm here)."""
    return (
        LON0 + np.asarray(x, dtype=float) / _M_PER_DEG_LON,
        LAT0 + np.asarray(y, dtype=float) / _M_PER_DEG_LAT,
    )


def write_osm(
    path: Path, ways: list[tuple[int, list[tuple[float, float]], dict[str, str]]]
) -> Path:
    """Write ways given as (way id, [(x, y) metres], tags) as an OSM XML file."""
    node_ids: dict[tuple[float, float], int] = {}
    nodes, way_xml = [], []
    for way_id, points, tags in ways:
        refs = []
        for point in points:
            if point not in node_ids:
                node_ids[point] = len(node_ids) + 1
                lon, lat = lonlat(*point)
                nodes.append(f'<node id="{node_ids[point]}" lat="{lat:.9f}" lon="{lon:.9f}"/>')
            refs.append(f'<nd ref="{node_ids[point]}"/>')
        tag_xml = "".join(f'<tag k="{k}" v="{v}"/>' for k, v in tags.items())
        way_xml.append(f'<way id="{way_id}">{"".join(refs)}{tag_xml}</way>')
    path.write_text(
        '<?xml version="1.0" encoding="UTF-8"?><osm version="0.6">'
        + "".join(nodes)
        + "".join(way_xml)
        + "</osm>",
        encoding="utf-8",
    )
    return path


def drive(
    xy: list[tuple[float, float]], *, speed_mps: float, interval_s: float = 1.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Positions, headings and times of a drive along a polyline at constant speed."""
    pts = np.asarray(xy, dtype=float)
    step = np.hypot(*np.diff(pts, axis=0).T)
    cum = np.concatenate(([0.0], np.cumsum(step)))
    s = np.arange(0.0, cum[-1] + 1e-9, speed_mps * interval_s)
    x, y = np.interp(s, cum, pts[:, 0]), np.interp(s, cum, pts[:, 1])
    seg = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(step) - 1)
    d = np.diff(pts, axis=0)[seg]
    heading = np.degrees(np.arctan2(d[:, 0], d[:, 1])) % 360
    return x, y, heading, np.arange(len(s)) * interval_s


def trace_of(
    x: np.ndarray,
    y: np.ndarray,
    *,
    time_s: np.ndarray,
    heading: np.ndarray | None = None,
    speed: np.ndarray | float | None = None,
    trace_id: str = "toy",
) -> mapmatch.Trace:
    lon, lat = lonlat(x, y)
    speeds = None if speed is None else np.broadcast_to(np.asarray(speed, float), x.shape)
    return mapmatch.Trace(
        time=1.7e9 + time_s, lon=lon, lat=lat, heading=heading, speed=speeds, trace_id=trace_id
    )


def load(path: Path) -> roadnets.RoadNetwork:
    return roadnets.load(path, use_cache=False)
