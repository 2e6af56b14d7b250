"""Most likely candidate sequence (Viterbi) and per-fix posteriors (forward-backward).

Works on padded trellises: ``log_emission[t, k]`` for candidate ``k`` of fix ``t`` (``-inf``
for padding or a fix with no candidate) and ``log_transition[t, j, k]`` from candidate ``j``
of fix ``t`` to candidate ``k`` of fix ``t + 1``. Where no candidate of a fix can be reached
from the previous fix, the sequence is split there (a *break*) and the next piece starts
afresh. The matcher's pass (:func:`viterbi_arrivals_kernel`) also carries, per state, the
edge its best path arrived by, so a fix held behind across a junction stands only on the road
the car came by. The loops run compiled (numba); numpy only.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from mapmatch.hmm.routes import ARRIVAL_SAME, ARRIVAL_UNKNOWN

if TYPE_CHECKING:
    from mapmatch.types import FloatArray, IntArray

__all__ = ["ViterbiResult", "posteriors", "viterbi", "viterbi_arrivals_kernel"]


@dataclass(frozen=True, slots=True)
class ViterbiResult:
    """
    The best state sequence.

    Attributes
    ----------
    states
        Chosen candidate of each fix, or -1 for a fix with no candidate.
    pieces
        ``(start, stop)`` fix ranges matched as one connected piece, in order.
    log_likelihood
        Sum over pieces of the best path's log-likelihood.
    """

    states: IntArray
    pieces: list[tuple[int, int]]
    log_likelihood: float

    @property
    def breaks(self) -> list[int]:
        """First fix of every piece but the first: where the trace was split."""
        return [start for start, _ in self.pieces[1:]]


@njit(cache=True, nogil=True)
def _backtrack(delta, back):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """The best states from the scores and back pointers, each piece from its last fix."""
    n_steps, width = delta.shape
    states = np.full(n_steps, -1, dtype=np.int64)
    starts = np.zeros(n_steps, dtype=np.bool_)
    total = 0.0
    t = n_steps - 1
    while t >= 0:
        best = -np.inf
        arg = -1
        for k in range(width):
            if delta[t, k] > best:
                best = delta[t, k]
                arg = k
        if arg < 0:
            t -= 1
            continue
        total += best
        k = arg
        states[t] = k
        while back[t, k] >= 0:
            k = back[t, k]
            t -= 1
            states[t] = k
        starts[t] = True
        t -= 1
    return states, starts, total


@njit(cache=True, nogil=True, inline="always")
def _sizes(em):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """Each fix's candidates: the padding (``-inf`` emissions) comes after them."""
    n_steps, width = em.shape
    size = np.zeros(n_steps, dtype=np.int64)
    for t in range(n_steps):
        for k in range(width):
            if em[t, k] > -np.inf:
                size[t] = k + 1
    return size


@njit(cache=True, nogil=True, inline="always")
def _refused(code, before, edge):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """Whether a transition (its ``pair`` code) holds across edges onto one not arrived by."""
    return code < -1 and before != ARRIVAL_UNKNOWN and before != edge


@njit(cache=True, nogil=True)
def viterbi_arrivals_kernel(  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    em, tr, pair, cand_edge, move_score, move_arrival, arrival_of
):
    """
    Viterbi over a trellis whose holds across edges depend on how the car got there.

    A transition that holds the car still with the next fix on another edge
    (:data:`~mapmatch.hmm.routes.ROUTE_STANDSTILL`, ``b`` behind ``a`` across a junction)
    says the car is still where it arrived from: that is only so on the edge it arrived
    on. Each state carries the edge its best path drove onto its edge from (``arrival``,
    an edge or :data:`~mapmatch.hmm.routes.ARRIVAL_UNKNOWN` at a piece's start); where a
    hold across edges leads to an edge other than that, the pair scores its move instead
    (``move_score``). Otherwise a state on the edge into a junction the car never drove
    hides a turn round there: the next move is scored from that edge, as a straight route,
    and the U-turn is never paid for.

    ``pair`` maps each padded transition to its pair ``i`` in ``move_score``,
    ``move_arrival`` and ``arrival_of`` (the arrival when the pair's best explanation is
    taken; :data:`~mapmatch.hmm.routes.ARRIVAL_SAME`: the state before's own): ``i``, or
    ``-2 - i`` where that explanation holds across edges (-1: no pair; one small array read
    per transition keeps the pass as fast as plain Viterbi). ``cand_edge`` is each padded
    candidate's edge. Returns the states, the piece starts, the total and, per padded
    state, whether its best path's last transition was the move.
    """
    n_steps, width = em.shape
    delta = np.full((n_steps, width), -np.inf)
    back = np.full((n_steps, width), -1, dtype=np.int64)
    arrival = np.full((n_steps, width), ARRIVAL_UNKNOWN, dtype=np.int64)
    moved = np.zeros((n_steps, width), dtype=np.bool_)
    size = _sizes(em)  # a padded state is never chosen, nor a way on from it: left out
    for k in range(width):
        delta[0, k] = em[0, k]
    for t in range(1, n_steps):
        alive = False
        for k in range(size[t]):
            if em[t, k] == -np.inf:
                continue
            best = -np.inf
            arg = -1
            for j in range(size[t - 1]):  # plain Viterbi first: a refused hold only lowers a score
                value = delta[t - 1, j] + tr[t - 1, j, k]
                if value > best:
                    best = value
                    arg = j
            fell = False
            if arg >= 0 and _refused(pair[t - 1, arg, k], arrival[t - 1, arg], cand_edge[t, k]):
                best = -np.inf
                arg = -1
                for j in range(size[t - 1]):
                    q = pair[t - 1, j, k]
                    if q == -1:
                        continue
                    move = _refused(q, arrival[t - 1, j], cand_edge[t, k])
                    value = delta[t - 1, j] + (move_score[-2 - q] if move else tr[t - 1, j, k])
                    if value > best:
                        best = value
                        arg = j
                        fell = move
            if arg >= 0:
                p = pair[t - 1, arg, k]
                p = -2 - p if p < -1 else p
                came = move_arrival[p] if fell else arrival_of[p]
                delta[t, k] = best + em[t, k]
                back[t, k] = arg
                arrival[t, k] = arrival[t - 1, arg] if came == ARRIVAL_SAME else came
                moved[t, k] = fell
                alive = True
        if not alive:
            for k in range(width):
                delta[t, k] = em[t, k]
                back[t, k] = -1
                arrival[t, k] = ARRIVAL_UNKNOWN
    states, starts, total = _backtrack(delta, back)
    return states, starts, total, moved


