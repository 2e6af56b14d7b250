"""roadnets.pages: the cache's files read and mapped on 2 MB pages where the kernel can."""

from __future__ import annotations

import hashlib
import mmap
from typing import TYPE_CHECKING

import numpy as np

from roadnets.cache import file_checksum
from roadnets.pages import advise_huge_pages, read_mapped

if TYPE_CHECKING:
    from pathlib import Path


def test_a_file_read_through_its_mapping_is_its_content(tmp_path: Path) -> None:
    for size in (0, 1, 4096, 3 * 2**21 + 17):  # empty, small, a page, past three 2 MB pages
        path = tmp_path / f"f{size}.bin"
        content = np.random.default_rng(size).integers(0, 256, size, dtype=np.uint8).tobytes()
        path.write_bytes(content)
        seen: list[bytes] = []
        read_mapped(path, lambda view, seen=seen: seen.append(bytes(view)))
        assert seen == [content]
        expected = hashlib.blake2b(content, digest_size=16).hexdigest()
        assert file_checksum(path) == expected  # the checksum the cache's entries hold


def test_the_advice_takes_any_mapping_and_leaves_the_rest(tmp_path: Path) -> None:
    path = tmp_path / "a.npy"
    np.save(path, np.arange(10.0))
    mapped = np.load(path, mmap_mode="c")
    advise_huge_pages(mapped)  # a numpy memmap: its mmap advised
    assert mapped[3] == 3.0
    with path.open("rb") as handle, mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ) as m:
        advise_huge_pages(m)
    advise_huge_pages(m)  # closed: nothing
    advise_huge_pages(np.zeros(3))  # not a mapping: nothing
    advise_huge_pages(None)
