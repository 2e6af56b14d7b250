"""
The look-up index of a route table: which record of a source's block holds a state.

A :class:`~roadnets.routes.RouteTable` keeps each source's records in settling order. The
matcher asks it for thousands of ``(source, state)`` pairs a trace; a binary search in each
block (over records sorted by state) costs ten or so dependent reads a pair. The index is one
open-addressing hash table per block instead: ``2 n + 1`` slots for a block of ``n``
records, each slot the record's place in its block plus one (0: empty), placed by a
Fibonacci hash of the state and linear probing. A look-up reads one or two slots and the
state of the record they name: about half the time of the binary search on the matcher's
pairs, and the same answer (each state is settled once per source, so a block holds it at
most once).

Slots are ``uint16`` where every block holds fewer than 65,535 records (a table within
2,000 m holds at most a few thousand per source), ``int32`` otherwise: two bytes a slot,
four bytes a record, as much as the sorted order the binary search needed.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numba import njit

if TYPE_CHECKING:
    import numpy.typing as npt

    IntArray = npt.NDArray[np.int64]

__all__ = ["find_record", "first_slot", "record_index"]

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)  # 2**64 over the golden ratio: Fibonacci hashing
_HIGH = np.uint64(32)


@njit(cache=True, nogil=True, inline="always")
def _home(state, capacity):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """The first slot ``state`` is looked for in, among ``capacity`` (multiply-shift range)."""
    mixed = (np.uint64(state) * _GOLDEN) >> _HIGH
    return np.int64((mixed * np.uint64(capacity)) >> _HIGH)


@njit(cache=True, nogil=True)
def _fill(ptr, state, index_ptr, slots):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """Place every record of every block in its block's slots (``slots`` all zero before)."""
    for block in range(len(ptr) - 1):
        base = index_ptr[block]
        capacity = index_ptr[block + 1] - base
        for r in range(ptr[block], ptr[block + 1]):
            h = _home(state[r], capacity)
            while slots[base + h] != 0:
                h += 1
                if h == capacity:
                    h = 0
            slots[base + h] = r - ptr[block] + 1


def record_index(
    ptr: IntArray, state: npt.NDArray[np.integer[Any]]
) -> tuple[IntArray, npt.NDArray[np.integer[Any]]]:
    """
    The index of a table's records: ``(index_ptr, slots)``.

    Block ``i`` (records ``ptr[i]:ptr[i + 1]``) has the slots ``index_ptr[i]:index_ptr[i + 1]``.

    Examples
    --------
    >>> ptr, state = np.array([0, 3, 3, 5]), np.array([7, 2, 9, 2, 4], dtype=np.int32)
    >>> index_ptr, slots = record_index(ptr, state)
    >>> index_ptr.tolist(), slots.dtype.name
    ([0, 7, 8, 13], 'uint16')
    >>> [find_record(ptr, state, index_ptr, slots, 0, s) for s in (7, 2, 9, 4)]
    [0, 1, 2, -1]
    >>> [find_record(ptr, state, index_ptr, slots, b, 2) for b in (1, 2, -1)]
    [-1, 3, -1]
    """
    sizes = np.diff(np.asarray(ptr, dtype=np.int64))
    index_ptr = np.zeros(len(sizes) + 1, dtype=np.int64)
    np.cumsum(2 * sizes + 1, out=index_ptr[1:])
    small = len(sizes) == 0 or int(sizes.max()) < np.iinfo(np.uint16).max
    slots: npt.NDArray[np.integer[Any]] = np.zeros(
        int(index_ptr[-1]), dtype=np.uint16 if small else np.int32
    )
    _fill(np.asarray(ptr, dtype=np.int64), state, index_ptr, slots)
    return index_ptr, slots


@njit(cache=True, nogil=True, inline="always")
def first_slot(index_ptr, block, wanted):  # type: ignore[no-untyped-def]  # pragma: no cover
    """The slot state ``wanted`` is looked for in first in block ``block`` (``block >= 0``)."""
    base = index_ptr[block]
    return base + _home(wanted, index_ptr[block + 1] - base)


@njit(cache=True, nogil=True, inline="always")
def find_record(ptr, state, index_ptr, slots, block, wanted):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Record of state ``wanted`` in block ``block`` (-1: no such record, or ``block < 0``)."""
    if block < 0:
        return -1
    base = index_ptr[block]
    capacity = index_ptr[block + 1] - base
    h = first_slot(index_ptr, block, wanted) - base
    while True:  # a block's slots are never full (2 n + 1 of them): an empty one ends it
        place = np.int64(slots[base + h])
        if place == 0:
            return -1
        r = ptr[block] + place - 1
        if state[r] == wanted:
            return r
        h += 1
        if h == capacity:
            h = 0
