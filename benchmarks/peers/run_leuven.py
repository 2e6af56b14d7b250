"""leuvenmapmatching peer runner (Python 3.11 venv ``.peers/py311``).

The map is the extract's drivable osmnx graph (``osm_graph``, offline) **unsimplified**, so that
every OSM node is a vertex and leuven's straight edges follow the true road geometry, projected
to the extract's UTM zone (metres; faster and more exact than leuven's lat/lon mode), in an
``InMemMap`` with an R-tree over edges. Matching uses ``DistanceMatcher`` with non-emitting
states. When the lattice dies (leuven stops early), matching restarts after the last matched
observation and the path gets a break, as our matcher does.

Tuning (leuven needs wide settings for sparse traces; chosen on separate interim traces of the
monaco extract, see README): ``obs_noise`` = sigma and ``obs_noise_ne`` = 2 sigma;
``max_dist`` = ``max_dist_init`` = max(60 m, 5 sigma) so outliers keep candidates;
``dist_noise`` grows with the sampling interval (sigma + 1.5 m per second between points)
because the route between far apart points differs more from the straight line;
``non_emitting_length_factor`` 0.75 at 1 s, 0.95 when sparse (many nodes between points);
``max_lattice_width`` 10 (widened to 50 when leuven stops early), ``min_prob_norm`` 0.001,
``avoid_goingback``. Any key can be overridden through ``params["leuven"]``.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import Geometry, TracePoints, run_peer


def matcher_settings(params: dict[str, Any]) -> dict[str, Any]:
    """DistanceMatcher keyword arguments for a set with ``noise_m`` and ``interval_s``."""
    sigma = max(float(params.get("noise_m", 5.0)), 3.0)
    interval = float(params.get("interval_s", 1.0))
    kw: dict[str, Any] = {
        "obs_noise": sigma,
        "obs_noise_ne": 2.0 * sigma,
        "max_dist": max(60.0, 5.0 * sigma),
        "max_dist_init": max(60.0, 5.0 * sigma),
        "dist_noise": sigma + 1.5 * interval,
        "non_emitting_length_factor": 0.75 if interval <= 2 else 0.95,
        "non_emitting_states": True,
        "max_lattice_width": 10,
        "min_prob_norm": 0.001,
        "avoid_goingback": True,
    }
    kw.update(params.get("leuven", {}))
    return kw


def load(job: dict[str, Any]) -> dict[str, Any]:
    """Build leuven's in-memory map from the unsimplified drivable graph, in UTM metres."""
    import osm_graph
    import pyproj
    from leuvenmapmatching.map.inmem import InMemMap

    g = osm_graph.load_drive_graph(job["extract"], simplify=False)
    xs = [d["x"] for _, d in g.nodes(data=True)]
    ys = [d["y"] for _, d in g.nodes(data=True)]
    lon0 = sum(xs) / len(xs)
    lat0 = sum(ys) / len(ys)
    zone = int((lon0 + 180) // 6) + 1
    utm = pyproj.CRS(f"+proj=utm +zone={zone} {'+south ' if lat0 < 0 else ''}+datum=WGS84")
    fwd = pyproj.Transformer.from_crs(4326, utm, always_xy=True)
    inv = pyproj.Transformer.from_crs(utm, 4326, always_xy=True)
    px, py = fwd.transform(xs, ys)
    m = InMemMap("net", use_latlon=False, use_rtree=True, index_edges=True)
    for node, x, y in zip(g.nodes, px, py, strict=True):
        m.add_node(int(node), (float(y), float(x)))
    for u, v in set(g.edges()):
        if u != v:
            m.add_edge(int(u), int(v))
    return {"map": m, "fwd": fwd, "inv": inv, "kw": matcher_settings(job["params"])}


def prepare(ctx: dict[str, Any], tr: TracePoints) -> list[tuple[float, float]]:
    """Trace as leuven's (y, x) observations in metres."""
    x, y = ctx["fwd"].transform(tr.lon, tr.lat)
    return list(zip(y, x, strict=True))


def _pieces(best: list[Any]) -> list[list[tuple[float, float]]]:
    """Polylines (y, x) from leuven's best lattice path, cut where edges do not join."""
    pieces: list[list[tuple[float, float]]] = []
    cur: list[tuple[float, float]] = []
    prev = None
    # the path is: first projection, every node passed, last projection (projections of the
    # points in between only jitter along the same edge)
    for mt in best:
        e = mt.edge_m
        if prev is None:
            cur = [tuple(e.pi)]
        elif (e.l1, e.l2) == (prev.l1, prev.l2):
            pass
        elif prev.l2 is not None and e.l1 == prev.l2:
            cur.append(tuple(prev.p2))
        else:
            cur.append(tuple(prev.pi))
            if len(cur) >= 2:
                pieces.append(cur)
            cur = [tuple(e.pi)]
        prev = e
    if prev is not None:
        cur.append(tuple(prev.pi))
    if len(cur) >= 2:
        pieces.append(cur)
    return pieces


def match(ctx: dict[str, Any], obs: list[tuple[float, float]]) -> list[list[tuple[float, float]]]:
    """Match with DistanceMatcher; restart after early stops (each restart is a break)."""
    from leuvenmapmatching.matcher.distance import DistanceMatcher

    pieces: list[list[tuple[float, float]]] = []
    start = 0
    while start < len(obs) - 1:
        matcher = DistanceMatcher(ctx["map"], **ctx["kw"])
        matcher.match(obs[start:])
        if matcher.early_stop_idx is not None and ctx["kw"].get("max_lattice_width"):
            matcher.increase_max_lattice_width(50)
        best = matcher.lattice_best or []
        pieces.extend(_pieces(best))
        stop = matcher.early_stop_idx
        if stop is None:
            break
        start += max(stop, 1) + 1 if stop else 1
    return pieces


def geometry(
    ctx: dict[str, Any], tr: TracePoints, raw: list[list[tuple[float, float]]]
) -> Geometry:
    """Back to lon/lat."""
    out: Geometry = []
    for piece in raw:
        lon, lat = ctx["inv"].transform([p[1] for p in piece], [p[0] for p in piece])
        out.append([[float(a), float(b)] for a, b in zip(lon, lat, strict=True)])
    return out


def settings(ctx: dict[str, Any]) -> dict[str, Any]:
    """Effective DistanceMatcher settings."""
    return {"map": "osmnx drive graph, unsimplified, UTM", "DistanceMatcher": ctx["kw"]}


def main() -> int:
    """Entry point: ``python run_leuven.py JOB.json``."""
    return run_peer("leuvenmapmatching", load, match, geometry, settings, prepare=prepare)


if __name__ == "__main__":
    raise SystemExit(main())
