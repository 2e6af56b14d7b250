"""Write docs/match.png: a real match on the embedded (Monaco) network, for the README.

Run ``.venv/bin/python scripts/make_readme_figure.py`` from the repository root; it needs the
``viz`` extra. The trip is simulated with a fixed seed, so the figure only changes when the
matcher or the drawing does.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt

import mapmatch
import roadnets
from mapmatch.simulate import SimulationConfig, simulate_trip
from mapmatch.viz import match_figure

OUT = Path(__file__).resolve().parent.parent / "docs" / "match.png"


def main(argv: list[str] | None = None) -> int:
    """Simulate, match and draw the demo trip; write the PNG."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT, help=f"PNG to write (default {OUT})")
    parser.add_argument("--seed", type=int, default=7, help="seed of the simulated trip")
    args = parser.parse_args(argv)

    net = roadnets.load(None)
    cfg = SimulationConfig(interval_s=5.0, noise_m=6.0, outlier_rate=0.03, route_length_m=1800.0)
    trace = simulate_trip(net, cfg, seed=args.seed, trace_id="monaco-demo").trace
    result = mapmatch.match(trace, net, diagnostics=True)
    fig, ax = plt.subplots(figsize=(8, 7), layout="constrained")
    match_figure(result, net, ax=ax, margin_m=80.0)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110, metadata={"Software": None})
    plt.close(fig)
    print(f"wrote {args.out} ({len(trace)} fixes, {result.matched_length_m:.0f} m matched)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
