"""Loops and spurs in a matched path that the fixes do not support, taken out.

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
loop, far from its start, and keeps it easily. A loop that a turn restriction forces (the
only legal way round a banned turn) is never taken out.
"""

from __future__ import annotations

import itertools
from typing import TYPE_CHECKING

import numpy as np

from mapmatch.hmm.emission import distance_emission
from mapmatch.hmm.routes import ROUTE_STANDSTILL, ROUTE_VIA_GRAPH
from mapmatch.hmm.transition import log_transition

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig
    from mapmatch.hmm.observations import Observations
    from mapmatch.hmm.solution import Solution
    from mapmatch.types import FloatArray
    from roadnets import RoadNetwork

__all__ = ["collapse_loops"]


_EPS_M = 1e-6


def _node_visits(net: RoadNetwork, entries: list[list[float]]) -> list[tuple[int, float]]:
    """The nodes the path passes, with the distance along the path where it passes them."""
    arrays = net.arrays
    visits: list[tuple[int, float]] = []
    base = 0.0
    for edge, lo, hi in entries:
        e = int(edge)
        if lo <= _EPS_M:
            visits.append((int(arrays.edge_u[e]), base))
        base += hi - lo
        if hi >= arrays.edge_length_m[e] - _EPS_M:
            visits.append((int(arrays.edge_v[e]), base))
    unique: list[tuple[int, float]] = []
    for node, at in visits:
        if not unique or unique[-1][0] != node or abs(unique[-1][1] - at) > _EPS_M:
            unique.append((node, at))
    return unique


def _turnback_returns(
    net: RoadNetwork, entries: list[list[float]]
) -> list[tuple[tuple[float, float], float, float]]:
    """
    Drives back from a U-turn in the middle of a road that return to where it turned.

    For each mid-road U-turn (a stretch of edge ``e`` ending at ``X``, then its reverse twin)
    the first later stretch of ``e`` that passes ``X`` again closes the excursion: its place
    ``(x, y)``, the distance along the path of the turn and of the return to ``X``.
    """
    arrays = net.arrays
    out: list[tuple[tuple[float, float], float, float]] = []
    starts = np.concatenate(([0.0], np.cumsum([hi - lo for _, lo, hi in entries])))
    for k in range(len(entries) - 1):
        e, _, turn = entries[k]
        nxt = int(entries[k + 1][0])
        ek = int(e)
        if arrays.edge_twin[ek] != nxt or turn >= arrays.edge_length_m[ek] - _EPS_M:
            continue  # not a U-turn in the middle of the road
        for m in range(k + 2, len(entries)):
            em, lo, hi = entries[m]
            if int(em) == ek and lo - _EPS_M <= turn <= hi + _EPS_M:
                px, py = net.point_on_edge(np.array([ek]), np.array([turn]))
                out.append(
                    (
                        (float(px[0]), float(py[0])),
                        float(starts[k + 1]),
                        float(starts[m] + turn - lo),
                    )
                )
                break
    return out


def _free_uturns(net: RoadNetwork, entries: list[list[float]], s0: float, s1: float) -> int:
    """U-turns the path makes between ``s0`` and ``s1`` along it, but at dead ends."""
    arrays = net.arrays
    count = 0
    base = 0.0
    for k in range(len(entries) - 1):
        e, lo, hi = entries[k]
        base += hi - lo
        nxt = int(entries[k + 1][0])
        if not (s0 - _EPS_M <= base <= s1 + _EPS_M) or arrays.edge_twin[int(e)] != nxt:
            continue
        node = int(arrays.edge_v[int(e)])
        at_node = hi >= arrays.edge_length_m[int(e)] - _EPS_M
        if not (at_node and arrays.out_ptr[node + 1] - arrays.out_ptr[node] <= 1):
            count += 1
    return count


def _cut(entries: list[list[float]], s0: float, s1: float) -> list[list[float]]:
    """The path without its stretch between ``s0`` and ``s1`` along it (cut mid-stretch too)."""
    kept: list[list[float]] = []
    base = 0.0
    for edge, lo, hi in entries:
        length = hi - lo
        a, b = base, base + length  # this stretch's extent along the path
        if b <= s0 + _EPS_M or a >= s1 - _EPS_M:
            kept.append([edge, lo, hi])
        else:
            if a < s0 - _EPS_M:
                kept.append([edge, lo, lo + (s0 - a)])
            if b > s1 + _EPS_M:
                kept.append([edge, lo + (s1 - a), hi])
        base = b
    merged: list[list[float]] = []
    for entry in kept:  # the two ends of a cut on one edge join up again
        if merged and int(merged[-1][0]) == int(entry[0]) and abs(merged[-1][2] - entry[1]) < 1e-3:
            merged[-1][2] = entry[2]
        else:
            merged.append(entry)
    return merged or entries[:1]


