from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mapmatch.hmm.routes import ARRIVAL_HELD
from mapmatch.hmm.viterbi import posteriors, viterbi, viterbi_arrivals_kernel


@dataclass
class Trellis:
    log_emission: np.ndarray
    log_transition: np.ndarray


@st.composite
def small_trellises(
    draw: st.DrawFn, max_steps: int = 5, max_states: int = 4, lowest: float = -20
) -> Trellis:
    steps = draw(st.integers(2, max_steps))
    width = draw(st.integers(1, max_states))
    finite = st.floats(min_value=lowest, max_value=0, allow_nan=False)
    em = np.array(draw(st.lists(finite, min_size=steps * width, max_size=steps * width)))
    tr_size = (steps - 1) * width * width
    tr = np.array(draw(st.lists(finite, min_size=tr_size, max_size=tr_size)))
    return Trellis(em.reshape(steps, width), tr.reshape(steps - 1, width, width))


def sequence_log_lik(trellis: Trellis, states: np.ndarray) -> float:
    em, tr = trellis.log_emission, trellis.log_transition
    total = em[0, states[0]]
    for t in range(1, len(states)):
        total += tr[t - 1, states[t - 1], states[t]] + em[t, states[t]]
    return float(total)


def all_sequences(trellis: Trellis) -> list[tuple[np.ndarray, float]]:
    steps, width = trellis.log_emission.shape
    out = []
    for seq in itertools.product(range(width), repeat=steps):
        states = np.array(seq)
        out.append((states, sequence_log_lik(trellis, states)))
    return out


def brute_force_max_log_lik(trellis: Trellis) -> float:
    return max(ll for _, ll in all_sequences(trellis))


def brute_force_marginals(trellis: Trellis) -> np.ndarray:
    steps, width = trellis.log_emission.shape
    seqs = all_sequences(trellis)
    lls = np.array([ll for _, ll in seqs])
    weights = np.exp(lls - lls.max())
    weights /= weights.sum()
    out = np.zeros((steps, width))
    for (states, _), w in zip(seqs, weights, strict=True):
        out[np.arange(steps), states] += w
    return out


@settings(max_examples=200)
@given(trellis=small_trellises(max_steps=5, max_states=4))
def test_viterbi_finds_the_most_likely_sequence(trellis: Trellis) -> None:
    best = viterbi(trellis.log_emission, trellis.log_transition)
    assert best.pieces == [(0, len(trellis.log_emission))]
    assert best.log_likelihood == pytest.approx(brute_force_max_log_lik(trellis))
    assert best.log_likelihood == pytest.approx(sequence_log_lik(trellis, best.states))


@settings(max_examples=100)
@given(trellis=small_trellises(max_steps=4, max_states=3))
def test_posteriors_are_the_brute_force_marginals(trellis: Trellis) -> None:
    steps = len(trellis.log_emission)
    post = posteriors(trellis.log_emission, trellis.log_transition, [(0, steps)])
    expected = brute_force_marginals(trellis)
    assert np.allclose(post, expected, atol=1e-9)
    assert np.allclose(post.sum(axis=1), 1.0)


@settings(max_examples=100)
@given(trellis=small_trellises(max_steps=4, max_states=3, lowest=-3000))
def test_posteriors_hold_where_scores_span_more_than_a_float_does(trellis: Trellis) -> None:
    # scores hundreds of nats apart: a pass in probability space would lose these marginals
    # in subnormal numbers (tried: off by 1e-9 here); the log-space pass keeps them
    steps = len(trellis.log_emission)
    post = posteriors(trellis.log_emission, trellis.log_transition, [(0, steps)])
    assert np.allclose(post, brute_force_marginals(trellis), atol=1e-9)


def test_a_piece_whose_only_way_on_is_far_below_the_best_start_keeps_its_marginals() -> None:
    # the way on leaves from the start 1,000 nats down: in probability space, rescaled at
    # each fix, every path through the first step would be 0
    em = np.array([[0.0, -1000.0], [0.0, -1.0], [0.0, 0.0]])
    tr = np.full((2, 2, 2), -np.inf)
    tr[0, 1, :] = [0.0, -2.0]
    tr[1] = [[0.0, -3.0], [-1.0, 0.0]]
    post = posteriors(em, tr, [(0, 3)])
    assert np.allclose(post, brute_force_marginals(Trellis(em, tr)), atol=1e-12)
    assert post[0, 0] == 0.0
    assert post[0, 1] == pytest.approx(1.0)


