"""
The unsettled window of a live trip as one HMM, solved by the offline stages.

The window is the settled prefix's last observation (the *anchor*) followed by the unsettled
observations in use. :func:`solve_window` hands it to :func:`~mapmatch.hmm.trellis.solve` as
it is, the anchor's candidates cut down to the one it settled on (that is the prior the window
starts from: every path leaves from there), leaves out a fix only a detour explains, repairs
its breaks and assembles its path as :func:`mapmatch.match` does
(:func:`~mapmatch.hmm.detours.drop_detour_fixes`, :func:`~mapmatch.hmm.trellis.repair_breaks`,
:func:`~mapmatch.hmm.assemble.assemble`). :func:`place_on_path` finds each observation's chosen
position on that path, where the settled part can be cut off, and :func:`path_confidence` how
sure the window is of it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

import numpy as np

from mapmatch.hmm.assemble import assemble
from mapmatch.hmm.detours import drop_detour_fixes
from mapmatch.hmm.trellis import cuts, repair_breaks, solve

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig
    from mapmatch.hmm.assemble import Assembled
    from mapmatch.hmm.candidates import Candidates
    from mapmatch.hmm.solution import Solution
    from mapmatch.online.tail import TailModel
    from mapmatch.types import BoolArray, FloatArray, IntArray
    from roadnets import RoadNetwork

__all__ = ["WindowSolve", "path_confidence", "place_on_path", "solve_window"]

_EPS_M: Final = 1e-6


@dataclass(frozen=True, slots=True)
class WindowSolve:
    """
    The window solved and assembled.

    ``used`` are the tail observations in the window, in order; ``solution`` the HMM over
    them (``solution.used`` equals ``used`` unless a break repair left some out);
    ``assembled`` the path and every tail fix's place; ``repairs`` the observations left out
    to join breaks.
    """

    used: IntArray
    solution: Solution
    assembled: Assembled
    repairs: int


def solve_window(
    net: RoadNetwork,
    config: MatchConfig,
    model: TailModel,
    cands: Candidates,
    used: IntArray,
    missing_before: IntArray,
    outlier: BoolArray,
    hold_limit_m: float,
) -> WindowSolve:
    """
    Solve, repair and assemble the window of tail observations ``used``.

    ``cands`` are every tail observation's candidates (the anchor's cut down to the one it
    settled on), ``missing_before`` the running count of stretches without roads (as
    :func:`mapmatch.match` counts them), ``outlier`` the outlier flag of every tail
    observation.
    """
    solution = solve(net, model.obs, cands, used, cuts(used, missing_before), config)
    repairs = 0
    detoured = drop_detour_fixes(net, model.obs, cands, solution, missing_before, config)
    if detoured is not None:  # a fix only a detour explained is an outlier, as in match
        solution, left_out = detoured
        outlier = outlier.copy()
        outlier[left_out] = True
    if solution.breaks and config.max_break_repairs:
        repaired = repair_breaks(net, model.obs, cands, solution, missing_before, config)
        if repaired is not None:
            solution, repairs = repaired
    assembled = assemble(
        net,
        model.view.as_trace(),
        model.fixes.x,
        model.fixes.y,
        model.obs,
        solution,
        outlier[model.obs.of_fix],
        model.fixes.radius_m,
        model.fixes.time_s,
        hold_limit_m,
        config,
    )
    return WindowSolve(used, solution, assembled, repairs)


def path_confidence(
    path: tuple[IntArray, FloatArray, FloatArray],
    at: int,
    edge: IntArray,
    offset_m: FloatArray,
    post: FloatArray,
    tolerance_m: float,
) -> float:
    """
    How sure a solved window is that an observation lies on the chosen path where it does.

    The posterior (``post``, as :func:`~mapmatch.hmm.viterbi.posteriors` gives it) of the
    observation's candidates (on ``edge`` at ``offset_m``) that the path
    (``path``: a segment's stretches) passes within ``tolerance_m``, on the stretches next to
    the one holding the chosen candidate (``at``). The end of one edge and the start of the
    next at a junction are the same answer; a parallel road, or the road the trip may have
    started on, is another.

    Examples
    --------
    >>> path = (np.array([4, 7]), np.array([0.0, 0.0]), np.array([50.0, 30.0]))
    >>> edge, offset = np.array([7, 4, 9]), np.array([0.0, 49.0, 5.0])
    >>> round(path_confidence(path, 1, edge, offset, np.array([0.5, 0.3, 0.2]), 5.0), 3)
    0.8
    """
    stretch, lo, hi = path
    near = range(max(at - 2, 0), min(at + 3, len(stretch)))
    total = 0.0
    for k in np.flatnonzero(post > 1e-4).tolist():
        e, o = int(edge[k]), float(offset_m[k])
        if any(
            int(stretch[j]) == e and lo[j] - tolerance_m <= o <= hi[j] + tolerance_m for j in near
        ):
            total += float(post[k])
    return total


def place_on_path(
    path: tuple[IntArray, FloatArray, FloatArray], edge: IntArray, offset_m: FloatArray
) -> list[int]:
    """
    Where along a path each position lies, in order: the index of the stretch holding it.

    ``path`` is a segment's stretches (edge, start and end offset); ``edge``/``offset_m``
    are positions it passes in driving order (the chosen candidates of a piece's
    observations). The path only moves forward, so each position is looked for from the
    stretch of the one before it on; -1 where the path does not pass it (a position the path
    was held ahead of, or one inside a loop taken out).

    Examples
    --------
    >>> path = (np.array([4, 7, 4]), np.array([10.0, 0.0, 0.0]), np.array([50.0, 30.0, 20.0]))
    >>> place_on_path(path, np.array([4, 7, 4, 9]), np.array([20.0, 5.0, 15.0, 1.0]))
    [0, 1, 2, -1]
    """
    stretch_edge, lo, hi = (a.tolist() for a in path)
    found: list[int] = []
    at = 0
    for e, o in zip(edge.tolist(), offset_m.tolist(), strict=True):
        hit = -1
        for j in range(at, len(stretch_edge)):
            if stretch_edge[j] == e and lo[j] - _EPS_M <= o <= hi[j] + _EPS_M:
                hit = j
                break
        found.append(hit)
        if hit >= 0:
            at = hit
    return found
