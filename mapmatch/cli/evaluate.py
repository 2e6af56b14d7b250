"""``mapmatch evaluate``: accuracy of matches against the truth of ``mapmatch simulate``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import roadnets
from mapmatch.config import MatchConfig
from mapmatch.errors import TraceFileError
from mapmatch.evaluate import TripScore, score_geojson, summarise
from mapmatch.matcher import match
from mapmatch.trace import read_traces

if TYPE_CHECKING:
    import argparse

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> None:
    """Register the ``evaluate`` sub-command."""
    parser = sub.add_parser(
        "evaluate",
        help="score matches against simulated ground truth",
        description=(
            "Score matches of a `mapmatch simulate` folder: route mismatch fraction (Newson & "
            "Krumm), share of fixes on the right edge and matched-length error, per trace and "
            "overall. Without --matched the traces are matched here first."
        ),
    )
    parser.add_argument("simulation", help="folder written by `mapmatch simulate`")
    parser.add_argument(
        "--matched", default=None, help="folder of <trace_id>.geojson from `mapmatch match`"
    )
    parser.add_argument("--network", default=None, help="OSM extract (default: embedded)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.set_defaults(run=run)


def _truth(folder: Path) -> dict[str, dict[str, Any]]:
    path = folder / "truth.jsonl"
    if not path.is_file():
        msg = f"{path} not found: is {folder} a folder written by `mapmatch simulate`?"
        raise TraceFileError(msg, path=str(path))
    records = [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines() if line]
    return {r["trace_id"]: r for r in records}


def run(args: argparse.Namespace) -> int:
    """Score every trace that has a truth record; print the table and the summary."""
    folder = Path(args.simulation)
    truth = _truth(folder)
    scores: list[TripScore] = []
    if args.matched:
        for trace_id, record in truth.items():
            path = Path(args.matched) / f"{trace_id}.geojson"
            if not path.is_file():
                msg = f"no match for trace {trace_id!r}: {path} is missing"
                raise TraceFileError(msg, path=str(path))
            scores.append(score_geojson(json.loads(path.read_text(encoding="utf-8")), record))
    else:
        net = roadnets.load(args.network)
        for trace in read_traces(folder / "traces.csv"):
            if trace.trace_id in truth:
                result = match(trace, net, MatchConfig())
                scores.append(score_geojson(result.to_geojson(), truth[trace.trace_id]))
    summary = summarise(scores)
    if args.json:
        print(json.dumps({"traces": [s.to_dict() for s in scores], "summary": summary}, indent=2))
        return 0
    head = f"{'trace':<14} {'points':>6} {'true m':>9} {'matched m':>9} {'mismatch':>8} "
    head += f"{'on edge':>7} {'len err':>8} {'breaks':>6}"
    lines = [head]
    for s in scores:
        lines.append(
            f"{s.trace_id:<14} {s.points:>6} {s.true_length_m:>9.1f} {s.matched_length_m:>9.1f} "
            f"{s.mismatch:>8.2%} {s.point_accuracy:>7.1%} {s.length_error:>+8.2%} {s.breaks:>6}"
        )
    lines.append(
        f"\n{len(scores)} traces: route mismatch mean {summary['mismatch_mean']:.2%}, "
        f"median {summary['mismatch_median']:.2%}; fixes on the right edge "
        f"{summary['point_accuracy']:.1%}; length error mean {summary['length_error_mean']:+.2%}, "
        f"worst {summary['length_error_abs_max']:.2%}"
    )
    print("\n".join(lines))
    return 0
