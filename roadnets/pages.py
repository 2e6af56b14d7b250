"""
The cache's files mapped on 2 MB pages where the kernel can.

A sparse trace's route-table look-ups land on a page each, and after other work (another
request's network, another program; in the peer comparison FMM's look-ups in a table of
gigabytes) the address translations are as cold as the data: with 4 KB pages every look-up
pays a page walk, with 2 MB pages a few hundred cover the table. Measured in turns
(``benchmarks/ab_turns.py --evict-mb 1024 --evict-pages``): 9-15 % off a Krems 30 s,
Liechtenstein 15 s and Andorra 15 s trace in a busy hour of the shared machine (stop 63), 2-3 %
when only the caches are cold, and none in a quiet hour, when a page walk finds its tables in
the caches (stop 64).

Linux maps a file on 2 MB pages when the page cache holds it in 2 MB folios (ext4 and xfs
make them on recent kernels) and the mapping asked for them (``MADV_HUGEPAGE``) before its
pages were read: a file first read through ``read()`` is cached in smaller folios, and every
later mapping of it gets 4 KB pages. So a cache file is read for its checksum through such a
mapping (:func:`read_mapped`), and the arrays' mappings ask for them too
(:func:`advise_huge_pages`). Elsewhere (another kernel, another filesystem, transparent huge
pages off) both are plain mappings; nothing else changes.
"""

from __future__ import annotations

import contextlib
import mmap
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Callable
    from pathlib import Path

__all__ = ["advise_huge_pages", "read_mapped"]


def advise_huge_pages(mapping: Any) -> None:
    """
    Ask for 2 MB pages behind ``mapping``: an :class:`mmap.mmap` or a :class:`numpy.memmap`.

    Anything else, or a system without the advice, is left as it is.
    """
    raw = getattr(mapping, "_mmap", mapping)  # a numpy memmap keeps its mmap there
    advice = getattr(mmap, "MADV_HUGEPAGE", None)
    if advice is not None and isinstance(raw, mmap.mmap):
        with contextlib.suppress(OSError, ValueError):  # refused, or the mapping is closed
            raw.madvise(advice)


def read_mapped(path: Path, consume: Callable[[memoryview], object]) -> None:
    """
    Hand ``consume`` the whole content of ``path``, read through a mapping on 2 MB pages.

    An empty file is handed as an empty view (it cannot be mapped).
    """
    with path.open("rb") as handle:
        try:
            mapping = mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ)
        except ValueError:  # empty
            consume(memoryview(b""))
            return
        with mapping:
            advise_huge_pages(mapping)
            view = memoryview(mapping)
            try:
                consume(view)
            finally:
                view.release()
