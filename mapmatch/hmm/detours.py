"""
Observations that only a detour explains: a displaced fix the outlier tests cannot judge.

The outlier tests (:mod:`mapmatch.hmm.selection`) judge a fix against its neighbours only
where they are at most ``outlier_max_gap_s`` apart, since at sparse sampling a fix that
sticks out is usually a car that went somewhere. But a fix thrown 40 m off at 15 s can land
on another road, and then the best path the model can find goes there and back: Helsinki's
15 s trip 14 of the accuracy matrix left a 354 m service road for one fix 55 m off it and
matched 49 % too long, two transitions of -33 and -48 nats on its path where the rest cost
less than 4. So where the solved path holds a transition below ``-detour_outlier_nats``,
the inner observations within ``_WINDOW`` of it are tried, those that stick out most from
their neighbours first: each is bridged (its neighbours' two-observation trellis) and the
best path through the bridge scored from the solved trellis; a transition scores at most 0,
which bounds what a fix can gain before any route is searched, and only the fixes whose
bound could make them the best are bridged (:func:`_tries_kernel`; on 40 traces each of
13, 30 and 100 fixes at 15 and 30 s of ``bench_fixed_cost`` on Krems, Andorra, Monaco and
Helsinki, 447 of 648 tries need no bridge by the bound alone). The best of them is left out
and the trace solved again; that solution is taken when its path scores more than
``detour_outlier_nats`` better (the left-out fix's emission and both its transitions
against the one transition that bridges it), and the search goes on for a second such fix.
A genuine drive the path explains with a costly transition (a U-turn without evidence at
a dead end's end costs ``uturn_penalty``, 14 nats) gains less than that by losing its fix,
and keeps it. Nor may the gain come from the other fixes: when their emissions lose more
than ``detour_max_emission_loss`` the fix stays. A piece's ends are never tried: leaving
one out drops its transition with nothing to bridge it. A left-out fix is an outlier in the
output (placed on the path when that lies within its search radius, else unmatched).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numba import njit

from mapmatch.hmm.trellis import bridge_transitions, cuts, solve, trace_inputs

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig
    from mapmatch.hmm.candidates import Candidates
    from mapmatch.hmm.observations import Observations
    from mapmatch.hmm.solution import Solution
    from mapmatch.types import BoolArray, FloatArray, IntArray
    from roadnets import RoadNetwork

__all__ = ["drop_detour_fixes", "path_score"]

#: how far from a costly transition (in observations) the fix that forced it is looked for:
#: Helsinki 15 s trip 14's lay 4 and 7 observations from the two
_WINDOW = 8


def path_score(solution: Solution) -> float:
    """
    The log score of the solution's chosen path: its emissions and its transitions.

    Transitions across a break (between pieces) are not part of any path and count nothing.
    """
    states = solution.states
    steps = np.flatnonzero(_inside(solution))
    transitions = solution.log_transition[steps, states[steps], states[steps + 1]]
    return float(_chosen_emissions(solution).sum() + transitions.sum())


def _chosen_emissions(solution: Solution) -> FloatArray:
    """The log emission of each used position's chosen candidate."""
    return solution.log_emission[np.arange(len(solution.used)), solution.states]


def _inside(solution: Solution) -> BoolArray:
    """For each step ``t -> t + 1`` between used positions, whether it lies inside a piece."""
    inside = np.ones(max(len(solution.used) - 1, 0), dtype=bool)
    for start, _ in solution.pieces[1:]:
        inside[start - 1] = False
    return inside


@njit(cache=True, nogil=True, inline="always")
def _max_of(v, best):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """``max`` as numpy's reductions take it: a NaN wins."""
    return v if v > best or np.isnan(v) or np.isnan(best) else best


