"""Health, readiness, auth, metrics, access logs, time budget and workers, on real servers."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import re
import signal
import socket
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import pytest

from api.errors import NotReadyError, ServiceError, UnknownNetworkError
from api.networks import NetworkRegistry
from api.server import listening_sockets
from api.service import SHORT_JOB_BYTES
from api.settings import Settings
from mapmatch.machine import available_cores


def _metric(text: str, name: str, **labels: str) -> float:
    """The value of one sample of the exposition text (0 when absent)."""
    for line in text.splitlines():
        if not line.startswith(name + "{") and not line.startswith(name + " "):
            continue
        found = dict(re.findall(r'(\w+)="([^"]*)"', line.split("}")[0])) if "{" in line else {}
        if all(found.get(k) == v for k, v in labels.items()):
            return float(line.rsplit(" ", 1)[1])
    return 0.0


def test_health_and_readiness(client: httpx.Client) -> None:
    assert client.get("/healthz").json() == {"status": "alive"}
    ready = client.get("/readyz")
    assert ready.status_code == 200
    assert ready.json() == {"status": "ready", "networks": ["monaco_2020", "west-oakland_us"]}


def test_auth_off_needs_no_token(client: httpx.Client) -> None:
    assert client.get("/v1/networks").status_code == 200
    assert "securitySchemes" not in client.get("/openapi.json").json()["components"]


@pytest.mark.parametrize(
    ("path", "method"),
    [
        ("/v1/networks", "GET"),
        ("/readyz", "GET"),
        ("/metrics", "GET"),
        ("/openapi.json", "GET"),
        ("/docs", "GET"),
        ("/v1/match", "POST"),
    ],
)
def test_token_is_required_everywhere_but_healthz(
    secured, token: str, path: str, method: str
) -> None:
    url = secured.base_url + path
    missing = httpx.request(method, url)
    assert missing.status_code == 401
    assert missing.headers["www-authenticate"].startswith("Bearer")
    assert missing.json()["error"]["code"] == "unauthorized"
    wrong = httpx.request(method, url, headers={"Authorization": "Bearer nope"})
    assert wrong.status_code == 401
    assert "wrong" in wrong.json()["error"]["message"]
    right = httpx.request(method, url, headers={"Authorization": f"Bearer {token}"})
    assert right.status_code != 401


def test_token_server_matches_and_documents_the_scheme(secured, token: str, trip, bodies) -> None:
    auth = {"Authorization": f"Bearer {token}"}
    assert httpx.get(secured.base_url + "/healthz").status_code == 200
    answer = httpx.post(
        secured.base_url + "/v1/match", json={"points": bodies.points(trip.trace)}, headers=auth
    )
    assert answer.status_code == 200, answer.text
    spec = httpx.get(secured.base_url + "/openapi.json", headers=auth).json()
    assert spec["components"]["securitySchemes"]["bearerAuth"]["scheme"] == "bearer"
    assert spec["paths"]["/healthz"]["get"]["security"] == []


def test_metrics_count_requests_points_and_latency(client: httpx.Client, trips, bodies) -> None:
    before = client.get("/metrics").text
    for t in trips:
        assert client.post("/v1/match", json={"points": bodies.points(t.trace)}).status_code == 200
    client.post("/v1/match", json={"points": []})
    after = client.get("/metrics").text
    ok = {"route": "/v1/match", "method": "POST", "status": "200"}
    name = "mapmatch_http_requests_total"
    assert _metric(after, name, **ok) - _metric(before, name, **ok) == len(trips)
    bad = {"route": "/v1/match", "method": "POST", "status": "422"}
    assert _metric(after, name, **bad) - _metric(before, name, **bad) == 1
    points = "mapmatch_points_matched_total"
    assert _metric(after, points) - _metric(before, points) == sum(len(t.trace) for t in trips)
    latency = "mapmatch_http_request_duration_seconds_count"
    grown = _metric(after, latency, route="/v1/match", status="200") - _metric(
        before, latency, route="/v1/match", status="200"
    )
    assert grown == len(trips)
    assert "mapmatch_breaks_total" in after
    outcome = {"outcome": "invalid_trace"}
    assert _metric(after, "mapmatch_matches_total", **outcome) >= 1


def test_access_log_has_one_json_line_per_request(live, client: httpx.Client, trip, bodies) -> None:
    request_id = f"test-{time.time_ns()}"
    body = {"points": bodies.points(trip.trace), "trace_id": "logged"}
    answer = client.post("/v1/match", json=body, headers={"X-Request-ID": request_id})
    assert answer.headers["x-request-id"] == request_id
    deadline = time.monotonic() + 10
    lines: list[dict[str, Any]] = []
    while time.monotonic() < deadline and not lines:
        lines = [
            json.loads(line)
            for line in live.log_lines()
            if request_id in line and line.startswith("{")
        ]
        time.sleep(0.05)
    assert len(lines) == 1
    line = lines[0]
    assert line["logger"] == "api.access"
    assert (line["route"], line["status"], line["method"]) == ("/v1/match", 200, "POST")
    assert (line["points"], line["trace_id"], line["network"]) == (
        len(trip.trace),
        "logged",
        "monaco_2020",
    )
    assert line["duration_ms"] > 0


def test_a_match_past_its_budget_answers_504_and_frees_the_worker(
    start_thread_server, cache_dir: Path, slow_trace, trip, bodies
) -> None:
    settings = Settings(
        cache_dir=str(cache_dir),
        time_budget_s=0.05,
        match_threads=1,
        max_queued=0,
        access_log=False,
    )
    with start_thread_server(settings) as server:
        url = server.base_url
        slow = httpx.post(url + "/v1/match", json={"points": bodies.points(slow_trace)}, timeout=60)
        assert slow.status_code == 504, slow.text
        assert slow.json()["error"]["code"] == "timeout"
        # the event loop answers other routes meanwhile, and the abandoned job stops at its
        # next check of the deadline and gives its thread back
        assert httpx.get(url + "/healthz").status_code == 200
        runner = server.app.state.service.runner
        deadline = time.monotonic() + 60
        while runner.in_system and time.monotonic() < deadline:
            time.sleep(0.05)
        assert runner.in_system == 0


def test_waiting_matches_are_bounded(
    start_thread_server, cache_dir: Path, slow_trace, trip, bodies
) -> None:
    settings = Settings(cache_dir=str(cache_dir), match_threads=1, max_queued=0, access_log=False)
    with start_thread_server(settings) as server:
        url = server.base_url + "/v1/match"
        answers: list[httpx.Response] = []
        first = threading.Thread(
            target=lambda: answers.append(
                httpx.post(url, json={"points": bodies.points(slow_trace)}, timeout=60)
            )
        )
        first.start()
        runner = server.app.state.service.runner
        deadline = time.monotonic() + 30
        while runner.in_system == 0 and time.monotonic() < deadline:
            time.sleep(0.001)
        second = httpx.post(url, json={"points": bodies.points(trip.trace)}, timeout=60)
        first.join()
        assert second.status_code == 503
        assert second.json()["error"]["code"] == "overloaded"
        assert answers[0].status_code == 200  # the first one was not disturbed


def test_a_long_trace_runs_beside_the_short_ones_which_share_one_thread(
    start_thread_server, cache_dir: Path, slow_trace, trip, bodies
) -> None:
    cores = available_cores()  # a worker per core: one short match at a time
    settings = Settings(
        cache_dir=str(cache_dir),
        match_threads=2,
        max_queued=8,
        worker_processes=cores,
        access_log=False,
    )
    slow_body = json.dumps({"points": bodies.points(slow_trace)}).encode()
    short_body = json.dumps({"points": bodies.points(trip.trace)}).encode()
    assert len(short_body) <= SHORT_JOB_BYTES < len(slow_body)
    with start_thread_server(settings) as server:
        url = server.base_url + "/v1/match"
        headers = {"content-type": "application/json"}
        slow: list[httpx.Response] = []
        post = httpx.post
        first = threading.Thread(
            target=lambda: slow.append(post(url, content=slow_body, headers=headers, timeout=60))
        )
        first.start()
        runner = server.app.state.service.runner
        deadline = time.monotonic() + 30
        while runner.in_system == 0 and time.monotonic() < deadline:
            time.sleep(0.001)
        for _ in range(3):  # answered while the long one still runs, in the short lane
            answer = httpx.post(url, content=short_body, headers=headers, timeout=60)
            assert answer.status_code == 200, answer.text[:300]
        names = {t.name.rsplit("_", 1)[0] for t in threading.enumerate()}
        long_running = first.is_alive()
        first.join()
        assert slow[0].status_code == 200
        assert long_running  # the short ones did not wait for it
        assert {"match", "match-long"} <= names


def test_a_network_that_fails_to_load_keeps_the_process_alive(
    start_thread_server, tmp_path: Path, trip, bodies
) -> None:
    missing = tmp_path / "nowhere.osm.pbf"
    settings = Settings(networks=(str(missing),), cache_dir=str(tmp_path), access_log=False)
    with start_thread_server(settings, wait=False) as server:
        url = server.base_url
        deadline = time.monotonic() + 30
        ready = httpx.get(url + "/readyz")
        while ready.json()["error"]["code"] == "not_ready" and time.monotonic() < deadline:
            time.sleep(0.05)
            ready = httpx.get(url + "/readyz")
        assert ready.status_code == 503
        assert ready.json()["error"]["code"] == "network_unavailable"
        assert "nowhere.osm.pbf" in ready.json()["error"]["message"]
        assert httpx.get(url + "/healthz").status_code == 200
        match = httpx.post(url + "/v1/match", json={"points": bodies.points(trip.trace)})
        assert match.status_code == 503
        assert match.json()["error"]["code"] == "network_unavailable"


def test_registry_is_not_ready_until_loaded(cache_dir: Path) -> None:
    registry = NetworkRegistry((), str(cache_dir))
    with pytest.raises(NotReadyError):
        registry.get(None)
    registry.load_all()
    assert registry.get(None).network_id == "monaco_2020"
    assert registry.get("monaco_2020").from_cache
    with pytest.raises(UnknownNetworkError, match="monaco_2020"):
        registry.get("atlantis")


def test_two_workers_share_one_metrics_view(
    start_serve_process, cache_dir: Path, tmp_path: Path, trip, bodies
) -> None:
    args = ["--workers", "2", "--cache-dir", str(cache_dir), "--no-access-log"]
    with start_serve_process(args, tmp_path / "workers.log") as server:
        body = {"points": bodies.points(trip.trace)}
        url = server.base_url + "/v1/match"
        done = 0
        deadline = time.monotonic() + 60
        while done < 12 and time.monotonic() < deadline:
            # a new connection each: the kernel spreads them over the workers; a worker still
            # warming up answers 503 not_ready with Retry-After, as a client would retry
            answer = httpx.post(url, json=body, timeout=60)
            if answer.status_code == 503 and answer.json()["error"]["code"] == "not_ready":
                time.sleep(0.1)
                continue
            assert answer.status_code == 200, answer.text
            done += 1
        for _ in range(3):  # whichever worker answers the scrape, it reports all of them
            text = httpx.get(server.base_url + "/metrics").text
            ok = {"route": "/v1/match", "method": "POST", "status": "200"}
            assert _metric(text, "mapmatch_http_requests_total", **ok) == 12


def test_concurrent_matches_do_not_crash_the_worker(
    live, client: httpx.Client, trips, bodies
) -> None:
    # regression: match threads sharing one R-tree (libspatialindex) segfaulted the worker
    payloads = [{"points": bodies.points(t.trace)} for t in trips]
    statuses: list[int] = []

    def hammer(seed: int) -> None:
        with httpx.Client(base_url=live.base_url, timeout=60) as own:
            for i in range(15):
                statuses.append(own.post("/v1/match", json=payloads[(seed + i) % 3]).status_code)

    threads = [threading.Thread(target=hammer, args=(n,)) for n in range(16)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert statuses == [200] * 240
    assert live.process.poll() is None
    assert client.get("/healthz").status_code == 200


def test_each_worker_socket_gets_a_share_of_the_connections() -> None:
    # one socket per worker on one port (SO_REUSEPORT): the kernel spreads connections over
    # them, so keep-alive clients do not all land on the worker that woke first
    sockets = listening_sockets("127.0.0.1", 0, 2, 64)
    try:
        port = sockets[0].getsockname()[1]
        assert sockets[1].getsockname()[1] == port
        clients = [socket.create_connection(("127.0.0.1", port)) for _ in range(32)]
        accepted = []
        for sock in sockets:
            sock.setblocking(False)
            count = 0
            with contextlib.suppress(BlockingIOError):
                while True:
                    sock.accept()[0].close()
                    count += 1
            accepted.append(count)
        for c in clients:
            c.close()
        assert sum(accepted) == 32
        assert min(accepted) > 0, accepted  # all on one: 2 ** -31 by chance
    finally:
        for sock in sockets:
            sock.close()


def test_connections_on_the_worker_sockets_send_without_delay() -> None:
    # asyncio sets TCP_NODELAY on an accepted connection only when the listening socket
    # says it is TCP (proto IPPROTO_TCP); without it Nagle and the client's delayed ACK add
    # 40 ms to every answer written in more than one piece
    sockets = listening_sockets("127.0.0.1", 0, 2, 64)
    nodelay: list[int] = []

    async def connect_some(count: int) -> None:
        done = asyncio.Event()

        def accepted(_reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            sock = writer.get_extra_info("socket")
            nodelay.append(sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY))
            writer.close()
            if len(nodelay) == count:
                done.set()

        servers = [await asyncio.start_server(accepted, sock=sock) for sock in sockets]
        port = sockets[0].getsockname()[1]
        clients = [await asyncio.open_connection("127.0.0.1", port) for _ in range(count)]
        await asyncio.wait_for(done.wait(), timeout=30)
        for _reader, writer in clients:
            writer.close()
        for server in servers:
            server.close()

    try:
        assert [sock.proto for sock in sockets] == [socket.IPPROTO_TCP] * 2
        asyncio.run(connect_some(8))
    finally:
        for sock in sockets:
            sock.close()
    assert len(nodelay) == 8
    assert all(flag != 0 for flag in nodelay), nodelay


def test_a_taken_port_is_a_clear_error() -> None:
    taken = socket.socket()
    taken.bind(("127.0.0.1", 0))
    taken.listen()
    try:
        port = taken.getsockname()[1]
        with pytest.raises(ServiceError, match=f"cannot listen on 127.0.0.1:{port}"):
            listening_sockets("127.0.0.1", port, 2, 64)
    finally:
        taken.close()
    # a second server's SO_REUSEPORT sockets would share the port silently: refused too
    first = listening_sockets("127.0.0.1", 0, 2, 64)
    try:
        port = first[0].getsockname()[1]
        with pytest.raises(ServiceError, match=f"cannot listen on 127.0.0.1:{port}"):
            listening_sockets("127.0.0.1", port, 2, 64)
    finally:
        for sock in first:
            sock.close()


def _worker_pids(parent: int) -> set[int]:
    """The ``mapmatch serve`` workers of a supervisor (its spawned children)."""
    found = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        with contextlib.suppress(OSError):
            fields = stat.read_text().rsplit(")", 1)[1].split()
            cmdline = (stat.parent / "cmdline").read_bytes()
            if int(fields[1]) == parent and b"spawn_main" in cmdline:
                found.add(int(stat.parent.name))
    return found


def test_a_worker_that_dies_is_replaced_on_its_socket(
    start_serve_process, cache_dir: Path, tmp_path: Path, trip, bodies
) -> None:
    args = ["--workers", "2", "--cache-dir", str(cache_dir), "--no-access-log"]
    with start_serve_process(args, tmp_path / "workers.log") as server:
        before = _worker_pids(server.process.pid)
        assert len(before) == 2
        victim = min(before)
        os.kill(victim, signal.SIGKILL)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            now = _worker_pids(server.process.pid)
            if len(now) == 2 and victim not in now:
                break
            time.sleep(0.2)
        else:
            pytest.fail(f"no worker replaced {victim}")
        body = {"points": bodies.points(trip.trace)}
        answered = 0
        while answered < 16 and time.monotonic() < deadline:
            # a new connection each: some land on the dead worker's socket, which its
            # replacement serves (a socket without a worker would leave them hanging)
            answer = httpx.post(server.base_url + "/v1/match", json=body, timeout=30)
            if answer.status_code == 503 and answer.json()["error"]["code"] == "not_ready":
                time.sleep(0.1)
                continue
            assert answer.status_code == 200, answer.text
            answered += 1
        assert answered == 16