def _loop_gain(
    net: RoadNetwork,
    obs: Observations,
    solution: Solution,
    start: int,
    along: FloatArray,
    entries: list[list[float]],
    place: tuple[float, float],
    s0: float,
    s1: float,
    config: MatchConfig,
) -> float:
    """Log-likelihood of the loop as driven minus that of holding at its node."""
    used, states = solution.used, solution.states
    inside = np.flatnonzero((along > s0 + _EPS_M) & (along < s1 - _EPS_M))
    ahead, behind = np.flatnonzero(along <= s0 + _EPS_M), np.flatnonzero(along >= s1 - _EPS_M)
    if not len(ahead) or not len(behind) or behind[0] <= ahead[-1]:
        return np.inf  # the loop is not between observations of the piece: keep it
    before, after = int(ahead[-1]), int(behind[0])
    chain = np.arange(before, after + 1)  # positions in the piece, the loop's and its ends
    k = used[start + chain]
    step_m = np.hypot(np.diff(obs.x[k]), np.diff(obs.y[k]))
    dt = np.diff(obs.time_s[k])
    sigma = np.maximum(obs.sigma_m[k[:-1]], obs.sigma_m[k[1:]])
    travel = None
    if obs.travel is not None:
        travel = obs.travel.between(k)
    kinds = np.full(len(chain) - 1, ROUTE_VIA_GRAPH)
    driven = np.diff(along[chain])
    no_time = np.full(len(driven), np.inf)  # no speed term: both alternatives alike
    as_driven = log_transition(step_m, driven, no_time, kinds, dt, sigma, config, travel)
    em_driven = solution.log_emission[start + inside, states[start + inside]]

    held = np.zeros(len(driven))
    held[0] = s0 - along[before]
    held[-1] = along[after] - s1 if len(inside) else along[after] - along[before] - (s1 - s0)
    held_kinds = np.full(len(driven), ROUTE_STANDSTILL)
    held_kinds[0] = held_kinds[-1] = ROUTE_VIA_GRAPH
    as_held = log_transition(step_m, held, no_time, held_kinds, dt, sigma, config, travel)
    px, py = place
    kk = used[start + inside]
    distance = np.hypot(obs.x[kk] - px, obs.y[kk] - py)
    em_held = distance_emission(distance, obs.sigma_m[kk], config)
    # the loop's U-turns cost what they cost in Viterbi, but one at a dead end's end is no
    # choice: the loop into a dead end is priced by loop_penalty alone
    uturns = _free_uturns(net, entries, s0, s1)
    driven_ll = float(np.sum(as_driven) + np.sum(em_driven)) - config.uturn_penalty * uturns
    held_ll = float(np.sum(as_held) + np.sum(em_held))
    return driven_ll - held_ll


def collapse_loops(
    net: RoadNetwork,
    obs: Observations,
    solution: Solution,
    start: int,
    entries: list[list[float]],
    along: FloatArray,
    config: MatchConfig,
) -> tuple[list[list[float]], FloatArray, int]:
    """
    Take out the loops of one piece's path that do not pay for themselves.

    ``entries`` are the path's ``[edge, start, end]`` stretches and ``along`` the distance
    along it of each of the piece's observations (the piece starts at used position
    ``start``). Returns the new stretches and distances, and how many loops were taken out.
    The innermost loops go first; each one taken out leaves its observations at its node.
    """
    removed = 0
    along = along.copy()
    arrays = net.arrays
    for _ in range(64):  # each pass takes out at most one loop
        loops: list[tuple[tuple[float, float], float, float]] = []
        seen: dict[int, float] = {}
        for node, at in _node_visits(net, entries):
            if node in seen and at > seen[node] + _EPS_M:
                place = (float(arrays.node_x[node]), float(arrays.node_y[node]))
                loops.append((place, seen[node], at))
            seen[node] = at
        loops.extend(_turnback_returns(net, entries))
        loops.sort(key=lambda loop: loop[2] - loop[1])  # innermost first
        cut = None
        for place, s0, s1 in loops:
            gain = _loop_gain(net, obs, solution, start, along, entries, place, s0, s1, config)
            if gain >= config.loop_penalty:
                continue
            shorter = _cut(entries, s0, s1)
            if _legal(net, shorter):  # a loop that a turn restriction forces stays
                cut = (s0, s1, shorter)
                break
        if cut is None:
            break
        s0, s1, entries = cut
        along = np.where(along >= s1 - _EPS_M, along - (s1 - s0), np.minimum(along, s0))
        removed += 1
    return entries, along, removed


def _legal(net: RoadNetwork, entries: list[list[float]]) -> bool:
    """Whether the path's moves from edge to edge are all allowed (restrictions obeyed)."""
    edges = [int(e) for e, _, _ in entries]
    drive = [e for i, e in enumerate(edges) if i == 0 or e != edges[i - 1]]
    arrays = net.arrays
    for a, b in itertools.pairwise(drive):
        if arrays.edge_v[a] != arrays.edge_u[b]:
            return True  # a jump in the path (drawn as such): nothing to check across it
    return net.turns.first_banned(drive) == -1
