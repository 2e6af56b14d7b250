"""
Load benchmark of the HTTP service on loopback: ``mapmatch serve`` under concurrent clients.

For each worker count, starts ``mapmatch serve --workers N`` on a free 127.0.0.1 port (the
embedded network, its own compiled cache), warms it up, then runs ``--clients`` concurrent
clients for ``--duration-s`` seconds, each posting simulated 100-point 1 Hz traces (JSON) in a
loop, once with httpx and once with a lean asyncio-streams client (``--client``; httpx's own
CPU, on the same cores as the server, weighs on the figures). Prints a markdown table:
requests/s, latency p50/p95/p99, error count (must be 0) and the server's memory (all its
processes) before and after the run (must be flat). RSS counts the memory-mapped network once
per process; PSS shares it out and is the honest total.

    .venv/bin/python benchmarks/bench_service.py          # 16 clients, 30 s, 1 and 2 workers
    .venv/bin/python benchmarks/bench_service.py --duration-s 5 --workers 1 --client raw
    .venv/bin/python benchmarks/bench_service.py --abuse  # also: the same load under attack
    .venv/bin/python benchmarks/bench_service.py --cost-model  # api.costs against peak RSS

``--abuse`` runs each worker count twice, quiet and then with 4 hostile clients beside the
ordinary ones (the same ``--client`` kind in both runs), each looping one attack: a gzip bomb
(a CSV that inflates to 520 MB), a wide CSV (100,000 columns), a body trickled a byte at a
time (or promising more than it sends), and options that would need gigabytes (10,000
points, 64 candidates in 200 m). It reports the
ordinary clients' p99 against the quiet run (must stay within 2x), every 5xx on either side
(must be 0), the hostile answers by status, and the server's memory before and after.

``--in-process`` also runs, for each worker count N, N processes that each call the service's
own request handler (``MatchService.run``: the JSON body parsed, matched, the GeoJSON written)
on the same bodies in a loop for ``--duration-s``, with no HTTP and no client, and prints the
HTTP rows' requests/s as a share of that (issue 15: the HTTP path at >= 70 % of in-process),
and the same per CPU second of the server's processes (all their threads, read from /proc
before and after the load) against per CPU second of the in-process ones: the clients share
the cores, so the first ratio also holds what they take, the second only what HTTP costs;
then the server's CPU per request split into its workers' main threads (their event loops:
HTTP, the framework, the answer sent) and their match threads, beside the in-process handler's.

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
import zlib
from collections.abc import Callable, Coroutine
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
MATCH_THREADS: list[int] = []  # --match-threads, when given
POINTS = 100


@dataclass(frozen=True)
class RunResult:
    client: str
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
    server_cpu_s: float = float("nan")
    loop_cpu_s: float = float("nan")  # the workers' main threads: their event loops

    def row(self) -> str:
        lat = np.array(self.latencies_s) * 1000.0
        p50, p95, p99 = np.percentile(lat, [50, 95, 99]) if lat.size else (np.nan,) * 3
        return (
            f"| {self.client} | {self.workers} | {self.clients} | {self.duration_s:.0f} | "
            f"{self.requests} | "
            f"{self.requests / self.duration_s:.1f} | {p50:.1f} | {p95:.1f} | {p99:.1f} | "
            f"{self.errors} | {self.rss_before_mb:.0f} -> {self.rss_after_mb:.0f} | "
            f"{self.pss_before_mb:.0f} -> {self.pss_after_mb:.0f} |"
        )


@dataclass(frozen=True)
class AbuseResult:
    workers: int
    quiet_latencies_s: list[float]
    latencies_s: list[float]
    requests: int
    errors: dict[str, int]
    attacks: dict[str, dict[str, int]]
    rss_before_mb: float
    rss_after_mb: float

    def row(self) -> str:
        quiet = float(np.percentile(self.quiet_latencies_s, 99)) * 1000.0
        loud = float(np.percentile(self.latencies_s, 99)) * 1000.0
        fives = sum(n for s, n in self.errors.items() if s.startswith("5"))
        fives += sum(n for a in self.attacks.values() for s, n in a.items() if s.startswith("5"))
        shown = "; ".join(
            f"{name}: " + ", ".join(f"{n} x {s}" for s, n in sorted(seen.items()))
            for name, seen in self.attacks.items()
        )
        return (
            f"| {self.workers} | {quiet:.1f} | {loud:.1f} | {loud / quiet:.2f} | "
            f"{self.requests} | {sum(self.errors.values())} | {fives} | {shown} | "
            f"{self.rss_before_mb:.0f} -> {self.rss_after_mb:.0f} |"
        )


ABUSE: list[AbuseResult] = []
ABUSE_HEADER = (
    "| workers | quiet p99 ms | under attack p99 ms | ratio | ordinary requests | ordinary "
    "errors | 5xx (all) | hostile answers | server RSS MB before -> after |\n"
    "|---|---|---|---|---|---|---|---|---|"
)

HEADER = (
    "| client | workers | clients | seconds | requests | req/s | p50 ms | p95 ms | p99 ms | "
    "errors | server RSS MB before -> after | server PSS MB before -> after |\n"
    "|---|---|---|---|---|---|---|---|---|---|---|---|"
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


def _ticks(stat: Path) -> int:
    """User + system clock ticks of a ``/proc/.../stat`` file."""
    # the fields after the command's closing parenthesis: utime and stime are 12 and 13
    fields = stat.read_text().rsplit(")", 1)[1].split()
    return int(fields[11]) + int(fields[12])


def cpu_seconds(pid: int) -> tuple[float, float]:
    """
    CPU seconds of a process tree so far: every thread, and the processes' main threads.

    A worker's main thread runs its event loop (HTTP, the framework, the answer sent), the
    others its matches; the server's supervisor, if any, adds its main thread's little.
    """
    every = main = 0
    for p in _tree(pid):
        with contextlib.suppress(OSError):
            every += _ticks(Path(f"/proc/{p}/stat"))
            main += _ticks(Path(f"/proc/{p}/task/{p}/stat"))
    per_second = os.sysconf("SC_CLK_TCK")
    return every / per_second, main / per_second


@contextlib.contextmanager
def server(
    workers: int, cache_dir: str, log: Path
) -> Iterator[tuple[str, subprocess.Popen[bytes]]]:
    port = free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("MAPMATCH_")}
    command = [
        sys.executable, "-m", "mapmatch", "serve", "--host", "127.0.0.1", "--port", str(port),
        "--workers", str(workers), "--cache-dir", cache_dir, "--no-access-log",
        *(["--match-threads", str(MATCH_THREADS[0])] if MATCH_THREADS else []),
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


async def _post_raw(
    reader: asyncio.StreamReader, writer: asyncio.StreamWriter, head: bytes, body: bytes
) -> str:
    """One keep-alive POST on an open connection; the status, after checking the answer."""
    writer.write(head + b"content-length: %d\r\n\r\n" % len(body) + body)
    await writer.drain()
    answer = await reader.readuntil(b"\r\n\r\n")
    status = answer[9:12].decode()
    fields = dict(line.split(b":", 1) for line in answer.lower().split(b"\r\n")[1:] if b":" in line)
    if b"content-length" not in fields:
        return "no content-length"
    content = await reader.readexactly(int(fields[b"content-length"]))
    if fields.get(b"content-encoding", b"").strip() == b"gzip":
        content = zlib.decompress(content, 31)
    if status == "200" and not content.startswith(b'{"type":"FeatureCollection"'):
        return "not a FeatureCollection"
    if fields.get(b"connection", b"").strip() == b"close":
        return f"{status} (closed)"
    return status


async def load_raw(
    url: str, bodies: list[bytes], *, clients: int, duration_s: float
) -> tuple[int, list[float], dict[str, int]]:
    """
    :func:`load` with a lean HTTP/1.1 client on asyncio streams instead of httpx.

    The same requests (JSON bodies, ``accept-encoding: gzip, deflate`` as httpx sends, so the
    server compresses as it does for httpx), each answer read whole, unzipped and checked.
    httpx spends about 2.8 ms of CPU per request here, half as much again as the server's
    match, on the same two cores; this client a tenth of that, so the figures say more about
    the server.
    """
    host, port = url.removeprefix("http://").split(":")
    head = (
        b"POST /v1/match HTTP/1.1\r\nhost: %s\r\ncontent-type: application/json\r\n"
        b"accept-encoding: gzip, deflate\r\n" % host.encode()
    )
    latencies: list[float] = []
    errors: dict[str, int] = {}
    stop = time.perf_counter() + duration_s

    async def one(seed: int) -> None:
        rng = random.Random(seed)
        reader, writer = await asyncio.open_connection(host, int(port))
        try:
            while time.perf_counter() < stop:
                body = bodies[rng.randrange(len(bodies))]
                started = time.perf_counter()
                try:
                    status = await _post_raw(reader, writer, head, body)
                except (OSError, asyncio.IncompleteReadError) as exc:
                    status = type(exc).__name__
                latencies.append(time.perf_counter() - started)
                if status != "200":
                    errors[status] = errors.get(status, 0) + 1
                    writer.close()
                    reader, writer = await asyncio.open_connection(host, int(port))
        finally:
            writer.close()

    await asyncio.gather(*(one(i) for i in range(clients)))
    return len(latencies), latencies, errors


#: The load generators of ``--client``.
Loader = Callable[..., Coroutine[Any, Any, tuple[int, list[float], dict[str, int]]]]
CLIENTS: dict[str, Loader] = {"httpx": load, "raw": load_raw}


def _gzip_bomb() -> bytes:
    import gzip
    import io

    out = io.BytesIO()
    with gzip.GzipFile(fileobj=out, mode="wb", compresslevel=9) as gz:
        gz.write(b"time,lat,lon\n")
        block = b"1700000000,43.7384,7.4246\n" * 10_000
        for _ in range(2_000):
            gz.write(block)
    return out.getvalue()


def _costly_body() -> bytes:
    import json

    rng = np.random.default_rng(1)
    lon = 7.4246 + np.cumsum(rng.normal(0, 5e-5, 10_000))
    lat = 43.7384 + np.cumsum(rng.normal(0, 5e-5, 10_000))
    points = [
        {"time": 1_700_000_000 + i, "lat": float(y), "lon": float(x)}
        for i, (x, y) in enumerate(zip(lon, lat, strict=True))
    ]
    options = {"search_radius_m": 200, "max_candidates": 64, "sigma_m": 50}
    return json.dumps({"points": points, "options": options}).encode()


async def _trickle(url: str, stop: float, statuses: dict[str, int]) -> None:
    """Open a connection, promise 10 kB of CSV and send a byte a second; again and again."""
    host, port = url.removeprefix("http://").split(":")
    while time.perf_counter() < stop:
        try:
            reader, writer = await asyncio.open_connection(host, int(port))
            writer.write(
                b"POST /v1/match HTTP/1.1\r\nhost: x\r\ncontent-type: text/csv\r\n"
                b"content-length: 10000\r\n\r\ntime,lat,lon\n"
            )
            await writer.drain()
            answer = b""
            while time.perf_counter() < stop and not answer:
                writer.write(b"1")
                await writer.drain()
                with contextlib.suppress(TimeoutError):
                    answer = await asyncio.wait_for(reader.read(64), timeout=1.0)
            status = answer[9:12].decode() or "open at the end"
            writer.close()
        except OSError as exc:
            status = type(exc).__name__
        statuses[status] = statuses.get(status, 0) + 1


async def hostile(url: str, *, duration_s: float) -> dict[str, dict[str, int]]:
    """The 4 hostile clients, each looping its attack until ``duration_s`` has passed."""
    stop = time.perf_counter() + duration_s
    bomb = _gzip_bomb()
    wide = b",".join(b"c%d" % i for i in range(100_000)) + b"\n"
    costly = _costly_body()
    attacks = {
        "gzip bomb": (bomb, {"content-type": "text/csv", "content-encoding": "gzip"}),
        "wide csv": (wide * 2, {"content-type": "text/csv"}),
        "costly options": (costly, {"content-type": "application/json"}),
    }
    seen: dict[str, dict[str, int]] = {name: {} for name in [*attacks, "slow body"]}

    async with httpx.AsyncClient(base_url=url, timeout=60.0) as client:

        async def loop(name: str) -> None:
            content, headers = attacks[name]
            while time.perf_counter() < stop:
                try:
                    answer = await client.post("/v1/match", content=content, headers=headers)
                    status = str(answer.status_code)
                except httpx.HTTPError as exc:
                    status = type(exc).__name__
                seen[name][status] = seen[name].get(status, 0) + 1

        await asyncio.gather(*(loop(n) for n in attacks), _trickle(url, stop, seen["slow body"]))
    return seen


async def load_under_attack(
    url: str, bodies: list[bytes], *, clients: int, duration_s: float, loader: Loader
) -> tuple[tuple[int, list[float], dict[str, int]], dict[str, dict[str, int]]]:
    """The ordinary load with ``loader`` (the quiet run's client kind) beside :func:`hostile`."""
    ordinary, attacks = await asyncio.gather(
        loader(url, bodies, clients=clients, duration_s=duration_s),
        hostile(url, duration_s=duration_s),
    )
    return ordinary, attacks


def run(
    workers: int, client: str, args: argparse.Namespace, bodies: list[bytes], cache_dir: str
) -> RunResult:
    log = Path(cache_dir) / f"server-{workers}.log"
    loader = CLIENTS[client]
    with server(workers, cache_dir, log) as (url, process):
        asyncio.run(loader(url, bodies, clients=args.clients, duration_s=args.warmup_s))
        rss0, pss0 = memory_mb(process.pid)
        cpu0, loop0 = cpu_seconds(process.pid)
        started = time.perf_counter()
        count, latencies, errors = asyncio.run(
            loader(url, bodies, clients=args.clients, duration_s=args.duration_s)
        )
        elapsed = time.perf_counter() - started
        cpu1, loop1 = cpu_seconds(process.pid)
        rss1, pss1 = memory_mb(process.pid)
        if process.poll() is not None:
            msg = f"the server died under load:\n{log.read_text()[-3000:]}"
            raise SystemExit(msg)
        if args.abuse:
            (a_count, a_lat, a_errors), attacks = asyncio.run(
                load_under_attack(
                    url, bodies, clients=args.clients, duration_s=args.duration_s, loader=loader
                )
            )
            rss2, _pss2 = memory_mb(process.pid)
            ABUSE.append(
                AbuseResult(workers, latencies, a_lat, a_count, a_errors, attacks, rss1, rss2)
            )
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
        client,
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
        cpu1 - cpu0,
        loop1 - loop0,
    )


