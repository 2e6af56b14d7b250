"""Loops and spurs in a matched path that the fixes do not support, taken out.

The HMM is first order: it prices each move on its own, so it cannot see that three cheap
moves in a row go round a 40 m roundabout, or that a drive out and back along a side street
ends where it began. Scattered fixes around a stop near a small ring, or a burst of fixes
pulled to one side, are explained that way. A loop (the path passes the same node twice) is
a second-order event, and it is priced here, after Viterbi: the loop's fixes are scored once
as driven (their chosen candidates and moves) and once as a car that held its place at the
node where the loop starts (every fix's emission at that node, no moves), each with the moves
into and out of the loop. A loop stays only when it explains the fixes better by at least
``loop_penalty`` nats; a car going round a block or into a dead end has fixes all along the
loop, far from its start, and keeps it easily.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from mapmatch.models import ROUTE_STANDSTILL, ROUTE_VIA_GRAPH, log_emission, log_transition

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig
    from mapmatch.observations import Observations
    from mapmatch.solution import Solution
    from roadnets import RoadNetwork

__all__ = ["collapse_loops"]

FloatArray = npt.NDArray[np.float64]

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


def _cut(entries: list[list[float]], s0: float, s1: float) -> list[list[float]]:
    """The path without its stretch between ``s0`` and ``s1`` (both at stretch boundaries)."""
    kept: list[list[float]] = []
    base = 0.0
    for entry in entries:
        length = entry[2] - entry[1]
        inside = base >= s0 - _EPS_M and base + length <= s1 + _EPS_M and length > 0
        if not inside:
            kept.append(entry)
        base += length
    return kept or entries[:1]


def _loop_gain(
    net: RoadNetwork,
    obs: Observations,
    solution: Solution,
    start: int,
    along: FloatArray,
    node: int,
    s0: float,
    s1: float,
    config: MatchConfig,
) -> float:
    """Log-likelihood of the loop as driven minus that of holding at its node."""
    used, states = solution.used, solution.states
    inside = np.flatnonzero((along > s0 + _EPS_M) & (along < s1 - _EPS_M))
    before = int(np.flatnonzero(along <= s0 + _EPS_M)[-1])
    after = int(np.flatnonzero(along >= s1 - _EPS_M)[0])
    chain = np.arange(before, after + 1)  # positions in the piece, the loop's and its ends
    k = used[start + chain]
    step_m = np.hypot(np.diff(obs.x[k]), np.diff(obs.y[k]))
    dt = np.diff(obs.time_s[k])
    sigma = np.maximum(obs.sigma_m[k[:-1]], obs.sigma_m[k[1:]])
    travel = None
    if obs.travel is not None:
        travel = obs.travel.between(k)
    rows = start + chain
    kinds = solution.kinds[rows[:-1], states[rows[:-1]], states[rows[1:]]]
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
    px, py = net.arrays.node_x[node], net.arrays.node_y[node]
    kk = used[start + inside]
    distance = np.hypot(obs.x[kk] - px, obs.y[kk] - py)
    em_held = log_emission(distance, sigma_m=obs.sigma_m[kk])
    if config.max_emission_penalty > 0:
        em_held = np.logaddexp(em_held, -config.max_emission_penalty)
    driven_ll = float(np.sum(as_driven) + np.sum(em_driven))
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
    for _ in range(64):  # each pass takes out at most one loop
        seen: dict[int, float] = {}
        cut = None
        for node, at in _node_visits(net, entries):
            if node in seen and at > seen[node] + _EPS_M:
                s0, s1 = seen[node], at
                gain = _loop_gain(net, obs, solution, start, along, node, s0, s1, config)
                if gain < config.loop_penalty:
                    cut = (s0, s1)
                    break
            seen[node] = at
        if cut is None:
            break
        s0, s1 = cut
        entries = _cut(entries, s0, s1)
        along = np.where(along >= s1 - _EPS_M, along - (s1 - s0), np.minimum(along, s0))
        removed += 1
    return entries, along, removed
