"""Side-by-side benchmark of our matcher against peer map matchers on the same simulated traces.

For each extract and each (sampling interval, noise) set it simulates traces with ground truth
(``python -m mapmatch simulate`` when it exists, else ``benchmarks/peers/interim_traces.py``),
runs every peer in its own subprocess and venv (``benchmarks/peers/run_<peer>.py``; load timed
apart, one warm-up trace, then only the matching calls timed, one process, one thread), scores
every peer's matched geometry the same way (``benchmarks/scoring.py``) and prints one markdown
table. Peers: ours, Valhalla Meili (pyvalhalla), leuvenmapmatching, mappymatch (LCSS); set them
up once with ``bash benchmarks/peers/setup.sh``.

Usage::

    .venv/bin/python benchmarks/compare_peers.py                       # defaults, ~10-15 min
    .venv/bin/python benchmarks/compare_peers.py --extract monaco_2020.osm.pbf --sets 1:5 \
        --traces 5 --peers ours,valhalla
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
import scoring

ROOT = Path(__file__).resolve().parents[1]
PEERS_DIR = ROOT / "benchmarks" / "peers"
OSM_DIR = ROOT.parent / "shared" / "data" / "osm"
DEFAULT_EXTRACTS = ("monaco_2020.osm.pbf", "andorra_2020.osm.pbf")
DEFAULT_SETS = "1:5,15:10,30:20"


@dataclass(frozen=True, slots=True)
class Peer:
    """A matcher under test: the python that runs it and its runner script."""

    name: str
    python: Path
    script: Path


PEERS: dict[str, Peer] = {
    "ours": Peer("ours", Path(sys.executable), PEERS_DIR / "run_ours.py"),
    "valhalla": Peer(
        "valhalla", ROOT / ".peers/valhalla/bin/python", PEERS_DIR / "run_valhalla.py"
    ),
    "leuvenmapmatching": Peer(
        "leuvenmapmatching", ROOT / ".peers/py311/bin/python", PEERS_DIR / "run_leuven.py"
    ),
    "mappymatch": Peer(
        "mappymatch", ROOT / ".peers/py311/bin/python", PEERS_DIR / "run_mappymatch.py"
    ),
}

# one process, one thread: no BLAS/numba thread pools in any peer
SINGLE_THREAD_ENV = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "NUMBA_NUM_THREADS": "1",
}


@dataclass(frozen=True, slots=True)
class TraceSet:
    """One simulated set: sampling interval and noise (outliers at a fixed small rate)."""

    interval_s: float
    noise_m: float
    outlier_rate: float

    @property
    def label(self) -> str:
        return f"{self.interval_s:g}s_{self.noise_m:g}m"


@dataclass(frozen=True, slots=True)
class Row:
    """One line of the table."""

    extract: str
    peer: str
    interval_s: float
    noise_m: float
    traces: int
    points: int
    failed: int
    load_s: float
    match_s: float
    points_per_s: float
    ours_ratio: float
    mismatch_mean: float
    mismatch_median: float
    precision: float
    recall: float
    peak_rss_mb: float
    error: str | None = None


def parse_sets(text: str, outlier_rate: float) -> list[TraceSet]:
    """Parse ``"1:5,15:10"`` into trace sets (interval seconds : noise metres)."""
    out = []
    for part in text.split(","):
        try:
            interval, noise = part.split(":")
            out.append(TraceSet(float(interval), float(noise), outlier_rate))
        except ValueError as exc:
            msg = f"bad set {part!r} in --sets {text!r}; write INTERVAL_S:NOISE_M, e.g. 15:10"
            raise SystemExit(msg) from exc
    return out


def resolve_extract(name: str) -> Path:
    """An extract path, or a file name in ../shared/data/osm/."""
    p = Path(name)
    if p.exists():
        return p.resolve()
    q = OSM_DIR / name
    if q.exists():
        return q
    msg = f"extract {name!r} not found (nor in {OSM_DIR}); give a path or a file name there"
    raise SystemExit(msg)


def simulate_available() -> bool:
    """Whether ``python -m mapmatch simulate --help`` works."""
    try:
        r = subprocess.run(
            [sys.executable, "-m", "mapmatch", "simulate", "--help"],
            capture_output=True,
            timeout=120,
            check=False,
        )
    except (OSError, subprocess.TimeoutExpired):
        return False
    return r.returncode == 0


def simulate(
    extract: Path, ts: TraceSet, traces: int, seed: int, out: Path, *, use_mapmatch: bool
) -> None:
    """Write ``out/traces.csv`` and ``out/truth.jsonl`` for one set."""
    if (out / "traces.csv").exists() and (out / "truth.jsonl").exists():
        return
    args = [
        "--network",
        str(extract),
        "--traces",
        str(traces),
        "--interval-s",
        f"{ts.interval_s:g}",
        "--noise-m",
        f"{ts.noise_m:g}",
        "--outlier-rate",
        f"{ts.outlier_rate:g}",
        "--seed",
        str(seed),
        "--out",
        str(out),
    ]
    if use_mapmatch:
        cmd = [sys.executable, "-m", "mapmatch", "simulate", *args]
    else:
        cmd = [sys.executable, str(PEERS_DIR / "interim_traces.py"), *args]
    subprocess.run(cmd, check=True, env=os.environ | SINGLE_THREAD_ENV)


def read_truth(path: Path) -> dict[str, list[list[float]]]:
    """Truth geometries by trace id."""
    out = {}
    with path.open() as f:
        for line in f:
            if line.strip():
                t = json.loads(line)
                out[str(t["trace_id"])] = t["geometry"]["coordinates"]
    return out


def peer_available(peer: Peer) -> tuple[bool, str]:
    """Whether a peer can run here, and why not."""
    if not peer.python.exists():
        return False, f"{peer.python} missing; run: bash benchmarks/peers/setup.sh"
    if peer.name == "ours":
        probe = "import mapmatch, roadnets; mapmatch.match; mapmatch.read_traces; roadnets.load"
        r = subprocess.run([str(peer.python), "-c", probe], capture_output=True, check=False)
        if r.returncode != 0:
            return False, "mapmatch.match / roadnets.load not importable yet"
    return True, ""


def run_job(
    peer: Peer,
    extract: Path,
    traces_csv: Path,
    params: dict[str, Any],
    work: Path,
    timeout_s: float,
) -> tuple[dict[str, Any] | None, str | None, float]:
    """Run one peer on one trace file; return (result, error, wall seconds of the process)."""
    work.mkdir(parents=True, exist_ok=True)
    job = {
        "extract": str(extract),
        "traces_csv": str(traces_csv),
        "params": params,
        "out": str(work / f"{peer.name}.result.json"),
    }
    job_path = work / f"{peer.name}.job.json"
    job_path.write_text(json.dumps(job, indent=1))
    env = os.environ | SINGLE_THREAD_ENV
    if peer.name == "valhalla":  # its console scripts look themselves up on PATH
        env["PATH"] = f"{peer.python.parent}{os.pathsep}{env.get('PATH', '')}"
    t0 = time.perf_counter()
    log = work / f"{peer.name}.log"
    try:
        with log.open("w") as lf:
            r = subprocess.run(
                [str(peer.python), str(peer.script), str(job_path)],
                stdout=lf,
                stderr=subprocess.STDOUT,
                timeout=timeout_s,
                env=env,
                cwd=str(work),
                check=False,
            )
    except subprocess.TimeoutExpired:
        return None, f"timeout after {timeout_s:.0f} s", time.perf_counter() - t0
    wall = time.perf_counter() - t0
    if r.returncode != 0 or not Path(job["out"]).exists():
        tail = log.read_text(errors="replace").strip().splitlines()[-3:]
        return None, f"exit {r.returncode}: {' | '.join(tail)}", wall
    return json.loads(Path(job["out"]).read_text()), None, wall


def score_result(
    truth: dict[str, list[list[float]]], result: dict[str, Any]
) -> tuple[scoring.ScoreSummary, int, list[dict[str, Any]]]:
    """Score every trace of a peer's result (missing or failed traces count as unmatched)."""
    by_id = {str(r["trace_id"]): r for r in result.get("results", [])}
    scores = []
    per_trace = []
    failed = 0
    for trace_id, geom in truth.items():
        r = by_id.get(trace_id)
        matched = r["geometry"] if r and not r.get("error") else []
        if r is None or r.get("error"):
            failed += 1
        s = scoring.score_route(geom, matched)
        scores.append(s)
        per_trace.append(
            {
                "trace_id": trace_id,
                "true_m": s.true_length_m,
                "matched_m": s.matched_length_m,
                "added_m": s.added_m,
                "missed_m": s.missed_m,
                "mismatch": s.mismatch,
                "error": None if r is None else r.get("error"),
            }
        )
    return scoring.summarize(scores), failed, per_trace


