"""Shared driver for the peer runners (standard library only: it runs in every peer's venv).

A runner is started as ``PYTHON run_<peer>.py JOB.json``. The job file holds
``{"extract", "traces_csv", "params", "out"}`` and optionally ``"repeats"`` (default 1) and
``"min_time_s"`` (default 0); the runner loads the network once (timed as ``load_s``), matches
the first trace once as a warm-up (not timed), then matches every trace ``repeats`` times over,
and more passes while the passes so far add up to less than ``min_time_s`` (a set that takes
20 ms per pass is measured over enough passes to be stable), timing only the matching calls;
``match_s`` is the median over the passes of one pass's total (``match_s_runs`` lists them
all; ``match_cpu_s`` is the same median of the process's CPU time, which other load on a shared
machine inflates far less). It writes ``{"peer", "load_s", "match_s", "match_s_runs",
"match_cpu_s", "points", "peak_rss_mb", "settings", "results": [...]}`` where each result (from
the first pass) is
``{"trace_id", "geometry": [[[lon, lat], ...], ...], "error"}``.

With ``"control": [COMMAND_FD, ANSWER_FD]`` in the job (two pipes the process inherits), the
runner says ``ready`` after the warm-up and runs each pass when told to instead
(:func:`serve_passes`): ``compare_peers.py`` runs the peers of one trace file side by side
that way, pass for pass in turns.
"""

from __future__ import annotations

import csv
import json
import resource
import statistics
import sys
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Callable

Geometry = list[list[list[float]]]
_MAX_PASSES = 1000


@dataclass(slots=True)
class TracePoints:
    """One trace as read from the traces CSV, sorted by time."""

    trace_id: str
    time: list[float] = field(default_factory=list)
    lon: list[float] = field(default_factory=list)
    lat: list[float] = field(default_factory=list)
    heading: list[float | None] = field(default_factory=list)
    speed: list[float | None] = field(default_factory=list)
    accuracy: list[float | None] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.time)


def _opt_float(value: str | None) -> float | None:
    if value is None or value.strip() == "":
        return None
    return float(value)


def read_traces(path: str | Path) -> list[TracePoints]:
    """Read a traces CSV (trace_id,time,lon,lat,heading,speed,accuracy,odometer), file order."""
    rows: dict[str, list[dict[str, str]]] = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            rows.setdefault(row["trace_id"], []).append(row)
    out: list[TracePoints] = []
    for trace_id, rs in rows.items():
        rs.sort(key=lambda r: float(r["time"]))
        tp = TracePoints(trace_id)
        for r in rs:
            tp.time.append(float(r["time"]))
            tp.lon.append(float(r["lon"]))
            tp.lat.append(float(r["lat"]))
            tp.heading.append(_opt_float(r.get("heading")))
            tp.speed.append(_opt_float(r.get("speed")))
            tp.accuracy.append(_opt_float(r.get("accuracy")))
        out.append(tp)
    return out


