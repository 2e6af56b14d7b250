"""The route table's look-up index answers what a scan of each source's block answers."""

from __future__ import annotations

import numpy as np
import pytest

from roadnets.record_index import find_record, record_index


def _blocks(
    rng: np.random.Generator, sizes: list[int], n_states: int
) -> tuple[np.ndarray, np.ndarray]:
    """Blocks of distinct random states (each state settled once per source)."""
    ptr = np.zeros(len(sizes) + 1, dtype=np.int64)
    np.cumsum(sizes, out=ptr[1:])
    state = np.concatenate(
        [rng.choice(n_states, size, replace=False) for size in sizes] or [np.zeros(0)]
    ).astype(np.int32)
    return ptr, state


def _scan(ptr: np.ndarray, state: np.ndarray, block: int, wanted: int) -> int:
    if block < 0:
        return -1
    hits = np.flatnonzero(state[ptr[block] : ptr[block + 1]] == wanted)
    return int(ptr[block] + hits[0]) if len(hits) else -1


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_every_state_of_every_block_is_found_and_no_other(seed: int) -> None:
    rng = np.random.default_rng(seed)
    sizes = [0, 1, 2, 7, 300, 1_000, 0, 5]
    n_states = 2_000
    ptr, state = _blocks(rng, sizes, n_states)
    index_ptr, slots = record_index(ptr, state)
    assert slots.dtype == np.uint16
    assert len(slots) == sum(2 * s + 1 for s in sizes)
    for block in range(-1, len(sizes)):
        for wanted in range(n_states):
            got = find_record(ptr, state, index_ptr, slots, block, wanted)
            assert got == _scan(ptr, state, block, wanted), (block, wanted)


def test_a_block_too_large_for_two_byte_slots_gets_four_byte_ones() -> None:
    rng = np.random.default_rng(3)
    ptr, state = _blocks(rng, [3, 70_000], 100_000)
    index_ptr, slots = record_index(ptr, state)
    assert slots.dtype == np.int32
    for wanted in rng.choice(100_000, 2_000, replace=False).tolist() + state[-50:].tolist():
        assert find_record(ptr, state, index_ptr, slots, 1, wanted) == _scan(ptr, state, 1, wanted)


def test_a_table_without_records_has_an_index_that_finds_nothing() -> None:
    ptr, state = np.zeros(1, dtype=np.int64), np.zeros(0, dtype=np.int32)
    index_ptr, slots = record_index(ptr, state)
    assert index_ptr.tolist() == [0]
    assert len(slots) == 0
