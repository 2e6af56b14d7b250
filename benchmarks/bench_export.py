"""
Output cost: the GeoJSON a user gets, and the tables, before and after :mod:`mapmatch.export`.

``legacy_geojson`` is the serialiser ``MatchResult.to_geojson`` used before the export module
(one dict per point, Python ``round`` on numpy scalars, then ``json.dumps``), kept here as
the reference: tests check that the new text keeps every field of it byte for byte
(``tests/mapmatch/test_export.py``) and this script times both.

Measured on simulated trips (network loaded, kernels warm, one process): a 1 Hz trace of 300
fixes and a 15 s trace, each median of ``--repeats`` rounds of ``--loops`` calls::

    .venv/bin/python benchmarks/bench_export.py [--network PATH] [--repeats 5] [--loops 50]

Prints two markdown tables, milliseconds per call. The first: the match itself;
``to_geojson()`` (the dict) before and after; the GeoJSON text (legacy: the dict + compact
``json.dumps``; now :func:`mapmatch.export.geojson_bytes`); the whole call a user makes
(match + text, on a fresh result, so the lazily made geometry and attributes are paid for);
and the per-point and per-edge tables. The second: :func:`mapmatch.export.geojson_bytes`
alone per trace on traces of 2, 12, 30 and 300 fixes (CPU time, minimum of the rounds),
where the small ones show what every document costs whatever its size; again on fresh
results (segments as a match returns them: attributes and geometry made by the call).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import statistics
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

if TYPE_CHECKING:
    from collections.abc import Callable

    from mapmatch.result import MatchResult
    from roadnets import RoadNetwork

ANDORRA = ROOT.parent / "shared" / "data" / "osm" / "andorra_2020.osm.pbf"


def legacy_geojson(result: MatchResult) -> dict[str, Any]:
    """The FeatureCollection as ``MatchResult.to_geojson`` built it before mapmatch.export."""

    def finite(value: float) -> float | None:
        return None if math.isnan(value) else round(float(value), 3)

    features: list[dict[str, Any]] = []
    for seg in result.segments:
        coords = np.column_stack((seg.lon, seg.lat)).round(7).tolist()
        if len(coords) == 1:
            coords = coords * 2
        features.append(
            {
                "type": "Feature",
                "geometry": {"type": "LineString", "coordinates": coords},
                "properties": {
                    "kind": "segment",
                    "segment": seg.index,
                    "point_range": [seg.first, seg.last],
                    "length_m": round(seg.length_m, 3),
                    "edges": [
                        {
                            "u": e.u,
                            "v": e.v,
                            "key": e.key,
                            "osm_way_ids": list(e.osm_way_ids),
                            "length_m": round(e.length_m, 3),
                            "start_offset_m": round(e.start_offset_m, 3),
                            "end_offset_m": round(e.end_offset_m, 3),
                        }
                        for e in seg.edges
                    ],
                },
            }
        )
    p = result.points
    for i in range(len(p.time_s)):
        matched = bool(p.matched[i])
        geometry = (
            {"type": "Point", "coordinates": [round(p.lon[i], 7), round(p.lat[i], 7)]}
            if matched
            else None
        )
        features.append(
            {
                "type": "Feature",
                "geometry": geometry,
                "properties": {
                    "kind": "point",
                    "index": i,
                    "time": None if math.isnan(p.time_s[i]) else float(p.time_s[i]),
                    "matched": matched,
                    "u": int(p.u[i]) if matched else None,
                    "v": int(p.v[i]) if matched else None,
                    "key": int(p.key[i]) if matched else None,
                    "offset_m": finite(p.offset_m[i]),
                    "distance_m": finite(p.distance_m[i]),
                    "confidence": round(float(p.confidence[i]), 4),
                    "interpolated": bool(p.interpolated[i]),
                    "outlier": bool(p.outlier[i]),
                },
            }
        )
    return {
        "type": "FeatureCollection",
        "trace_id": result.trace_id,
        "network": dict(result.network),
        "matched_length_m": round(result.matched_length_m, 3),
        "distance_check": result.distance_check.to_dict(),
        "breaks": list(result.breaks),
        "stats": result.stats.to_dict(),
        "features": features,
    }


def legacy_geojson_bytes(result: MatchResult) -> bytes:
    """What the batch and the service wrote before (compact ``json.dumps``)."""
    text = json.dumps(legacy_geojson(result), allow_nan=False, separators=(",", ":"))
    return text.encode("ascii")


def _ms(fn: Callable[[], object], repeats: int, loops: int) -> float:
    fn()
    rounds = []
    for _ in range(repeats):
        started = time.perf_counter()
        for _ in range(loops):
            fn()
        rounds.append((time.perf_counter() - started) / loops)
    return 1000.0 * statistics.median(rounds)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument("--network", default=None, help="OSM extract (default: shared Andorra)")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--loops", type=int, default=50)
    args = parser.parse_args()

    import roadnets

    source = args.network or (str(ANDORRA) if ANDORRA.exists() else None)
    net = roadnets.load(source)
    print(f"network {net.network_id}; median of {args.repeats} x {args.loops} calls, ms per call\n")
    print(
        "| trace | fixes | edges | match | to_geojson() before | after | ratio "
        "| GeoJSON text before | after | ratio | match + text before | after | ratio "
        "| points table | edges table |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for label, interval, noise, fixes in (("1 Hz", 1.0, 5.0, 300), ("15 s", 15.0, 10.0, 120)):
        row = _bench_set(net, label, interval, noise, fixes, args.repeats, args.loops)
        if row is None:
            print(f"{label}: the legacy fields differ from geojson_bytes", file=sys.stderr)
            return 1
        print(row, flush=True)
    print(
        "\nGeoJSON text per trace, by trace size (geojson_bytes on a matched result; CPU time, "
        f"min of {args.repeats} rounds of {args.loops} calls over {len(SEEDS)} trips, ms)\n"
    )
    print(
        "| interval | fixes | edges (mean) | bytes (mean) | geojson_bytes ms/trace "
        "| on a fresh result |"
    )
    print("|---|---:|---:|---:|---:|---:|")
    for interval, noise, fixes in SIZES:
        print(_per_trace_row(net, interval, noise, fixes, args.repeats, args.loops), flush=True)
    return 0


#: Trace sizes of the per-trace table: small sparse traces (where the fixed cost of a
#: document shows) up to a long 1 Hz one.
SIZES = ((30.0, 20.0, 2), (30.0, 20.0, 12), (15.0, 10.0, 30), (1.0, 5.0, 300))
SEEDS = (11, 12, 13, 14, 15)


def _per_trace_row(
    net: RoadNetwork, interval: float, noise: float, fixes: int, n: int, k: int
) -> str:
    """One row of the per-trace table: ``geojson_bytes`` of a few trips of ``fixes`` fixes."""
    import mapmatch
    from mapmatch import export
    from mapmatch.evaluation.simulate import SimulationConfig, simulate_trip

    cfg = SimulationConfig(
        interval_s=interval, noise_m=noise, route_length_m=(fixes + 2) * 12.0 * interval
    )
    results = []
    for seed in SEEDS:
        trace = simulate_trip(net, cfg, seed=seed, trace_id=f"size-{fixes}").trace
        results.append(mapmatch.match(trace.slice(0, min(fixes, len(trace))), net))
    sizes = [len(export.geojson_bytes(r)) for r in results]  # also makes the lazy geometry
    best = fresh = math.inf
    for _ in range(n):
        started = time.process_time()
        for _ in range(k):
            for r in results:
                export.geojson_bytes(r)
        best = min(best, (time.process_time() - started) / k / len(results))
        unmade = [_unmade(r, net) for _ in range(k) for r in results]
        started = time.process_time()
        for r in unmade:
            export.geojson_bytes(r)
        fresh = min(fresh, (time.process_time() - started) / len(unmade))
    points = statistics.mean(len(r.points.time_s) for r in results)
    edges = statistics.mean(sum(len(s.edge) for s in r.segments) for r in results)
    return (
        f"| {interval:g} s | {points:.0f} | {edges:.1f} | {statistics.mean(sizes):,.0f} "
        f"| {1000.0 * best:.3f} | {1000.0 * fresh:.3f} |"
    )


def _unmade(result: MatchResult, net: RoadNetwork) -> MatchResult:
    """``result`` with new segments, as a match returns them: attributes and geometry not made."""
    from mapmatch.result import Segment

    segments = [
        Segment(s.index, s.first, s.last, s.edge, s.start_offset_m, s.end_offset_m, net=net)
        for s in result.segments
    ]
    return dataclasses.replace(result, segments=segments)


def _bench_set(
    net: RoadNetwork, label: str, interval: float, noise: float, fixes: int, n: int, k: int
) -> str | None:
    """One table row; ``None`` when the new GeoJSON lost or changed a legacy field."""
    import mapmatch
    from mapmatch import export
    from mapmatch.evaluation.simulate import SimulationConfig, simulate_trip

    cfg = SimulationConfig(
        interval_s=interval, noise_m=noise, route_length_m=fixes * 12.0 * interval
    )
    trace = simulate_trip(net, cfg, seed=3, trace_id="bench").trace
    trace = trace.slice(0, min(fixes, len(trace)))
    result = mapmatch.match(trace, net)
    legacy = legacy_geojson_bytes(result)
    if json.loads(legacy) != _without_new_fields(json.loads(export.geojson_bytes(result))):
        return None
    t_match = _ms(lambda: mapmatch.match(trace, net), n, max(1, k // 5))
    t_dict0 = _ms(lambda: legacy_geojson(result), n, k)
    t_dict1 = _ms(result.to_geojson, n, k)
    t_text0 = _ms(lambda: legacy_geojson_bytes(result), n, k)
    t_text1 = _ms(lambda: export.geojson_bytes(result), n, k)
    # the whole call a user makes, on a fresh result (geometry and attributes not made yet)
    t_all0 = _ms(lambda: legacy_geojson_bytes(mapmatch.match(trace, net)), n, max(1, k // 5))
    t_all1 = _ms(lambda: export.geojson_bytes(mapmatch.match(trace, net)), n, max(1, k // 5))
    t_points = _ms(result.to_dataframe, n, k)
    t_edges = _ms(lambda: export.edges_frame(result), n, k)
    edges = sum(len(s.edge) for s in result.segments)
    return (
        f"| {label} | {len(trace)} | {edges} | {t_match:.2f} "
        f"| {t_dict0:.2f} | {t_dict1:.2f} | {t_dict0 / t_dict1:.1f}x "
        f"| {t_text0:.2f} | {t_text1:.2f} | {t_text0 / t_text1:.1f}x "
        f"| {t_all0:.2f} | {t_all1:.2f} | {t_all0 / t_all1:.2f}x "
        f"| {t_points:.2f} | {t_edges:.2f} |"
    )


#: Members the export module added to the legacy document (removed before comparing).
NEW_EDGE_FIELDS = frozenset(
    {
        "name",
        "road_class",
        "speed_limit_kph",
        "entry_time",
        "exit_time",
        "duration_s",
        "mean_speed_kph",
    }
)
NEW_POINT_FIELDS = frozenset({"segment", "edge_index", "along_m"})
NEW_SEGMENT_FIELDS = frozenset({"start_time", "end_time"})


def _without_new_fields(doc: dict[str, Any]) -> dict[str, Any]:
    """The document with the members added since the legacy serialiser taken out."""
    for feature in doc["features"]:
        props = feature["properties"]
        if props["kind"] == "segment":
            for name in NEW_SEGMENT_FIELDS:
                props.pop(name, None)
            for edge in props["edges"]:
                for name in NEW_EDGE_FIELDS:
                    edge.pop(name, None)
        else:
            for name in NEW_POINT_FIELDS:
                props.pop(name, None)
    return doc


if __name__ == "__main__":
    raise SystemExit(main())
