"""Side-by-side benchmark of our matcher against peer map matchers on the same simulated traces.

For each extract and each (sampling interval, noise) set it simulates traces with ground truth
(``python -m mapmatch simulate`` when it exists, else ``benchmarks/peers/interim_traces.py``),
writes them twice, as **positions only** (``trace_id,time,lon,lat``) and as **full input**
(plus heading, speed, accuracy, odometer), and runs every peer on each in its own subprocess and
venv (``benchmarks/peers/run_<peer>.py``; one process, one thread; load timed apart; one
warm-up trace; then every trace matched ``--repeats`` times and the median pass timed; the
timed part includes building the output a user gets: our GeoJSON, FMM's path in lon/lat).
The peers of one trace file run side by side, loaded one after the other and then timed one
pass each in turn (``--back-to-back``: each peer's passes in one block instead), so that all
meet the same slow and fast spells of a shared machine. A peer that can only use positions
runs again beside our full-input run; the slow pure-Python peers run once per set and their
row stands in both classes.
Every matched geometry is scored the same way (``benchmarks/scoring.py``: route mismatch, and
the matched length against the true one), and one markdown table plus JSON are written.

Peers: ours, FMM (stock, and with the points that have no road within its radius dropped),
Valhalla Meili, leuvenmapmatching, mappymatch. Set them up once with
``bash benchmarks/peers/setup.sh`` (FMM also needs ``../shared/peers/fmm``).

Usage::

    .venv/bin/python benchmarks/compare_peers.py                # full run (4 extracts)
    .venv/bin/python benchmarks/compare_peers.py --quick        # a few minutes
    .venv/bin/python benchmarks/compare_peers.py --extract monaco_2020.osm.pbf --sets 1:5 \
        --traces 5 --peers ours,fmm-drop,valhalla
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import datetime as dt
import json
import math
import os
import platform
import select
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent / "peers"))
import common
import fmm_network
import scoring

ROOT = Path(__file__).resolve().parents[1]
PEERS_DIR = ROOT / "benchmarks" / "peers"
OSM_DIR = ROOT.parent / "shared" / "data" / "osm"
FMM_PYTHON_DIR = fmm_network.DEFAULT_BUILD / "src" / "build" / "python"
DEFAULT_EXTRACTS = (
    "andorra_2020.osm.pbf",
    "monaco_2020.osm.pbf",
    "liechtenstein_2015.osm.pbf",
    "krems_at_2013.osm.gz",
)
DEFAULT_SETS = "1:5,15:10,30:20"
INPUTS = ("positions", "full")
POSITION_COLUMNS = ("trace_id", "time", "lon", "lat")
QUICK = {
    "extract": ["monaco_2020.osm.pbf", "andorra_2020.osm.pbf"],
    "sets": "1:5,15:10",
    "traces": 5,
    "repeats": 1,
    "min_time": 0.0,
    "peers": "ours,fmm-drop,valhalla",
}
# the peers the summary table compares us with, in its column order
KEY_PEERS = ("fmm", "fmm-drop", "valhalla")


@dataclass(frozen=True, slots=True)
class Peer:
    """A matcher under test: the python that runs it, its runner and how it is fed."""

    name: str
    label: str
    python: Path
    script: Path
    full_input: bool
    params: dict[str, Any] = field(default_factory=dict)
    env: dict[str, str] = field(default_factory=dict)
    max_repeats: int | None = None
    needs_fmm: bool = False


_FMM_ENV = {"PYTHONPATH": str(FMM_PYTHON_DIR)}
PEERS: dict[str, Peer] = {
    "ours": Peer("ours", "ours", Path(sys.executable), PEERS_DIR / "run_ours.py", True),
    "fmm": Peer(
        "fmm",
        "FMM",
        Path(sys.executable),
        PEERS_DIR / "run_fmm.py",
        False,
        {"fmm": {"variant": "stock"}},
        _FMM_ENV,
        needs_fmm=True,
    ),
    "fmm-drop": Peer(
        "fmm-drop",
        "FMM drop",
        Path(sys.executable),
        PEERS_DIR / "run_fmm.py",
        False,
        {"fmm": {"variant": "drop"}},
        _FMM_ENV,
        needs_fmm=True,
    ),
    "valhalla": Peer(
        "valhalla",
        "Meili",
        ROOT / ".peers/valhalla/bin/python",
        PEERS_DIR / "run_valhalla.py",
        True,
    ),
    "leuvenmapmatching": Peer(
        "leuvenmapmatching",
        "leuven",
        ROOT / ".peers/py311/bin/python",
        PEERS_DIR / "run_leuven.py",
        False,
        max_repeats=1,  # pure Python, 100x slower: one timed pass
    ),
    "mappymatch": Peer(
        "mappymatch",
        "mappymatch",
        ROOT / ".peers/py311/bin/python",
        PEERS_DIR / "run_mappymatch.py",
        False,
    ),
}

# one process, one thread: no BLAS/numba/OpenMP thread pools in any peer
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
    """One peer on one set and input class."""

    extract: str
    peer: str
    interval_s: float
    noise_m: float
    input: str
    traces: int
    points: int = 0
    failed: int = 0
    load_s: float = math.nan
    match_s: float = math.nan
    repeats: int = 0
    points_per_s: float = math.nan
    cpu_points_per_s: float = math.nan
    ours_ratio: float = math.nan
    ours_cpu_ratio: float = math.nan
    mismatch_mean: float = math.nan
    mismatch_median: float = math.nan
    precision: float = math.nan
    recall: float = math.nan
    length_err_mean: float = math.nan
    length_abs_err_mean: float = math.nan
    within_1pct: float = math.nan
    peak_rss_mb: float = math.nan
    positions_only: bool = False
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
            cwd=str(Path(tempfile.gettempdir())),
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
    # run from the set's folder: `-m mapmatch` must not find the working tree's package through
    # the current directory when --ours-tree puts a snapshot on PYTHONPATH
    out.mkdir(parents=True, exist_ok=True)
    subprocess.run(cmd, check=True, env=os.environ | SINGLE_THREAD_ENV, cwd=str(out))


def write_positions_only(full_csv: Path, out_csv: Path) -> tuple[int, list[str]]:
    """
    Copy a traces CSV keeping only ``trace_id,time,lon,lat``.

    Returns the number of rows and the full file's columns.

    Raises
    ------
    SystemExit
        The file lacks one of the position columns (names the file and the column).
    """
    with full_csv.open(newline="") as src:
        reader = csv.DictReader(src)
        columns = list(reader.fieldnames or [])
        missing = [c for c in POSITION_COLUMNS if c not in columns]
        if missing:
            msg = f"{full_csv}: no column {missing[0]!r} (columns: {columns})"
            raise SystemExit(msg)
        rows = 0
        with out_csv.open("w", newline="") as dst:
            writer = csv.writer(dst)
            writer.writerow(POSITION_COLUMNS)
            for row in reader:
                writer.writerow([row[c] for c in POSITION_COLUMNS])
                rows += 1
    return rows, columns


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
    probe = None
    if peer.name == "ours":
        probe = "import mapmatch, roadnets; mapmatch.match; mapmatch.read_traces; roadnets.load"
    elif peer.needs_fmm:
        ubodt_gen = fmm_network.DEFAULT_BUILD / "src" / "build" / "ubodt_gen"
        if not ubodt_gen.exists():
            return False, f"{ubodt_gen} missing; run: bash benchmarks/peers/setup.sh"
        probe = "import fmm; fmm.FastMapMatch; fmm.UBODT"
    if probe:
        r = subprocess.run(
            [str(peer.python), "-c", probe],
            capture_output=True,
            text=True,
            check=False,
            env=os.environ | peer.env,
        )
        if r.returncode != 0:
            last = (r.stderr.strip().splitlines() or ["?"])[-1]
            return False, f"not importable ({last}); run: bash benchmarks/peers/setup.sh"
    return True, ""


@dataclass(frozen=True, slots=True)
class Job:
    """One peer on one trace file: what its runner's job file says."""

    peer: Peer
    extract: Path
    traces_csv: Path
    params: dict[str, Any]
    repeats: int
    min_time_s: float
    work: Path

    @property
    def out_path(self) -> Path:
        return self.work / f"{self.peer.name}.result.json"

    @property
    def log_path(self) -> Path:
        return self.work / f"{self.peer.name}.log"

    def wants_pass(self, runs: list[float]) -> bool:
        """Whether the runner's rule asks for another pass after ``runs``."""
        return common.wants_pass(runs, self.repeats, self.min_time_s)

    def start(self, control: tuple[int, int] | None = None) -> subprocess.Popen[bytes]:
        """Write the job file and start the runner (with the two pipes of ``control``)."""
        self.work.mkdir(parents=True, exist_ok=True)
        self.out_path.unlink(missing_ok=True)
        job: dict[str, Any] = {
            "extract": str(self.extract),
            "traces_csv": str(self.traces_csv),
            "params": self.params,
            "repeats": self.repeats,
            "min_time_s": self.min_time_s,
            "out": str(self.out_path),
        }
        if control is not None:
            job["control"] = list(control)
        job_path = self.work / f"{self.peer.name}.job.json"
        job_path.write_text(json.dumps(job, indent=1))
        env = os.environ | SINGLE_THREAD_ENV | self.peer.env
        if self.peer.name == "valhalla":  # its console scripts look themselves up on PATH
            env["PATH"] = f"{self.peer.python.parent}{os.pathsep}{env.get('PATH', '')}"
        with self.log_path.open("w") as log:
            return subprocess.Popen(
                [str(self.peer.python), str(self.peer.script), str(job_path)],
                stdout=log,
                stderr=subprocess.STDOUT,
                env=env,
                cwd=str(self.work),
                pass_fds=control or (),
            )

    def log_tail(self) -> str:
        """The last lines of the runner's log, joined: what a failure says."""
        return " | ".join(self.log_path.read_text(errors="replace").strip().splitlines()[-3:])

    def outcome(self, returncode: int | None, wall: float) -> JobOutcome:
        """The result file the runner wrote, or what went wrong (the log's last lines)."""
        if returncode != 0 or not self.out_path.exists():
            return None, f"exit {returncode}: {self.log_tail()}", wall
        return json.loads(self.out_path.read_text()), None, wall


