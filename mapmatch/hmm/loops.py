"""Loops and spurs in a matched path that the fixes do not support, taken out.

(Over 400 lines on purpose: finding loops and spurs and pricing them are one compiled pass over
the path.)

The HMM is first order: it prices each move on its own, so it cannot see that three cheap
moves in a row go round a 40 m roundabout, or that a drive back after a U-turn in the middle of
a road, then forward again after a second one, ends where it began. Scattered fixes around a
stop near a small ring, or a burst of fixes pulled to one side, are explained that way. A loop
(the path passes the same node twice, or drives back from a U-turn to the place where it
turned) is a second-order event, and it is priced here, after Viterbi: the loop's fixes are
scored once as driven (their chosen candidates and moves) and once as a car that held its
place where the loop starts (every fix's emission there, no moves), each with the moves into
and out of the loop. A loop stays only when it explains the fixes better by at least
``loop_penalty`` nats; a car going round a block or into a dead end has fixes all along the
loop, far from its start, and keeps it easily. Holding where the loop begins pays for a U-turn
there when the path without the loop turns round at that place and drives back further than a
held car scatters (a car that drove into a dead-end spur off a junction and came back the way
it came), as Viterbi would have charged it. A loop that turns round and could not be
driven in the time between its fixes, the car slowing to ``uturn_speed_mps`` to turn and
neither braking nor accelerating faster than ``travel_accel_mps2``, is taken out whatever its
price: a burst of fixes to one side at 1 s no longer buys a 20 m spur out and back in a second.
A loop that a turn restriction forces (the only legal way round a banned turn) is never taken
out.

Compiled (:func:`collapse_kernel`): the path walk of :mod:`mapmatch.hmm.pathwalk` runs it on
every piece that passes a place twice.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from mapmatch._sums import pairwise_sum
from mapmatch.hmm.emission import distance_score
from mapmatch.hmm.geometry import network_geometry, point_on_edge
from mapmatch.hmm.observations import between_kernel, sigma_of_distances
from mapmatch.hmm.params import (
    P_ACCEL,
    P_STANDSTILL_M,
    P_STANDSTILL_SIGMAS,
    P_UTURN_PENALTY,
    P_UTURN_SPEED,
)
from mapmatch.hmm.transition import transition_score

if TYPE_CHECKING:
    from typing import Any

    from roadnets import RoadNetwork

__all__ = [
    "SCATTER_MIN_OBSERVATIONS",
    "chosen_scatter_kernel",
    "collapse_kernel",
    "loop_network",
]

#: Fewest chosen observations from which :func:`chosen_scatter_kernel` estimates a scatter.
SCATTER_MIN_OBSERVATIONS = 5


_EPS_M = 1e-6


@njit(cache=True, nogil=True)
def _loops(e, lo, hi, net):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    The loops of a path, innermost first: ``(x, y, s0, s1)`` arrays.

    Each node passed twice (the stretch between the passes), then each drive back from a
    mid-road U-turn to the place where it turned; sorted by length, stably.
    """
    edge_len, edge_u, edge_v, edge_twin, node_x, node_y = net[:6]
    geom = net[8]
    n = len(e)
    nodes = np.empty(2 * n, dtype=np.int64)
    at = np.empty(2 * n)
    m = 0
    base = 0.0
    for k in range(n):
        if lo[k] <= _EPS_M:
            m = _visit(nodes, at, m, edge_u[e[k]], base)
        base += hi[k] - lo[k]
        if hi[k] >= edge_len[e[k]] - _EPS_M:
            m = _visit(nodes, at, m, edge_v[e[k]], base)
    by_node = np.argsort(nodes[:m], kind="mergesort")
    where = np.empty(m + n, dtype=np.int64)  # the visit that closes each loop (order found)
    lx, ly, s0, s1 = np.empty(m + n), np.empty(m + n), np.empty(m + n), np.empty(m + n)
    count = 0
    for i in range(1, m):
        j, k = by_node[i - 1], by_node[i]
        if nodes[j] == nodes[k] and at[k] > at[j] + _EPS_M:
            where[count] = k
            lx[count], ly[count] = node_x[nodes[k]], node_y[nodes[k]]
            s0[count], s1[count] = at[j], at[k]
            count += 1
    found = np.argsort(where[:count], kind="mergesort")
    lx[:count], ly[:count] = lx[:count][found], ly[:count][found]
    s0[:count], s1[:count] = s0[:count][found], s1[:count][found]
    starts = np.empty(n + 1)
    starts[0] = 0.0
    for k in range(n):
        starts[k + 1] = starts[k] + (hi[k] - lo[k])
    for k in range(n - 1):
        turn = hi[k]
        if edge_twin[e[k]] != e[k + 1] or turn >= edge_len[e[k]] - _EPS_M:
            continue  # not a U-turn in the middle of the road
        for j in range(k + 2, n):
            if e[j] == e[k] and lo[j] - _EPS_M <= turn <= hi[j] + _EPS_M:
                lx[count], ly[count] = point_on_edge(e[k], turn, *geom)
                s0[count], s1[count] = starts[k + 1], starts[j] + turn - lo[j]
                count += 1
                break
    order = np.argsort(s1[:count] - s0[:count], kind="mergesort")
    return lx[:count][order], ly[:count][order], s0[:count][order], s1[:count][order]


