"""A real headless Chromium for the browser tests, driven over the DevTools protocol.

The browser is Debian's ``chromium`` (``.ci/run`` installs it; ``MAPMATCH_CHROMIUM`` names
another binary). It talks the DevTools protocol over a pipe (``--remote-debugging-pipe``: JSON
messages ending in a NUL byte on file descriptors 3 and 4), so no port, websocket library or
browser download is needed. Every page a test opens records what a person's browser would
show in its console: uncaught exceptions, ``console.error`` calls, log entries of level
error (failed resource loads among them), failed requests and HTTP answers >= 400, and every
URL requested; :meth:`Page.problems` lists them and the tests assert there are none.

Name resolution is switched off (``--host-resolver-rules``) so that a page which reaches for
a CDN fails loudly instead of depending on whether this machine happens to be online.
"""

from __future__ import annotations

import base64
import contextlib
import json
import os
import select
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from mapmatch.viz.browser import HEADLESS_FLAGS, OFFLINE_FLAG, find_chromium

if TYPE_CHECKING:
    from collections.abc import Iterator

#: Flags that work in a container as root without a display or GPU, and no DNS at all: a
#: page that needs a CDN fails here even on an online machine.
FLAGS = (*HEADLESS_FLAGS, OFFLINE_FLAG)
COMMAND_TIMEOUT_S = 60.0

#: Moves two inherited fds to 3 (commands in) and 4 (answers out), then runs the browser.
_TRAMPOLINE = """
import fcntl, os, sys
read, write = (fcntl.fcntl(int(fd), fcntl.F_DUPFD, 10) for fd in sys.argv[1:3])
os.dup2(read, 3)
os.dup2(write, 4)
for fd in {read, write, int(sys.argv[1]), int(sys.argv[2])} - {3, 4}:
    os.close(fd)
os.execv(sys.argv[3], sys.argv[3:])
"""


class BrowserError(RuntimeError):
    """The browser answered a command with an error, died, or did not answer in time."""