COST_CONFIGS = [  # points, max_candidates, search_radius_m, sigma_m
    (3000, 16, 50.0, 5.0),
    (6000, 16, 50.0, 5.0),
    (3000, 8, 20.0, 3.0),
    (3000, 64, 50.0, 5.0),
    (3000, 16, 200.0, 50.0),
    (3000, 32, 100.0, 20.0),
    (3000, 64, 200.0, 50.0),
]


def _in_process_worker(
    cache_dir: str, bodies: list[bytes], warmup_s: float, duration_s: float, barrier: Any, out: Any
) -> None:
    """One process of :func:`in_process`: ``MatchService.run`` on the bodies in a loop."""
    import logging

    from api.app import create_app
    from api.schemas import MatchQuery
    from api.settings import Settings

    logging.disable(logging.WARNING)  # the server runs without an access log too
    service = create_app(Settings(cache_dir=cache_dir)).state.service
    service.networks.load_all()  # returns loaded, or with the reason it failed
    if service.networks.failure:
        raise SystemExit(service.networks.failure)
    query = MatchQuery()
    stop = time.perf_counter() + warmup_s
    while time.perf_counter() < stop:
        for body in bodies:
            service.run(body, "json", query)
    barrier.wait()
    count, started, cpu = 0, time.perf_counter(), time.process_time()
    stop = started + duration_s
    while time.perf_counter() < stop:
        service.run(bodies[count % len(bodies)], "json", query)
        count += 1
    out.put((count, time.perf_counter() - started, time.process_time() - cpu))