#: What running a job gives: (result, error, wall seconds of the process).
JobOutcome = tuple[dict[str, Any] | None, str | None, float]


def run_job(job: Job, timeout_s: float) -> JobOutcome:
    """Run one peer on one trace file, its passes back to back."""
    t0 = time.perf_counter()
    proc = job.start()
    try:
        returncode = proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        return None, f"timeout after {timeout_s:.0f} s", time.perf_counter() - t0
    return job.outcome(returncode, time.perf_counter() - t0)


@dataclass(slots=True)
class _Turns:
    """A runner taking passes in turns: its process, pipes, passes so far and deadline."""

    job: Job
    proc: subprocess.Popen[bytes]
    commands: Any
    answers: Any
    started: float
    deadline: float
    runs: list[float] = field(default_factory=list)
    error: str | None = None

    def ask(self, command: str) -> str:
        """Send a command, and wait (until the deadline) for the answer line ('' on none)."""
        try:
            if command:
                self.commands.write(command + "\n")
                self.commands.flush()
            left = self.deadline - time.perf_counter()
            ready, _, _ = select.select([self.answers], [], [], max(left, 0.0))
            return self.answers.readline().strip() if ready else ""
        except OSError:  # the runner is gone
            return ""

    def fail(self, why: str) -> None:
        self.error = why
        self.proc.kill()