class Browser:
    """One headless Chromium process and its DevTools pipe."""

    def __init__(self, executable: str, profile: Path, log: Path) -> None:
        to_browser_r, self._to_browser = os.pipe()
        self._from_browser, from_browser_w = os.pipe()
        self.log = log
        command = [
            executable,
            *FLAGS,
            f"--user-data-dir={profile}",
            "--remote-debugging-pipe",
            "--window-size=1200,900",
            "about:blank",
        ]
        with log.open("wb") as sink:
            # a small trampoline puts the pipe ends on fds 3 and 4, where the browser wants them
            self.process = subprocess.Popen(
                [
                    sys.executable,
                    "-c",
                    _TRAMPOLINE,
                    str(to_browser_r),
                    str(from_browser_w),
                    *command,
                ],
                pass_fds=(to_browser_r, from_browser_w),
                stdin=subprocess.DEVNULL,
                stdout=sink,
                stderr=sink,
            )
        os.close(to_browser_r)
        os.close(from_browser_w)
        self._buffer = b""
        self._next_id = 0
        self.events: list[dict[str, Any]] = []
        try:
            self.version = self.call("Browser.getVersion")
        except (BrowserError, OSError):
            self.close()
            raise

    # --------------------------------------------------------------------------- transport

    def _read_message(self, deadline: float) -> dict[str, Any]:
        while b"\0" not in self._buffer:
            left = deadline - time.monotonic()
            if left <= 0:
                msg = f"no message from the browser in time\n{self._log_tail()}"
                raise BrowserError(msg)
            ready, _, _ = select.select([self._from_browser], [], [], min(left, 0.5))
            if not ready:
                if self.process.poll() is not None:
                    msg = f"chromium exited with {self.process.returncode}\n{self._log_tail()}"
                    raise BrowserError(msg)
                continue
            chunk = os.read(self._from_browser, 1 << 20)
            if not chunk:
                msg = f"chromium closed its DevTools pipe\n{self._log_tail()}"
                raise BrowserError(msg)
            self._buffer += chunk
        raw, self._buffer = self._buffer.split(b"\0", 1)
        message: dict[str, Any] = json.loads(raw)
        return message

    def call(
        self,
        method: str,
        params: dict[str, Any] | None = None,
        *,
        session: str | None = None,
        timeout_s: float = COMMAND_TIMEOUT_S,
    ) -> dict[str, Any]:
        """Send one command and return its result; events read meanwhile are kept."""
        self._next_id += 1
        message: dict[str, Any] = {"id": self._next_id, "method": method, "params": params or {}}
        if session is not None:
            message["sessionId"] = session
        os.write(self._to_browser, json.dumps(message).encode() + b"\0")
        deadline = time.monotonic() + timeout_s
        while True:
            answer = self._read_message(deadline)
            if answer.get("id") == self._next_id:
                if "error" in answer:
                    msg = f"{method} failed: {answer['error']}"
                    raise BrowserError(msg)
                result: dict[str, Any] = answer.get("result", {})
                return result
            if "method" in answer:
                self.events.append(answer)

    def pump(self, seconds: float) -> None:
        """Read events for a while (network and console events arrive on their own)."""
        deadline = time.monotonic() + seconds
        with contextlib.suppress(BrowserError):
            while time.monotonic() < deadline:
                answer = self._read_message(deadline)
                if "method" in answer:
                    self.events.append(answer)

    def wait_event(self, method: str, session: str, timeout_s: float) -> dict[str, Any]:
        """Wait for an event of a page (one already read counts)."""
        for event in self.events:
            if event["method"] == method and event.get("sessionId") == session:
                return event
        deadline = time.monotonic() + timeout_s
        while True:
            answer = self._read_message(deadline)
            if "method" in answer:
                self.events.append(answer)
                if answer["method"] == method and answer.get("sessionId") == session:
                    return answer

    def _log_tail(self) -> str:
        text = self.log.read_text(errors="replace") if self.log.exists() else ""
        return text[-3000:]

    # --------------------------------------------------------------------------- pages

    def new_page(self, width: int = 1200, height: int = 900) -> Page:
        """Open a blank tab with console, log, network and page events switched on."""
        target = self.call("Target.createTarget", {"url": "about:blank"})["targetId"]
        session = self.call("Target.attachToTarget", {"targetId": target, "flatten": True})[
            "sessionId"
        ]
        page = Page(self, target, session)
        for domain in ("Page", "Runtime", "Log", "Network"):
            self.call(f"{domain}.enable", session=session)
        self.call(
            "Emulation.setDeviceMetricsOverride",
            {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False},
            session=session,
        )
        return page

    def close(self) -> None:
        with contextlib.suppress(BrowserError, OSError):
            self.call("Browser.close", timeout_s=10)
        try:
            self.process.wait(timeout=15)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        for fd in (self._to_browser, self._from_browser):
            with contextlib.suppress(OSError):
                os.close(fd)


