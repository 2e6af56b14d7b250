"""Real servers on loopback for the API tests: ``mapmatch serve`` subprocesses and in-thread
uvicorn servers, plus simulated traces on the embedded network."""

from __future__ import annotations

import contextlib
import json
import os
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import httpx
import numpy as np
import pytest
import uvicorn

import roadnets
from api.main import create_app
from api.settings import Settings
from mapmatch import Trace
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trips

if TYPE_CHECKING:
    from collections.abc import Iterator

    from fastapi import FastAPI

    from mapmatch.evaluation.simulate import SimulatedTrip

DATA = Path(__file__).resolve().parents[1] / "data"
ROOT = Path(__file__).resolve().parents[2]
READY_TIMEOUT_S = 90.0

#: Runs ``mapmatch serve ARGS``: through the full CLI when every sub-command module exists,
#: else through a parser holding only ``serve`` (same add_parser/run; other sub-commands are
#: still being written by others).
LAUNCHER = """
import argparse, importlib.util, sys
from mapmatch import cli
from mapmatch.cli import serve
if all(importlib.util.find_spec(f"mapmatch.cli.{name}") for name in cli.COMMANDS):
    sys.exit(cli.main(sys.argv[1:]))
parser = argparse.ArgumentParser(prog="mapmatch")
serve.add_parser(parser.add_subparsers(dest="command", required=True))
args = parser.parse_args(sys.argv[1:])
sys.exit(args.run(args))
"""
TOKEN = "s3cret-token"


def free_port() -> int:
    """A TCP port nobody listens on at the moment (loopback)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def wait_ready(
    base_url: str,
    *,
    headers: dict[str, str] | None = None,
    log: Path | None = None,
    process: subprocess.Popen[bytes] | None = None,
) -> None:
    """Poll ``/readyz`` until it answers 200; fail with the server's log otherwise."""
    deadline = time.monotonic() + READY_TIMEOUT_S
    last = "no answer"
    while time.monotonic() < deadline:
        if process is not None and process.poll() is not None:
            last = f"the server exited with {process.returncode}"
            break
        try:
            answer = httpx.get(f"{base_url}/readyz", headers=headers, timeout=2.0)
            if answer.status_code == 200:
                return
            last = answer.text
        except httpx.TransportError as exc:
            last = repr(exc)
        time.sleep(0.1)
    text = log.read_text(errors="replace")[-4000:] if log and log.exists() else ""
    pytest.fail(f"server at {base_url} not ready after {READY_TIMEOUT_S} s: {last}\n{text}")


@dataclass
class ServeProcess:
    """A ``mapmatch serve`` subprocess and where its stderr (the JSON access log) goes."""

    base_url: str
    process: subprocess.Popen[bytes]
    log: Path

    def log_lines(self) -> list[str]:
        return self.log.read_text(errors="replace").splitlines()


@contextlib.contextmanager
def serve_process(
    args: list[str], log: Path, env: dict[str, str] | None = None
) -> Iterator[ServeProcess]:
    """Run ``python -m mapmatch serve ARGS --port P`` until the block ends."""
    port = free_port()
    full_env = {k: v for k, v in os.environ.items() if not k.startswith("MAPMATCH_")}
    full_env.pop("PROMETHEUS_MULTIPROC_DIR", None)
    full_env.update(env or {})
    command = [
        sys.executable,
        "-c",
        LAUNCHER,
        "serve",
        "--host",
        "127.0.0.1",
        "--port",
        str(port),
    ]
    with log.open("wb") as sink:
        process = subprocess.Popen(command + args, stdout=sink, stderr=sink, env=full_env, cwd=ROOT)
    base_url = f"http://127.0.0.1:{port}"
    try:
        wait_ready(base_url, log=log, process=process)
        yield ServeProcess(base_url, process, log)
    finally:
        process.terminate()
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def _wait_listening(base_url: str) -> None:
    deadline = time.monotonic() + READY_TIMEOUT_S
    while time.monotonic() < deadline:
        try:
            httpx.get(f"{base_url}/healthz", timeout=2.0)
            return
        except httpx.TransportError:
            time.sleep(0.05)
    pytest.fail(f"server at {base_url} does not answer")


@dataclass
class ThreadServer:
    """An in-process uvicorn server (its app reachable for white-box checks)."""

    base_url: str
    app: FastAPI


@contextlib.contextmanager
def thread_server(
    settings: Settings, *, ready_headers: dict[str, str] | None = None, wait: bool = True
) -> Iterator[ThreadServer]:
    """Serve ``create_app(settings)`` with uvicorn in a thread on a free loopback port."""
    app = create_app(settings)
    port = free_port()
    config = uvicorn.Config(
        app, host="127.0.0.1", port=port, ws="none", lifespan="on", log_level="warning"
    )
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, name=f"uvicorn-{port}", daemon=True)
    thread.start()
    base_url = f"http://127.0.0.1:{port}"
    try:
        if wait:
            wait_ready(base_url, headers=ready_headers)
        else:
            _wait_listening(base_url)
        yield ThreadServer(base_url, app)
    finally:
        server.should_exit = True
        thread.join(timeout=20)


# ----------------------------------------------------------------------------- data


@pytest.fixture(scope="session")
def trips(default_net: roadnets.RoadNetwork) -> list[SimulatedTrip]:
    """Simulated 1 Hz trips on the embedded network, each at least 60 points."""
    cfg = SimulationConfig(interval_s=1.0, noise_m=4.0, route_length_m=900.0)
    found = [t for t in simulate_trips(default_net, cfg, count=6, seed=11) if len(t.trace) >= 60]
    assert len(found) >= 3
    return found[:3]


@pytest.fixture(scope="session")
def trip(trips: list[SimulatedTrip]) -> SimulatedTrip:
    return trips[0]