@st.composite
def padded_trellises(draw: st.DrawFn) -> Trellis:
    """A trellis whose fixes have 1-3 candidates each, padded to the widest (as the matcher's)."""
    trellis = draw(small_trellises(max_steps=4, max_states=3))
    em, tr = trellis.log_emission.copy(), trellis.log_transition.copy()
    steps, width = em.shape
    sizes = draw(st.lists(st.integers(1, width), min_size=steps, max_size=steps))
    for t, size in enumerate(sizes):
        em[t, size:] = -np.inf
        if t + 1 < steps:  # no way on from a padded state, nor onto one
            tr[t, size:, :] = -np.inf
            tr[t, :, sizes[t + 1] :] = -np.inf
    return Trellis(em, tr)


@settings(max_examples=150)
@given(trellis=padded_trellises())
def test_a_padded_trellis_is_solved_over_its_candidates_alone(trellis: Trellis) -> None:
    # the passes skip each fix's padding: the same best sequence and marginals as over all
    steps = len(trellis.log_emission)
    best = viterbi(trellis.log_emission, trellis.log_transition)
    assert best.pieces == [(0, steps)]
    assert np.isfinite(trellis.log_emission[np.arange(steps), best.states]).all()
    assert best.log_likelihood == pytest.approx(brute_force_max_log_lik(trellis))
    post = posteriors(trellis.log_emission, trellis.log_transition, [(0, steps)])
    expected = brute_force_marginals(trellis)
    assert np.allclose(post, expected, atol=1e-9)
    assert (post[~np.isfinite(trellis.log_emission)] == 0).all()


def test_no_possible_transition_splits_the_sequence() -> None:
    em = np.log(np.full((4, 2), 0.5))
    tr = np.zeros((3, 2, 2))
    tr[1] = -np.inf  # nothing connects fix 1 to fix 2
    best = viterbi(em, tr)
    assert best.pieces == [(0, 2), (2, 4)]
    assert best.breaks == [2]
    assert (best.states >= 0).all()


def test_a_fix_without_candidates_is_unmatched_and_splits() -> None:
    em = np.zeros((5, 2))
    em[2] = -np.inf
    best = viterbi(em, np.zeros((4, 2, 2)))
    assert best.states[2] == -1
    assert best.pieces == [(0, 2), (3, 5)]


def test_padding_states_are_never_chosen() -> None:
    em = np.array([[0.0, -np.inf], [-1.0, -0.5], [0.0, -np.inf]])
    tr = np.zeros((2, 2, 2))
    best = viterbi(em, tr)
    assert best.states.tolist() == [0, 1, 0]


def _held_across_trellis(arrived_from: int) -> tuple[np.ndarray, ...]:
    """
    Three fixes: one state on edge 10, one on edge 20 (reached from ``arrived_from``), then
    a hold across edges back onto edge 30 (score -1, its move -5) or a move onto edge 40 (-3).
    """
    em = np.array([[0.0, -np.inf], [0.0, -np.inf], [0.0, 0.0]])
    tr = np.full((2, 2, 2), -np.inf)
    pair = np.full((2, 2, 2), -1, dtype=np.int32)
    tr[0, 0, 0], pair[0, 0, 0] = -1.0, 0
    tr[1, 0, 0], pair[1, 0, 0] = -1.0, -2 - 1  # the hold across edges
    tr[1, 0, 1], pair[1, 0, 1] = -3.0, 2
    cand_edge = np.array([[10, -1], [20, -1], [30, 40]], dtype=np.int64)
    move_score = np.array([-1.0, -5.0, -3.0])
    move_arrival = np.array([arrived_from, 20, 20], dtype=np.int64)
    arrival_of = np.array([arrived_from, ARRIVAL_HELD, 20], dtype=np.int64)
    return em, tr, pair, cand_edge, move_score, move_arrival, arrival_of


def test_a_hold_across_edges_stands_only_on_the_edge_the_car_arrived_by() -> None:
    # arrived on edge 20 from edge 30: the fix behind it on edge 30 is the car held still
    states, _, total, moved = viterbi_arrivals_kernel(*_held_across_trellis(arrived_from=30))
    assert states.tolist() == [0, 0, 0]
    assert total == pytest.approx(-2.0)
    assert not moved.any()
    # arrived from edge 15: edge 30 is a road it never drove, and holding there would hide a
    # turn round at the junction; the pair scores its move (-5), and the other road wins
    states, _, total, moved = viterbi_arrivals_kernel(*_held_across_trellis(arrived_from=15))
    assert states.tolist() == [0, 0, 1]
    assert total == pytest.approx(-4.0)
    assert moved[2].tolist() == [True, False]