def run_jobs_in_turns(jobs: list[Job], timeout_s: float) -> list[JobOutcome]:
    """
    Run the peers of one trace file side by side: one pass of each in turn, round after round.

    Each runner is started, loads and warms up alone (its load time is its own), then waits;
    every round asks each runner that still wants passes (its ``repeats`` and ``min_time_s``)
    for one. On a shared machine whose speed drifts from one spell to the next, every peer's
    median pass then comes from the same spells, which back-to-back jobs do not give: a slow
    spell over one peer's whole job moved a ratio by up to 2x.
    """
    turns: list[_Turns] = []
    for job in jobs:
        command_read, command_write = os.pipe()
        answer_read, answer_write = os.pipe()
        started = time.perf_counter()
        proc = job.start((command_read, answer_write))
        os.close(command_read)
        os.close(answer_write)
        turn = _Turns(
            job,
            proc,
            os.fdopen(command_write, "w", encoding="ascii"),
            os.fdopen(answer_read, encoding="ascii"),
            started,
            started + timeout_s,
        )
        turns.append(turn)
        if turn.ask("") != "ready":
            turn.fail("no 'ready' from the runner (it failed, or timed out loading)")
    while wanting := [t for t in turns if t.error is None and t.job.wants_pass(t.runs)]:
        for turn in wanting:
            answer = turn.ask("pass")
            if not answer.startswith("done "):
                turn.fail(f"no answer to pass {len(turn.runs) + 1}")
                continue
            turn.runs.append(float(answer.split()[1]))
    outcomes: list[JobOutcome] = []
    for turn in turns:
        with contextlib.suppress(OSError):
            turn.commands.write("end\n")
            turn.commands.close()
        try:
            returncode = turn.proc.wait(timeout=max(turn.deadline - time.perf_counter(), 1.0))
        except subprocess.TimeoutExpired:
            turn.fail("timeout")
            returncode = turn.proc.wait()
        turn.answers.close()
        wall = time.perf_counter() - turn.started
        if turn.error is not None and returncode != 0:
            outcomes.append((None, f"{turn.error}: {turn.job.log_tail()}", wall))
        elif turn.error is not None:
            outcomes.append((None, turn.error, wall))
        else:
            outcomes.append(turn.job.outcome(returncode, wall))
    return outcomes


