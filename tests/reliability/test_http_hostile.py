"""Hostile input and slow clients against a real ``mapmatch serve`` on loopback (issue 14).

Every case ends in a 4xx with a small error body, the server's memory stays bounded (its RSS
read from /proc, the limit generous against noise but far below what the attack used to
cost), and ``/readyz`` answers 200 afterwards. Bounded: each case sends at most a few MB and
waits a few seconds.
"""

from __future__ import annotations

import gzip
import io
import json
import os
import socket
import subprocess
import sys
import time
import zlib
from pathlib import Path
from typing import TYPE_CHECKING, Any

import httpx
import numpy as np
import pytest

from mapmatch.evaluation.simulate import SimulationConfig, simulate_trips

if TYPE_CHECKING:
    from collections.abc import Iterator

    import roadnets

ROOT = Path(__file__).resolve().parents[2]
HEADER_TIMEOUT_S = 1.0
BODY_TIMEOUT_S = 2.0
RSS_GROWTH_MB = 300.0
ERROR_BODY_BYTES = 8_192
#: ``mapmatch serve ARGS`` with only the serve sub-command loaded (same add_parser and run).
LAUNCHER = """
import argparse, sys
from mapmatch.cli import serve
parser = argparse.ArgumentParser(prog="mapmatch")
serve.add_parser(parser.add_subparsers(dest="command", required=True))
args = parser.parse_args(sys.argv[1:])
sys.exit(args.run(args))
"""


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    msg = f"no VmRSS in /proc/{pid}/status"
    raise AssertionError(msg)


class Server:
    """A ``mapmatch serve`` subprocess (one worker: its pid is the one that matches)."""

    def __init__(self, process: subprocess.Popen[bytes], url: str, log: Path) -> None:
        self.process, self.url, self.log = process, url, log

    @property
    def rss_mb(self) -> float:
        return _rss_mb(self.process.pid)

    def healthy(self) -> None:
        assert self.process.poll() is None, self.log.read_text()[-3000:]
        ready = httpx.get(self.url + "/readyz", timeout=10)
        assert ready.status_code == 200, ready.text


@pytest.fixture(scope="module")
def server(cache_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    log = tmp_path_factory.mktemp("hostile") / "server.log"
    port = _free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("MAPMATCH_")}
    env.pop("PROMETHEUS_MULTIPROC_DIR", None)
    env.update(
        MAPMATCH_HEADER_TIMEOUT_S=str(HEADER_TIMEOUT_S),
        MAPMATCH_BODY_TIMEOUT_S=str(BODY_TIMEOUT_S),
        MAPMATCH_ACCESS_LOG="true",
    )
    command = [sys.executable, "-c", LAUNCHER, "serve", "--port", str(port)]
    command += ["--cache-dir", str(cache_dir), "--log-level", "info"]
    with log.open("wb") as sink:
        process = subprocess.Popen(command, stdout=sink, stderr=sink, env=env, cwd=ROOT)
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 90
        while True:
            assert process.poll() is None, log.read_text()[-3000:]
            assert time.monotonic() < deadline, log.read_text()[-3000:]
            try:
                if httpx.get(url + "/readyz", timeout=2).status_code == 200:
                    break
            except httpx.TransportError:
                pass
            time.sleep(0.1)
        yield Server(process, url, log)
    finally:
        process.terminate()
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


@pytest.fixture(scope="module")
def csv_trip(default_net: roadnets.RoadNetwork) -> bytes:
    cfg = SimulationConfig(interval_s=1.0, noise_m=4.0, route_length_m=900.0)
    trip = next(t for t in simulate_trips(default_net, cfg, count=4, seed=5) if len(t.trace) > 50)
    frame = trip.trace.to_dataframe().drop(columns="odometer", errors="ignore")
    return frame.to_csv(index=False, float_format="%.7f").encode()


def _post(server: Server, content: bytes, headers: dict[str, str], **kw: Any) -> httpx.Response:
    return httpx.post(server.url + "/v1/match", content=content, headers=headers, timeout=60, **kw)


def _refused(answer: httpx.Response, status: int, code: str) -> dict[str, Any]:
    assert answer.status_code == status, answer.text[:2000]
    assert len(answer.content) <= ERROR_BODY_BYTES, len(answer.content)
    error: dict[str, Any] = answer.json()["error"]
    assert error["code"] == code, error
    return error


