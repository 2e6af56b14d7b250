"""``mapmatch simulate``: synthetic traces with ground truth on a real network."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

import roadnets
from mapmatch.simulate import SimulationConfig, simulate_trips, write_trips

if TYPE_CHECKING:
    import argparse

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> None:
    """Register the ``simulate`` sub-command."""
    parser = sub.add_parser(
        "simulate",
        help="write simulated traces with ground truth",
        description=(
            "Drive random fastest routes on a real network and write traces.csv (the "
            "observed fused traces) and truth.jsonl (true route, edges and length per trace)."
        ),
    )
    parser.add_argument("--network", default=None, help="OSM extract (default: embedded)")
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument("--traces", type=int, default=10, help="number of traces (10)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (0)")
    defaults = SimulationConfig()
    parser.add_argument("--interval-s", type=float, default=defaults.interval_s)
    parser.add_argument("--noise-m", type=float, default=defaults.noise_m)
    parser.add_argument("--noise-correlation-s", type=float, default=defaults.noise_correlation_s)
    parser.add_argument("--outlier-rate", type=float, default=defaults.outlier_rate)
    parser.add_argument("--outage-rate", type=float, default=defaults.outage_rate)
    parser.add_argument("--route-length-m", type=float, default=defaults.route_length_m)
    parser.add_argument("--route", choices=("fastest", "random_walk"), default=defaults.route)
    parser.add_argument(
        "--raw",
        action="store_true",
        help="also write raw GNSS/odometer/gyro logs per trace (input of `mapmatch fuse`)",
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Simulate and write the traces; print where they went."""
    started = time.perf_counter()
    net = roadnets.load(args.network)
    config = SimulationConfig(
        interval_s=args.interval_s,
        noise_m=args.noise_m,
        noise_correlation_s=args.noise_correlation_s,
        outlier_rate=args.outlier_rate,
        outage_rate=args.outage_rate,
        route_length_m=args.route_length_m,
        route=args.route,
    )
    trips = simulate_trips(net, config, count=args.traces, seed=args.seed)
    traces, truth = write_trips(trips, args.out)
    lines = [f"wrote {len(trips)} traces to {traces} and their truth to {truth}"]
    if args.raw:
        from mapmatch.fusion import RawLogSimConfig
        from mapmatch.fusion.pipeline import write_raw_logs

        raw = write_raw_logs(trips, args.out, RawLogSimConfig(), args.seed)
        lines.append(f"wrote {len(raw)} raw sensor logs (*.raw.csv) to {args.out}")
    points = sum(len(t.trace) for t in trips)
    km = sum(t.length_m for t in trips) / 1000
    lines.append(f"{points:,} points, {km:,.1f} km in {time.perf_counter() - started:.1f} s")
    print("\n".join(lines))
    return 0
