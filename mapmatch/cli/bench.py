"""``mapmatch bench``: matching speed and accuracy on simulated traces."""

from __future__ import annotations

import json
import logging
import os
from typing import TYPE_CHECKING, Any

import roadnets
from mapmatch.evaluation.accuracy import add_arguments, run_cli
from mapmatch.evaluation.benchmark import bench_network, markdown_table, parse_sets

if TYPE_CHECKING:
    import argparse

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> None:
    """Register the ``bench`` sub-command."""
    parser = sub.add_parser(
        "bench",
        help="measure matching speed and accuracy on simulated traces",
        description=(
            "Simulate traces on each network and report points/s (one process, matching "
            "only, median of repeats), peak memory and accuracy against the truth. With "
            "--matrix: the accuracy matrix (every extract x input class x condition: matched "
            "length, spurious U-turns and loops, verdict; benchmarks/bench_accuracy.py); with "
            "--truth: the noise-free truth check; with --inspect: one trip of those again."
        ),
    )
    parser.add_argument(
        "--network",
        action="append",
        default=None,
        help="OSM extract (repeatable; default: embedded)",
    )
    parser.add_argument("--sets", default="1:5,15:10,30:20", help="interval_s:noise_m,... ")
    parser.add_argument("--traces", type=int, default=20, help="traces per set (20)")
    parser.add_argument("--repeats", type=int, default=3, help="timed repeats (3)")
    parser.add_argument(
        "--json",
        nargs="?",
        const="-",
        default=None,
        metavar="PATH",
        help="print JSON instead of a table; with --matrix/--truth: also write it to PATH",
    )
    matrix = parser.add_argument_group("accuracy matrix")
    matrix.add_argument(
        "--matrix", action="store_true", help="run the accuracy matrix instead (2 processes)"
    )
    add_arguments(matrix)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Run the benchmark and print its table."""
    logging.getLogger("mapmatch").setLevel(logging.ERROR)  # per-trace verdicts would drown it
    if args.matrix or args.truth or args.inspect:
        args.extract = (args.extract or []) + (args.network or [])
        return run_cli(args)
    rows = []
    for source in args.network or [None]:
        net = roadnets.load(source)
        rows += bench_network(net, parse_sets(args.sets), traces=args.traces, repeats=args.repeats)
    if args.json:
        print(json.dumps([r.to_dict() for r in rows], indent=2))
    else:
        print(f"{os.cpu_count()} cores\n")
        print(markdown_table(rows))
    return 0
