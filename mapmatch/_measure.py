"""
The distance check's compiled parts: the span of fixes it compares and the chord over it.

:mod:`mapmatch.distance` calls them (imported when first used, so that ``import mapmatch``
does not load numba).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from mapmatch._sums import pairwise_sum
from mapmatch.distance import END_OUTLIERS

__all__ = ["chord_kernel", "measure_kernel", "span_kernel"]


@njit(cache=True, nogil=True)
def span_kernel(matched, outlier, segments, has_odometer):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    :func:`~mapmatch.distance.measured_span` as bounds: ``(lo, hi, complete)``.

    ``(0, len(matched), complete)`` where the check compares the whole trace.
    """
    n = len(matched)
    first, last = -1, -1
    for i in range(n):
        if matched[i]:
            if first < 0:
                first = i
            last = i
    if segments != 1 or first < 0:
        return 0, n, False
    if first == 0 and last == n - 1:
        return 0, n, True
    if first > END_OUTLIERS or n - 1 - last > END_OUTLIERS or not has_odometer:
        return 0, n, False
    for i in range(first):
        if not outlier[i]:
            return 0, n, False
    for i in range(last + 1, n):
        if not outlier[i]:
            return 0, n, False
    return first, last + 1, True


@njit(cache=True, nogil=True)
def chord_kernel(x, y, lo, hi):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    :func:`~mapmatch.distance.chord_length_m` of the positions ``lo:hi``.

    To the bit what ``np.hypot(np.diff(x), np.diff(y)).sum()`` gives (numpy adds pairwise).
    """
    steps = np.empty(max(hi - lo - 1, 0))
    for i in range(len(steps)):
        steps[i] = math.hypot(x[lo + i + 1] - x[lo + i], y[lo + i + 1] - y[lo + i])
    return pairwise_sum(steps, 0, len(steps))


@njit(cache=True, nogil=True)
def measure_kernel(matched, outlier, segments, has_odometer, x, y):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """:func:`span_kernel`'s answer and the :func:`chord_kernel` length over it, one call."""
    lo, hi, complete = span_kernel(matched, outlier, segments, has_odometer)
    return lo, hi, complete, chord_kernel(x, y, lo, hi)
