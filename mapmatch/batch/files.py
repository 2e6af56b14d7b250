"""
Files that are complete under their final name, durable, and made as the umask says.

Every output is written to a hidden temporary sibling (``.tmp-<name>.<random><suffix>``),
its data flushed to the disk (``fsync``), its permissions set from the umask (``0666 &
~umask``; ``mkstemp`` alone gives ``0600``) and only then renamed into place: a file under
its final name is whole, even after a power loss. :func:`sync_folder` makes the renames
themselves durable (the batch calls it once at the end).

``fsync`` waits for the disk (milliseconds each). A :class:`Committer` does the flush and the
rename on a thread of its own, in the order the files were written, while the worker goes
on matching the next trace; :meth:`Committer.wait` returns when every file is in place.
"""

from __future__ import annotations

import contextlib
import os
import queue
import tempfile
import threading
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Callable

__all__ = [
    "TMP_PREFIX",
    "Committer",
    "atomic_write",
    "remove_temporaries",
    "sync_folder",
]

#: Name start of every temporary file a batch makes in its output folder.
TMP_PREFIX = ".tmp-"


def _sync(path: Path) -> None:
    """Flush a file's data to the disk, so a rename never exposes an empty file."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def sync_folder(folder: Path) -> None:
    """Flush a folder's entries (the renames into it) to the disk; a no-op where unsupported."""
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _umask() -> int:
    """The umask of this process (read without changing it where Linux tells it)."""
    with contextlib.suppress(OSError, ValueError):
        for line in Path("/proc/self/status").read_text(encoding="ascii").splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _place(tmp: Path, path: Path) -> None:
    """Flush, set the permissions of, and rename a written temporary file into place."""
    _sync(tmp)
    os.chmod(tmp, 0o666 & ~_umask())
    os.replace(tmp, path)


def atomic_write(
    path: Path,
    write: Callable[[Path], object],
    *,
    committer: Committer | None = None,
    group: str = "",
) -> None:
    """
    Write a file through a hidden temporary sibling, then put it in place (module docstring).

    Parameters
    ----------
    path
        Final file name.
    write
        Called with the temporary path; must create that file.
    committer
        Flush and rename on this committer's thread instead of now.
    group
        What the file belongs to (a trace's output name), for the committer's report.
    """
    fd, tmp_name = tempfile.mkstemp(
        prefix=f"{TMP_PREFIX}{path.name}.", suffix=path.suffix, dir=path.parent
    )
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        write(tmp)
        if committer is None:
            _place(tmp, path)
        else:
            committer.submit(tmp, path, group)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def remove_temporaries(out_dir: Path) -> int:
    """Delete temporary files a killed run left in ``out_dir``; return how many."""
    removed = 0
    for tmp in out_dir.glob(f"{TMP_PREFIX}*"):
        with contextlib.suppress(OSError):
            tmp.unlink()
            removed += 1
    return removed


class Committer:
    """
    Puts written files in place on a thread of its own, in the order they were submitted.

    One per worker process. Files are grouped (a trace's files; :meth:`seal` says a group
    has all its files): :meth:`finished` tells the sealed groups whose files are all in
    place, :meth:`wait` waits for all and tells the groups where one failed (the disk
    filled up ...) with the error.
    """

    def __init__(self) -> None:
        self._queue: queue.Queue[tuple[Path, Path, str] | None] = queue.Queue()
        self._lock = threading.Lock()
        self._pending: dict[str, int] = {}
        self._open: set[str] = set()  # groups that may get more files
        self._done: list[str] = []
        self._failed: dict[str, OSError] = {}
        self._thread = threading.Thread(target=self._run, name="committer", daemon=True)
        self._thread.start()

    def submit(self, tmp: Path, path: Path, group: str) -> None:
        """Queue ``tmp`` to be flushed and renamed to ``path``; the group stays open."""
        with self._lock:
            self._pending[group] = self._pending.get(group, 0) + 1
            self._open.add(group)
        self._queue.put((tmp, path, group))

    def seal(self, group: str) -> None:
        """The group has all its files: it is finished once they are in place."""
        with self._lock:
            self._open.discard(group)
            self._settle(group)

    def _settle(self, group: str) -> None:
        """Under the lock: report a sealed group whose files are all placed (or failed)."""
        if group in self._open or self._pending.get(group, 0) > 0:
            return
        self._pending.pop(group, None)
        if group not in self._failed:
            self._done.append(group)

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                self._queue.task_done()
                return
            tmp, path, group = item
            try:
                if group not in self._failed:  # a group's later files wait for its first
                    _place(tmp, path)
                else:
                    tmp.unlink(missing_ok=True)
            except OSError as exc:
                with contextlib.suppress(OSError):
                    tmp.unlink()
                with self._lock:
                    self._failed[group] = exc
            with self._lock:
                self._pending[group] -= 1
                self._settle(group)
            self._queue.task_done()

    def finished(self) -> list[str]:
        """Groups whose files all came into place since the last call."""
        with self._lock:
            done, self._done = self._done, []
        return done

    def wait(self) -> dict[str, OSError]:
        """Wait until every file submitted is in place; the groups that failed, with why."""
        self._queue.join()
        with self._lock:
            failed, self._failed = self._failed, {}
        return failed
