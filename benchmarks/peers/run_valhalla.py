"""Valhalla Meili peer runner (Python 3.12 venv ``.peers/valhalla``, package ``pyvalhalla``).

Matches each trace with ``Actor.trace_attributes`` (``costing=auto``, ``shape_match=map_snap``)
on tiles built offline by ``setup.sh`` under ``.peers/tiles/<extract-stem>/``. The matched
geometry is the response's ``shape``, cut where consecutive matched edges do not join (Meili
starts a new path after a break or a point it could not match).

Tuning (Meili at its best, not its defaults): ``turn_penalty_factor=500`` (default 0, which at
1 Hz lets noise add short detours), ``gps_accuracy`` = the noise sigma (floor 5 m) and
``search_radius`` = max(50 m, 5 x sigma) so that the true road is a candidate even for the
40 m outliers (25 m left a third of the 1 Hz traces broken into pieces);
``breakage_distance`` raised to 3000 m so sparse traces do not break; ``interpolation_distance``
left at 10 m (its default). Any of these can be overridden with ``params["trace_options"]``.

Input: time, lon, lat, and each point's ``accuracy`` when the traces CSV has that column (the
full-input class): Meili takes a per-point GPS accuracy (``accuracy`` of a shape point, which
replaces ``gps_accuracy`` for that point). It has no use for heading, speed or odometer
(shape points carry no such fields for map matching).
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
import itertools

from common import Geometry, TracePoints, decode_polyline, run_peer, split_polyline

ROOT = Path(__file__).resolve().parents[2]


def trace_options(params: dict[str, Any]) -> dict[str, Any]:
    """Meili trace options for a set with ``noise_m`` and ``interval_s``."""
    sigma = max(float(params.get("noise_m", 5.0)), 5.0)
    opts: dict[str, Any] = {
        "gps_accuracy": sigma,
        "search_radius": max(50.0, 5.0 * sigma),
        "turn_penalty_factor": 500,
        "breakage_distance": 3000,
    }
    opts.update(params.get("trace_options", {}))
    return opts


def load(job: dict[str, Any]) -> dict[str, Any]:
    """Open the Actor on the extract's prebuilt tiles."""
    from valhalla import Actor

    stem = Path(job["extract"]).name.split(".")[0]
    config = Path(
        job["params"].get("valhalla_config", ROOT / ".peers/tiles" / stem / "valhalla.json")
    )
    if not config.exists():
        msg = f"no Valhalla tiles for {stem} at {config}; run benchmarks/peers/setup.sh"
        raise FileNotFoundError(msg)
    opts = trace_options(job["params"])
    return {"actor": Actor(str(config)), "options": opts}


def request(ctx: dict[str, Any], tr: TracePoints) -> str:
    """The trace_attributes request body for one trace."""
    shape: list[dict[str, float]] = [
        {"lon": lon, "lat": lat, "time": t}
        for lon, lat, t in zip(tr.lon, tr.lat, tr.time, strict=True)
    ]
    for point, acc in zip(shape, tr.accuracy, strict=True):
        if acc is not None and acc > 0:
            point["accuracy"] = acc
    return json.dumps(
        {
            "shape": shape,
            "costing": "auto",
            "shape_match": "map_snap",
            "trace_options": ctx["options"],
            "filters": {
                "attributes": ["shape", "edge.begin_shape_index", "edge.end_shape_index"],
                "action": "include",
            },
        }
    )


def match(ctx: dict[str, Any], body: str) -> str:
    """One Meili call on a prepared request body."""
    return str(ctx["actor"].trace_attributes(body))


def geometry(ctx: dict[str, Any], tr: TracePoints, raw: str) -> Geometry:
    """Decode the matched shape and cut it where consecutive edges do not join."""
    d = json.loads(raw)
    coords = decode_polyline(d.get("shape", ""))
    edges = d.get("edges", [])
    if not edges:
        return split_polyline(coords, [])
    breaks = [
        e2["begin_shape_index"]
        for e1, e2 in itertools.pairwise(edges)
        if e1["end_shape_index"] != e2["begin_shape_index"]
        and math.dist(coords[e1["end_shape_index"]], coords[e2["begin_shape_index"]]) > 1e-7
    ]
    return split_polyline(coords, breaks)


def settings(ctx: dict[str, Any]) -> dict[str, Any]:
    """Effective Meili options."""
    return {"costing": "auto", "shape_match": "map_snap", "trace_options": ctx["options"]}


def main() -> int:
    """Entry point: ``python run_valhalla.py JOB.json``."""
    return run_peer("valhalla", load, match, geometry, settings, prepare=request)


if __name__ == "__main__":
    raise SystemExit(main())