def peak_rss_mb() -> float:
    """Peak resident set size of this process so far, in MiB (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def run_peer(
    peer: str,
    load: Callable[[dict[str, Any]], Any],
    match: Callable[[Any, TracePoints], Any],
    geometry: Callable[[Any, TracePoints, Any], Geometry],
    settings: Callable[[Any], dict[str, Any]] | None = None,
    prepare: Callable[[Any, TracePoints], Any] | None = None,
    argv: list[str] | None = None,
) -> int:
    """Run one benchmark job for a peer and write its result JSON.

    Parameters
    ----------
    peer
        Name written into the result.
    load
        ``load(job) -> ctx``: load network/tiles; timed as ``load_s``.
    match
        ``match(ctx, prepared) -> raw``: the matching call and the building of the output a
        user of the matcher gets (GeoJSON, coordinates in lon/lat); timed.
    geometry
        ``geometry(ctx, trace, raw) -> [[[lon, lat], ...], ...]``: pick the polylines in
        driving order out of the raw result for scoring; not timed.
    settings
        ``settings(ctx) -> dict``: the effective parameters, recorded in the result.
    prepare
        ``prepare(ctx, trace) -> prepared``: turn a trace into the peer's input object (request
        body, data frame, ...); not timed, like reading the trace file. Default: the trace.
    argv
        Command line; ``argv[1]`` is the job file.
    """
    argv = sys.argv if argv is None else argv
    job = json.loads(Path(argv[1]).read_text())
    traces = read_traces(job["traces_csv"])
    t0 = time.perf_counter()
    ctx = load(job)
    load_s = time.perf_counter() - t0
    inputs = [prepare(ctx, tr) if prepare else tr for tr in traces]
    if traces:  # warm-up: caches, JIT, lazily loaded tiles
        try:
            match(ctx, inputs[0])
        except Exception:
            traceback.print_exc()
    runs: list[float] = []
    cpu_runs: list[float] = []
    results: list[dict[str, Any]] = []

    def one_pass() -> tuple[float, float]:
        """Match every trace once; the seconds and CPU seconds of the matching calls."""
        first = not runs
        total = cpu = 0.0
        for tr, prepared in zip(traces, inputs, strict=True):
            t1, c1 = time.perf_counter(), time.process_time()
            try:
                raw = match(ctx, prepared)
            except Exception as exc:
                total += time.perf_counter() - t1
                cpu += time.process_time() - c1
                if first:
                    error = f"{type(exc).__name__}: {exc}"
                    results.append({"trace_id": tr.trace_id, "geometry": [], "error": error})
                continue
            total += time.perf_counter() - t1
            cpu += time.process_time() - c1
            if not first:
                continue
            try:
                geom = geometry(ctx, tr, raw)
                results.append({"trace_id": tr.trace_id, "geometry": geom, "error": None})
            except Exception as exc:
                error = f"{type(exc).__name__}: {exc}"
                results.append({"trace_id": tr.trace_id, "geometry": [], "error": error})
        runs.append(total)
        cpu_runs.append(cpu)
        return total, cpu

    if "control" in job:  # passes on command, in turns with the other peers' processes
        serve_passes(job["control"], one_pass)
        if not runs:  # told to stop before any pass: one, so the result has a time
            one_pass()
    else:
        repeats = max(1, int(job.get("repeats", 1)))
        min_time_s = float(job.get("min_time_s", 0.0))
        while wants_pass(runs, repeats, min_time_s):
            one_pass()
    match_s = statistics.median(runs)
    out = {
        "peer": peer,
        "load_s": load_s,
        "match_s": match_s,
        "match_s_runs": runs,
        "match_cpu_s": statistics.median(cpu_runs),
        "repeats": len(runs),
        "points": sum(len(t) for t in traces),
        "peak_rss_mb": peak_rss_mb(),
        "settings": settings(ctx) if settings else job.get("params", {}),
        "results": results,
    }
    Path(job["out"]).write_text(json.dumps(out))
    return 0


def wants_pass(runs: list[float], repeats: int, min_time_s: float) -> bool:
    """Whether a job with these passes so far needs another: ``repeats``, then ``min_time_s``."""
    return len(runs) < repeats or (sum(runs) < min_time_s and len(runs) < _MAX_PASSES)


def serve_passes(control: list[int], one_pass: Callable[[], tuple[float, float]]) -> None:
    """
    Run passes when told to, so that several peers' processes take turns pass by pass.

    ``control`` is two inherited file descriptors: commands come in on the first (``pass``:
    run one and answer ``done SECONDS CPU_SECONDS``; ``end``: stop), answers go out on the
    second, which first says ``ready``. Peers on one machine then meet the same slow and
    fast spells of a shared CPU, and their ratios compare like with like.
    """
    commands = open(control[0], encoding="ascii")  # noqa: SIM115 - closed at the end
    answers = open(control[1], "w", encoding="ascii")  # noqa: SIM115
    answers.write("ready\n")
    answers.flush()
    for line in commands:
        if line.strip() != "pass":
            break
        total, cpu = one_pass()
        answers.write(f"done {total!r} {cpu!r}\n")
        answers.flush()
    commands.close()
    answers.close()


def split_polyline(coords: list[list[float]], breaks: list[int]) -> Geometry:
    """Split a polyline into pieces at the given vertex indices (a piece starts at each)."""
    pieces: Geometry = []
    start = 0
    for b in [*sorted(set(breaks)), len(coords)]:
        if b - start >= 2:
            pieces.append(coords[start:b])
        start = b
    return pieces


def decode_polyline(encoded: str, precision: int = 6) -> list[list[float]]:
    """Decode a Google/Valhalla encoded polyline to ``[[lon, lat], ...]``."""
    coords: list[list[float]] = []
    index = lat = lon = 0
    factor = 10.0**precision
    n = len(encoded)
    while index < n:
        vals = []
        for _ in range(2):
            shift = result = 0
            while True:
                b = ord(encoded[index]) - 63
                index += 1
                result |= (b & 0x1F) << shift
                shift += 5
                if b < 0x20:
                    break
            vals.append(~(result >> 1) if result & 1 else result >> 1)
        lat += vals[0]
        lon += vals[1]
        coords.append([lon / factor, lat / factor])
    return coords