@njit(cache=True, nogil=True, inline="always")
def _logsumexp(values, n):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """log(sum(exp(values[:n]))); ``-inf`` entries (padding) add nothing and are skipped."""
    top = -np.inf
    for i in range(n):
        if values[i] > top:
            top = values[i]
    if top == -np.inf:
        return -np.inf
    acc = 0.0
    for i in range(n):
        if values[i] > -np.inf:  # exp(-inf) is 0: skipping it changes nothing
            acc += np.exp(values[i] - top)
    return top + np.log(acc)


@njit(cache=True, nogil=True)
def _posterior_kernel(em, tr, starts, stops):  # type: ignore[no-untyped-def]  # pragma: no cover
    n_steps, width = em.shape
    post = np.zeros((n_steps, width))
    alpha = np.full((n_steps, width), -np.inf)
    beta = np.full((n_steps, width), -np.inf)
    work = np.empty(width)
    size = _sizes(em)  # padded states keep alpha and beta -inf and posterior 0
    for p in range(len(starts)):
        s, e = starts[p], stops[p]
        for k in range(width):
            alpha[s, k] = em[s, k]
        for t in range(s + 1, e):
            for k in range(size[t]):
                if em[t, k] == -np.inf:
                    continue
                for j in range(size[t - 1]):
                    work[j] = alpha[t - 1, j] + tr[t - 1, j, k]
                alpha[t, k] = _logsumexp(work, size[t - 1]) + em[t, k]
        for k in range(width):
            beta[e - 1, k] = 0.0
        for t in range(e - 2, s - 1, -1):
            for j in range(size[t]):
                for k in range(size[t + 1]):
                    work[k] = tr[t, j, k] + em[t + 1, k] + beta[t + 1, k]
                beta[t, j] = _logsumexp(work, size[t + 1])
        z = _logsumexp(alpha[e - 1], width)
        for t in range(s, e):
            for k in range(width):
                v = alpha[t, k] + beta[t, k] - z
                post[t, k] = np.exp(v) if v > -np.inf else 0.0
    return post


def viterbi(log_emission: FloatArray, log_transition: FloatArray) -> ViterbiResult:
    """
    Most likely candidate sequence of a padded trellis, split where no transition is possible.

    Parameters
    ----------
    log_emission
        ``(T, K)`` log emission of candidate ``k`` at fix ``t``; ``-inf`` pads.
    log_transition
        ``(T - 1, K, K)`` log transition from candidate ``j`` at ``t`` to ``k`` at ``t + 1``.

    Examples
    --------
    >>> em = np.log(np.array([[0.6, 0.4], [0.5, 0.5]]))
    >>> tr = np.log(np.array([[[0.1, 0.9], [0.9, 0.1]]]))
    >>> viterbi(em, tr).states.tolist()
    [0, 1]
    """
    em = np.ascontiguousarray(log_emission, dtype=np.float64)
    tr = np.ascontiguousarray(log_transition, dtype=np.float64)
    if em.shape[0] == 0:
        return ViterbiResult(np.empty(0, dtype=np.int64), [], 0.0)
    # no holds: every transition a move along one edge
    pair = np.arange(tr.size, dtype=np.int32).reshape(tr.shape)
    same = np.full(tr.size, ARRIVAL_SAME, dtype=np.int64)
    states, starts, total, _ = viterbi_arrivals_kernel(
        em, tr, pair, np.zeros(em.shape, dtype=np.int64), tr.ravel(), same, same
    )
    pieces: list[tuple[int, int]] = []
    matched = states >= 0
    begin = np.flatnonzero(starts & matched)
    for start in begin.tolist():
        stop = start + 1
        while stop < len(states) and matched[stop] and not starts[stop]:
            stop += 1
        pieces.append((start, stop))
    return ViterbiResult(states, pieces, float(total))


def posteriors(
    log_emission: FloatArray, log_transition: FloatArray, pieces: list[tuple[int, int]]
) -> FloatArray:
    """
    Posterior probability of every candidate given its whole piece (forward-backward).

    Returns
    -------
    FloatArray
        ``(T, K)``; rows of fixes outside every piece are 0.
    """
    em = np.ascontiguousarray(log_emission, dtype=np.float64)
    tr = np.ascontiguousarray(log_transition, dtype=np.float64)
    starts = np.array([p[0] for p in pieces], dtype=np.int64)
    stops = np.array([p[1] for p in pieces], dtype=np.int64)
    return np.asarray(_posterior_kernel(em, tr, starts, stops), dtype=np.float64)
