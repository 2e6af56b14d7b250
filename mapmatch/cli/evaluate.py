"""``mapmatch evaluate``: accuracy of matches against the truth of ``mapmatch simulate``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import roadnets
from mapmatch.config import MatchConfig
from mapmatch.errors import TraceFileError
from mapmatch.evaluation.scoring import TripScore, score_geojson, summarise
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
            "Krumm), share of fixes on the right edge, matched-length error, U-turns and loops "
            "the vehicle did not drive, and whether the distance verdict is the one the true "
            "length gives, per trace and overall. Without --matched the traces are matched "
            "here first."
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
    head += f"{'on edge':>7} {'len err':>8} {'breaks':>6} {'U-turns':>9} {'loops':>7} verdict"
    lines = [head]
    for s in scores:
        verdict = s.verdict or "-"
        if s.verdict and not s.verdict_ok:
            verdict += f" (true length: {s.true_verdict})"
        lines.append(
            f"{s.trace_id:<14} {s.points:>6} {s.true_length_m:>9.1f} {s.matched_length_m:>9.1f} "
            f"{s.mismatch:>8.2%} {s.point_accuracy:>7.1%} {s.length_error:>+8.2%} {s.breaks:>6} "
            f"{f'{s.uturns}/{s.true_uturns}':>9} {f'{s.loops}/{s.true_loops}':>7} {verdict}"
        )
    verdicts = (
        f"verdict right on {summary['verdict_accuracy']:.0%} of {summary['verdict_trips']:.0f} "
        "odometer trips without breaks"
        if summary["verdict_trips"]
        else "no odometer trip without breaks to judge the verdict on"
    )
    lines.append(
        f"\n{len(scores)} traces: route mismatch mean {summary['mismatch_mean']:.2%}, "
        f"median {summary['mismatch_median']:.2%}, p95 {summary['mismatch_p95']:.2%}; fixes on "
        f"the right edge {summary['point_accuracy']:.1%}; length error mean "
        f"{summary['length_error_mean']:+.2%}, p95 |err| {summary['length_error_abs_p95']:.2%}, "
        f"worst {summary['length_error_abs_max']:.2%}, within 1 % on "
        f"{summary['within_1pct']:.0%} of traces, within 2 % on {summary['within_2pct']:.0%}; "
        f"spurious U-turn or loop on {summary['spurious_share']:.0%} of traces "
        f"({summary['spurious_uturns']:.0f} U-turns, {summary['spurious_loops']:.0f} loops); "
        f"{verdicts}\n(U-turns and loops: matched/true)"
    )
    print("\n".join(lines))
    return 0
