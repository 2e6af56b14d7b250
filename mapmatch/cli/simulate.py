"""``mapmatch simulate``: synthetic traces with ground truth on a real network."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

import roadnets
from mapmatch.evaluation.simulate import (
    INPUT_CLASSES,
    SimulationConfig,
    simulate_trips,
    write_trips,
)

if TYPE_CHECKING:
    import argparse

__all__ = ["add_parser", "config_from_args", "run"]

# (flag = the SimulationConfig field with dashes, help); a flag left out keeps the preset's value
_FLOAT_FLAGS = (
    ("interval-s", "sampling interval, s; 0.1 is 10 Hz"),
    ("noise-m", "1-sigma position error per axis, m; the stationary std when correlated"),
    ("noise-correlation-per-s", "AR(1) correlation of the position error 1 s apart, e.g. 0.95"),
    ("noise-correlation-s", "the same as a time constant tau, s; give one of the two"),
    ("outlier-rate", "share of fixes displaced by --outlier-m"),
    ("outlier-m", "outlier displacement, m"),
    ("outage-rate", "chance per minute of an outage of --outage-s"),
    ("outage-s", "length of an --outage-rate outage, s"),
    ("outage-per-km", "GNSS outages per km of route (durations from --outage-range-s)"),
    ("canyon-per-km", "urban-canyon stretches per km of route"),
    ("canyon-bias-m", "lateral pull of a canyon stretch to one side of the road, m"),
    ("heading-noise-deg", "1-sigma heading noise, degrees"),
    ("heading-noise-slow-deg", "extra heading noise x exp(-v) at low speed, degrees, e.g. 87"),
    ("speed-noise-mps", "1-sigma speed noise, m/s"),
    ("odometer-scale-error", "largest random odometer scale error per trip; 0.005 is 0.5 %"),
    ("odometer-bias", "fixed odometer scale error; 0.02 reads 2 % high"),
    ("stop-probability", "chance of a brief stop at any node between edges"),
    ("stop-s", "longest brief stop, s"),
    ("junction-stop-share", "share of real junctions where the car stops, e.g. 0.33"),
    ("route-length-m", "target trip length, m"),
)
_RANGE_FLAGS = (
    ("outage-range-s", "outage duration range, s"),
    ("canyon-s", "canyon stretch duration range, s"),
    ("junction-stop-s", "junction stop duration range, s"),
)


def add_parser(sub: Any) -> None:
    """Register the ``simulate`` sub-command."""
    parser = sub.add_parser(
        "simulate",
        help="write simulated traces with ground truth",
        description=(
            "Drive random fastest routes on a real network and write traces.csv (the "
            "observed traces) and truth.jsonl (true route, edges and length per trace, its "
            "stops, outages and urban-canyon stretches, its own U-turns and loops). Every "
            "realistic-noise option is off by default; --realistic switches them all on "
            "(AR(1) 0.95/s 6 m noise, canyons, junction stops, slow-speed heading noise, "
            "outages, odometer 2 % high), --noise-free gives the exact truth at any "
            "interval; other flags then change single values."
        ),
    )
    parser.add_argument("--network", default=None, help="OSM extract (default: embedded)")
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument("--traces", type=int, default=10, help="number of traces (10)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (0)")
    preset = parser.add_mutually_exclusive_group()
    preset.add_argument(
        "--realistic", action="store_true", help="start from SimulationConfig.realistic()"
    )
    preset.add_argument(
        "--noise-free",
        action="store_true",
        help="start from SimulationConfig.noise_free(): no noise, exact odometer, all columns",
    )
    defaults = SimulationConfig()
    for flag, text in _FLOAT_FLAGS:
        value = getattr(defaults, flag.replace("-", "_"))
        parser.add_argument(
            f"--{flag}",
            type=float,
            default=None,
            help=f"{text} (default {value:g})".replace("%", "%%"),
        )
    for flag, text in _RANGE_FLAGS:
        lo, hi = getattr(defaults, flag.replace("-", "_"))
        parser.add_argument(
            f"--{flag}",
            type=float,
            nargs=2,
            metavar=("LOW", "HIGH"),
            default=None,
            help=f"{text} (default {lo:g} {hi:g})",
        )
    parser.add_argument("--route", choices=("fastest", "random_walk"), default=None)
    columns = parser.add_mutually_exclusive_group()
    columns.add_argument(
        "--input-class",
        choices=sorted(INPUT_CLASSES),
        default=None,
        help="optional columns to keep: positions (plain GPS), accuracy, heading_speed "
        "(+ accuracy), odometer (all; default)",
    )
    columns.add_argument(
        "--plain-gps",
        action="store_true",
        help="time, lon, lat only (the same as --input-class positions)",
    )
    parser.add_argument(
        "--raw",
        action="store_true",
        help="also write raw GNSS/odometer/gyro logs per trace (input of `mapmatch fuse`)",
    )
    parser.set_defaults(run=run)


def config_from_args(args: argparse.Namespace) -> SimulationConfig:
    """The preset the flags name, with every flag given on top of it."""
    if args.realistic:
        base = SimulationConfig.realistic()
    elif args.noise_free:
        base = SimulationConfig.noise_free()
    else:
        base = SimulationConfig()
    changes: dict[str, Any] = {}
    for flag, _ in _FLOAT_FLAGS + _RANGE_FLAGS:
        name = flag.replace("-", "_")
        value = getattr(args, name)
        if value is not None:
            changes[name] = tuple(value) if isinstance(value, list) else value
    if args.route is not None:
        changes["route"] = args.route
    if args.plain_gps:
        changes["input_class"] = "positions"
    elif args.input_class is not None:
        changes["input_class"] = args.input_class
    return base.replace(**changes)


def run(args: argparse.Namespace) -> int:
    """Simulate and write the traces; print where they went."""
    started = time.perf_counter()
    config = config_from_args(args)
    net = roadnets.load(args.network)
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
    stops = sum(len(t.stops) for t in trips)
    outages = sum(len(t.outages) for t in trips)
    canyons = sum(len(t.canyons) for t in trips)
    lines.append(
        f"{points:,} points, {km:,.1f} km, {stops} stops, {outages} outages, "
        f"{canyons} canyon stretches in {time.perf_counter() - started:.1f} s"
    )
    print("\n".join(lines))
    return 0
