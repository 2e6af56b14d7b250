"""
Sums of float arrays as numpy adds them, to the bit, inside compiled code.

``np.sum`` adds in blocks (pairwise summation); a plain loop gives a different last bit.
Kernels whose sums must equal what a numpy expression gives (a score compared against
one made by numpy, a length the output shows) add with :func:`pairwise_sum`; a path's length
is added in driving order (:func:`path_length_m`), wherever it is asked for.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["pairwise_sum", "path_length_m"]


@njit(cache=True, nogil=True)
def _block_sum(a, lo, n):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """The sum of at most 128 values as numpy adds them: in order below 8, else in eight runs."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[lo + i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    while i < n - (n % 8):
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@njit(cache=True, nogil=True)
def pairwise_sum(a, lo, n):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    ``np.sum(a[lo:lo + n])`` as numpy adds it, to the bit.

    Blocks of up to 128 values summed by :func:`_block_sum`, longer runs halved (at a
    multiple of 8) and the halves added. The halving runs on an explicit stack: numba cannot
    cache a function that calls itself.
    """
    if n <= 128:
        return _block_sum(a, lo, n)
    s_lo = np.empty(64, dtype=np.int64)
    s_n = np.empty(64, dtype=np.int64)
    stage = np.zeros(64, dtype=np.int64)  # 0: new, 1: left half pending, 2: right pending
    left = np.empty(64)
    s_lo[0], s_n[0], stage[0] = lo, n, 0
    top = 1
    result = 0.0
    while top > 0:
        i = top - 1
        half = s_n[i] // 2
        half -= half % 8
        if s_n[i] <= 128 or stage[i] == 3:
            value = _block_sum(a, s_lo[i], s_n[i]) if s_n[i] <= 128 else left[i]
            top -= 1
            if top == 0:
                result = value
            elif stage[top - 1] == 1:
                left[top - 1] = value
            else:
                left[top - 1] = left[top - 1] + value
                stage[top - 1] = 3
        elif stage[i] == 0:
            stage[i] = 1
            s_lo[top], s_n[top], stage[top] = s_lo[i], half, 0
            top += 1
        elif stage[i] == 1:
            stage[i] = 2
            s_lo[top], s_n[top], stage[top] = s_lo[i] + half, s_n[i] - half, 0
            top += 1
    return result


@njit(cache=True, nogil=True)
def path_length_m(start_m, end_m, lo, hi):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    Metres driven over the stretches ``lo:hi``: ``end_m - start_m`` added in driving order.

    What :attr:`mapmatch.result.Segment.length_m` is, so that the segment's length, the result's
    and the GeoJSON's agree to the bit.
    """
    total = 0.0
    for k in range(lo, hi):
        total += end_m[k] - start_m[k]
    return total