def _fmt(x: float, nd: int = 2) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    return f"{x:,.{nd}f}"


def markdown(rows: list[Row], header: dict[str, Any]) -> str:
    """The results table with a header naming date, cores and tools."""
    lines = [
        f"Peer comparison, {header['date']}, {header['nproc']} cores ({header['cpu']}), "
        f"one process and one thread per matcher; trace source: {header['trace_source']}; "
        f"outlier rate {header['outlier_rate']:g} (40 m); scoring tolerance "
        f"{scoring.DEFAULT_TOLERANCE_M:g} m, direction within "
        f"{scoring.DEFAULT_MAX_ANGLE_DEG:g} deg.",
        "",
        "| extract | peer | interval s | noise m | traces | points | failed | load s | match s "
        "| points/s | ours ÷ peer | mismatch mean | mismatch median | precision | recall "
        "| peak RSS MB |",
        "|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|",
    ]
    for r in rows:
        if r.error:
            lines.append(
                f"| {r.extract} | {r.peer} | {r.interval_s:g} | {r.noise_m:g} | {r.traces} "
                f"| - | - | - | - | - | - | - | - | - | - | - |  (failed: {r.error[:120]})"
            )
            continue
        lines.append(
            f"| {r.extract} | {r.peer} | {r.interval_s:g} | {r.noise_m:g} | {r.traces} "
            f"| {r.points:,} | {r.failed} | {_fmt(r.load_s)} | {_fmt(r.match_s)} "
            f"| {_fmt(r.points_per_s, 0)} | {_fmt(r.ours_ratio, 1)} "
            f"| {_fmt(100 * r.mismatch_mean, 1)} % | {_fmt(100 * r.mismatch_median, 1)} % "
            f"| {_fmt(r.precision, 3)} | {_fmt(r.recall, 3)} | {_fmt(r.peak_rss_mb, 0)} |"
        )
    return "\n".join(lines) + "\n"