def in_process(
    workers: int, args: argparse.Namespace, bodies: list[bytes], cache_dir: str
) -> tuple[float, float]:
    """
    Requests/s of ``workers`` processes each running the service's handler, no HTTP.

    And requests per CPU second of those processes (every thread's).
    """
    import multiprocessing

    spawn = multiprocessing.get_context("spawn")
    barrier, out = spawn.Barrier(workers), spawn.Queue()
    procs = [
        spawn.Process(
            target=_in_process_worker,
            args=(cache_dir, bodies, args.warmup_s, args.duration_s, barrier, out),
        )
        for _ in range(workers)
    ]
    for proc in procs:
        proc.start()
    done = [out.get(timeout=args.duration_s + 300) for _ in procs]
    for proc in procs:
        proc.join()
    rate = float(sum(count / elapsed for count, elapsed, _ in done))
    per_cpu = sum(count for count, _, _ in done) / sum(cpu for _, _, cpu in done)
    return rate, float(per_cpu)


def _one_cost(n: int, k: int, r: float, s: float, cache_dir: str) -> None:
    """In a fresh process: peak RSS growth of one match, printed as JSON."""
    import gc
    import json
    import resource

    import pandas as pd

    import mapmatch

    net = roadnets.load(cache_dir=cache_dir)
    cfg = SimulationConfig(interval_s=1.0, noise_m=5.0, route_length_m=3000.0)
    trips = list(simulate_trips(net, cfg, count=30, seed=3))
    frames: list[pd.DataFrame] = []
    offset = 0.0
    while sum(len(f) for f in frames) < n:
        for trip in trips:
            frame = trip.trace.to_dataframe().drop(columns="odometer", errors="ignore")
            frame["time"] = frame["time"] - frame["time"].iloc[0] + offset
            offset = float(frame["time"].iloc[-1]) + 1.0
            frames.append(frame)
    table = pd.concat(frames, ignore_index=True).iloc[:n]
    trace = mapmatch.Trace.from_dataframe(table, trace_id="cost")
    mapmatch.match(mapmatch.Trace.from_dataframe(table.iloc[:50]), net)  # warm up
    gc.collect()
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    now = int(Path("/proc/self/statm").read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE") // 1024
    options = {"max_candidates": k, "search_radius_m": r, "sigma_m": s, "thinning_sigmas": 0.0}
    mapmatch.match(trace, net, mapmatch.MatchConfig().replace(options))
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(json.dumps({"peak_mb": (peak - max(base, now)) / 1024.0}))


def cost_model(cache_dir: str) -> None:
    """Peak RSS of single matches (every fix kept) against api.costs' estimate."""
    import json

    import mapmatch
    from api.costs import CandidateDensity, match_cost

    net = roadnets.load(cache_dir=cache_dir)
    density = CandidateDensity.of(net)
    print("| points | max_candidates | search_radius_m | sigma_m | measured MB | model MB |")
    print("|---|---|---|---|---|---|")
    for n, k, r, s in COST_CONFIGS:
        out = subprocess.run(
            [sys.executable, __file__, "--one-cost", f"{n},{k},{r},{s}", "--cache", cache_dir],
            capture_output=True,
            text=True,
            check=True,
        )
        measured = json.loads(out.stdout.strip().splitlines()[-1])["peak_mb"]
        trace = mapmatch.Trace(
            time=np.arange(n, dtype=float), lon=7.42 + np.arange(n) * 1e-5, lat=np.full(n, 43.73)
        )
        options = {"max_candidates": k, "search_radius_m": r, "sigma_m": s}
        model = match_cost(trace, mapmatch.MatchConfig().replace(options), density).megabytes
        print(f"| {n} | {k} | {r:g} | {s:g} | {measured:.0f} | {model:.0f} |", flush=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument("--clients", type=int, default=16, help="concurrent clients (16)")
    parser.add_argument("--duration-s", type=float, default=30.0, help="seconds per run (30)")
    parser.add_argument("--warmup-s", type=float, default=3.0, help="unmeasured seconds first (3)")
    parser.add_argument(
        "--workers", type=int, nargs="+", default=[1, 2], help="worker counts (1 2)"
    )
    parser.add_argument("--traces", type=int, default=40, help="distinct traces sent (40)")
    parser.add_argument(
        "--client",
        nargs="+",
        choices=sorted(CLIENTS),
        default=["httpx", "raw"],
        help="HTTP clients to load the server with: httpx, and a lean one on asyncio streams",
    )
    parser.add_argument(
        "--match-threads", type=int, default=None, help="matches at once per worker (serve's)"
    )
    parser.add_argument(
        "--abuse", action="store_true", help="also run the load beside 4 hostile clients"
    )
    parser.add_argument(
        "--in-process",
        action="store_true",
        help="also run the service's handler in N processes without HTTP, for the ratio",
    )
    parser.add_argument(
        "--cost-model", action="store_true", help="measure api.costs against peak RSS, then exit"
    )
    parser.add_argument("--one-cost", help=argparse.SUPPRESS)
    parser.add_argument("--cache", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.match_threads:
        MATCH_THREADS.append(args.match_threads)
    if args.one_cost:
        n, k, r, s = args.one_cost.split(",")
        _one_cost(int(n), int(k), float(r), float(s), args.cache)
        return 0
    if args.cost_model:
        with tempfile.TemporaryDirectory(prefix="bench-cost-") as cache_dir:
            cost_model(cache_dir)
        return 0
    with tempfile.TemporaryDirectory(prefix="bench-service-") as cache_dir:
        bodies = make_bodies(args.traces, cache_dir)
        results: list[Any] = [
            run(w, c, args, bodies, cache_dir) for c in args.client for w in args.workers
        ]
        local = (
            {w: in_process(w, args, bodies, cache_dir) for w in args.workers}
            if args.in_process
            else {}
        )
    print(
        f"\n{len(bodies)} simulated {POINTS}-point 1 Hz traces on the embedded network, JSON "
        f"bodies, {args.clients} clients on loopback, {os.cpu_count()} CPUs shared by clients "
        "and server.\n"
    )
    print(HEADER)
    for result in results:
        print(result.row())
    if local:
        print(
            f"\nIn-process: N processes each running the service's handler (JSON body -> "
            f"GeoJSON) on the same bodies, no HTTP, no client ({args.duration_s:.0f} s):\n"
        )
        print(
            "The next three columns count requests per CPU second of the server's processes "
            "(HTTP) and of the in-process ones: the cost of the HTTP path itself, whatever "
            "share of the cores the clients take. The last three split the server's CPU per "
            "request into its event loops' (HTTP, framework, answer sent) and its match "
            "threads', against the in-process handler's.\n"
        )
        print(
            "| workers | client | HTTP req/s | in-process req/s | HTTP / in-process | "
            "HTTP req per server CPU-s | in-process req per CPU-s | HTTP / in-process per CPU "
            "| event loop ms/req | match threads ms/req | in-process ms/req |"
        )
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        for result in results:
            rate = result.requests / result.duration_s
            base, base_cpu = local[result.workers]
            per_cpu = result.requests / result.server_cpu_s
            loop_ms = 1000.0 * result.loop_cpu_s / result.requests
            match_ms = 1000.0 * (result.server_cpu_s - result.loop_cpu_s) / result.requests
            print(
                f"| {result.workers} | {result.client} | {rate:.1f} | {base:.1f} | "
                f"{100 * rate / base:.0f} % | {per_cpu:.1f} | {base_cpu:.1f} | "
                f"{100 * per_cpu / base_cpu:.0f} % | {loop_ms:.2f} | {match_ms:.2f} | "
                f"{1000.0 / base_cpu:.2f} |"
            )
    if ABUSE:
        print(f"\nThe same load with 4 hostile clients beside it ({args.duration_s:.0f} s):\n")
        print(ABUSE_HEADER)
        for abuse in ABUSE:
            print(abuse.row())
    bad = [r for r in results if r.errors] + [a for a in ABUSE if a.errors]
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
