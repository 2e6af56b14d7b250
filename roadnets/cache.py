"""On-disk cache of compiled networks, keyed by the source's content hash and the format.

A cache entry is a folder with one binary file of all arrays (memory-mapped read-only, so
server and batch workers share one copy through the page cache) and ``meta.json`` with the
arrays' layout and a checksum of the file. An entry is written to a temporary folder and
renamed into place, so a crash never leaves half an entry; an entry whose file does not match
its checksum is removed and rebuilt.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

from roadnets.arrays import NetworkArrays
from roadnets.errors import CacheError
from roadnets.pages import read_mapped

__all__ = [
    "FORMAT_VERSION",
    "default_cache_dir",
    "entry_folder",
    "file_checksum",
    "put_in_place",
    "read_entry",
    "write_entry",
]

#: Bump whenever the compiled arrays change meaning; old entries are then ignored.
FORMAT_VERSION = 7

#: The one file holding every array of an entry (layout and checksum in meta.json).
ARRAYS_FILE = "arrays.bin"

_log = logging.getLogger("roadnets")


def default_cache_dir() -> Path:
    """``$MAPMATCH_CACHE_DIR``, else ``$XDG_CACHE_HOME/mapmatch``, else ``~/.cache/mapmatch``."""
    explicit = os.environ.get("MAPMATCH_CACHE_DIR")
    if explicit:
        return Path(explicit)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "mapmatch"


def file_digest(path: Path) -> str:
    """SHA-256 of a file's content, hex."""
    digest = hashlib.sha256()
    with path.open("rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def entry_folder(cache_dir: Path, source_digest: str) -> Path:
    """The folder of the entry for a source with this digest under the current format."""
    return cache_dir / f"{source_digest[:24]}-v{FORMAT_VERSION}"


def ensure_writable(cache_dir: Path) -> None:
    """
    Create the cache folder if needed and check that files can be written in it.

    Raises
    ------
    CacheError
        The folder cannot be created or written.
    """
    try:
        cache_dir.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=cache_dir, prefix=".probe-"):
            pass
    except OSError as exc:
        raise CacheError(str(cache_dir), exc.strerror or str(exc)) from exc


def file_checksum(path: Path) -> str:
    """
    BLAKE2b (16 bytes) of a file's content, hex: the check of a cache file's integrity.

    Read through a mapping on 2 MB pages (:func:`~roadnets.pages.read_mapped`), so that the
    page cache holds the file as the arrays' own mappings of it want it.
    """
    digest = hashlib.blake2b(digest_size=16)
    read_mapped(path, digest.update)
    return digest.hexdigest()


def put_in_place(tmp: Path, folder: Path) -> None:
    """
    Rename a finished temporary folder to ``folder``; one another process finished first wins.

    A ``folder`` without its ``meta.json`` (a leftover) is replaced.

    Raises
    ------
    OSError
        The rename fails.
    """
    try:
        tmp.rename(folder)
    except OSError:
        if not (folder / "meta.json").exists():  # not another process that won the race
            shutil.rmtree(folder, ignore_errors=True)
            tmp.rename(folder)


def write_entry(folder: Path, arrays: NetworkArrays, meta: dict[str, Any]) -> None:
    """
    Write an entry atomically: into a temporary sibling folder, then rename it into place.

    Raises
    ------
    CacheError
        The cache folder cannot be written.
    """
    parent = folder.parent
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{folder.name}-", dir=parent))
    except OSError as exc:
        raise CacheError(str(parent), exc.strerror or str(exc)) from exc
    try:
        layout = arrays.save(tmp / ARRAYS_FILE)
        payload = {
            **meta,
            "format_version": FORMAT_VERSION,
            "layout": layout,
            "checksum": file_checksum(tmp / ARRAYS_FILE),
        }
        (tmp / "meta.json").write_text(json.dumps(payload), encoding="utf-8")
        put_in_place(tmp, folder)
    except OSError as exc:
        raise CacheError(str(parent), exc.strerror or str(exc)) from exc
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def read_entry(folder: Path) -> tuple[NetworkArrays, dict[str, Any]] | None:
    """Read and verify an entry; ``None`` when there is none or it was corrupt (then removed)."""
    meta_path = folder / "meta.json"
    if not meta_path.exists():
        return None
    try:
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
        if meta.get("format_version") != FORMAT_VERSION:
            msg = "format version differs"
            raise ValueError(msg)
        if file_checksum(folder / ARRAYS_FILE) != meta["checksum"]:
            msg = f"checksum of {ARRAYS_FILE} differs"
            raise ValueError(msg)
        arrays = NetworkArrays.load(folder / ARRAYS_FILE, meta["layout"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        _log.warning("network cache entry %s is corrupt (%s); rebuilding it", folder, exc)
        with contextlib.suppress(OSError):
            shutil.rmtree(folder)
        return None
    return arrays, meta