@dataclass(frozen=True, slots=True)
class Accuracy:
    """Scores of one peer's result on one set."""

    summary: scoring.ScoreSummary
    failed: int
    length_err: list[float]
    per_trace: list[dict[str, Any]]

    @property
    def length_err_mean(self) -> float:
        return statistics.fmean(self.length_err) if self.length_err else math.nan

    @property
    def length_abs_err_mean(self) -> float:
        return statistics.fmean(abs(e) for e in self.length_err) if self.length_err else math.nan

    @property
    def within_1pct(self) -> float:
        if not self.length_err:
            return math.nan
        return sum(abs(e) <= 0.01 for e in self.length_err) / len(self.length_err)


def score_result(truth: dict[str, list[list[float]]], result: dict[str, Any]) -> Accuracy:
    """
    Score every trace of a peer's result (missing or failed traces count as unmatched).

    Length error per trace is ``matched length / true length - 1`` from the same geometry the
    mismatch is measured on; a failed trace has matched nothing (-100 %).
    """
    by_id = {str(r["trace_id"]): r for r in result.get("results", [])}
    scores = []
    per_trace = []
    length_err = []
    failed = 0
    for trace_id, geom in truth.items():
        r = by_id.get(trace_id)
        matched = r["geometry"] if r and not r.get("error") else []
        if r is None or r.get("error"):
            failed += 1
        s = scoring.score_route(geom, matched)
        scores.append(s)
        err = s.matched_length_m / s.true_length_m - 1.0 if s.true_length_m > 0 else math.nan
        if not math.isnan(err):
            length_err.append(err)
        per_trace.append(
            {
                "trace_id": trace_id,
                "true_m": s.true_length_m,
                "matched_m": s.matched_length_m,
                "added_m": s.added_m,
                "missed_m": s.missed_m,
                "mismatch": s.mismatch,
                "length_err": err,
                "error": "missing" if r is None else r.get("error"),
            }
        )
    return Accuracy(scoring.summarize(scores), failed, length_err, per_trace)


def _rate(points: int, seconds: float | None) -> float:
    return points / seconds if seconds else math.nan


def _ratio(ours: float, peer: float) -> float:
    return ours / peer if peer > 0 and not math.isnan(ours) else math.nan


def _fmt(x: float | None, nd: int = 2) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    return f"{x:,.{nd}f}"


def _pct(x: float | None, nd: int = 1, *, sign: bool = False) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    return f"{100 * x:+.{nd}f}" if sign else f"{100 * x:.{nd}f}"


def _set_label(r: Row) -> str:
    return f"{r.interval_s:g} s / {r.noise_m:g} m"


