"""Accuracy matrix: matched length, spurious U-turns/loops and the verdict, whatever the input.

    .venv/bin/python benchmarks/bench_accuracy.py [--quick] [--extract PATH ...]
        [--conditions 1s-5m,realistic-1s] [--classes positions,odometer] [--trips 30]
        [--config KEY=VALUE ...] [--sim KEY=VALUE ...] [--json out.json] [--rows rows.csv]
        [--worst 10] [--per-extract] [--workers 2]
    .venv/bin/python benchmarks/bench_accuracy.py --truth [--trips 5]
    .venv/bin/python benchmarks/bench_accuracy.py --inspect monaco_2020:realistic-1s:7 [--out DIR]

1. The matrix (default): every shared extract (../shared/data/osm/, else the embedded network
   and tests/data) x input class (positions only, + accuracy, + heading & speed, + odometer) x
   condition (1 s / 5 m, 15 s / 10 m, 30 s / 20 m with 2 % outliers of 40 m; realistic 1 s and
   15 s: AR(1) 0.95/s 6 m noise, urban canyons, stops at a third of the junctions, heading noise
   3 + 87 exp(-v) deg, outages, odometer 2 % high). Trip i of every cell has seed 1000 + i, so
   every input class of a condition sees the same trips. Per cell: route mismatch mean / p95,
   length error mean / p95 of |error| / share within 1 % and 2 %, share of trips with a U-turn
   or loop the truth does not have, verdict right (odometer trips without breaks), points/s.
   Then the within-1 % and spurious shares per extract, issue 11's acceptance rules checked on
   every extract cell, and the worst trips with the id to re-run them by.
2. --truth: noise-free traces at 0.1 (10 Hz), 1, 5, 15 and 30 s with every subset of the true
   speed / heading / odometer columns; the matched length must be within 0.1 % of the true one
   on every trip of every extract (exit status 1 otherwise).
3. --inspect TRIP_ID: re-run one trip of the tables in the chosen classes, list where the match
   turns back or drives an edge again; --out writes its trace, truth, matches and maps.

--config sets any MatchConfig field for every match (e.g. --config uturn_penalty=20), --sim any
SimulationConfig field for every condition. Two processes by default (--workers).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mapmatch.errors import MapMatchError  # noqa: E402
from mapmatch.evaluation.accuracy import add_arguments, run_cli  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(
        description=(__doc__ or "").splitlines()[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="\n".join((__doc__ or "").splitlines()[1:]),
    )
    add_arguments(parser)
    parser.add_argument(
        "--json", default=None, metavar="PATH", help="also write the report as JSON (- stdout)"
    )
    args = parser.parse_args()
    try:
        return run_cli(args)
    except MapMatchError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