@njit(cache=True, nogil=True, inline="always")
def _visit(nodes, at, m, node, here):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Add a node passed, unless it repeats the last one passed (the path's node visits)."""
    if m == 0 or nodes[m - 1] != node or abs(at[m - 1] - here) > _EPS_M:
        nodes[m], at[m] = node, here
        m += 1
    return m


@njit(cache=True, nogil=True)
def _turns(e, lo, hi, s0, s1, edge_len, edge_v, edge_twin, out_ptr):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    The path's U-turns between ``s0`` and ``s1`` along it.

    Returns how many there are, but at dead ends, and where along the path the first of them
    all is (NaN: none).
    """
    count = 0
    first = np.nan
    base = 0.0
    for k in range(len(e) - 1):
        base += hi[k] - lo[k]
        if not (s0 - _EPS_M <= base <= s1 + _EPS_M) or edge_twin[e[k]] != e[k + 1]:
            continue
        if np.isnan(first):
            first = base
        node = edge_v[e[k]]
        at_node = hi[k] >= edge_len[e[k]] - _EPS_M
        if not (at_node and out_ptr[node + 1] - out_ptr[node] <= 1):
            count += 1
    return count, first


@njit(cache=True, nogil=True, inline="always")
def _time_to_cover(distance, speed, accel):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Least time to drive ``distance`` from ``speed`` at ``accel`` (or to brake into it)."""
    return (np.sqrt(speed * speed + 2.0 * accel * distance) - speed) / accel


@njit(cache=True, nogil=True)
def _too_fast(along, before, after, turn_at, model):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Whether a turn round ``turn_at`` along the path is too fast for the fixes' times.

    The car drives out from observation ``before`` (``along`` the path) to the turn and back
    to observation ``after``, slowing to ``uturn_speed_mps`` to turn and neither braking nor
    accelerating faster than ``travel_accel_mps2``; each side's length less a sigma of the
    fixes' own error.
    """
    start, used, otime, osigma, params = model[0], model[1], model[6], model[7], model[8]
    if params[P_ACCEL] <= 0:
        return False
    a, b = used[start + before], used[start + after]
    sigma_ends = max(osigma[a], osigma[b])
    least = _time_to_cover(
        max(turn_at - along[before] - sigma_ends, 0.0), params[P_UTURN_SPEED], params[P_ACCEL]
    ) + _time_to_cover(
        max(along[after] - turn_at - sigma_ends, 0.0), params[P_UTURN_SPEED], params[P_ACCEL]
    )
    return otime[b] - otime[a] < least


@njit(cache=True, nogil=True)
def _cut(e, lo, hi, s0, s1):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """The path without its stretch between ``s0`` and ``s1`` along it (cut mid-stretch too)."""
    n = len(e)
    ke, klo, khi = np.empty(2 * n, dtype=np.int64), np.empty(2 * n), np.empty(2 * n)
    m = 0
    base = 0.0
    for k in range(n):
        a, b = base, base + (hi[k] - lo[k])  # this stretch's extent along the path
        if b <= s0 + _EPS_M or a >= s1 - _EPS_M:
            ke[m], klo[m], khi[m] = e[k], lo[k], hi[k]
            m += 1
        else:
            if a < s0 - _EPS_M:
                ke[m], klo[m], khi[m] = e[k], lo[k], lo[k] + (s0 - a)
                m += 1
            if b > s1 + _EPS_M:
                ke[m], klo[m], khi[m] = e[k], lo[k] + (s1 - a), hi[k]
                m += 1
        base = b
    j = 0  # the two ends of a cut on one edge join up again
    for k in range(m):
        if j and ke[j - 1] == ke[k] and abs(khi[j - 1] - klo[k]) < 1e-3:
            khi[j - 1] = khi[k]
        else:
            ke[j], klo[j], khi[j] = ke[k], klo[k], khi[k]
            j += 1
    if j == 0:
        return e[:1].copy(), lo[:1].copy(), hi[:1].copy()
    return ke[:j].copy(), klo[:j].copy(), khi[:j].copy()


@njit(cache=True, nogil=True)
def _legal(e, edge_u, edge_v, trans_ptr, trans_to, state_edge):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Whether the path's moves from edge to edge are all allowed (restrictions obeyed)."""
    drive = np.empty(len(e), dtype=np.int64)
    m = 0
    for k in range(len(e)):
        if k == 0 or e[k] != e[k - 1]:
            drive[m] = e[k]
            m += 1
    for k in range(m - 1):
        if edge_v[drive[k]] != edge_u[drive[k + 1]]:
            return True  # a jump in the path (drawn as such): nothing to check across it
    if m == 0:
        return True
    state = drive[0]
    for k in range(1, m):  # TurnGraph.first_banned: follow the restricted copies
        nxt = -1
        for i in range(trans_ptr[state], trans_ptr[state + 1]):
            if state_edge[trans_to[i]] == drive[k]:
                nxt = trans_to[i]
                break
        if nxt < 0:
            return False
        state = nxt
    return True


@njit(cache=True, nogil=True)
def _gain(along, e, lo, hi, place_x, place_y, s0, s1, model, travel, net):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Log-likelihood of the loop as driven minus that of holding where it begins."""
    start, used, states, em_pad, ox, oy, otime, osigma, params = model[:9]
    scatter, chosen_dist = model[10], model[11]
    edge_len, edge_v, edge_twin, out_ptr = net[0], net[2], net[3], net[6]
    n = len(along)
    before, after, inside = -1, -1, 0
    for i in range(n):
        if along[i] <= s0 + _EPS_M:
            before = i
    for i in range(n - 1, -1, -1):
        if along[i] >= s1 - _EPS_M:
            after = i
    for i in range(n):
        if s0 + _EPS_M < along[i] < s1 - _EPS_M:
            inside += 1
    if before < 0 or after < 0 or after <= before:
        return np.inf  # the loop is not between observations of the piece: keep it
    k = used[start + before : start + after + 1]
    steps = len(k) - 1
    # a car turning round slows to uturn_speed_mps there: a loop that turns round faster
    # than that allows, each side's length less a sigma of the fixes' own error, was never
    # driven (a 14 m spur out and back between two fixes 1 s apart at 8 m/s)
    uturns, turn_at = _turns(e, lo, hi, s0, s1, edge_len, edge_v, edge_twin, out_ptr)
    if np.isfinite(turn_at) and _too_fast(along, before, after, turn_at, model):
        return -np.inf
    odometer, speed_m, slack_m, unknown_lo, unknown_hi = travel
    if len(odometer) or len(speed_m):
        travel_m, slack = between_kernel(k, odometer, speed_m, slack_m, unknown_lo, unknown_hi)
    else:
        travel_m, slack = np.full(steps, np.nan), np.zeros(steps)
    penalty = params[P_UTURN_PENALTY]
    as_driven = np.empty(steps)
    as_held = np.empty(steps)
    held = np.zeros(steps)
    held[0] = s0 - along[before]
    if inside:
        held[steps - 1] = along[after] - s1
    else:
        held[steps - 1] = along[after] - along[before] - (s1 - s0)
    for i in range(steps):
        a, b = k[i], k[i + 1]
        gc = np.hypot(ox[b] - ox[a], oy[b] - oy[a])
        dt = otime[b] - otime[a]
        sigma = max(osigma[a], osigma[b])
        driven = along[before + i + 1] - along[before + i]
        # no speed term (no free-flow time): both alternatives alike
        as_driven[i] = transition_score(
            gc, driven, np.inf, False, dt, sigma, travel_m[i], slack[i], penalty, params
        )
        as_held[i] = transition_score(
            gc, held[i], np.inf, False, dt, sigma, travel_m[i], slack[i], penalty, params
        )
    em_driven = np.empty(inside)
    em_held = np.empty(inside)
    j = 0
    for i in range(n):
        if s0 + _EPS_M < along[i] < s1 - _EPS_M:
            t = start + i
            o = used[t]
            # both priced at the scatter the trace shows when it is below the assumed sigma:
            # exact fixes 15 m into a dead end are no held car's scatter
            sigma = min(osigma[o], scatter)
            em_driven[j] = (
                em_pad[t, states[t]]
                - distance_score(chosen_dist[t], osigma[o], params)
                + distance_score(chosen_dist[t], sigma, params)
            )
            em_held[j] = distance_score(np.hypot(ox[o] - place_x, oy[o] - place_y), sigma, params)
            j += 1
    # the loop's U-turns cost what they cost in Viterbi, but one at a dead end's end is no
    # choice: the loop into a dead end is priced by loop_penalty alone
    driven_ll = (
        pairwise_sum(as_driven, 0, steps) + pairwise_sum(em_driven, 0, inside)
    ) - penalty * uturns
    held_ll = pairwise_sum(as_held, 0, steps) + pairwise_sum(em_held, 0, inside)
    return driven_ll - held_ll


@njit(cache=True, nogil=True)
def _turn_round_held(e, lo, hi, ce, clo, chi, along, s0, s1, model, net):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    What holding where a loop begins pays for a turn round there: a U-turn, or nothing.

    A car held at the loop's start that then drives back the way it came (out of a dead-end
    spur off a junction onto the road it came by) turned round there, as Viterbi would have
    charged it: it does when the path without the loop (``ce, clo, chi``) turns round at
    ``s0`` where the path with it did not, and a fix after the loop lies further along than
    a held car's scatter (a parked car's fixes a few metres back are no drive back).
    """
    start, used, osigma, params = model[0], model[1], model[7], model[8]
    edge_len, edge_v, edge_twin, out_ptr = net[0], net[2], net[3], net[6]
    made = _turns(ce, clo, chi, s0, s0, edge_len, edge_v, edge_twin, out_ptr)[0]
    had = (
        _turns(e, lo, hi, s0, s0, edge_len, edge_v, edge_twin, out_ptr)[0]
        + _turns(e, lo, hi, s1, s1, edge_len, edge_v, edge_twin, out_ptr)[0]
    )
    if made <= had:
        return 0.0
    for q in range(len(along)):
        scatter = max(params[P_STANDSTILL_M], params[P_STANDSTILL_SIGMAS] * osigma[used[start + q]])
        if along[q] - s1 > scatter:
            return (made - had) * params[P_UTURN_PENALTY]
    return 0.0


@njit(cache=True, nogil=True)
def collapse_kernel(e, lo, hi, along, model, travel, net):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Take out the loops of one piece's path that do not pay for themselves.

    ``(e, lo, hi)`` are the path's stretches and ``along`` the distance along it of each of
    the piece's observations; ``model`` is ``(start, used, states, log_emission, x, y, time,
    sigma, params, loop_penalty, scatter, chosen distance)`` of the solution (the piece
    starting at used position ``start``) and its observations, ``travel`` their
    travel arrays, ``net`` :func:`loop_network`. Returns the new stretches and distances and
    how many loops were taken out. The innermost loops go first; each one taken out leaves
    its observations at its node.
    """
    edge_u, edge_v = net[1], net[2]
    trans_ptr, trans_to, state_edge = net[7][0], net[7][1], net[7][2]
    loop_penalty = model[9]
    removed = 0
    along = along.copy()
    for _ in range(64):  # each pass takes out at most one loop
        lx, ly, ls0, ls1 = _loops(e, lo, hi, net)
        cut = False
        for i in range(len(ls0)):
            s0, s1 = ls0[i], ls1[i]
            gain = _gain(along, e, lo, hi, lx[i], ly[i], s0, s1, model, travel, net)
            if gain >= loop_penalty:
                continue
            ce, clo, chi = _cut(e, lo, hi, s0, s1)
            if gain + _turn_round_held(e, lo, hi, ce, clo, chi, along, s0, s1, model, net) >= (
                loop_penalty
            ):
                continue
            if _legal(ce, edge_u, edge_v, trans_ptr, trans_to, state_edge):
                # a loop that a turn restriction forces stays
                e, lo, hi = ce, clo, chi
                for j in range(len(along)):
                    along[j] = (
                        along[j] - (s1 - s0) if along[j] >= s1 - _EPS_M else min(along[j], s0)
                    )
                cut = True
                break
        if not cut:
            break
        removed += 1
    e, lo, hi, along, ends = _end_turns(e, lo, hi, along, model, net)
    return e, lo, hi, along, removed + ends


@njit(cache=True, nogil=True)
def _end_turns(e, lo, hi, along, model, net):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Take out a turn back at the path's end, then one at its start, that is too fast to drive.

    After its last U-turn a path may drive back to its last observation, and no loop closes
    behind it for :func:`_gain` to price: a last fix thrown 40 m behind the one before, 1 s
    earlier, is explained that way. A drive back that could not be driven in the time
    (:func:`_too_fast`, the rule loops obey) ends the path where it turned, its observations
    held there. Likewise a path that starts by driving to a U-turn starts where it turned.
    """
    edge_twin = net[3]
    removed = 0
    n = len(e)
    starts = np.empty(n + 1)
    starts[0] = 0.0
    for k in range(n):
        starts[k + 1] = starts[k] + (hi[k] - lo[k])
    last = len(along) - 1
    for k in range(n - 2, -1, -1):  # the last U-turn
        if edge_twin[e[k]] == e[k + 1]:
            turn = starts[k + 1]
            before = -1
            for i in range(last + 1):
                if along[i] <= turn + _EPS_M:
                    before = i
            if 0 <= before < last and _too_fast(along, before, last, turn, model):
                e, lo, hi = e[: k + 1].copy(), lo[: k + 1].copy(), hi[: k + 1].copy()
                along = np.minimum(along, turn)
                removed += 1
            break
    for k in range(len(e) - 1):  # the first U-turn
        if edge_twin[e[k]] == e[k + 1]:
            turn = starts[k + 1]
            after = last + 1
            for i in range(last, -1, -1):
                if along[i] >= turn - _EPS_M:
                    after = i
            if 0 < after <= last and _too_fast(along, 0, after, turn, model):
                e, lo, hi = e[k + 1 :].copy(), lo[k + 1 :].copy(), hi[k + 1 :].copy()
                along = np.maximum(along - turn, 0.0)
                removed += 1
            break
    return e, lo, hi, along, removed


