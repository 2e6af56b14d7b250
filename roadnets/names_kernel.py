"""The compiled gather of :mod:`roadnets.names`.

Separate from :mod:`roadnets.names` so that importing roadnets (and loading a network) does
not import numba.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["gather_names"]


@njit(cache=True, nogil=True)
def gather_names(ids, ptr, blob, ways):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    The UTF-8 bytes of each way's name (nothing where it has none), NUL-separated.

    Also where each name starts in ``blob`` and how long it is (0 for none). ``ids`` are
    the sorted named ways, name ``i`` is ``blob[ptr[i]:ptr[i + 1]]``.
    """
    n = len(ways)
    start = np.zeros(n, dtype=np.int64)
    size = np.zeros(n, dtype=np.int64)
    total = max(n - 1, 0)
    for k in range(n):
        i = np.searchsorted(ids, ways[k])
        if i < len(ids) and ids[i] == ways[k]:
            start[k] = ptr[i]
            size[k] = ptr[i + 1] - ptr[i]
            total += size[k]
    joined = np.zeros(total, dtype=np.uint8)
    at = 0
    for k in range(n):
        if k:
            at += 1  # the NUL after the previous name
        for j in range(start[k], start[k] + size[k]):
            joined[at] = blob[j]
            at += 1
    return joined, start, size
