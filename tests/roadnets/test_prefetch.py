"""The compiled prefetch hint: for any one-dimensional array; it reads and changes nothing."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit
from numba.core.errors import TypingError

from roadnets.prefetch import prefetch


@njit(cache=False)
def _sum_after_prefetch(values):  # type: ignore[no-untyped-def]
    for i in range(len(values)):
        prefetch(values, i)
    total = 0.0
    for i in range(len(values)):
        prefetch(values, len(values) - 1 - i)
        total += values[i]
    return total


@pytest.mark.parametrize("dtype", [np.uint16, np.int16, np.int32, np.int64, np.float64])
def test_prefetching_leaves_the_values_as_they_were(dtype: type) -> None:
    values = np.arange(1, 5001, dtype=np.int64).astype(dtype)
    before = values.copy()
    assert _sum_after_prefetch(values) == float(before.astype(np.float64).sum())
    assert np.array_equal(values, before)


def test_a_strided_or_read_only_array_is_prefetched_by_its_own_items() -> None:
    values = np.arange(30.0)
    view = values[::3]
    assert _sum_after_prefetch(view) == view.sum()
    frozen = values.copy()
    frozen.flags.writeable = False
    assert _sum_after_prefetch(frozen) == values.sum()


@njit(cache=False)
def _prefetch_first(values, index):  # type: ignore[no-untyped-def]
    prefetch(values, index)


def test_only_a_one_dimensional_array_and_an_integer_index_are_accepted() -> None:
    _prefetch_first(np.zeros(3), 0)
    for values, index in ((np.zeros((3, 3)), 0), (np.zeros(3), 1.5), ([1.0, 2.0], 0)):
        with pytest.raises(TypingError, match="_prefetch"):
            _prefetch_first(values, index)