def points_of(trace: Trace, *, odometer: bool = True) -> list[dict[str, Any]]:
    """The JSON ``points`` of a trace."""
    frame = trace.to_dataframe()
    if not odometer and "odometer" in frame:
        frame = frame.drop(columns="odometer")
    return [{k: float(v) for k, v in row.items()} for row in frame.to_dict("records")]


def long_trace(trips: list[SimulatedTrip], copies: int) -> Trace:
    """The trips driven one after the other ``copies`` times (a long, slow-to-match trace)."""
    parts = []
    offset = 0.0
    for _ in range(copies):
        for t in trips:
            frame = t.trace.to_dataframe()
            frame["time"] = frame["time"] - frame["time"].iloc[0] + offset
            offset = float(frame["time"].iloc[-1]) + 30.0
            parts.append(frame.drop(columns="odometer", errors="ignore"))
    import pandas as pd

    frame = pd.concat(parts, ignore_index=True)
    return Trace.from_dataframe(frame, trace_id="long")


@pytest.fixture(scope="session")
def slow_trace(trips: list[SimulatedTrip]) -> Trace:
    """
    About 21 000 points with breaks between the trips: a match of about half a second.

    Within the default memory budget (``api.costs`` puts it at about 1.9 of 2 GB).
    """
    trace = long_trace(trips, copies=36)
    assert len(trace) > 20_000
    assert np.all(np.diff(trace.time_s) > 0)
    return trace


# ----------------------------------------------------------------------------- bodies


def csv_body(trace: Trace) -> bytes:
    return trace.to_dataframe().to_csv(index=False, float_format="%.7f").encode()


def _iso(t: float) -> str:
    return datetime.fromtimestamp(t, tz=UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def gpx_body(trace: Trace, name: str = "gpx-trip") -> bytes:
    points = "".join(
        f'<trkpt lat="{lat:.7f}" lon="{lon:.7f}"><time>{_iso(t)}</time></trkpt>'
        for t, lon, lat in zip(trace.time_s, trace.lon, trace.lat, strict=True)
    )
    return (
        '<?xml version="1.0" encoding="UTF-8"?>'
        '<gpx version="1.1" creator="tests" xmlns="http://www.topografix.com/GPX/1/1">'
        f"<trk><name>{name}</name><trkseg>{points}</trkseg></trk></gpx>"
    ).encode()


def geojson_body(trace: Trace) -> bytes:
    features = [
        {
            "type": "Feature",
            "geometry": {"type": "Point", "coordinates": [float(lon), float(lat)]},
            "properties": {"time": float(t)},
        }
        for t, lon, lat in zip(trace.time_s, trace.lon, trace.lat, strict=True)
    ]
    return json.dumps({"type": "FeatureCollection", "features": features}).encode()


CONTENT_TYPES = {
    "csv": "text/csv",
    "gpx": "application/gpx+xml",
    "geojson": "application/geo+json",
}
BUILDERS = {"csv": csv_body, "gpx": gpx_body, "geojson": geojson_body}


@dataclass(frozen=True)
class Bodies:
    """Body builders, handed to tests as a fixture (test modules cannot import conftest)."""

    def points(self, trace: Trace, *, odometer: bool = True) -> list[dict[str, Any]]:
        return points_of(trace, odometer=odometer)

    def file(self, fmt: str, trace: Trace) -> tuple[bytes, dict[str, str]]:
        return BUILDERS[fmt](trace), {"content-type": CONTENT_TYPES[fmt]}

    def long(self, trips: list[SimulatedTrip], copies: int) -> Trace:
        return long_trace(trips, copies)


@pytest.fixture(scope="session")
def bodies() -> Bodies:
    return Bodies()


# ----------------------------------------------------------------------------- servers

#: Limits of the main test server: small, so that the limit tests send small bodies.
MAX_BODY_BYTES = 300_000
MAX_POINTS = 1_000


@pytest.fixture(scope="session")
def live(cache_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServeProcess]:
    """``mapmatch serve`` with the embedded network and West Oakland, small limits, no token."""
    log = tmp_path_factory.mktemp("live") / "server.log"
    args = [
        "--network",
        str(roadnets.default_network_path()),
        "--network",
        str(DATA / "west-oakland_us.osm.bz2"),
        "--cache-dir",
        str(cache_dir),
        "--max-body-bytes",
        str(MAX_BODY_BYTES),
        "--max-points",
        str(MAX_POINTS),
        "--log-level",
        "warning",
    ]
    with serve_process(args, log) as server:
        yield server


@pytest.fixture(scope="session")
def client(live: ServeProcess) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=live.base_url, timeout=60.0) as session:
        yield session


@pytest.fixture(scope="session")
def secured(cache_dir: Path) -> Iterator[ThreadServer]:
    """An in-thread server that requires a bearer token."""
    settings = Settings(cache_dir=str(cache_dir), token=TOKEN, access_log=False)
    with thread_server(settings, ready_headers={"Authorization": f"Bearer {TOKEN}"}) as server:
        yield server


@pytest.fixture(scope="session")
def token() -> str:
    """The bearer token of the ``secured`` server."""
    return TOKEN


@pytest.fixture(scope="session")
def start_thread_server() -> Any:
    """:func:`thread_server`, for tests that need a server with settings of their own."""
    return thread_server


@pytest.fixture(scope="session")
def start_serve_process() -> Any:
    """:func:`serve_process`, for tests that need a ``mapmatch serve`` of their own."""
    return serve_process


@pytest.fixture(scope="module")
def api_schema(live: ServeProcess) -> Any:
    """The served OpenAPI document, for the schemathesis fuzzing tests."""
    import schemathesis

    return schemathesis.openapi.from_url(live.base_url + "/openapi.json")