def summary_markdown(rows: list[Row], key_peers: list[str]) -> str:
    """One line per extract, set and input class: our speed, ratios and everyone's accuracy."""
    labels = [PEERS[p].label for p in key_peers]
    who = " / ".join(["ours", *labels])
    head = (
        "| extract | set | input | ours points/s | "
        + " | ".join(f"ours ÷ {lab} (CPU)" for lab in labels)
        + f" | mismatch mean % ({who}) | length error mean % ({who}) "
        f"| length within 1 % ({who}) |"
    )
    lines = [head, "|---|---|---|--:|" + "--:|" * len(labels) + "---|---|---|"]
    groups: dict[tuple[str, float, float, str], dict[str, Row]] = {}
    for r in rows:
        groups.setdefault((r.extract, r.interval_s, r.noise_m, r.input), {})[r.peer] = r
    for (extract, _, _, inp), by_peer in groups.items():
        ours = by_peer.get("ours")
        if ours is None:
            continue
        order = [ours] + [by_peer.get(p) for p in key_peers]
        ratios = []
        for p in key_peers:
            peer_row = by_peer.get(p)
            bad = peer_row is None or bool(peer_row.error)
            if bad or peer_row is None:
                ratios.append("-")
            else:
                cpu = peer_row.ours_cpu_ratio
                extra = "" if math.isnan(cpu) else f" ({_fmt(cpu, 2)})"
                ratios.append(_fmt(peer_row.ours_ratio, 2) + extra)
        mism = " / ".join("-" if r is None or r.error else _pct(r.mismatch_mean) for r in order)
        lerr = " / ".join(
            "-" if r is None or r.error else _pct(r.length_err_mean, sign=True) for r in order
        )
        within = " / ".join("-" if r is None or r.error else _pct(r.within_1pct, 0) for r in order)
        pps = "-" if ours.error else _fmt(ours.points_per_s, 0)
        lines.append(
            f"| {extract} | {_set_label(ours)} | {inp} | {pps} | {' | '.join(ratios)} "
            f"| {mism} | {lerr} | {within} |"
        )
    return "\n".join(lines) + "\n"


def detail_markdown(rows: list[Row]) -> str:
    """Every row: speed, failures, route mismatch, length error, memory."""
    lines = [
        "| extract | set | input | peer | traces | points | failed | load s | match s "
        "| points/s | CPU points/s | ours ÷ peer (CPU) | mismatch mean | mismatch median "
        "| precision | recall | length err mean | abs length err mean | length within 1 % "
        "| peak RSS MB |",
        "|---|---|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|",
    ]
    for r in rows:
        peer = PEERS[r.peer].label if r.peer in PEERS else r.peer
        if r.positions_only and r.input == "full":
            peer += " (positions)"
        if r.error:
            lines.append(
                f"| {r.extract} | {_set_label(r)} | {r.input} | {peer} | {r.traces} "
                f"| - | - | - | - | - | - | - | - | - | - | - | - | - | - | - | "
                f"(failed: {r.error[:120]})"
            )
            continue
        lines.append(
            f"| {r.extract} | {_set_label(r)} | {r.input} | {peer} | {r.traces} | {r.points:,} "
            f"| {r.failed} | {_fmt(r.load_s)} | {_fmt(r.match_s, 3)} "
            f"| {_fmt(r.points_per_s, 0)} | {_fmt(r.cpu_points_per_s, 0)} "
            f"| {_fmt(r.ours_ratio, 2)} ({_fmt(r.ours_cpu_ratio, 2)}) "
            f"| {_pct(r.mismatch_mean)} % | {_pct(r.mismatch_median)} % "
            f"| {_fmt(r.precision, 3)} | {_fmt(r.recall, 3)} "
            f"| {_pct(r.length_err_mean, 2, sign=True)} % | {_pct(r.length_abs_err_mean, 2)} % "
            f"| {_pct(r.within_1pct, 0)} % | {_fmt(r.peak_rss_mb, 0)} |"
        )
    return "\n".join(lines) + "\n"


def markdown(rows: list[Row], header: dict[str, Any]) -> str:
    """Both tables with a header naming date, cores, repeats and tools."""
    key = [p for p in KEY_PEERS if any(r.peer == p for r in rows)]
    in_turns = header.get("schedule") == "in turns"
    schedule = (
        "the peers of each trace file side by side, one pass each in turn"
        if in_turns
        else "each peer's passes back to back, one peer after the other"
    )
    reuse = (
        "leuven and mappymatch use positions only, so their one run stands in both; FMM, "
        "positions only too, runs again beside our full-input run"
        if in_turns
        else "FMM, leuven and mappymatch use positions only, so their one run stands in both"
    )
    intro = (
        f"Peer comparison, {header['date']}, {header['nproc']} cores ({header['cpu']}), "
        f"one process and one thread per matcher, {schedule}, median of at least "
        f"{header['repeats']} timed passes (more until {header['min_time_s']:g} s of matching; "
        "leuven: one) after a "
        "warm-up trace (ours: `match` + `geojson_bytes()`; FMM: `match_wkt` + its path in "
        f"lon/lat); {header['traces_per_set']} traces per set from "
        f"{header['trace_source']}, outlier rate {header['outlier_rate']:g} (40 m); "
        f"scoring tolerance {scoring.DEFAULT_TOLERANCE_M:g} m, direction within "
        f"{scoring.DEFAULT_MAX_ANGLE_DEG:g} deg. Input `positions`: time, lon, lat; `full`: "
        f"plus heading, speed, accuracy, odometer ({reuse}; Meili uses the per-point "
        "accuracy). "
        f"Our code: {header['ours_tree']} (git HEAD {header['git_head'][:10]} at the start). "
        f"Run wall time {header['wall_s'] / 60:.1f} min; load average "
        f"{header['loadavg_start']:.1f} at the start, {header['loadavg_end']:.1f} at the end "
        "(other work on the machine inflates wall-clock points/s; `CPU points/s` uses the "
        "matcher process's CPU time and is inflated far less)."
    )
    return intro + "\n\n" + summary_markdown(rows, key) + "\nAll rows:\n\n" + detail_markdown(rows)


