"""
Batch faults (issue 14 items 7, 8, 11): dead workers, a killed parent, too many workers,
durability and permissions of the outputs, and honest figures (issue 16).

The runs are real ``mapmatch match`` processes with real worker pools; processes are killed
with SIGKILL, found through ``/proc``. After every fault the outputs must be byte for byte
those of an uninterrupted run.
"""

from __future__ import annotations

import csv
import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

import pandas as pd
import pytest

from mapmatch.batch.executors import ProcessExecutor, WorkerLostError, available_cores
from mapmatch.batch.files import atomic_write, sync_folder
from mapmatch.cli import main as cli_main
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trips

if TYPE_CHECKING:
    import roadnets

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")

HERE = Path(__file__).resolve().parent


def _ppid(pid: int) -> int | None:
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return int(text.rsplit(")", 1)[1].split()[1])


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def _descendants(pid: int) -> list[int]:
    """Every live process below ``pid`` (children, their children ...)."""
    pids = [int(p.name) for p in Path("/proc").iterdir() if p.name.isdigit()]
    parent = {p: _ppid(p) for p in pids}
    found, frontier = [], [pid]
    while frontier:
        kids = [p for p, pp in parent.items() if pp in frontier and _alive(p)]
        found += kids
        frontier = kids
    return found


def _workers(pid: int) -> list[int]:
    """The pool's worker processes: the children of the batch's fork server."""
    servers = [
        p
        for p in _descendants(pid)
        if _ppid(p) == pid and b"forkserver" in Path(f"/proc/{p}/cmdline").read_bytes()
    ]
    return [p for s in servers for p in _descendants(s) if _ppid(p) == s]