def _bounded(server: Server, before_mb: float) -> None:
    grown = server.rss_mb - before_mb
    assert grown < RSS_GROWTH_MB, f"server RSS grew by {grown:.0f} MB"
    server.healthy()


def _gzip_of_repeated(line: bytes, count: int, head: bytes = b"") -> bytes:
    """gzip of ``head`` + ``line`` x ``count``, compressed in pieces (never held inflated)."""
    out = io.BytesIO()
    with gzip.GzipFile(fileobj=out, mode="wb", compresslevel=9) as gz:
        gz.write(head)
        block = line * 10_000
        for _ in range(count // 10_000):
            gz.write(block)
    return out.getvalue()


# --------------------------------------------------------------------------- bombs


def test_gzip_csv_bomb_is_refused_while_it_inflates(server: Server) -> None:
    before = server.rss_mb
    row = b"1700000000,43.7384,7.4246\n"
    bomb = _gzip_of_repeated(row, 20_000_000, head=b"time,lat,lon\n")  # ~520 MB inflated
    assert len(bomb) < 2_000_000
    answer = _post(server, bomb, {"content-type": "text/csv", "content-encoding": "gzip"})
    error = _refused(answer, 413, "too_many_points")
    assert "lines" in error["message"]
    _bounded(server, before)


def test_gzip_file_sent_as_plain_csv_is_inflated_under_the_same_limit(server: Server) -> None:
    before = server.rss_mb
    bomb = _gzip_of_repeated(b"0" * 100, 5_000_000)  # 500 MB of one line
    answer = _post(server, bomb, {"content-type": "text/csv"})
    error = _refused(answer, 413, "too_many_columns")  # its "header" never ends
    assert "header" in error["message"]
    bomb = _gzip_of_repeated(b"0\n", 100_000_000)
    _refused(_post(server, bomb, {"content-type": "text/csv"}), 413, "too_many_points")
    _bounded(server, before)


def test_gzip_json_bomb_is_refused_at_the_decompressed_limit(server: Server) -> None:
    before = server.rss_mb
    bomb = _gzip_of_repeated(b" " * 1000, 500_000, head=b'{"points": [')  # 500 MB of spaces
    answer = _post(server, bomb, {"content-type": "application/json", "content-encoding": "gzip"})
    error = _refused(answer, 413, "body_too_large")
    assert "decompresses" in error["message"]
    _bounded(server, before)


def test_corrupt_gzip_and_unknown_encodings_are_refused(server: Server, csv_trip: bytes) -> None:
    broken = gzip.compress(csv_trip)[:-20]
    headers = {"content-type": "text/csv", "content-encoding": "gzip"}
    _refused(_post(server, broken, headers), 400, "invalid_encoding")
    headers = {"content-type": "text/csv", "content-encoding": "br"}
    error = _refused(_post(server, csv_trip, headers), 415, "unsupported_encoding")
    assert error["field"] == "Content-Encoding"


def test_large_plain_csv_answers_413_not_an_error_per_row(server: Server) -> None:
    before = server.rss_mb
    rows = b"".join(b"%d,43.7384,7.4246\n" % (1_700_000_000 + i) for i in range(900_000))
    body = b"time,lat,lon\n" + rows[: 9_900_000 - 13]
    _refused(_post(server, body, {"content-type": "text/csv"}), 413, "too_many_points")
    _bounded(server, before)


def test_every_row_bad_answers_a_few_kb(server: Server) -> None:
    rows = b"".join(b"%d,95.0,7.4246\n" % (1_700_000_000 + i) for i in range(50_000))
    answer = _post(server, b"time,lat,lon\n" + rows, {"content-type": "text/csv"})
    error = _refused(answer, 422, "invalid_trace")
    assert len(error["rows"]) == 100
    assert error["rows_total"] == 50_000
    assert "more" in error["message"]


# --------------------------------------------------------------------------- parsers


def test_wide_csv_is_refused_before_parsing(server: Server) -> None:
    before = server.rss_mb
    header = b",".join(b"c%d" % i for i in range(100_000)) + b"\n"
    row = b",".join(b"1" for _ in range(100_000)) + b"\n"
    answer = _post(server, header + row * 2, {"content-type": "text/csv"})
    error = _refused(answer, 413, "too_many_columns")
    assert "256" in error["message"]
    # a narrow header with one very wide row: the parser's own error, a 422
    wide_row = b"time,lat,lon\n1700000000,43.7,7.42\n" + row
    _refused(_post(server, wide_row, {"content-type": "text/csv"}), 422, "invalid_body")
    _bounded(server, before)


@pytest.mark.parametrize(
    ("media", "status", "code"),
    [("application/json", 400, "invalid_json"), ("application/geo+json", 422, "invalid_body")],
)
def test_deep_nesting_is_refused(server: Server, media: str, status: int, code: str) -> None:
    deep = b'{"type": "FeatureCollection", "features": ' + b"[" * 3000 + b"]" * 3000 + b"}"
    _refused(_post(server, deep, {"content-type": media}), status, code)
    server.healthy()


@pytest.mark.parametrize("digits", [5000, 4000])
@pytest.mark.parametrize("media", ["application/json", "application/geo+json"])
def test_huge_numbers_are_refused(server: Server, media: str, digits: int) -> None:
    number = b"7" * digits
    if media == "application/json":
        body = (
            b'{"points": [{"time": 0, "lat": 43.7, "lon": %s},'
            b' {"time": 1, "lat": 43.7, "lon": 7.4}]}'
        )
    else:
        body = (
            b'{"type": "FeatureCollection", "features": ['
            b'{"type": "Feature", "geometry": {"type": "Point", "coordinates": [%s, 43.7]},'
            b' "properties": {"time": 0}},'
            b'{"type": "Feature", "geometry": {"type": "Point", "coordinates": [7.4, 43.7]},'
            b' "properties": {"time": 1}}]}'
        )
    answer = _post(server, body % number, {"content-type": media})
    assert 400 <= answer.status_code < 500, answer.text
    assert answer.json()["error"]["code"] in ("invalid_json", "invalid_trace", "invalid_body")
    server.healthy()


# --------------------------------------------------------------------------- cost model


def test_options_that_would_exhaust_memory_are_refused_before_matching(server: Server) -> None:
    before = server.rss_mb
    rng = np.random.default_rng(1)
    lon = 7.4246 + np.cumsum(rng.normal(0, 5e-5, 10_000))
    lat = 43.7384 + np.cumsum(rng.normal(0, 5e-5, 10_000))
    points = [
        {"time": 1_700_000_000 + i, "lat": float(y), "lon": float(x)}
        for i, (x, y) in enumerate(zip(lon, lat, strict=True))
    ]
    options = {"search_radius_m": 200, "max_candidates": 64, "sigma_m": 50}
    answer = httpx.post(
        server.url + "/v1/match", json={"points": points, "options": options}, timeout=60
    )
    error = _refused(answer, 413, "over_budget")
    assert error["field"] == "options.max_candidates"
    assert "MB" in error["message"]
    _bounded(server, before)
    # the same trace with the server's own options is within the budget
    answer = httpx.post(server.url + "/v1/match", json={"points": points[:2000]}, timeout=60)
    assert answer.status_code in (200, 422), answer.text[:500]


# --------------------------------------------------------------------------- slow clients


def _connect(server: Server) -> socket.socket:
    host, port = server.url.removeprefix("http://").split(":")
    return socket.create_connection((host, int(port)), timeout=30)


def _read_all(sock: socket.socket) -> bytes:
    chunks = []
    while True:
        try:
            chunk = sock.recv(65536)
        except (ConnectionResetError, TimeoutError):
            break
        if not chunk:
            break
        chunks.append(chunk)
    return b"".join(chunks)


def test_a_trickled_request_head_is_cut_off(server: Server) -> None:
    sock = _connect(server)
    with sock:
        sock.sendall(b"POST /v1/match HTTP/1.1\r\nHost: x\r\n")
        time.sleep(HEADER_TIMEOUT_S / 2)
        sock.sendall(b"X-A: 1\r\n")  # still trickling when the deadline passes
        answer = _read_all(sock)
    assert answer.startswith(b"HTTP/1.1 408"), answer[:200]
    assert b"header_timeout" in answer
    server.healthy()


def test_an_idle_connection_is_closed(server: Server) -> None:
    with _connect(server) as sock:
        started = time.monotonic()
        answer = _read_all(sock)  # the server ends it: recv returns b""
        assert time.monotonic() - started < 30
    assert answer == b"" or answer.startswith(b"HTTP/1.1 408")


@pytest.mark.parametrize("declared", [True, False])
def test_a_body_that_never_completes_is_cut_off(server: Server, declared: bool) -> None:
    with _connect(server) as sock:
        length = b"content-length: 1000\r\n" if declared else b"transfer-encoding: chunked\r\n"
        sock.sendall(
            b"POST /v1/match HTTP/1.1\r\nhost: x\r\ncontent-type: text/csv\r\n" + length + b"\r\n"
        )
        sock.sendall(b"time,lat,lon\n" if declared else b"d\r\ntime,lat,lon\n\r\n")
        answer = _read_all(sock)  # and nothing more is sent
    assert answer.startswith(b"HTTP/1.1 408"), answer[:300]
    assert b"body_timeout" in answer
    server.healthy()


def test_many_trickling_connections_do_not_starve_real_clients(
    server: Server, csv_trip: bytes
) -> None:
    socks = []
    try:
        for _ in range(300):
            sock = _connect(server)
            sock.sendall(b"POST /v1/match HTTP/1.1\r\n")
            socks.append(sock)
        answer = _post(server, csv_trip, {"content-type": "text/csv"})
        assert answer.status_code == 200, answer.text[:500]
        assert httpx.get(server.url + "/healthz", timeout=10).status_code == 200
    finally:
        for sock in socks:
            sock.close()
    server.healthy()


# --------------------------------------------------------------------------- small things


def test_json_with_a_byte_order_mark_and_gzip_json_are_read(
    server: Server, csv_trip: bytes
) -> None:
    lines = csv_trip.decode().splitlines()
    names = lines[0].split(",")
    points = [dict(zip(names, map(float, line.split(",")), strict=True)) for line in lines[1:]]
    body = json.dumps({"points": points}).encode()
    answer = _post(server, b"\xef\xbb\xbf" + body, {"content-type": "application/json"})
    assert answer.status_code == 200, answer.text[:500]
    packed = gzip.compress(body)
    headers = {"content-type": "application/json", "content-encoding": "gzip"}
    unpacked = _post(server, packed, headers)
    assert unpacked.status_code == 200, unpacked.text[:500]
    assert unpacked.json()["features"] == answer.json()["features"]
    deflated = zlib.compress(body)
    headers = {"content-type": "application/json", "content-encoding": "deflate"}
    _refused(_post(server, deflated, headers), 415, "unsupported_encoding")


def test_a_repeated_query_option_names_itself(server: Server, csv_trip: bytes) -> None:
    answer = _post(
        server, csv_trip, {"content-type": "text/csv"}, params=[("sigma_m", 4), ("sigma_m", 9)]
    )
    error = _refused(answer, 422, "repeated_parameter")
    assert error["field"] == "query.sigma_m"
    band = [("distance_band", -0.5), ("distance_band", 0.5)]  # a pair: two values
    assert _post(server, csv_trip, {"content-type": "text/csv"}, params=band).status_code == 200


def test_every_log_line_is_json(server: Server, csv_trip: bytes) -> None:
    # a short fused distance makes the matcher log a warning of its own
    answer = _post(
        server, csv_trip, {"content-type": "text/csv"}, params={"fused_distance_m": 10.0}
    )
    assert answer.status_code == 200, answer.text[:500]
    time.sleep(0.5)
    lines = [line for line in server.log.read_text().splitlines() if line.strip()]
    assert lines
    parsed = [json.loads(line) for line in lines]  # fails on the first plain-text line
    loggers = {line["logger"] for line in parsed}
    assert "api.access" in loggers
    assert any(line["level"] == "warning" and line["logger"] != "api.access" for line in parsed)


def test_a_client_that_leaves_mid_body_is_not_a_server_error(server: Server) -> None:
    for _ in range(3):
        with _connect(server) as sock:
            sock.sendall(
                b"POST /v1/match HTTP/1.1\r\nhost: x\r\ncontent-type: text/csv\r\n"
                b"content-length: 5000\r\n\r\ntime,lat,lon\n1700000000,43.7,7.42\n"
            )
            time.sleep(0.2)
    time.sleep(0.5)
    text = httpx.get(server.url + "/metrics", timeout=10).text
    fives = [line for line in text.splitlines() if 'status="5' in line and "_total" in line]
    assert [line for line in fives if 'route="/readyz"' not in line] == []
    assert "incomplete_body" in text
    server.healthy()