def _cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def _git_head() -> str:
    try:
        r = subprocess.run(
            ["git", "-C", str(ROOT), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            check=False,
        )
    except OSError:
        return "unknown"
    return r.stdout.strip() or "unknown"


def _nan_to_none(x: Any) -> Any:
    return None if isinstance(x, float) and math.isnan(x) else str(x)


def _json_clean(obj: Any) -> Any:
    """NaN/inf as null, so the JSON is strict."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _json_clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_json_clean(v) for v in obj]
    return obj


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """The command line; ``--quick`` fills what was not given with a small subset."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument(
        "--extract",
        action="append",
        help="OSM extract path or file name in ../shared/data/osm (repeatable; "
        f"default: {', '.join(DEFAULT_EXTRACTS)})",
    )
    p.add_argument("--sets", default=None, help=f"INTERVAL_S:NOISE_M,... (default {DEFAULT_SETS})")
    p.add_argument("--traces", type=int, default=None, help="traces per set (default 20)")
    p.add_argument("--repeats", type=int, default=None, help="timed passes, median (default 3)")
    p.add_argument(
        "--min-time",
        type=float,
        default=None,
        help="more passes while the timed total is below this many seconds (default 1)",
    )
    p.add_argument(
        "--inputs",
        default=",".join(INPUTS),
        help="input classes to run: positions, full or both (default %(default)s)",
    )
    p.add_argument("--outlier-rate", type=float, default=0.02, help="share of 40 m outliers")
    p.add_argument("--seed", type=int, default=7)
    p.add_argument(
        "--peers",
        default=None,
        help=f"comma-separated subset of {','.join(PEERS)} (default: all available)",
    )
    p.add_argument(
        "--fmm-delta",
        type=float,
        default=fmm_network.DEFAULT_DELTA_M,
        help="UBODT upper bound, metres (default %(default)g)",
    )
    p.add_argument(
        "--fmm-layout",
        choices=fmm_network.LAYOUTS,
        default="segments",
        help="FMM edges: one per geometry segment (default) or one per edge of ours",
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help="small subset for development: "
        + ", ".join(f"{k}={v}" for k, v in QUICK.items())
        + " (explicit options win)",
    )
    p.add_argument(
        "--out", type=Path, default=None, help="output folder (default .bench/peers/DATE)"
    )
    p.add_argument("--timeout", type=float, default=900.0, help="seconds per peer job")
    p.add_argument(
        "--back-to-back",
        action="store_true",
        help="run each peer's passes in one block, one peer after the other (default: the "
        "peers of a trace file side by side, one pass each in turn, so that they meet the same "
        "spells of a shared machine's speed)",
    )
    p.add_argument(
        "--ours-tree",
        type=Path,
        default=None,
        help="run our matcher and the simulator from this source tree instead of the installed "
        "package (e.g. `git archive HEAD | tar -x -C /tmp/mm-head`), so that edits in progress "
        "in the working tree cannot reach a long run",
    )
    p.add_argument(
        "--interim",
        action="store_true",
        help="use the interim simulator even when `mapmatch simulate` exists",
    )
    a = p.parse_args(argv)
    defaults = {
        "extract": list(DEFAULT_EXTRACTS),
        "sets": DEFAULT_SETS,
        "traces": 20,
        "repeats": 3,
        "min_time": 1.0,
        "peers": "all",
    }
    for k, v in (QUICK if a.quick else defaults).items():
        if getattr(a, k) is None:
            setattr(a, k, v)
    for k, v in defaults.items():
        if getattr(a, k) is None:
            setattr(a, k, v)
    return a


