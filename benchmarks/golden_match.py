"""Golden check of the matcher: the same traces must give the same matches.

    .venv/bin/python benchmarks/golden_match.py --write [--out .bench/golden.pkl]
    .venv/bin/python benchmarks/golden_match.py --check [--out .bench/golden.pkl] [--show 10]

``--write`` simulates 528 traces on six extracts (three shared ones, three of tests/data) in
eight conditions (1 s / 5 m, 15 s / 10 m, 30 s / 20 m with 2 % outliers of 40 m; realistic 1 s,
15 s and 30 s; 60 s / 20 m with 5 % outliers; 5 s / 15 m with 10 % outliers of 80 m) and four
input classes (positions, + accuracy, + heading & speed, + odometer), plus
2-point and 30-point slices and traces without times; it stores the traces' columns (so that a
change to the simulator does not change the check) and, per trace, what the match says: each
segment's edges with their start and end offsets, the matched length, every fix's edge, offset,
matched flag and confidence, the breaks and the verdict. ``--check`` matches the stored traces
again and compares: integers exactly, floats within ``--tol`` metres (1e-9: a changed
summation order), and prints the first differences.

Speed work on the matcher is checked against it before every commit: a faster path must give
the same result, or the difference is explained.
"""

from __future__ import annotations

import argparse
import logging
import pickle
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import mapmatch  # noqa: E402
import roadnets  # noqa: E402
from mapmatch.evaluation.simulate import (  # noqa: E402
    SimulationConfig,
    simulate_trips,
    strip_to_class,
)

SHARED = ROOT.parent / "shared" / "data" / "osm"
EXTRACTS = [
    SHARED / "andorra_2020.osm.pbf",
    SHARED / "monaco_2020.osm.pbf",
    SHARED / "liechtenstein_2015.osm.pbf",
    ROOT / "tests" / "data" / "bayfront_singapore_2019.osm.pbf",
    ROOT / "tests" / "data" / "melbourne-suburb_au.osm.pbf",
    ROOT / "tests" / "data" / "west-oakland_us.osm.bz2",
]
CLASSES = ("positions", "accuracy", "heading_speed", "odometer")
COLUMNS = ("time", "lon", "lat", "heading", "speed", "accuracy", "odometer")


def conditions() -> dict[str, SimulationConfig]:
    """The simulated conditions, by name."""
    plain = {"outlier_rate": 0.02, "outlier_m": 40.0, "route_length_m": 3000.0}
    return {
        "1s-5m": SimulationConfig(interval_s=1.0, noise_m=5.0, **plain),
        "15s-10m": SimulationConfig(interval_s=15.0, noise_m=10.0, **plain),
        "30s-20m": SimulationConfig(interval_s=30.0, noise_m=20.0, **plain),
        "realistic-1s": SimulationConfig.realistic(interval_s=1.0, route_length_m=3000.0),
        "realistic-15s": SimulationConfig.realistic(interval_s=15.0, route_length_m=3000.0),
        # harder: sparse, very noisy, many outliers (breaks, repairs, jumps, loops)
        "60s-20m": SimulationConfig(
            interval_s=60.0, noise_m=20.0, **{**plain, "outlier_rate": 0.05}
        ),
        "realistic-30s": SimulationConfig.realistic(interval_s=30.0, route_length_m=3000.0),
        "noisy-5s": SimulationConfig(
            interval_s=5.0, noise_m=15.0, outlier_rate=0.1, outlier_m=80.0, route_length_m=3000.0
        ),
    }


def columns_of(trace: mapmatch.Trace, *, timed: bool = True) -> dict[str, Any]:
    """A trace's columns as plain arrays (``None`` where absent)."""
    return {
        "trace_id": trace.trace_id,
        "time": trace.time_s if timed else None,
        "lon": trace.lon,
        "lat": trace.lat,
        "heading": trace.heading_deg,
        "speed": trace.speed_mps,
        "accuracy": trace.accuracy_m,
        "odometer": trace.odometer_m,
    }


def trace_of(cols: dict[str, Any]) -> mapmatch.Trace:
    """The trace back from its stored columns."""
    return mapmatch.Trace(**{k: cols[k] for k in COLUMNS}, trace_id=cols["trace_id"])


def build_traces() -> list[tuple[str, dict[str, Any]]]:
    """(extract path, columns) of every golden trace."""
    out: list[tuple[str, dict[str, Any]]] = []
    for path in EXTRACTS:
        if not path.exists():
            print(f"skipping {path} (not present)", file=sys.stderr)
            continue
        net = roadnets.load(path)
        for name, cfg in conditions().items():
            trips = simulate_trips(net, cfg, count=2, seed=500, prefix=f"{path.stem}-{name}")
            for trip in trips:
                for input_class in CLASSES:
                    trace = strip_to_class(trip.trace, input_class)
                    cols = columns_of(trace)
                    cols["trace_id"] = f"{trace.trace_id}-{input_class}"
                    out.append((str(path), cols))
            full = strip_to_class(trips[0].trace, "heading_speed")
            for size in (2, 30):
                part = full.slice(0, min(size, len(full)))
                cols = columns_of(part)
                cols["trace_id"] = f"{full.trace_id}-first{size}"
                out.append((str(path), cols))
            cols = columns_of(strip_to_class(trips[1].trace, "positions"), timed=False)
            cols["trace_id"] = f"{trips[1].trace.trace_id}-untimed"
            out.append((str(path), cols))
    return out


