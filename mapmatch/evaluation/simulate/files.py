"""Simulated trips on disk: ``traces.csv`` (the observed traces) and ``truth.jsonl``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import os

    import pandas as pd

    from mapmatch.evaluation.simulate.truth import SimulatedTrip

__all__ = ["write_trips"]


def write_trips(trips: list[SimulatedTrip], out_dir: str | os.PathLike[str]) -> tuple[Path, Path]:
    """
    Write ``traces.csv`` and ``truth.jsonl`` into ``out_dir``.

    ``traces.csv`` holds all traces in docs/DESIGN.md's input columns; ``truth.jsonl`` one
    JSON object per trace: true route edges, geometry and length.
    """
    import pandas as pd

    folder = Path(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    frames: list[pd.DataFrame] = []
    for trip in trips:
        frame = trip.trace.to_dataframe()
        frame.insert(0, "trace_id", trip.trace.trace_id)
        frames.append(frame)
    traces = folder / "traces.csv"
    tmp = traces.with_suffix(".csv.tmp")
    pd.concat(frames).to_csv(tmp, index=False, float_format="%.7f")
    tmp.replace(traces)
    truth = folder / "truth.jsonl"
    tmp = truth.with_suffix(".jsonl.tmp")
    tmp.write_text("".join(json.dumps(t.truth_record()) + "\n" for t in trips), encoding="utf-8")
    tmp.replace(truth)
    return traces, truth