def main(argv: list[str] | None = None) -> int:
    """Run the comparison, print and write the tables."""
    t_start = time.perf_counter()
    load_start = os.getloadavg()[0]
    head_at_start = _git_head()
    a = parse_args(argv)
    if a.ours_tree is not None:
        tree = a.ours_tree.resolve()
        if not (tree / "mapmatch" / "__init__.py").exists() or not (tree / "roadnets").is_dir():
            msg = f"--ours-tree {tree}: no mapmatch/ and roadnets/ packages there"
            raise SystemExit(msg)
        # children (our runner, the simulator) and this process's roadnets import come from it
        os.environ["PYTHONPATH"] = os.pathsep.join(
            p for p in (str(tree), os.environ.get("PYTHONPATH", "")) if p
        )
        sys.path.insert(0, str(tree))
    extracts = [resolve_extract(e) for e in a.extract]
    sets = parse_sets(a.sets, a.outlier_rate)
    inputs = [s.strip() for s in a.inputs.split(",") if s.strip()]
    if not inputs or any(s not in INPUTS for s in inputs):
        msg = f"--inputs {a.inputs!r}: choose from {','.join(INPUTS)}"
        raise SystemExit(msg)
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
    fmm_files: dict[str, Any] = {}
    for extract in extracts:
        stem = extract.name.split(".")[0]
        fmm_spec: dict[str, Any] | None = None
        fmm_error: str | None = None
        if any(p.needs_fmm for p in peers):
            print(f"[compare_peers] {stem}: FMM edge file and UBODT ...", end=" ", flush=True)
            try:
                files = fmm_network.prepare(extract, layout=a.fmm_layout, delta_m=a.fmm_delta)
            except (RuntimeError, FileNotFoundError, OSError) as exc:
                fmm_error = f"FMM preparation failed: {exc}"
                print(fmm_error, flush=True)
            else:
                fmm_files[stem] = asdict(files)
                fmm_spec = {"edges_shp": files.edges_shp, "ubodt": files.ubodt, "crs": files.crs}
                print(
                    f"{files.edge_file['edges']:,} edges, UBODT {files.ubodt_mb:,.0f} MB "
                    f"({'cached' if files.from_cache else f'built in {files.ubodt_s:.0f} s'})",
                    flush=True,
                )
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
            csvs = {"full": set_dir / "traces.csv", "positions": set_dir / "positions.csv"}
            _, columns = write_positions_only(csvs["full"], csvs["positions"])
            base = {
                "interval_s": ts.interval_s,
                "noise_m": ts.noise_m,
                "outlier_rate": ts.outlier_rate,
            }
            set_rows: list[Row] = []
            first_run: dict[str, Row] = {}
            for inp in inputs:
                # the peers to run on this file, each with its row so far; the others' rows
                planned: list[tuple[Job, Row, str]] = []
                for peer in peers:
                    # a positions-only peer's row stands for both inputs; in turns it runs
                    # again beside our full-input run (the slow pure-Python peers do not)
                    again = not a.back_to_back and peer.max_repeats is None
                    if (
                        inp == "full"
                        and not peer.full_input
                        and peer.name in first_run
                        and not again
                    ):
                        set_rows.append(replace(first_run[peer.name], input=inp))
                        continue
                    feed = "positions" if not peer.full_input else inp
                    row0 = Row(stem, peer.name, ts.interval_s, ts.noise_m, inp, len(truth))
                    row0 = replace(row0, positions_only=feed != inp or not peer.full_input)
                    if peer.needs_fmm and fmm_spec is None:
                        row = replace(row0, error=fmm_error or "FMM not prepared")
                        set_rows.append(row)
                        first_run[peer.name] = row
                        continue
                    params: dict[str, Any] = dict(base)
                    for key, value in peer.params.items():
                        params[key] = dict(value)
                    if peer.needs_fmm and fmm_spec is not None:
                        params["fmm"] = params.get("fmm", {}) | fmm_spec
                    job = Job(
                        peer,
                        extract,
                        csvs[feed],
                        params,
                        min(a.repeats, peer.max_repeats or a.repeats),
                        a.min_time if peer.max_repeats is None else 0.0,
                        set_dir / "runs" / feed,
                    )
                    planned.append((job, row0, feed))
                names_run = ", ".join(job.peer.name for job, _, _ in planned)
                how = "back to back" if a.back_to_back else "in turns"
                print(f"[compare_peers] {stem} {ts.label} {inp}: {names_run} ({how})", flush=True)
                jobs = [job for job, _, _ in planned]
                if a.back_to_back:
                    outcomes = [run_job(job, a.timeout) for job in jobs]
                else:
                    outcomes = run_jobs_in_turns(jobs, a.timeout)
                for (job, row0, feed), (res, err, wall) in zip(planned, outcomes, strict=True):
                    peer = job.peer
                    print(f"[compare_peers]   {peer.name}:", end=" ", flush=True)
                    if res is None:
                        print(f"FAILED ({err})", flush=True)
                        row = replace(row0, error=err)
                        details.append(
                            {
                                "extract": stem,
                                "set": ts.label,
                                "input": feed,
                                "peer": peer.name,
                                "error": err,
                            }
                        )
                    else:
                        acc = score_result(truth, res)
                        pps = res["points"] / res["match_s"] if res["match_s"] > 0 else math.nan
                        print(
                            f"{res['points']} points in {res['match_s']:.3f} s ({pps:,.0f}/s), "
                            f"mismatch {100 * acc.summary.mismatch_mean:.1f} %, length "
                            f"{100 * acc.length_err_mean:+.2f} %, failed {acc.failed} "
                            f"(process {wall:.0f} s)",
                            flush=True,
                        )
                        row = replace(
                            row0,
                            traces=acc.summary.traces,
                            points=int(res["points"]),
                            failed=acc.failed,
                            load_s=float(res["load_s"]),
                            match_s=float(res["match_s"]),
                            repeats=int(res.get("repeats", 1)),
                            points_per_s=pps,
                            cpu_points_per_s=_rate(res["points"], res.get("match_cpu_s")),
                            mismatch_mean=acc.summary.mismatch_mean,
                            mismatch_median=acc.summary.mismatch_median,
                            precision=acc.summary.precision,
                            recall=acc.summary.recall,
                            length_err_mean=acc.length_err_mean,
                            length_abs_err_mean=acc.length_abs_err_mean,
                            within_1pct=acc.within_1pct,
                            peak_rss_mb=float(res["peak_rss_mb"]),
                        )
                        details.append(
                            {
                                "extract": stem,
                                "set": ts.label,
                                "input": feed,
                                "peer": peer.name,
                                "columns": POSITION_COLUMNS if feed == "positions" else columns,
                                "settings": res.get("settings"),
                                "match_s_runs": res.get("match_s_runs"),
                                "process_wall_s": wall,
                                "per_trace": acc.per_trace,
                            }
                        )
                    set_rows.append(row)
                    first_run[peer.name] = row
            for inp in inputs:
                ours = next(
                    (r for r in set_rows if r.peer == "ours" and r.input == inp and not r.error),
                    None,
                )
                for r in set_rows:
                    if r.input != inp:
                        continue
                    if ours is None or r.error:
                        rows.append(r)
                        continue
                    rows.append(
                        replace(
                            r,
                            ours_ratio=_ratio(ours.points_per_s, r.points_per_s),
                            ours_cpu_ratio=_ratio(ours.cpu_points_per_s, r.cpu_points_per_s),
                        )
                    )

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
        "inputs": inputs,
        "traces_per_set": a.traces,
        "repeats": a.repeats,
        "min_time_s": a.min_time,
        "schedule": "back to back" if a.back_to_back else "in turns",
        "fmm": fmm_files,
        "command": " ".join([Path(sys.executable).name, *sys.argv]),
        "ours_tree": str(a.ours_tree) if a.ours_tree else "installed package",
        "git_head": head_at_start,
        "wall_s": time.perf_counter() - t_start,
        "loadavg_start": load_start,
        "loadavg_end": os.getloadavg()[0],
    }
    table = markdown(rows, header)
    (out / "peers.md").write_text(table)
    (out / "peers.json").write_text(
        json.dumps(
            _json_clean({"header": header, "rows": [asdict(r) for r in rows], "details": details}),
            indent=1,
            default=_nan_to_none,
        )
    )
    print()
    print(table)
    if skipped:
        print("skipped: " + "; ".join(f"{k}: {v}" for k, v in skipped.items()))
    print(f"results: {out / 'peers.json'}, {out / 'peers.md'}")
    print(f"wall time {header['wall_s'] / 60:.1f} min")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