@njit(cache=True, nogil=True)
def _best_paths_kernel(em, tr, piece_lo, piece_hi):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    :func:`_best_paths` over arrays: the same sums in the same order, the same maxima.

    Plain loops (row assignments and 2-d ``np.full`` cost seconds of compiling).
    """
    n, width = em.shape
    ahead = np.empty((n, width))
    behind = np.empty((n, width))
    for t in range(n):
        for k in range(width):
            ahead[t, k] = -np.inf
            behind[t, k] = -np.inf
    for p in range(len(piece_lo)):
        start, stop = piece_lo[p], piece_hi[p]
        for k in range(width):
            ahead[start, k] = em[start, k]
            behind[stop - 1, k] = 0.0
        for t in range(start + 1, stop):
            for j in range(width):
                best = -np.inf
                for i in range(width):
                    best = _max_of(ahead[t - 1, i] + tr[t - 1, i, j], best)
                ahead[t, j] = em[t, j] + best
        for t in range(stop - 2, start - 1, -1):
            for i in range(width):
                best = -np.inf
                for j in range(width):
                    best = _max_of(tr[t, i, j] + (em[t + 1, j] + behind[t + 1, j]), best)
                behind[t, i] = best
    return ahead, behind


def _best_paths(solution: Solution) -> tuple[FloatArray, FloatArray]:
    """
    Per used position and candidate, the best path score up to it and on after it.

    ``ahead[t, k]``: the best score of a path from its piece's start that ends in candidate
    ``k`` of position ``t`` (its emission included); ``behind[t, k]``: the best score of
    the rest of the piece after it (emission of ``t`` excluded). Max-product over the solved
    trellis' emissions and transitions (compiled: :func:`_best_paths_kernel`).
    """
    ahead, behind = _best_paths_kernel(
        np.ascontiguousarray(solution.log_emission, dtype=np.float64),
        np.ascontiguousarray(solution.log_transition, dtype=np.float64),
        solution.piece_start,
        solution.piece_stop,
    )
    return ahead, behind


@njit(cache=True, nogil=True)
def _tries_kernel(states, em, tr, piece_lo, piece_hi, used, ox, oy, nats, tries):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    The fixes one round of :func:`drop_detour_fixes` tries, and a bound of what each gains.

    The steps whose chosen transition scores below ``-nats`` (inside a piece); the inner
    fixes of the pieces within :data:`_WINDOW` of one; the ``tries`` of them that stick out
    most from their neighbours (ties: the earlier first). Of those, the ones whose bound
    exceeds ``nats``: leaving a fix out drops its emission and its two transitions for one
    that bridges its neighbours, and a transition scores at most 0 (a -gap / beta less
    penalties, :func:`~mapmatch.hmm.transition.transition_score`), so the best path through
    the bridge scores at most the best path up to the left neighbour plus the best from the
    right neighbour on; rounding is monotonic, so the gain computed from a bridge is at most
    that bound computed the same way (NaN: no bound, ``inf``).

    Returns the number of fixes tried (-1: no costly step, or no inner fix near one: the
    search ends), the positions kept, their bounds and their pieces' best scores (largest
    bound first), and :func:`_best_paths`' ``ahead`` and ``behind`` (empty when not
    needed). ``tests/mapmatch/test_detours.py`` holds the premise (no transition above 0)
    and compares the search with one that bridges every try.
    """
    n, width = em.shape
    none = np.empty(0, dtype=np.int64)
    inside = np.ones(max(n - 1, 0), dtype=np.bool_)
    for p in range(1, len(piece_lo)):
        inside[piece_lo[p] - 1] = False
    costly = np.empty(n, dtype=np.int64)
    m = 0
    for t in range(1, n):
        i, j = states[t - 1], states[t]
        # a position off every piece has state -1, which numpy's indexing reads from the end
        score = tr[t - 1, i + width if i < 0 else i, j + width if j < 0 else j]
        if inside[t - 1] and score < -nats:
            costly[m] = t
            m += 1
    if m == 0:
        return -1, none, np.empty(0), np.empty(0), em[:0], em[:0]
    # the inner fixes of the pieces within _WINDOW of a costly step, and how far each sticks
    # out from its neighbours
    piece = np.full(n, -1, dtype=np.int64)
    for p in range(len(piece_lo)):
        for t in range(piece_lo[p] + 1, piece_hi[p] - 1):
            piece[t] = p
    positions = np.empty(n, dtype=np.int64)
    sticks_out = np.empty(n)
    found = 0
    for t in range(n):
        if piece[t] < 0:
            continue
        near = False
        for c in range(m):
            near = near or abs(t - costly[c]) <= _WINDOW
        if not near:
            continue
        a, b, c = used[t - 1], used[t], used[t + 1]
        mid_x = 0.5 * (ox[a] + ox[c])
        mid_y = 0.5 * (oy[a] + oy[c])
        positions[found] = t
        sticks_out[found] = np.hypot(ox[b] - mid_x, oy[b] - mid_y)
        found += 1
    if found == 0:  # no inner fix near: nothing to try
        return -1, none, np.empty(0), np.empty(0), em[:0], em[:0]
    # the `tries` that stick out most, as a stable sort on -sticks_out orders them (the
    # earlier of equals first, NaN last)
    for q in range(found):
        sticks_out[q] = np.inf if np.isnan(sticks_out[q]) else -sticks_out[q]
    tried = min(found, max(tries, 0))
    for q in range(tried):
        top = q
        for r in range(q + 1, found):
            if sticks_out[r] < sticks_out[top]:
                top = r
        if top != q:  # move it to q, keeping the order of those between
            t, v = positions[top], sticks_out[top]
            for r in range(top, q, -1):
                positions[r], sticks_out[r] = positions[r - 1], sticks_out[r - 1]
            positions[q], sticks_out[q] = t, v
    ahead, behind = _best_paths_kernel(em, tr, piece_lo, piece_hi)
    drops = np.empty(tried, dtype=np.int64)
    bounds = np.empty(tried)
    bests = np.empty(tried)
    k = 0
    for q in range(tried):
        drop = positions[q]
        best, to_left, to_right = -np.inf, -np.inf, -np.inf
        for j in range(width):
            best = _max_of(ahead[piece_hi[piece[drop]] - 1, j], best)
            to_left = _max_of(ahead[drop - 1, j], to_left)
            to_right = _max_of(em[drop + 1, j] + behind[drop + 1, j], to_right)
        bound = (to_left + to_right) - best
        if np.isnan(bound):
            bound = np.inf
        if bound > nats:  # kept largest bound first
            r = k
            while r > 0 and bounds[r - 1] < bound:
                drops[r], bounds[r], bests[r] = drops[r - 1], bounds[r - 1], bests[r - 1]
                r -= 1
            drops[r], bounds[r], bests[r] = drop, bound, best
            k += 1
    return tried, drops[:k], bounds[:k], bests[:k], ahead, behind