def loop_network(net: RoadNetwork) -> tuple[Any, ...]:
    """The network arrays :func:`collapse_kernel` reads."""
    a, turns = net.arrays, net.turns
    return (
        a.edge_length_m,
        a.edge_u,
        a.edge_v,
        a.edge_twin,
        a.node_x,
        a.node_y,
        a.out_ptr,
        (turns.trans_ptr, turns.trans_to, turns.state_edge),
        network_geometry(net),
    )


@njit(cache=True, nogil=True)
def chosen_scatter_kernel(c_ptr, c_dist, states, used, o_first, o_stop):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Each used observation's chosen distance, and the scatter the matched fixes show.

    The first: the distance of each used observation's chosen candidate from it (NaN: none
    chosen). The second: the position sigma the matched fixes show about their roads (inf:
    fewer than :data:`SCATTER_MIN_OBSERVATIONS` chosen),
    :func:`~mapmatch.hmm.observations.sigma_of_distances` of those distances, each
    scaled by the square root of the observation's fix count, since a centroid of ``m``
    fixes scatters ``sqrt(m)`` times less.
    """
    n = len(states)
    chosen_m = np.full(n, np.nan)
    scaled = np.empty(n)
    m = 0
    for i in range(n):
        if states[i] >= 0:
            chosen_m[i] = c_dist[c_ptr[i] + states[i]]
            o = used[i]
            scaled[m] = chosen_m[i] * np.sqrt(float(o_stop[o] - o_first[o]))
            m += 1
    if m < SCATTER_MIN_OBSERVATIONS:
        return chosen_m, np.inf
    return chosen_m, sigma_of_distances(scaled[:m])