@pytest.fixture(scope="module")
def many(default_net: roadnets.RoadNetwork, tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("faults-in")
    cfg = SimulationConfig(interval_s=1.0, route_length_m=1200.0, noise_m=4.0)
    frames = []
    for trip in simulate_trips(default_net, cfg, count=48, seed=77):
        frame = trip.trace.to_dataframe()
        frame.insert(0, "trace_id", trip.trace.trace_id)
        frames.append(frame)
    pd.concat(frames[:24]).to_csv(folder / "one.csv", index=False)
    pd.concat(frames[24:]).to_csv(folder / "two.csv", index=False)
    return folder


@pytest.fixture(scope="module")
def reference(many: Path, cache_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("faults-reference")
    argv = ["match", str(many), "--out", str(out), "--format", "csv", "--workers", "1"]
    assert cli_main([*argv, "--cache-dir", str(cache_dir), "--quiet"]) == 0
    return out


def _outputs(out: Path) -> dict[str, bytes]:
    return {
        p.name: p.read_bytes()
        for p in sorted(out.iterdir())
        if p.is_file() and p.name not in {"summary.csv", "run.json"}
    }


def _summary(out: Path) -> list[dict[str, str]]:
    with (out / "summary.csv").open(newline="", encoding="utf-8") as handle:
        return [{k: v for k, v in r.items() if k != "seconds"} for r in csv.DictReader(handle)]


def _command(many: Path, out: Path, cache_dir: Path) -> list[str]:
    argv = [sys.executable, "-m", "mapmatch", "match", str(many), "--out", str(out)]
    return [*argv, "--format", "csv", "--cache-dir", str(cache_dir), "--chunk-traces", "3"]


def _wait_for(predicate: object, timeout_s: float = 60.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():  # type: ignore[operator]
            return True
        time.sleep(0.01)
    return False


def _written(out: Path) -> int:
    return len(list(out.glob("trip-*.edges.csv"))) if out.is_dir() else 0


def _logged(out: Path) -> int:
    """Rows the parent has appended to summary.csv so far."""
    try:
        return max(0, len((out / "summary.csv").read_text().splitlines()) - 1)
    except OSError:
        return 0


@pytest.mark.skipif(available_cores() < 2, reason="a pool needs two cores")
def test_a_killed_worker_costs_nothing(
    many: Path, reference: Path, cache_dir: Path, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [*_command(many, out, cache_dir), "--workers", "2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        start_new_session=True,
    )
    try:
        assert _wait_for(lambda: _written(out) >= 4 and len(_workers(proc.pid)) == 2)
        victim = _workers(proc.pid)[0]
        os.kill(victim, signal.SIGKILL)
        stdout, stderr = proc.communicate(timeout=180)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)
    assert proc.returncode == 0, stderr.decode()
    text = stdout.decode()
    assert "48 ok, 0 failed" in text
    assert "retried   " in text  # the dead worker's unfinished traces ran again
    assert _outputs(out) == _outputs(reference)
    assert _summary(out) == _summary(reference)
    assert not list(out.glob(".tmp-*"))


@pytest.mark.skipif(available_cores() < 2, reason="a pool needs two cores")
def test_a_killed_parent_takes_its_workers_and_resume_finishes_the_job(
    many: Path, reference: Path, cache_dir: Path, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [*_command(many, out, cache_dir), "--workers", "2", "--quiet"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        assert _wait_for(lambda: _logged(out) >= 3 and len(_workers(proc.pid)) == 2)
        below = _descendants(proc.pid)
        assert len(below) >= 3  # the fork server and two workers (and a resource tracker)
        os.kill(proc.pid, signal.SIGKILL)  # the parent only, not its process group
        proc.wait(timeout=30)
        assert _wait_for(lambda: not any(_alive(p) for p in below), timeout_s=15), [
            Path(f"/proc/{p}/cmdline").read_bytes() for p in below if _alive(p)
        ]
    finally:
        os.killpg(proc.pid, signal.SIGKILL) if _alive(proc.pid) else None
    settled = _outputs(out)
    time.sleep(1.0)
    assert _outputs(out) == settled  # nothing goes on writing after the parent died
    assert 0 < _written(out) < 48
    resumed = subprocess.run(
        [*_command(many, out, cache_dir), "--workers", "2", "--resume"],
        capture_output=True,
        timeout=180,
        check=False,
    )
    assert resumed.returncode == 0, resumed.stderr.decode()
    assert "from an earlier run" in resumed.stdout.decode()
    assert _outputs(out) == _outputs(reference)
    assert _summary(out) == _summary(reference)
    assert not list(out.glob(".tmp-*"))


def test_too_many_workers_are_cut_to_the_cores_unless_forced(
    many: Path, cache_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    source = many / "one.csv"
    base = [str(source), "--format", "csv", "--cache-dir", str(cache_dir), "--chunk-traces", "8"]
    code = cli_main(["match", *base, "--out", str(tmp_path / "cut"), "--workers", "1000"])
    out = capsys.readouterr().out
    assert code == 0
    cores = available_cores()
    assert f"note      --workers 1000 cut to {cores}, the cores this process may use" in out
    assert f"on {cores} processes" in out or (cores == 1 and "1 process (in-process)" in out)
    code = cli_main(
        ["match", *base, "--out", str(tmp_path / "forced"), "--workers", "3", "--force-workers"]
    )
    out = capsys.readouterr().out
    assert code == 0
    assert "on 3 processes" in out
    assert "note" not in out


def test_resume_with_nothing_to_do_says_so(
    many: Path, cache_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["match", str(many / "two.csv"), "--out", str(tmp_path), "--format", "csv"]
    argv += ["--cache-dir", str(cache_dir), "--workers", "1"]
    assert cli_main(argv) == 0
    first = capsys.readouterr().out
    assert "points/s per worker" in first
    assert cli_main([*argv, "--resume"]) == 0
    again = capsys.readouterr().out
    assert "nothing to do: every trace was complete from an earlier run" in again
    assert "points/s" not in again
    assert "(24 from an earlier run)" in again


@pytest.mark.parametrize("umask", [0o027, 0o002])
def test_outputs_follow_the_umask(umask: int, many: Path, cache_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    code = (
        f"import os, sys; os.umask({umask}); from mapmatch.cli import main; "
        f"sys.exit(main(sys.argv[1:]))"
    )
    argv = ["match", str(many / "one.csv"), "--out", str(out), "--format", "geoparquet"]
    proc = subprocess.run(
        [sys.executable, "-c", code, *argv, "--cache-dir", str(cache_dir), "--workers", "1"],
        capture_output=True,
        timeout=180,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr.decode()
    modes = {stat.S_IMODE(p.stat().st_mode) for p in out.iterdir() if p.is_file()}
    assert modes == {0o666 & ~umask}


def test_files_and_folder_are_flushed_to_the_disk(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    synced: list[str] = []
    real = os.fsync

    def fsync(fd: int) -> None:
        synced.append(os.readlink(f"/proc/self/fd/{fd}"))
        real(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    target = tmp_path / "a.csv"
    atomic_write(target, lambda tmp: tmp.write_text("x\n"))
    sync_folder(tmp_path)
    assert target.read_text() == "x\n"
    assert len(synced) == 2
    assert Path(synced[0]).name.startswith(".tmp-a.csv.")  # the data, before the rename
    assert synced[1] == str(tmp_path)  # the rename


# --------------------------------------------------------------------------- the pool itself


def _dies_on_three(task: int, marker: str) -> int:
    if task == 3:
        os._exit(9)
    time.sleep(0.2)  # the other tasks are still running when task 3 kills the pool
    return task * 10


def _dies_once_on_three(task: int, marker: str) -> int:
    if task == 3 and not Path(marker).exists():
        Path(marker).write_text("died once")
        os._exit(9)
    return task * 10


@pytest.mark.parametrize(("fn", "lost"), [(_dies_on_three, {3}), (_dies_once_on_three, set())])
def test_a_dead_worker_costs_a_retry_and_only_a_task_that_kills_again_fails(
    fn: object, lost: set[int], tmp_path: Path
) -> None:
    executor = ProcessExecutor(2, shared=str(tmp_path / "marker"))
    try:
        outcomes = dict(executor.run(fn, list(range(8)), retry=lambda t: [t]))  # type: ignore[arg-type]
    finally:
        executor.close()
    assert set(outcomes) == set(range(8))
    failed = {t for t, o in outcomes.items() if isinstance(o, BaseException)}
    assert failed == lost
    for t in lost:
        assert isinstance(outcomes[t], WorkerLostError)
    assert all(outcomes[t] == t * 10 for t in set(range(8)) - lost)


def test_a_file_that_cannot_be_put_in_place_fails_its_trace_alone(tmp_path: Path) -> None:
    from mapmatch.batch.files import Committer

    committer = Committer()
    (tmp_path / "b.csv").mkdir()  # a folder in the way of b's file: the rename must fail
    (tmp_path / "b.csv" / "keep").write_text("x")
    for name in ("a", "b", "c"):
        atomic_write(
            tmp_path / f"{name}.edges.csv",
            lambda p: p.write_text("e\n"),
            committer=committer,
            group=name,
        )
        atomic_write(
            tmp_path / f"{name}.csv", lambda p: p.write_text("p\n"), committer=committer, group=name
        )
        committer.seal(name)
    failed = committer.wait()
    assert set(failed) == {"b"}
    assert isinstance(failed["b"], OSError)
    assert sorted(committer.finished()) == ["a", "c"]
    assert (tmp_path / "a.csv").read_text() == "p\n"
    assert not list(tmp_path.glob(".tmp-*"))  # b's temporaries are gone too
