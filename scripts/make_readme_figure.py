"""Write the README's pictures: docs/match.png (static figure) and docs/map.png (the web map).

Run ``.venv/bin/python scripts/make_readme_figure.py`` from the repository root; it needs the
``viz`` extra, and for the map a headless Chromium (Debian: ``apt-get install chromium``),
which opens the saved map offline and takes the screenshot. The trips are simulated with
fixed seeds, so the pictures only change when the matcher or the drawing does.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np

import mapmatch
import roadnets
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trip
from mapmatch.viz import match_figure, match_map
from mapmatch.viz.browser import find_chromium, screenshot

DOCS = Path(__file__).resolve().parent.parent / "docs"


def static_figure(net: roadnets.RoadNetwork, out: Path, seed: int) -> str:
    """The matplotlib figure of a 5 s trip with outliers."""
    cfg = SimulationConfig(interval_s=5.0, noise_m=6.0, outlier_rate=0.03, route_length_m=1800.0)
    trace = simulate_trip(net, cfg, seed=seed, trace_id="monaco-demo").trace
    result = mapmatch.match(trace, net, diagnostics=True)
    fig, ax = plt.subplots(figsize=(8, 7), layout="constrained")
    match_figure(result, net, ax=ax, margin_m=80.0)
    fig.savefig(out, dpi=110, metadata={"Software": None})
    plt.close(fig)
    return f"{len(trace)} fixes, {result.matched_length_m:.0f} m matched"


def web_map(net: roadnets.RoadNetwork, out: Path, seed: int, chromium: str) -> str:
    """A screenshot of the Leaflet map of a 1 Hz trip with a 40 s outage and outliers."""
    cfg = SimulationConfig(interval_s=1.0, noise_m=5.0, outlier_rate=0.02, route_length_m=1600.0)
    trip = simulate_trip(net, cfg, seed=seed, trace_id="monaco-1hz").trace
    keep = np.ones(len(trip), dtype=bool)
    keep[70:110] = False  # an outage
    trace = mapmatch.Trace(
        time=trip.time_s[keep],
        lon=trip.lon[keep],
        lat=trip.lat[keep],
        heading=trip.heading_deg[keep] if trip.heading_deg is not None else None,
        speed=trip.speed_mps[keep] if trip.speed_mps is not None else None,
        trace_id="monaco-1hz",
    )
    result = mapmatch.match(trace, net)
    with tempfile.TemporaryDirectory(prefix="mapmatch-map-") as folder:
        page = Path(folder) / "map.html"
        match_map(result, net, margin_m=60.0).save(str(page))
        screenshot(page, out, size=(1100, 760), chromium=chromium)
    return f"{len(trace)} fixes at 1 Hz, {result.matched_length_m:.0f} m matched"


def main(argv: list[str] | None = None) -> int:
    """Simulate, match and draw the demo trips; write the PNGs."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DOCS / "match.png", help="static figure")
    parser.add_argument("--map-out", type=Path, default=DOCS / "map.png", help="map screenshot")
    parser.add_argument("--only", choices=("static", "map"), help="write one picture only")
    parser.add_argument("--seed", type=int, default=7, help="seed of the simulated trips")
    args = parser.parse_args(argv)

    net = roadnets.load(None)
    if args.only != "map":
        args.out.parent.mkdir(parents=True, exist_ok=True)
        print(f"wrote {args.out} ({static_figure(net, args.out, args.seed)})")
    if args.only != "static":
        chromium = find_chromium()
        if chromium is None:
            parser.error("the map screenshot needs chromium: apt-get install -y chromium")
        args.map_out.parent.mkdir(parents=True, exist_ok=True)
        print(f"wrote {args.map_out} ({web_map(net, args.map_out, args.seed, chromium)})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
