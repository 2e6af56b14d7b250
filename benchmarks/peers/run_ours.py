"""Our matcher as a "peer" (project venv), under the same job, warm-up and timing rules.

``roadnets.load`` is the timed load (the compiled network cache counts as a normal second load),
with the route table for sparse traces that ``mapmatch network build`` stores in the cache
(read, or built the first time, as FMM's UBODT is built once and cached);
traces are read with ``mapmatch.read_traces`` (not timed, like the peers' input preparation);
the timed call is ``mapmatch.match`` followed by ``mapmatch.export.geojson_bytes(result)``, the
GeoJSON document a user gets (what ``POST /v1/match`` answers and ``mapmatch match`` writes), as
FMM's conversion of its result to lon/lat and Meili's JSON response text are timed. The
geometry is the LineStrings of the GeoJSON's ``kind == "segment"`` features, in driving order.

Input: whatever columns the job's traces CSV has (positions only, or with heading, speed,
accuracy and odometer); ``mapmatch.read_traces`` takes them all.

Configuration: ``MatchConfig(sigma_m=noise)`` (our documented knob for the sensor noise); any
other ``MatchConfig`` field can be given through ``params["config"]``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import Geometry, TracePoints, run_peer


def config_kwargs(params: dict[str, Any]) -> dict[str, Any]:
    """MatchConfig keyword arguments for a set with ``noise_m``."""
    kw: dict[str, Any] = {"sigma_m": float(params.get("noise_m", 5.0))}
    kw.update(params.get("config", {}))
    return kw


def load(job: dict[str, Any]) -> dict[str, Any]:
    """Load the network (timed) and read the traces with our reader."""
    import mapmatch
    import roadnets

    net = roadnets.load(job["extract"])
    net.sparse_route_table()  # read from the cache entry, as `mapmatch network build` left it
    traces = {t.trace_id: t for t in mapmatch.read_traces(job["traces_csv"])}
    kw = config_kwargs(job["params"])
    return {"net": net, "traces": traces, "config": mapmatch.MatchConfig(**kw), "kw": kw}


def prepare(ctx: dict[str, Any], tr: TracePoints) -> Any:
    """Our Trace object for this trace id."""
    return ctx["traces"][tr.trace_id]


def match(ctx: dict[str, Any], trace: Any) -> Any:
    """One ``mapmatch.match`` call and the GeoJSON text of its result."""
    import mapmatch
    from mapmatch.export import geojson_bytes

    return geojson_bytes(mapmatch.match(trace, ctx["net"], ctx["config"]))


def geometry(ctx: dict[str, Any], tr: TracePoints, raw: Any) -> Geometry:
    """LineStrings of the segment features, in order."""
    fc = json.loads(raw) if isinstance(raw, str | bytes) else raw
    out: Geometry = []
    for feat in fc.get("features", []):
        props = feat.get("properties") or {}
        geom = feat.get("geometry") or {}
        if props.get("kind") == "segment" and geom.get("type") == "LineString":
            coords = [[float(c[0]), float(c[1])] for c in geom.get("coordinates", [])]
            if len(coords) >= 2:
                out.append(coords)
    return out


def settings(ctx: dict[str, Any]) -> dict[str, Any]:
    """The MatchConfig fields we set, and the route table sparse traces were matched with."""
    return {"MatchConfig": ctx["kw"], "route_table": ctx["net"].route_table_note}


def main() -> int:
    """Entry point: ``python run_ours.py JOB.json``."""
    return run_peer("ours", load, match, geometry, settings, prepare=prepare)


if __name__ == "__main__":
    raise SystemExit(main())