def outcome(result: mapmatch.MatchResult) -> dict[str, Any]:
    """What the golden check compares of one match."""
    segments = []
    for s in result.segments:
        if hasattr(s, "edge"):
            edge, lo, hi = s.edge, s.start_offset_m, s.end_offset_m
        else:  # a segment of per-edge objects
            edge = np.array([e.edge for e in s.edges], dtype=np.int64)
            lo = np.array([e.start_offset_m for e in s.edges])
            hi = np.array([e.end_offset_m for e in s.edges])
        segments.append(
            {
                "first": int(s.first),
                "last": int(s.last),
                "edge": np.asarray(edge, dtype=np.int64).copy(),
                "start_m": np.asarray(lo, dtype=np.float64).copy(),
                "end_m": np.asarray(hi, dtype=np.float64).copy(),
            }
        )
    p = result.points
    return {
        "segments": segments,
        "matched_length_m": float(result.matched_length_m),
        "breaks": [int(b) for b in result.breaks],
        "verdict": result.distance_check.verdict,
        "point_edge": np.asarray(p.edge, dtype=np.int64).copy(),
        "point_offset_m": np.asarray(p.offset_m, dtype=np.float64).copy(),
        "point_matched": np.asarray(p.matched, dtype=bool).copy(),
        "point_outlier": np.asarray(p.outlier, dtype=bool).copy(),
        "point_confidence": np.asarray(p.confidence, dtype=np.float64).copy(),
        "model_points": int(result.stats.model_points),
        "candidates": int(result.stats.candidates),
    }


def run(traces: list[tuple[str, dict[str, Any]]]) -> tuple[list[dict[str, Any] | str], float]:
    """Match every trace (network loaded once per extract); the outcomes and the seconds."""
    nets: dict[str, roadnets.RoadNetwork] = {}
    out: list[dict[str, Any] | str] = []
    seconds = 0.0
    for path, cols in traces:
        net = nets.get(path)
        if net is None:
            net = nets[path] = roadnets.load(path)
        trace = trace_of(cols)
        started = time.perf_counter()
        try:
            result = mapmatch.match(trace, net)
        except mapmatch.MapMatchError as exc:
            out.append(f"{type(exc).__name__}: {exc}")
            continue
        finally:
            seconds += time.perf_counter() - started
        out.append(outcome(result))
    return out, seconds


def differences(want: Any, got: Any, tol: float, where: str = "") -> list[str]:
    """Where two outcomes differ (floats within ``tol``)."""
    if isinstance(want, dict) and isinstance(got, dict):
        out = []
        for key in want:
            out += differences(want[key], got.get(key), tol, f"{where}.{key}")
        return out
    if isinstance(want, list) and isinstance(got, list):
        if len(want) != len(got):
            return [f"{where}: {len(want)} entries, now {len(got)}"]
        out = []
        for i, (a, b) in enumerate(zip(want, got, strict=True)):
            out += differences(a, b, tol, f"{where}[{i}]")
        return out
    if isinstance(want, np.ndarray):
        b = np.asarray(got)
        if want.shape != b.shape:
            return [f"{where}: shape {want.shape}, now {b.shape}"]
        if want.dtype.kind == "f":
            same = (np.abs(want - b) <= tol) | (np.isnan(want) & np.isnan(b)) | (want == b)
        else:
            same = want == b
        if not bool(np.all(same)):
            i = int(np.flatnonzero(~same)[0])
            n = int((~same).sum())
            return [f"{where}: {n} differ, first at [{i}]: {want.flat[i]!r} now {b.flat[i]!r}"]
        return []
    if isinstance(want, float) and isinstance(got, float):
        if abs(want - got) <= tol or want == got:
            return []
        return [f"{where}: {want!r} now {got!r} ({got - want:+.3g})"]
    if want != got:
        return [f"{where}: {want!r} now {got!r}"]
    return []


def main() -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    mode = parser.add_mutually_exclusive_group(required=True)
    mode.add_argument("--write", action="store_true", help="simulate, match and store")
    mode.add_argument("--check", action="store_true", help="match the stored traces, compare")
    parser.add_argument("--out", type=Path, default=ROOT / ".bench" / "golden.pkl")
    parser.add_argument("--tol", type=float, default=1e-9, help="float tolerance (m)")
    parser.add_argument("--show", type=int, default=10, help="differences printed")
    args = parser.parse_args()
    logging.getLogger("mapmatch").setLevel(logging.ERROR)
    if args.write:
        traces = build_traces()
        outcomes, seconds = run(traces)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        with args.out.open("wb") as handle:
            pickle.dump({"traces": traces, "outcomes": outcomes}, handle)
        print(f"wrote {len(traces)} traces and their matches to {args.out} ({seconds:.1f} s)")
        return 0
    with args.out.open("rb") as handle:
        golden = pickle.load(handle)  # our own file
    outcomes, seconds = run(golden["traces"])
    bad = 0
    shown = 0
    for (_, cols), want, got in zip(golden["traces"], golden["outcomes"], outcomes, strict=True):
        diff = differences(want, got, args.tol)
        if diff:
            bad += 1
            if shown < args.show:
                shown += 1
                print(f"{cols['trace_id']} ({len(cols['lon'])} fixes):")
                for line in diff[:6]:
                    print(f"  {line}")
    total = len(outcomes)
    print(f"{total - bad}/{total} traces match the golden outcomes ({seconds:.2f} s matching)")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
