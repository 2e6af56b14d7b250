"""Interim trace simulator: noisy traces with ground truth, until ``mapmatch simulate`` exists.

Writes ``DIR/traces.csv`` and ``DIR/truth.jsonl`` in the same format as ``mapmatch simulate``
(see benchmarks/peers/README.md). Each trace drives the shortest path between two random nodes of
the largest strongly connected component of the extract's drivable graph (osmnx, offline, see
``osm_graph``), at a constant speed drawn per trace, sampled every ``interval_s`` seconds, with
isotropic Gaussian noise of ``noise_m`` metres per axis and a share ``outlier_rate`` of points
displaced by ``outlier_m`` in a random direction. The truth is the driven path from the first
sample to the last one.

Usage::

    .venv/bin/python benchmarks/peers/interim_traces.py --network X.osm.pbf --traces 20 \
        --interval-s 15 --noise-m 10 --outlier-rate 0.02 --seed 1 --out DIR
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from pathlib import Path
from typing import Any

import networkx as nx
import numpy as np
import pyproj

sys.path.insert(0, str(Path(__file__).resolve().parent))
import itertools

import osm_graph

START_EPOCH_S = 1_700_000_000.0


def _edge_coords(g: nx.MultiDiGraph, u: int, v: int, key: int) -> list[tuple[float, float]]:
    data = g.edges[u, v, key]
    pu = (g.nodes[u]["x"], g.nodes[u]["y"])
    pv = (g.nodes[v]["x"], g.nodes[v]["y"])
    if "geometry" not in data:
        return [pu, pv]
    coords = [tuple(c) for c in data["geometry"].coords]
    d_fwd = math.dist(coords[0], pu) + math.dist(coords[-1], pv)
    d_rev = math.dist(coords[-1], pu) + math.dist(coords[0], pv)
    return coords if d_fwd <= d_rev else coords[::-1]


def _best_key(g: nx.MultiDiGraph, u: int, v: int) -> int:
    return int(min(g[u][v], key=lambda k: g[u][v][k]["length"]))


def simulate(
    network: str,
    *,
    traces: int,
    interval_s: float,
    noise_m: float,
    outlier_rate: float,
    seed: int,
    out: Path,
    outlier_m: float = 40.0,
    min_length_m: float = 2000.0,
    max_length_m: float = 8000.0,
) -> None:
    """Simulate ``traces`` noisy traces with truth and write them under ``out``."""
    rng = np.random.default_rng(seed)
    g = osm_graph.load_drive_graph(network)
    scc = max(nx.strongly_connected_components(g), key=len)
    g = g.subgraph(scc).copy()
    nodes = np.array(sorted(g.nodes))
    lon0 = float(np.mean([g.nodes[n]["x"] for n in nodes]))
    lat0 = float(np.mean([g.nodes[n]["y"] for n in nodes]))
    utm = pyproj.CRS(f"+proj=utm +zone={int((lon0 + 180) // 6) + 1} +datum=WGS84")
    if lat0 < 0:
        utm = pyproj.CRS(f"+proj=utm +zone={int((lon0 + 180) // 6) + 1} +south +datum=WGS84")
    fwd = pyproj.Transformer.from_crs(4326, utm, always_xy=True)
    inv = pyproj.Transformer.from_crs(utm, 4326, always_xy=True)

    out.mkdir(parents=True, exist_ok=True)
    rows: list[list[Any]] = []
    truths: list[dict[str, Any]] = []
    made = 0
    attempts = 0
    while made < traces:
        attempts += 1
        if attempts > 200 * traces:
            msg = f"could not find {traces} routes of {min_length_m}-{max_length_m} m"
            raise RuntimeError(msg)
        a, b = (int(x) for x in rng.choice(nodes, size=2, replace=False))
        try:
            path = nx.shortest_path(g, a, b, weight="length")
        except nx.NetworkXNoPath:
            continue
        hops = [(u, v, _best_key(g, u, v)) for u, v in itertools.pairwise(path)]
        length = sum(g.edges[h]["length"] for h in hops)
        if not min_length_m <= length <= max_length_m:
            continue
        lonlat: list[tuple[float, float]] = []
        for h in hops:
            c = _edge_coords(g, *h)
            lonlat.extend(c if not lonlat else c[1:])
        ll = np.array(lonlat)
        xs, ys = fwd.transform(ll[:, 0], ll[:, 1])
        xy = np.column_stack([xs, ys])
        seg = np.hypot(*np.diff(xy, axis=0).T)
        keep = np.concatenate([[True], seg > 0.01])
        xy, ll = xy[keep], ll[keep]
        cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
        speed = float(rng.uniform(8.0, 14.0))
        s = np.arange(0.0, cum[-1], speed * interval_s)
        if len(s) < 3:
            continue
        px = np.interp(s, cum, xy[:, 0])
        py = np.interp(s, cum, xy[:, 1])
        idx = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(xy) - 2)
        d = xy[idx + 1] - xy[idx]
        heading = np.degrees(np.arctan2(d[:, 0], d[:, 1])) % 360.0
        nx_ = px + rng.normal(0.0, noise_m, len(s))
        ny_ = py + rng.normal(0.0, noise_m, len(s))
        outl = rng.random(len(s)) < outlier_rate
        ang = rng.uniform(0, 2 * math.pi, len(s))
        nx_ = np.where(outl, nx_ + outlier_m * np.cos(ang), nx_)
        ny_ = np.where(outl, ny_ + outlier_m * np.sin(ang), ny_)
        lon, lat = inv.transform(nx_, ny_)
        trace_id = f"t{made:03d}"
        t0 = START_EPOCH_S + made * 10_000.0
        hdg = (heading + rng.normal(0.0, 3.0, len(s))) % 360.0
        spd = np.maximum(speed + rng.normal(0.0, 0.3, len(s)), 0.0)
        rows.extend(
            [
                trace_id,
                f"{t0 + i * interval_s:.1f}",
                f"{lon[i]:.7f}",
                f"{lat[i]:.7f}",
                f"{hdg[i]:.1f}",
                f"{spd[i]:.2f}",
                f"{noise_m:.1f}",
                f"{s[i]:.1f}",
            ]
            for i in range(len(s))
        )
        # truth: driven path from the first sample (s=0) to the last one
        s_end = float(s[-1])
        inside = cum < s_end
        tx = np.concatenate([xy[inside, 0], [np.interp(s_end, cum, xy[:, 0])]])
        ty = np.concatenate([xy[inside, 1], [np.interp(s_end, cum, xy[:, 1])]])
        tlon, tlat = inv.transform(tx, ty)
        edges = []
        start = 0.0
        for h in hops:
            e_len = float(g.edges[h]["length"])
            if start >= s_end:
                break
            osmid = g.edges[h].get("osmid")
            edges.append(
                {
                    "u": h[0],
                    "v": h[1],
                    "key": h[2],
                    "osm_way_ids": osmid if isinstance(osmid, list) else [osmid],
                    "length_m": e_len,
                    "start_offset_m": 0.0,
                    "end_offset_m": min(e_len, s_end - start),
                }
            )
            start += e_len
        truths.append(
            {
                "trace_id": trace_id,
                "length_m": s_end,
                "geometry": {
                    "type": "LineString",
                    "coordinates": [
                        [round(float(a_), 7), round(float(b_), 7)]
                        for a_, b_ in zip(tlon, tlat, strict=True)
                    ],
                },
                "edges": edges,
            }
        )
        made += 1
    with (out / "traces.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["trace_id", "time", "lon", "lat", "heading", "speed", "accuracy", "odometer"])
        w.writerows(rows)
    with (out / "truth.jsonl").open("w") as f:
        f.writelines(json.dumps(t) + "\n" for t in truths)


def main(argv: list[str] | None = None) -> int:
    """Command line entry point (same options as ``mapmatch simulate``)."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--network", required=True)
    p.add_argument("--traces", type=int, default=20)
    p.add_argument("--interval-s", type=float, default=1.0)
    p.add_argument("--noise-m", type=float, default=5.0)
    p.add_argument("--outlier-rate", type=float, default=0.02)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--out", type=Path, required=True)
    a = p.parse_args(argv)
    simulate(
        a.network,
        traces=a.traces,
        interval_s=a.interval_s,
        noise_m=a.noise_m,
        outlier_rate=a.outlier_rate,
        seed=a.seed,
        out=a.out,
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
