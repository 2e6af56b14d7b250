"""The service's /docs (Swagger UI) and /redoc (ReDoc) in a real headless Chromium, offline.

A real server on loopback (uvicorn in a thread, the app as ``mapmatch serve`` builds it); the
browser resolves no names, so a page that reached for a CDN would fail here. Each page must
load with no console error or failed request, ask for nothing but the server, and render
every operation of the OpenAPI description.
"""

from __future__ import annotations

import contextlib
import socket
import threading
import time
from typing import TYPE_CHECKING, Any

import httpx
import pytest
import uvicorn

from api.docs import ASSETS_PATH
from api.main import create_app
from api.settings import Settings

if TYPE_CHECKING:
    from collections.abc import Iterator
    from pathlib import Path


@contextlib.contextmanager
def _serve(settings: Settings) -> Iterator[str]:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = int(sock.getsockname()[1])
    config = uvicorn.Config(
        create_app(settings), host="127.0.0.1", port=port, ws="none", log_level="warning"
    )
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, name=f"docs-{port}", daemon=True)
    thread.start()
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                httpx.get(f"{base}/healthz", timeout=2.0)
                break
            except httpx.TransportError:
                if time.monotonic() > deadline:
                    pytest.fail(f"server at {base} does not answer")
                time.sleep(0.05)
        yield base
    finally:
        server.should_exit = True
        thread.join(timeout=20)


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    cache = tmp_path_factory.mktemp("docs-cache")
    with _serve(Settings(cache_dir=str(cache), access_log=False)) as base:
        yield base


@pytest.fixture(scope="module")
def operations(server: str) -> list[str]:
    paths = httpx.get(f"{server}/openapi.json", timeout=30).json()["paths"]
    return [f"{method.upper()} {path}" for path, item in paths.items() for method in item]


def _local_only(page: Any, server: str) -> None:
    page.browser.pump(0.3)
    problems = page.problems()
    assert problems == [], "\n".join(problems)
    elsewhere = [u for u in page.requests() if not u.startswith((server + "/", "data:", "blob:"))]
    assert elsewhere == []


def test_swagger_ui_renders_every_operation_offline(
    page: Any, server: str, operations: list[str], tmp_path: Path
) -> None:
    page.goto(f"{server}/docs")
    count = page.wait_for("document.querySelectorAll('.opblock').length", timeout_s=30)
    assert count == len(operations)
    shown = page.evaluate(
        "[...document.querySelectorAll('.opblock-summary')].map((e) =>"
        " e.querySelector('.opblock-summary-method').textContent + ' ' +"
        " e.querySelector('.opblock-summary-path').dataset.path)"
    )
    assert sorted(shown) == sorted(operations)
    assert "mapmatch" in page.evaluate("document.querySelector('.info .title').textContent")
    assert (
        page.evaluate("document.querySelectorAll('.errors-wrapper, .swagger-ui .error').length")
        == 0
    )
    requests = page.requests()
    assert f"{server}{ASSETS_PATH}/swagger-ui-bundle.js" in requests
    assert f"{server}/openapi.json" in requests
    _local_only(page, server)
    assert page.screenshot(tmp_path / "docs.png").stat().st_size > 10_000


def test_redoc_renders_every_operation_offline(
    page: Any, server: str, operations: list[str]
) -> None:
    page.goto(f"{server}/redoc")
    count = page.wait_for(
        "document.querySelectorAll('[data-section-id^=\"operation/\"]').length", timeout_s=30
    )
    assert count == len(operations)
    assert f"{server}{ASSETS_PATH}/redoc.standalone.js" in page.requests()
    _local_only(page, server)


def test_docs_pages_link_the_cdn_when_asked(tmp_path_factory: pytest.TempPathFactory) -> None:
    # no browser needed: the pages' HTML names FastAPI's CDN files and no bundled file
    settings = Settings(cache_dir=str(tmp_path_factory.mktemp("cdn")), docs_assets="cdn")
    with _serve(settings) as base:
        docs = httpx.get(f"{base}/docs", timeout=10).text
        redoc = httpx.get(f"{base}/redoc", timeout=10).text
        assets = httpx.get(f"{base}{ASSETS_PATH}/swagger-ui.css", timeout=10)
    assert "https://cdn.jsdelivr.net/npm/swagger-ui-dist@5/swagger-ui-bundle.js" in docs
    assert "https://cdn.jsdelivr.net/npm/redoc@2/bundles/redoc.standalone.js" in redoc
    assert ASSETS_PATH not in docs + redoc
    assert assets.status_code == 404


def test_bundled_docs_files_are_served(server: str) -> None:
    for name, kind in (
        ("swagger-ui-bundle.js", "javascript"),
        ("swagger-ui.css", "css"),
        ("redoc.standalone.js", "javascript"),
        ("favicon.png", "image/png"),
    ):
        answer = httpx.get(f"{server}{ASSETS_PATH}/{name}", timeout=10)
        assert answer.status_code == 200, name
        assert kind in answer.headers["content-type"], name
        assert len(answer.content) > 1000, name
    docs = httpx.get(f"{server}/docs", timeout=10).text
    assert "cdn.jsdelivr.net" not in docs
    assert "fastapi.tiangolo.com" not in docs
    assert '"validatorUrl": null' in docs