def drop_detour_fixes(
    net: RoadNetwork,
    obs: Observations,
    cands: Candidates,
    solution: Solution,
    missing_before: IntArray,
    config: MatchConfig,
) -> tuple[Solution, IntArray] | None:
    """
    Leave out the observations only a detour explains (see the module's description).

    Parameters
    ----------
    net, obs, cands
        What :func:`~mapmatch.hmm.trellis.solve` solved.
    solution
        Its solution.
    missing_before
        From :func:`~mapmatch.hmm.trellis.model_fixes`: where the trace splits.
    config
        ``detour_outlier_nats`` and ``detour_max_emission_loss`` decide;
        ``max_detour_tries`` (fixes tried in all) bounds the search.

    Returns
    -------
    tuple of Solution and IntArray, or None
        The better solution and the observations it left out (indices into ``obs``);
        ``None`` when no transition is that costly or leaving a fix out does not pay.
    """
    nats, tries = config.detour_outlier_nats, config.max_detour_tries
    inputs: tuple[Any, ...] | None = None  # the trace's arrays, once a bridge needs them
    left_out: list[int] = []
    while tries > 0:
        used = solution.used
        # the fixes within _WINDOW of a transition below -nats, those that stick out most
        # from their neighbours first: the fix that forced it is thrown off, and the detour
        # can start and end far from it. A piece's ends are left alone: leaving one out
        # drops its transition with nothing to bridge it (a 30 s step round a hairpin costs
        # 20 nats on the noise-free truth), and the end tests judge them
        f8, i8 = np.float64, np.int64  # one compiled signature (no copies: they are so)
        tried, drops, bounds, bests, ahead, behind = _tries_kernel(
            np.ascontiguousarray(solution.states, i8),
            np.ascontiguousarray(solution.log_emission, f8),
            np.ascontiguousarray(solution.log_transition, f8),
            solution.piece_start,
            solution.piece_stop,
            np.ascontiguousarray(used, i8),
            np.ascontiguousarray(obs.x, f8),
            np.ascontiguousarray(obs.y, f8),
            float(nats),
            int(tries),
        )
        if tried < 0:
            break
        tries -= tried
        # each try bridges the fix's neighbours (a two-observation trellis) and scores the
        # best path through that bridge from the solved trellis, forwards and backwards:
        # solving the stretch around every fix with and without it cost 1.6x the whole
        # match on Helsinki 15 s. The trellis alone knows no arrival rule (a fix held behind
        # a junction stands on the road the car came by), so it only ranks the fixes, and
        # the best is solved whole (solving the best two found no more on the matrix). A
        # fix whose bound (_tries_kernel) cannot beat nats or the best gain found is not
        # bridged: it could not be the one chosen
        estimates: list[tuple[float, int]] = []
        top = nats
        for drop, bound, best in zip(drops.tolist(), bounds.tolist(), bests.tolist(), strict=True):
            if bound < top:
                break  # bounds come largest first: none of the rest can be chosen
            inputs = inputs or trace_inputs(obs, cands, config)
            pair = used[[drop - 1, drop + 1]]
            bridge = bridge_transitions(net, inputs, pair, cuts(pair, missing_before), solution)
            width = bridge.shape[-1]  # the pair's padding, within the trace's
            if not len(bridge) or not width:
                continue
            through = (
                ahead[drop - 1, :width, None]
                + bridge[0]
                + (solution.log_emission[drop + 1, :width] + behind[drop + 1, :width])[None, :]
            )
            gain = float(through.max()) - best
            if gain > nats:
                estimates.append((gain, drop))
                top = max(top, gain)
        if not estimates:
            break
        _, drop = max(estimates)
        kept = np.delete(used, drop)
        trial = solve(net, obs, cands, kept, cuts(kept, missing_before), config)
        gained = path_score(trial) - path_score(solution) > nats
        if not gained or len(trial.piece_start) > len(solution.piece_start):
            break
        # the gain must not come from moving the other fixes off their roads (the emission
        # floor makes a wrong road cheap for a fix or two)
        before = np.delete(_chosen_emissions(solution), drop).sum()
        if before - _chosen_emissions(trial).sum() > config.detour_max_emission_loss:
            break
        left_out.append(int(used[drop]))
        solution = trial
    return (solution, np.asarray(left_out, dtype=np.int64)) if left_out else None