@dataclass
class Page:
    """One tab: navigate, evaluate JavaScript, screenshot, and what went wrong on it."""

    browser: Browser
    target: str
    session: str
    url: str = ""
    _first_event: int = 0

    def call(self, method: str, params: dict[str, Any] | None = None) -> dict[str, Any]:
        return self.browser.call(method, params, session=self.session)

    def goto(self, url: str, *, timeout_s: float = 60.0) -> None:
        """Open a URL and wait for its load event."""
        self._first_event = len(self.browser.events)
        self.url = url
        answer = self.call("Page.navigate", {"url": url})
        if answer.get("errorText"):
            msg = f"navigating to {url} failed: {answer['errorText']}"
            raise BrowserError(msg)
        self.browser.wait_event("Page.loadEventFired", self.session, timeout_s)

    def evaluate(self, expression: str, *, timeout_s: float = 30.0) -> Any:
        """The value of a JavaScript expression (awaited when it is a promise)."""
        answer = self.browser.call(
            "Runtime.evaluate",
            {"expression": expression, "returnByValue": True, "awaitPromise": True},
            session=self.session,
            timeout_s=timeout_s,
        )
        if "exceptionDetails" in answer:
            details = answer["exceptionDetails"]
            text = details.get("exception", {}).get("description") or details.get("text")
            msg = f"evaluating {expression[:80]!r} threw: {text}"
            raise BrowserError(msg)
        return answer["result"].get("value")

    def wait_for(self, expression: str, *, timeout_s: float = 30.0) -> Any:
        """Poll a JavaScript expression until it is truthy; return its value."""
        deadline = time.monotonic() + timeout_s
        value = None
        while time.monotonic() < deadline:
            value = self.evaluate(expression)
            if value:
                return value
            self.browser.pump(0.1)
        problems = "\n".join(self.problems())
        msg = f"{expression!r} still {value!r} after {timeout_s} s on {self.url}\n{problems}"
        raise BrowserError(msg)

    def screenshot(self, path: Path) -> Path:
        data = self.call("Page.captureScreenshot", {"format": "png"})["data"]
        path.write_bytes(base64.b64decode(data))
        return path

    def _events(self) -> list[dict[str, Any]]:
        return [
            e
            for e in self.browser.events[self._first_event :]
            if e.get("sessionId") == self.session
        ]

    def requests(self) -> list[str]:
        """Every URL the page asked for since the last :meth:`goto`."""
        return [
            e["params"]["request"]["url"]
            for e in self._events()
            if e["method"] == "Network.requestWillBeSent"
        ]

    def problems(self) -> list[str]:
        """What a person would see in the console, or in the network panel in red."""
        found = []
        urls = {
            e["params"]["requestId"]: e["params"]["request"]["url"]
            for e in self._events()
            if e["method"] == "Network.requestWillBeSent"
        }
        for e in self._events():
            method, p = e["method"], e["params"]
            if method == "Runtime.exceptionThrown":
                d = p["exceptionDetails"]
                text = d.get("exception", {}).get("description") or d.get("text")
                found.append(f"uncaught exception: {text}")
            elif method == "Runtime.consoleAPICalled" and p["type"] in ("error", "assert"):
                args = " ".join(str(a.get("value", a.get("description", ""))) for a in p["args"])
                found.append(f"console.{p['type']}: {args}")
            elif method == "Log.entryAdded" and p["entry"]["level"] == "error":
                entry = p["entry"]
                found.append(f"log error: {entry.get('text')} ({entry.get('url', '')})")
            elif method == "Network.loadingFailed" and not p.get("canceled"):
                url = urls.get(p["requestId"], "?")
                found.append(f"request failed: {url}: {p.get('errorText')}")
            elif method == "Network.responseReceived" and p["response"]["status"] >= 400:
                found.append(f"HTTP {p['response']['status']}: {p['response']['url']}")
        return found

    def close(self) -> None:
        with contextlib.suppress(BrowserError):
            self.browser.call("Target.closeTarget", {"targetId": self.target})


@pytest.fixture(scope="session")
def browser(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Browser]:
    """A headless Chromium for the session; the tests skip, saying why, when there is none."""
    executable = find_chromium()
    if executable is None:
        named = os.environ.get("MAPMATCH_CHROMIUM")
        pytest.skip(
            f"MAPMATCH_CHROMIUM={named} is not a file"
            if named
            else "no Chromium: install Debian's package (apt-get install -y chromium; .ci/run "
            "does) or set MAPMATCH_CHROMIUM to a Chromium binary"
        )
    folder = tmp_path_factory.mktemp("chromium")
    profile = Path(tempfile.mkdtemp(prefix="profile-", dir=folder))
    instance = Browser(executable, profile, folder / "chromium.log")
    try:
        yield instance
    finally:
        instance.close()


@pytest.fixture
def page(browser: Browser) -> Iterator[Page]:
    """A fresh tab, closed after the test."""
    tab = browser.new_page()
    try:
        yield tab
    finally:
        tab.close()
