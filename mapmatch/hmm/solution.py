"""The HMM solved over a trace: the model's fixes, candidates, chosen states and scores."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from mapmatch.frozen import quick_init

if TYPE_CHECKING:
    from mapmatch.hmm.candidates import Candidates
    from mapmatch.types import FloatArray, IntArray
    from roadnets.arrays import Int32Array

__all__ = ["Solution"]


@quick_init
@dataclass(frozen=True, slots=True)
class Solution:
    """
    The HMM solved over a subset of fixes (``used``, indices into the trace).

    ``states`` is the chosen candidate rank of each used fix (-1: none); the pieces are the
    ranges ``piece_start[i]:piece_stop[i]`` of *used* positions (:attr:`pieces`); ``kinds``
    the route kind of every padded transition; ``route_records`` the routes the transitions
    were scored on: each pair's record (-1: no route), and every record's turn-graph state
    and predecessor record (the search's own, or the precomputed table's), which give a
    route edge by edge;
    ``course_deg`` and ``pace_mps`` each observation's course and pace the candidates were
    chosen by (NaN: none).
    """

    used: IntArray
    cands: Candidates
    states: IntArray
    piece_start: IntArray
    piece_stop: IntArray
    post: FloatArray
    kinds: IntArray
    route_records: tuple[IntArray, Int32Array, Int32Array]
    log_emission: FloatArray
    log_transition: FloatArray
    course_deg: FloatArray
    pace_mps: FloatArray

    @property
    def pieces(self) -> list[tuple[int, int]]:
        """The pieces' ``(start, stop)`` ranges of used positions."""
        return list(zip(self.piece_start.tolist(), self.piece_stop.tolist(), strict=True))

    @property
    def breaks(self) -> list[int]:
        """Used positions where a new piece starts."""
        starts: list[int] = self.piece_start[1:].tolist()
        return starts
