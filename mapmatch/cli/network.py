"""``mapmatch network build|info SOURCE``: compile, cache and describe road networks."""

from __future__ import annotations

import argparse
import json
import math
import time
from typing import Any

import roadnets
from roadnets.route_store import DEFAULT_BUDGET_MB, table_bytes

__all__ = ["add_parser", "run"]


def _megabytes(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not (value >= 0 and math.isfinite(value)):
        msg = f"must be a number of MB >= 0 (got {text!r})"
        raise argparse.ArgumentTypeError(msg)
    return value


def add_parser(sub: Any) -> None:
    """Register the ``network`` sub-command."""
    parser = sub.add_parser(
        "network",
        help="build the cache of a road network, or describe one",
        description="Compile an OSM extract into the cache, or print its figures.",
    )
    parser.add_argument("action", choices=("build", "info"))
    parser.add_argument(
        "source", nargs="?", default=None, help="OSM extract (default: the embedded network)"
    )
    parser.add_argument("--cache-dir", default=None, help="folder of compiled networks")
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    parser.add_argument(
        "--route-table-mb",
        type=_megabytes,
        default=DEFAULT_BUDGET_MB,
        metavar="MB",
        help="build: also build the route table sparse traces are matched with, within "
        "the longest reach (2,000 m down to 500 m) whose estimated size fits this many MB "
        f"(default {DEFAULT_BUDGET_MB:.0f}; 0: none; building it takes about twice its size "
        "for a moment)",
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """
    Build or describe the network; print its figures.

    ``build`` compiles the extract into the cache unless it is there already (then it says so
    and prints no build time), builds the R-tree once and compiles the routing kernels
    (:func:`roadnets.warm_kernels`) and the matcher's (short matches,
    :mod:`mapmatch.batch.warm`, and a short live trip, :mod:`mapmatch.online.warm`), reported
    on lines of their own: compiling them happens once per install (a few minutes on a fresh
    one), not once per network; later processes load them from numba's on-disk cache in a
    fraction of a second. It then builds the route table
    sparse traces are matched with into the cache entry when it fits ``--route-table-mb``
    (:meth:`roadnets.RoadNetwork.sparse_route_table`).
    """
    started = time.perf_counter()
    net = roadnets.load(args.source, cache_dir=args.cache_dir)
    kernels = None
    matcher_s = 0.0
    if args.action == "build":
        net.rtree  # noqa: B018 - build the index so that its time is part of the build
        built_s = time.perf_counter() - started
        kernels = roadnets.warm_kernels()
        from mapmatch.batch import warm  # its import matches once: the matcher's kernels
        from mapmatch.online.warm import warm_up_live

        matcher_s = warm.WARMUP_S + warm_up_live()
        net.route_table_budget_mb = args.route_table_mb
        table_started = time.perf_counter()
        table = net.sparse_route_table()
        table_s = time.perf_counter() - table_started
    info = net.info()
    elapsed = time.perf_counter() - started
    if args.json:
        payload: dict[str, Any] = {
            "id": info.network_id,
            "source": info.source,
            "crs": info.crs,
            "nodes": info.nodes,
            "edges": info.edges,
            "road_km": round(info.road_km, 3),
            "road_km_by_class": info.road_km_by_class,
            "oneway_share": round(info.oneway_share, 4),
            "bbox": list(info.bbox),
            "turn_restrictions": info.turn_restrictions,
            "clipped_ways": info.clipped_ways,
            "from_cache": info.from_cache,
            "cache_entry": net.cache_entry,
            "load_s": round(info.load_s, 4),
            "elapsed_s": round(elapsed, 4),
        }
        if kernels is not None:
            payload["build_s"] = None if info.from_cache else round(built_s, 4)
            payload["kernels"] = {
                "seconds": round(kernels.seconds, 4),
                "compiled": kernels.compiled,
                "loaded": kernels.loaded,
                "matcher_s": round(matcher_s, 4),
            }
            payload["route_table"] = {
                "note": net.route_table_note,
                "bytes": table_bytes(table) if table is not None else 0,
                "seconds": round(table_s, 4),
            }
        print(json.dumps(payload, indent=2))
        return 0
    lines = [
        f"network      {info.network_id}",
        f"source       {info.source}",
        f"crs          {net.projector.label}",
        f"nodes        {info.nodes:,}",
        f"edges        {info.edges:,} directed",
        f"road         {info.road_km:,.1f} km ({info.oneway_share:.0%} one-way)",
    ]
    lines += [f"  {name:<14} {km:>9,.1f} km" for name, km in info.road_km_by_class.items()]
    lon0, lat0, lon1, lat1 = info.bbox
    lines += [
        f"bbox         {lon0:.5f},{lat0:.5f} .. {lon1:.5f},{lat1:.5f}",
        f"restrictions {info.turn_restrictions} banned turns",
        f"clipped ways {info.clipped_ways}",
    ]
    where = f" in {net.cache_entry}" if net.cache_entry else " (not cached)"
    if kernels is None:
        origin = "from the cache" if info.from_cache else "compiled"
        lines.append(f"load         {info.load_s:.3f} s ({origin}{where})")
    elif info.from_cache:
        lines.append(f"build        already cached{where}; opened in {info.load_s:.3f} s")
    else:
        lines.append(f"build        {built_s:.3f} s (parsed, compiled, indexed){where}")
    if kernels is not None:
        lines.append(f"kernels      {kernels.describe()}")
        lines.append(f"matcher      kernels ready in {matcher_s:.2f} s (short matches)")
        lines.append(f"route table  {net.route_table_note} ({table_s:.2f} s)")
    print("\n".join(lines))
    return 0
