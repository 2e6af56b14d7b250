"""FMM peer runner (project venv, FMM's SWIG binding on ``PYTHONPATH``).

FMM (Fast Map Matching, Yang and Gidófalvi 2018; built from source by
``../shared/peers/fmm/build.sh`` into ``.bench/fmm``) matches on our own network written as its
edge shapefile, one FMM edge per geometry segment, with its UBODT built by ``ubodt_gen``
(``fmm_network.py``; ``compare_peers.py`` prepares both once per extract and passes the paths in
``params["fmm"]``). ``load`` reads the network, its graph and the UBODT (timed as ``load_s``).

Per trace, untimed (like a request body): the lon/lat fixes projected to the network's UTM zone
and written as the WKT LineString FMM takes. Timed: ``FastMapMatch.match_wkt`` and the
conversion of its matched geometry back to lon/lat (what a user needs). Input: positions only;
FMM has no use for time, heading, speed or accuracy.

Variants (``params["fmm"]["variant"]``):

``stock``
    The trace as it is. FMM leaves a whole trace unmatched when one point has no edge within
    the search radius (the 40 m outliers do that now and then).
``drop``
    Points with no edge within the radius dropped: when FMM returns nothing, those points are
    found (a vectorised ``dwithin`` query on a shapely STRtree of the same edges, built at
    load) and the rest matched again, all timed. Same result as dropping them up front on
    every trace, without paying the query on the traces that need none; the fair speed
    comparison.

Settings fair to FMM (measured, ``../shared/peers/fmm/README.md``): ``k = 8`` candidates,
search radius ``r = 50 m``, ``gps_error`` = the set's noise sigma, ``reverse_tolerance = 0.5``
(the default 0 loses precision at 1 s). Override with ``params["fmm"]["config"]``.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import Geometry, TracePoints, run_peer

VARIANTS = ("stock", "drop")


def fmm_settings(params: dict[str, Any]) -> dict[str, Any]:
    """FastMapMatchConfig values for a set with ``noise_m``."""
    cfg: dict[str, Any] = {
        "k": 8,
        "radius_m": 50.0,
        "gps_error_m": float(params.get("noise_m", 5.0)),
        "reverse_tolerance": 0.5,
    }
    cfg.update(params.get("fmm", {}).get("config", {}))
    return cfg


def load(job: dict[str, Any]) -> dict[str, Any]:
    """Read FMM's network, graph and UBODT; the STRtree for the drop variant."""
    import fmm  # type: ignore[import-not-found]
    import numpy as np
    import pyproj
    import shapely

    spec = job["params"]["fmm"]
    variant = spec.get("variant", "stock")
    if variant not in VARIANTS:
        msg = f"unknown FMM variant {variant!r}; choose one of {VARIANTS}"
        raise ValueError(msg)
    network = fmm.Network(spec["edges_shp"], "id", "source", "target")
    graph = fmm.NetworkGraph(network)
    ubodt = fmm.UBODT.read_ubodt_binary(spec["ubodt"])
    model = fmm.FastMapMatch(network, graph, ubodt)
    cfg = fmm_settings(job["params"])
    config = fmm.FastMapMatchConfig(
        int(cfg["k"]),
        float(cfg["radius_m"]),
        float(cfg["gps_error_m"]),
        float(cfg["reverse_tolerance"]),
    )
    ctx: dict[str, Any] = {
        "model": model,
        "config": config,
        "cfg": cfg,
        "variant": variant,
        "network": network,
        "graph": graph,
        "ubodt": ubodt,
        "to_utm": pyproj.Transformer.from_crs("EPSG:4326", spec["crs"], always_xy=True),
        "to_lonlat": pyproj.Transformer.from_crs(spec["crs"], "EPSG:4326", always_xy=True),
        "np": np,
        "shapely": shapely,
        "spec": {k: v for k, v in spec.items() if k != "config"},
    }
    if variant == "drop":
        import pyogrio  # type: ignore[import-untyped]

        lines = pyogrio.read_dataframe(spec["edges_shp"], columns=[]).geometry.to_numpy()
        ctx["tree"] = shapely.STRtree(lines)
    return ctx


def prepare(ctx: dict[str, Any], tr: TracePoints) -> Any:
    """The trace's fixes in UTM metres (array) and as FMM's WKT LineString."""
    np = ctx["np"]
    x, y = ctx["to_utm"].transform(np.asarray(tr.lon), np.asarray(tr.lat))
    xy = np.column_stack([x, y])
    return xy, _wkt(xy)


def _wkt(xy: Any) -> str:
    return "LINESTRING(" + ",".join(f"{x:.3f} {y:.3f}" for x, y in xy) + ")"


def match(ctx: dict[str, Any], prepared: Any) -> Geometry:
    """One ``match_wkt`` call (retried without the uncovered points in that variant)."""
    np = ctx["np"]
    xy, wkt = prepared
    result = ctx["model"].match_wkt(wkt, ctx["config"])
    if len(result.cpath) == 0 and ctx["variant"] == "drop":
        # FMM gives up on the whole trace when one point has no edge within the radius; only
        # then is it worth finding those points (the result is the same as always dropping)
        radius = float(ctx["cfg"]["radius_m"])
        hits = ctx["tree"].query(ctx["shapely"].points(xy), predicate="dwithin", distance=radius)
        keep = np.zeros(len(xy), dtype=bool)
        keep[hits[0]] = True
        if not keep.all():
            if int(keep.sum()) < 2:
                msg = f"{int((~keep).sum())} of {len(keep)} points have no edge within {radius} m"
                raise RuntimeError(msg)
            result = ctx["model"].match_wkt(_wkt(xy[keep]), ctx["config"])
    if len(result.cpath) == 0:
        msg = "FMM matched nothing (a point without candidates, or points not connected)"
        raise RuntimeError(msg)
    text = result.mgeom.export_wkt()
    body = text[text.index("(") + 1 : text.rindex(")")]
    pts = np.array(body.replace(",", " ").split(), dtype=np.float64).reshape(-1, 2)
    lon, lat = ctx["to_lonlat"].transform(pts[:, 0], pts[:, 1])
    return [np.column_stack([lon, lat]).tolist()]


def geometry(ctx: dict[str, Any], tr: TracePoints, raw: Geometry) -> Geometry:
    """The matched path, already in lon/lat."""
    return [piece for piece in raw if len(piece) >= 2]


def settings(ctx: dict[str, Any]) -> dict[str, Any]:
    """Effective FMM settings and the files it ran on."""
    return {"variant": ctx["variant"], "FastMapMatchConfig": ctx["cfg"], "files": ctx["spec"]}


def main() -> int:
    """Entry point: ``python run_fmm.py JOB.json``."""
    return run_peer("fmm", load, match, geometry, settings, prepare=prepare)


if __name__ == "__main__":
    raise SystemExit(main())
