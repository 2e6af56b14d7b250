"""
A headless Chromium for pictures of saved maps (and for the real-browser tests).

Chromium is a system package, not a Python one (Debian: ``apt-get install chromium``);
``MAPMATCH_CHROMIUM`` names another binary. Nothing here is imported by ``mapmatch.viz``
itself.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

__all__ = ["HEADLESS_FLAGS", "OFFLINE_FLAG", "find_chromium", "screenshot"]

#: Flags that run Chromium without a display, GPU or sandbox (containers, CI, root).
HEADLESS_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-dev-shm-usage",
    "--hide-scrollbars",
    "--mute-audio",
)
#: No name resolution but loopback: a page that needs the internet fails even when online.
OFFLINE_FLAG = "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1, EXCLUDE localhost"


def find_chromium() -> str | None:
    """The Chromium binary: ``MAPMATCH_CHROMIUM`` if set (and there), else one on PATH."""
    named = os.environ.get("MAPMATCH_CHROMIUM")
    if named:
        return named if Path(named).is_file() else None
    for name in ("chromium", "chromium-browser"):
        found = shutil.which(name)
        if found:
            return found
    return None


def screenshot(
    page: Path,
    out: Path,
    *,
    size: tuple[int, int] = (1100, 760),
    chromium: str | None = None,
    timeout_s: float = 120.0,
) -> Path:
    """
    Write a PNG of a saved HTML page (a map from ``match_map(...).save(path)``), offline.

    Parameters
    ----------
    page
        The HTML file.
    out
        The PNG to write.
    size
        Window width and height, pixels.
    chromium
        The browser binary; default :func:`find_chromium`.
    timeout_s
        Seconds the browser may take.

    Returns
    -------
    pathlib.Path
        ``out``.

    Raises
    ------
    FileNotFoundError
        No Chromium (install Debian's ``chromium`` or set ``MAPMATCH_CHROMIUM``), or no page.
    RuntimeError
        The browser failed; its output is in the message.
    """
    binary = chromium or find_chromium()
    if binary is None:
        msg = "no Chromium found: apt-get install -y chromium, or set MAPMATCH_CHROMIUM"
        raise FileNotFoundError(msg)
    if not page.is_file():
        msg = f"{page}: no such page to take a picture of"
        raise FileNotFoundError(msg)
    with tempfile.TemporaryDirectory(prefix="mapmatch-chromium-") as profile:
        command = [
            binary,
            *HEADLESS_FLAGS,
            OFFLINE_FLAG,
            f"--user-data-dir={profile}",
            f"--window-size={size[0]},{size[1]}",
            f"--screenshot={out.resolve()}",
            page.resolve().as_uri(),
        ]
        done = subprocess.run(command, capture_output=True, timeout=timeout_s, check=False)
    if done.returncode != 0 or not out.is_file():
        output = (done.stdout + done.stderr).decode(errors="replace")[-2000:]
        msg = f"chromium could not take a picture of {page} (exit {done.returncode}):\n{output}"
        raise RuntimeError(msg)
    return out
