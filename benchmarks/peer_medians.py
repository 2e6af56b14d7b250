"""Per-row ratios of several `compare_peers.py` runs side by side, and their median.

On a shared machine one run's ratio moves by up to a sixth between sittings with the same code
on both sides; the median over a few runs says which rows are really below a target.

    .venv/bin/python benchmarks/peer_medians.py .bench/peers/RUN1 .bench/peers/RUN2 ...
        [--target fmm=1.5 --target valhalla=2]

Prints one markdown table: per extract, set and input class, ours ÷ peer (process CPU time, as
`compare_peers.py` reports it) in each run and the median, ``*`` where the median is below the
peer's target; then whether our accuracy (mismatch, length error, within 1 %) was the same in
every run.
"""

from __future__ import annotations

import argparse
import json
import statistics
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Sequence

#: The targets of issue 15: points/s at least this many times the peer's.
DEFAULT_TARGETS = {"fmm": 1.5, "valhalla": 2.0}
#: Our accuracy columns, which must not change between runs of the same code.
ACCURACY = ("mismatch_mean", "length_err_mean", "within_1pct", "failed")

Key = tuple[str, float, str]


def read_rows(run: Path) -> list[dict[str, Any]]:
    """The rows of one run (its folder or its ``peers.json``)."""
    path = run / "peers.json" if run.is_dir() else run
    rows: list[dict[str, Any]] = json.loads(path.read_text())["rows"]
    return rows


def ratios(
    runs: Sequence[list[dict[str, Any]]], peers: Sequence[str]
) -> dict[Key, dict[str, list[float | None]]]:
    """Per row (extract, interval, input) and peer, ours ÷ peer (CPU) in each run, or None."""
    out: dict[Key, dict[str, list[float | None]]] = {}
    for i, rows in enumerate(runs):
        for r in rows:
            if r["peer"] not in peers:
                continue
            key = (r["extract"], float(r["interval_s"]), r["input"])
            cell = out.setdefault(key, {p: [None] * len(runs) for p in peers})
            cell[r["peer"]][i] = r.get("ours_cpu_ratio")
    return out


def accuracy_changes(runs: Sequence[list[dict[str, Any]]]) -> list[str]:
    """Our rows whose accuracy differs from the first run's: ``extract interval input column``."""
    first = {(r["extract"], r["interval_s"], r["input"]): r for r in runs[0] if r["peer"] == "ours"}
    changed = []
    for rows in runs[1:]:
        for r in rows:
            if r["peer"] != "ours":
                continue
            key = (r["extract"], r["interval_s"], r["input"])
            base = first.get(key)
            for column in ACCURACY:
                if base is not None and base[column] != r[column]:
                    changed.append(f"{key[0]} {key[1]:g} s {key[2]} {column}")
    return changed


def median_table(
    table: dict[Key, dict[str, list[float | None]]], targets: dict[str, float], names: Sequence[str]
) -> str:
    """The markdown table: each run's ratio and the median per peer, ``*`` below its target."""
    peers = list(targets)
    head = "| extract | set | input | " + " | ".join(
        f"ours ÷ {p} ({' / '.join(names)}) | median" for p in peers
    )
    lines = [head + " |", "|---|---|---|" + "---|--:|" * len(peers)]
    for key in sorted(table):
        cells = []
        for p in peers:
            values = table[key][p]
            known = [v for v in values if v is not None]
            if not known:
                cells += [" / ".join("-" for _ in values), "-"]
                continue
            median = statistics.median(known)
            mark = " *" if median < targets[p] else ""
            shown = " / ".join("-" if v is None else f"{v:.2f}" for v in values)
            cells += [shown, f"{median:.2f}{mark}"]
        lines.append(f"| {key[0]} | {key[1]:g} s | {key[2]} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def parse_target(text: str) -> tuple[str, float]:
    """``peer=ratio``."""
    peer, _, ratio = text.partition("=")
    try:
        return peer.strip(), float(ratio)
    except ValueError:
        msg = f"--target {text!r}: give PEER=RATIO, e.g. fmm=1.5"
        raise argparse.ArgumentTypeError(msg) from None


def main(argv: list[str] | None = None) -> int:
    """Print the table for the runs given."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", type=Path, nargs="+", help="run folders (or their peers.json)")
    p.add_argument(
        "--target",
        type=parse_target,
        action="append",
        help="PEER=RATIO (repeatable; default fmm=1.5 and valhalla=2)",
    )
    a = p.parse_args(argv)
    targets = dict(a.target) if a.target else dict(DEFAULT_TARGETS)
    runs = [read_rows(run) for run in a.runs]
    names = [run.name if run.is_dir() else run.parent.name for run in a.runs]
    print(median_table(ratios(runs, list(targets)), targets, names))
    changed = accuracy_changes(runs)
    print(
        "\nour accuracy: the same in every run"
        if not changed
        else "\nour accuracy differs between runs: " + "; ".join(changed)
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