def _cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def main(argv: list[str] | None = None) -> int:
    """Run the comparison and print the table."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument(
        "--extract",
        action="append",
        help="OSM extract path or file name in ../shared/data/osm (repeatable; "
        f"default: {', '.join(DEFAULT_EXTRACTS)})",
    )
    p.add_argument(
        "--sets", default=DEFAULT_SETS, help="INTERVAL_S:NOISE_M,... (default %(default)s)"
    )
    p.add_argument("--traces", type=int, default=20, help="traces per set (default %(default)s)")
    p.add_argument("--outlier-rate", type=float, default=0.02, help="share of 40 m outliers")
    p.add_argument("--seed", type=int, default=7)
    p.add_argument(
        "--peers",
        default="all",
        help=f"comma-separated subset of {','.join(PEERS)} (default: all available)",
    )
    p.add_argument(
        "--out", type=Path, default=None, help="output folder (default .bench/peers/DATE)"
    )
    p.add_argument("--timeout", type=float, default=900.0, help="seconds per peer job")
    p.add_argument(
        "--interim",
        action="store_true",
        help="use the interim simulator even when `mapmatch simulate` exists",
    )
    a = p.parse_args(argv)

    extracts = [resolve_extract(e) for e in (a.extract or DEFAULT_EXTRACTS)]
    sets = parse_sets(a.sets, a.outlier_rate)
    names = list(PEERS) if a.peers == "all" else [n.strip() for n in a.peers.split(",")]
    unknown = [n for n in names if n not in PEERS]
    if unknown:
        msg = f"unknown peer(s) {unknown}; choose from {list(PEERS)}"
        raise SystemExit(msg)
    peers: list[Peer] = []
    skipped: dict[str, str] = {}
    for n in names:
        ok, why = peer_available(PEERS[n])
        if ok:
            peers.append(PEERS[n])
        else:
            skipped[n] = why
            print(f"[compare_peers] skipping {n}: {why}", flush=True)
    stamp = dt.datetime.now(dt.UTC).strftime("%Y%m%dT%H%M%SZ")
    out = (a.out or ROOT / ".bench" / "peers" / stamp).resolve()
    out.mkdir(parents=True, exist_ok=True)
    use_mapmatch = not a.interim and simulate_available()
    if not use_mapmatch:
        print(
            "[compare_peers] notice: `python -m mapmatch simulate` is not available (or --interim "
            "given); using benchmarks/peers/interim_traces.py for traces and truth",
            flush=True,
        )
    trace_source = "mapmatch simulate" if use_mapmatch else "interim_traces.py"

    rows: list[Row] = []
    details: list[dict[str, Any]] = []
    for extract in extracts:
        stem = extract.name.split(".")[0]
        for k, ts in enumerate(sets):
            set_dir = out / stem / ts.label
            try:
                simulate(
                    extract, ts, a.traces, a.seed + 100 * k, set_dir, use_mapmatch=use_mapmatch
                )
            except subprocess.CalledProcessError as exc:
                print(f"[compare_peers] {stem} {ts.label}: simulation failed ({exc}); skipped")
                skipped[f"{stem} {ts.label}"] = "simulation failed"
                continue
            truth = read_truth(set_dir / "truth.jsonl")
            params = {
                "interval_s": ts.interval_s,
                "noise_m": ts.noise_m,
                "outlier_rate": ts.outlier_rate,
            }
            set_rows: list[Row] = []
            for peer in peers:
                print(f"[compare_peers] {stem} {ts.label} {peer.name} ...", end=" ", flush=True)
                res, err, wall = run_job(
                    peer, extract, set_dir / "traces.csv", params, set_dir / "runs", a.timeout
                )
                if res is None:
                    print(f"FAILED ({err})", flush=True)
                    set_rows.append(
                        Row(
                            stem,
                            peer.name,
                            ts.interval_s,
                            ts.noise_m,
                            len(truth),
                            0,
                            len(truth),
                            math.nan,
                            math.nan,
                            math.nan,
                            math.nan,
                            math.nan,
                            math.nan,
                            math.nan,
                            math.nan,
                            math.nan,
                            err,
                        )
                    )
                    details.append(
                        {"extract": stem, "set": ts.label, "peer": peer.name, "error": err}
                    )
                    continue
                summary, failed, per_trace = score_result(truth, res)
                pps = res["points"] / res["match_s"] if res["match_s"] > 0 else math.nan
                print(
                    f"{res['points']} points in {res['match_s']:.2f} s ({pps:,.0f}/s), "
                    f"mismatch {100 * summary.mismatch_mean:.1f} % (process {wall:.0f} s)",
                    flush=True,
                )
                set_rows.append(
                    Row(
                        extract=stem,
                        peer=peer.name,
                        interval_s=ts.interval_s,
                        noise_m=ts.noise_m,
                        traces=summary.traces,
                        points=int(res["points"]),
                        failed=failed,
                        load_s=float(res["load_s"]),
                        match_s=float(res["match_s"]),
                        points_per_s=pps,
                        ours_ratio=math.nan,
                        mismatch_mean=summary.mismatch_mean,
                        mismatch_median=summary.mismatch_median,
                        precision=summary.precision,
                        recall=summary.recall,
                        peak_rss_mb=float(res["peak_rss_mb"]),
                    )
                )
                details.append(
                    {
                        "extract": stem,
                        "set": ts.label,
                        "peer": peer.name,
                        "settings": res.get("settings"),
                        "process_wall_s": wall,
                        "per_trace": per_trace,
                    }
                )
            ours = next((r for r in set_rows if r.peer == "ours" and not r.error), None)
            for r in set_rows:
                ratio = (
                    ours.points_per_s / r.points_per_s if ours and r.points_per_s > 0 else math.nan
                )
                rows.append(Row(**(asdict(r) | {"ours_ratio": ratio})))

    header = {
        "date": dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "nproc": os.cpu_count(),
        "cpu": _cpu_name(),
        "trace_source": trace_source,
        "outlier_rate": a.outlier_rate,
        "python": platform.python_version(),
        "skipped": skipped,
        "extracts": [str(e) for e in extracts],
        "sets": a.sets,
        "traces_per_set": a.traces,
    }
    table = markdown(rows, header)
    (out / "peers.md").write_text(table)
    (out / "peers.json").write_text(
        json.dumps(
            {"header": header, "rows": [asdict(r) for r in rows], "details": details},
            indent=1,
            default=lambda x: None if isinstance(x, float) and math.isnan(x) else str(x),
        )
    )
    print()
    print(table)
    if skipped:
        print("skipped: " + "; ".join(f"{k}: {v}" for k, v in skipped.items()))
    print(f"results: {out / 'peers.json'}, {out / 'peers.md'}")
    medians = [r.mismatch_median for r in rows if not r.error]
    if medians:
        print(
            f"(median of the per-set median mismatches: {100 * statistics.median(medians):.1f} %)"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
