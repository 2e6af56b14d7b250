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
best path through the bridge scored from the solved trellis. The best of them is left out
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


@njit(cache=True, nogil=True)
def _best_paths_kernel(em, tr, piece_lo, piece_hi):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """:func:`_best_paths` over arrays: the same sums and maxima, NaN propagated as numpy's."""
    n, width = em.shape
    ahead = np.full((n, width), -np.inf)
    behind = np.full((n, width), -np.inf)
    for p in range(len(piece_lo)):
        start, stop = piece_lo[p], piece_hi[p]
        ahead[start] = em[start]
        for t in range(start + 1, stop):
            for j in range(width):
                best = -np.inf
                for i in range(width):
                    v = ahead[t - 1, i] + tr[t - 1, i, j]
                    if v > best or np.isnan(v):
                        best = v
                        if np.isnan(v):
                            break
                ahead[t, j] = em[t, j] + best
        behind[stop - 1] = 0.0
        for t in range(stop - 2, start - 1, -1):
            for i in range(width):
                best = -np.inf
                for j in range(width):
                    v = tr[t, i, j] + (em[t + 1, j] + behind[t + 1, j])
                    if v > best or np.isnan(v):
                        best = v
                        if np.isnan(v):
                            break
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
    bounds = np.asarray(solution.pieces, dtype=np.int64).reshape(-1, 2)
    ahead, behind = _best_paths_kernel(
        np.ascontiguousarray(solution.log_emission, dtype=np.float64),
        np.ascontiguousarray(solution.log_transition, dtype=np.float64),
        np.ascontiguousarray(bounds[:, 0]),
        np.ascontiguousarray(bounds[:, 1]),
    )
    return ahead, behind


def _costly_steps(solution: Solution, floor: float) -> IntArray:
    """Used positions ``t`` whose chosen transition from ``t - 1`` scores below ``floor``."""
    states = solution.states
    steps = np.arange(1, len(solution.used))
    scores = solution.log_transition[steps - 1, states[steps - 1], states[steps]]
    return np.asarray(steps[_inside(solution) & (scores < floor)], dtype=np.int64)


def _bridged_gains(
    net: RoadNetwork,
    inputs: tuple[Any, ...],
    solution: Solution,
    ahead: FloatArray,
    behind: FloatArray,
    piece: IntArray,
    order: IntArray,
    missing_before: IntArray,
    nats: float,
) -> list[tuple[float, int]]:
    """
    What leaving out each fix of ``order`` gains, where it may gain more than ``nats``.

    A fix's neighbours are bridged (:func:`~mapmatch.hmm.trellis.bridge_transitions`) and
    the best path through the bridge, from its piece's start to its end, scored against
    the piece's best (``ahead``/``behind``: :func:`_best_paths`); the gain and the used
    position of each fix that gains more than ``nats``. ``max`` of them picks the same fix
    as bridging every fix of ``order`` would.

    A transition scores at most 0 (:func:`~mapmatch.hmm.transition.transition_score`), so
    the best path through a bridge scores at most the best path up to the fix's left
    neighbour plus the best from its right neighbour on (their emission included), in
    floating point too (rounding is monotonic). A fix whose bound does not exceed ``nats``,
    or falls below a gain already found, needs no bridge: on the Krems, Andorra, Monaco and
    Helsinki traces of ``bench_fixed_cost`` at 15 and 30 s, 447 of 648 tries.
    """
    em = solution.log_emission
    to_right = (em + behind).max(axis=1)
    to_left = ahead.max(axis=1)
    bounds = []
    for drop in order.tolist():
        _, stop = solution.pieces[piece[drop]]
        best = float(ahead[stop - 1].max())
        bound = float(to_left[drop - 1] + to_right[drop + 1]) - best
        if np.isnan(bound):
            bound = np.inf  # no bound: bridged
        if bound > nats:
            bounds.append((bound, drop, best))
    used = solution.used
    estimates: list[tuple[float, int]] = []
    top = nats
    for bound, drop, best in sorted(bounds, reverse=True):
        if bound < top:
            break  # neither this fix nor the rest can beat the gain found
        pair = used[[drop - 1, drop + 1]]
        bridge = bridge_transitions(net, inputs, pair, cuts(pair, missing_before))
        width = bridge.shape[-1]  # the pair's padding, within the trace's
        if not len(bridge) or not width:
            continue
        through = (
            ahead[drop - 1, :width, None]
            + bridge[0]
            + (em[drop + 1, :width] + behind[drop + 1, :width])[None, :]
        )
        gain = float(through.max()) - best
        if gain > nats:
            estimates.append((gain, drop))
            top = max(top, gain)
    return estimates


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
    inputs: tuple[Any, ...] | None = None  # the trace's arrays, once a try needs them
    left_out: list[int] = []
    while tries > 0:
        costly = _costly_steps(solution, -nats)
        if not len(costly):
            break
        used = solution.used
        # a piece's ends are left alone: leaving one out drops its transition with nothing
        # to bridge it (a 30 s step round a hairpin costs 20 nats on the noise-free truth),
        # and the end tests judge them
        piece = np.empty(len(used), dtype=np.int64)
        inner = np.ones(len(used), dtype=bool)
        for k, (start, stop) in enumerate(solution.pieces):
            piece[start:stop] = k
            inner[[start, stop - 1]] = False
        positions = np.flatnonzero(inner)
        if not len(positions):
            break
        # within the detour, the fixes that stick out most from their neighbours first: the
        # fix that forced it is thrown off, and the detour can start and end far from it
        reach = np.abs(positions[:, None] - costly[None, :]).min(axis=1)
        positions = positions[reach <= _WINDOW]
        xs, ys = obs.x[used], obs.y[used]
        mid_x = 0.5 * (xs[positions - 1] + xs[positions + 1])
        mid_y = 0.5 * (ys[positions - 1] + ys[positions + 1])
        sticks_out = np.hypot(xs[positions] - mid_x, ys[positions] - mid_y)
        order = positions[np.argsort(-sticks_out, kind="stable")][:tries]
        # each try bridges the fix's neighbours (a two-observation trellis) and scores the
        # best path through that bridge from the solved trellis, forwards and backwards:
        # solving the stretch around every fix with and without it cost 1.6x the whole
        # match on Helsinki 15 s. The trellis alone knows no arrival rule (a fix held behind
        # a junction stands on the road the car came by), so it only ranks the fixes, and
        # the best is solved whole (solving the best two found no more on the matrix)
        tries -= len(order)
        ahead, behind = _best_paths(solution)
        inputs = inputs or trace_inputs(obs, cands, config)
        estimates = _bridged_gains(
            net, inputs, solution, ahead, behind, piece, order, missing_before, nats
        )
        if not estimates:
            break
        _, drop = max(estimates)
        kept = np.delete(used, drop)
        trial = solve(net, obs, cands, kept, cuts(kept, missing_before), config)
        gained = path_score(trial) - path_score(solution) > nats
        if not gained or len(trial.pieces) > len(solution.pieces):
            break
        # the gain must not come from moving the other fixes off their roads (the emission
        # floor makes a wrong road cheap for a fix or two)
        before = np.delete(_chosen_emissions(solution), drop).sum()
        if before - _chosen_emissions(trial).sum() > config.detour_max_emission_loss:
            break
        left_out.append(int(used[drop]))
        solution = trial
    return (solution, np.asarray(left_out, dtype=np.int64)) if left_out else None
