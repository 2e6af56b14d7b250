"""
Load benchmark of the HTTP service on loopback: ``mapmatch serve`` under concurrent clients.

For each worker count, starts ``mapmatch serve --workers N`` on a free 127.0.0.1 port (the
embedded network, its own compiled cache), warms it up, then runs ``--clients`` concurrent
clients for ``--duration-s`` seconds, each posting simulated 100-point 1 Hz traces (JSON) in a
loop. Prints a markdown table: requests/s, latency p50/p95/p99, error count (must be 0) and the
server's memory (all its processes) before and after the run (must be flat). RSS counts the
memory-mapped network once per process; PSS shares it out and is the honest total.

    .venv/bin/python benchmarks/bench_service.py          # 16 clients, 30 s, 1 and 2 workers
    .venv/bin/python benchmarks/bench_service.py --duration-s 5 --workers 1

Bounded: loopback only, a fixed duration, a fixed number of clients.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import random
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import httpx
import numpy as np

import roadnets
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trips

if TYPE_CHECKING:
    from collections.abc import Iterator

ROOT = Path(__file__).resolve().parents[1]
POINTS = 100


@dataclass(frozen=True)
class RunResult:
    workers: int
    clients: int
    duration_s: float
    requests: int
    errors: int
    latencies_s: list[float]
    rss_before_mb: float
    rss_after_mb: float
    pss_before_mb: float
    pss_after_mb: float

    def row(self) -> str:
        lat = np.array(self.latencies_s) * 1000.0
        p50, p95, p99 = np.percentile(lat, [50, 95, 99]) if lat.size else (np.nan,) * 3
        return (
            f"| {self.workers} | {self.clients} | {self.duration_s:.0f} | {self.requests} | "
            f"{self.requests / self.duration_s:.1f} | {p50:.1f} | {p95:.1f} | {p99:.1f} | "
            f"{self.errors} | {self.rss_before_mb:.0f} -> {self.rss_after_mb:.0f} | "
            f"{self.pss_before_mb:.0f} -> {self.pss_after_mb:.0f} |"
        )


HEADER = (
    "| workers | clients | seconds | requests | req/s | p50 ms | p95 ms | p99 ms | errors "
    "| server RSS MB before -> after | server PSS MB before -> after |\n"
    "|---|---|---|---|---|---|---|---|---|---|---|"
)


def make_bodies(count: int, cache_dir: str) -> list[bytes]:
    """``count`` JSON bodies of simulated 100-point 1 Hz traces on the embedded network."""
    import json

    net = roadnets.load(cache_dir=cache_dir)
    cfg = SimulationConfig(interval_s=1.0, noise_m=5.0, outlier_rate=0.02, route_length_m=1200.0)
    bodies: list[bytes] = []
    seed = 0
    while len(bodies) < count:
        for trip in simulate_trips(net, cfg, count=count, seed=seed):
            if len(trip.trace) >= POINTS and len(bodies) < count:
                frame = trip.trace.slice(0, POINTS).to_dataframe()
                points = [{k: float(v) for k, v in r.items()} for r in frame.to_dict("records")]
                bodies.append(
                    json.dumps({"points": points, "trace_id": trip.trace.trace_id}).encode()
                )
        seed += count
    return bodies


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _tree(pid: int) -> list[int]:
    """``pid`` and all its descendants (Linux /proc)."""
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        out.append(p)
        for task in Path(f"/proc/{p}/task").glob("*"):
            with contextlib.suppress(OSError):
                todo += [int(c) for c in (task / "children").read_text().split()]
    return out


def memory_mb(pid: int) -> tuple[float, float]:
    """RSS and PSS of a process tree, MB."""
    rss = pss = 0
    for p in _tree(pid):
        with contextlib.suppress(OSError):
            for line in Path(f"/proc/{p}/smaps_rollup").read_text().splitlines():
                if line.startswith("Rss:"):
                    rss += int(line.split()[1])
                elif line.startswith("Pss:"):
                    pss += int(line.split()[1])
    return rss / 1024.0, pss / 1024.0


@contextlib.contextmanager
def server(
    workers: int, cache_dir: str, log: Path
) -> Iterator[tuple[str, subprocess.Popen[bytes]]]:
    port = free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("MAPMATCH_")}
    command = [
        sys.executable, "-m", "mapmatch", "serve", "--host", "127.0.0.1", "--port", str(port),
        "--workers", str(workers), "--cache-dir", cache_dir, "--no-access-log",
    ]  # fmt: skip
    with log.open("wb") as sink:
        process = subprocess.Popen(command, stdout=sink, stderr=sink, env=env, cwd=ROOT)
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 120
        ready = 0
        while ready < 4 * workers:  # several 200s in a row: every worker has loaded
            if process.poll() is not None or time.monotonic() > deadline:
                msg = f"server did not start:\n{log.read_text()[-3000:]}"
                raise SystemExit(msg)
            try:
                ok = httpx.get(url + "/readyz", timeout=2).status_code == 200
            except httpx.TransportError:
                ok = False
            ready = ready + 1 if ok else 0
            time.sleep(0.05)
        yield url, process
    finally:
        process.terminate()
        try:
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            process.kill()


async def load(
    url: str, bodies: list[bytes], *, clients: int, duration_s: float
) -> tuple[int, list[float], dict[str, int]]:
    """``clients`` concurrent loops posting bodies until ``duration_s`` has passed."""
    latencies: list[float] = []
    errors: dict[str, int] = {}
    stop = time.perf_counter() + duration_s
    limits = httpx.Limits(max_connections=clients, max_keepalive_connections=clients)
    headers = {"content-type": "application/json"}

    async with httpx.AsyncClient(base_url=url, timeout=60.0, limits=limits) as client:

        async def one(seed: int) -> None:
            rng = random.Random(seed)
            while time.perf_counter() < stop:
                body = bodies[rng.randrange(len(bodies))]
                started = time.perf_counter()
                try:
                    answer = await client.post("/v1/match", content=body, headers=headers)
                    status = str(answer.status_code)
                except httpx.HTTPError as exc:
                    status = type(exc).__name__
                latencies.append(time.perf_counter() - started)
                if status != "200":
                    errors[status] = errors.get(status, 0) + 1

        await asyncio.gather(*(one(i) for i in range(clients)))
    return len(latencies), latencies, errors


def run(workers: int, args: argparse.Namespace, bodies: list[bytes], cache_dir: str) -> RunResult:
    log = Path(cache_dir) / f"server-{workers}.log"
    with server(workers, cache_dir, log) as (url, process):
        asyncio.run(load(url, bodies, clients=args.clients, duration_s=args.warmup_s))
        rss0, pss0 = memory_mb(process.pid)
        started = time.perf_counter()
        count, latencies, errors = asyncio.run(
            load(url, bodies, clients=args.clients, duration_s=args.duration_s)
        )
        elapsed = time.perf_counter() - started
        rss1, pss1 = memory_mb(process.pid)
        if process.poll() is not None:
            msg = f"the server died under load:\n{log.read_text()[-3000:]}"
            raise SystemExit(msg)
        metrics = httpx.get(url + "/metrics").text
    if errors:
        print(f"workers={workers}: errors {errors}", file=sys.stderr)
    five = [  # /readyz answers 503 while the workers start; nothing else may be a 5xx
        line
        for line in metrics.splitlines()
        if 'status="5' in line and "_total" in line and 'route="/readyz"' not in line
    ]
    if five:
        print(f"workers={workers}: server counted 5xx: {five}", file=sys.stderr)
    return RunResult(
        workers,
        args.clients,
        elapsed,
        count,
        sum(errors.values()),
        latencies,
        rss0,
        rss1,
        pss0,
        pss1,
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument("--clients", type=int, default=16, help="concurrent clients (16)")
    parser.add_argument("--duration-s", type=float, default=30.0, help="seconds per run (30)")
    parser.add_argument("--warmup-s", type=float, default=3.0, help="unmeasured seconds first (3)")
    parser.add_argument(
        "--workers", type=int, nargs="+", default=[1, 2], help="worker counts (1 2)"
    )
    parser.add_argument("--traces", type=int, default=40, help="distinct traces sent (40)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench-service-") as cache_dir:
        bodies = make_bodies(args.traces, cache_dir)
        results: list[Any] = [run(w, args, bodies, cache_dir) for w in args.workers]
    print(
        f"\n{len(bodies)} simulated {POINTS}-point 1 Hz traces on the embedded network, JSON "
        f"bodies, {args.clients} clients on loopback, {os.cpu_count()} CPUs shared by clients "
        "and server.\n"
    )
    print(HEADER)
    for result in results:
        print(result.row())
    bad = [r for r in results if r.errors]
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
