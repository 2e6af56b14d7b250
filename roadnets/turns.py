"""The turn graph: which edge may follow which, with every turn restriction compiled in.

Edge-based routing searches over *states*. State ``e < n_edges`` is "driving along edge
``e``"; its transitions are the edges leaving ``edge_v[e]`` that the banned pairs
(``arrays.banned_in/banned_out``, via-node restrictions) allow. Via-way restrictions ban a
whole sequence of edges; as OSRM does, the edges of each proper prefix of a banned sequence
(two edges or more) get a *restricted copy*: a state ``>= n_edges`` that drives the same edge
but remembers how it was entered, so that the banned continuation is missing from its
transitions. Copies are linked as an Aho-Corasick automaton over the banned sequences, so
overlapping restrictions are all obeyed.

A state is *plain* when it is an original edge whose transitions are every edge leaving its
end node: the router may then prune (see :mod:`roadnets.routes`).
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from collections.abc import Sequence

    from roadnets.arrays import NetworkArrays

__all__ = ["DEFAULT_UTURN_COST_M", "TurnGraph", "build_turn_graph"]

#: Search-key cost of a U-turn at a node, metres (not part of the reported length; see
#: :mod:`roadnets.routes`). Here, with the turn graph, so that it is known without importing
#: the compiled router.
DEFAULT_UTURN_COST_M = 50.0

IntArray = npt.NDArray[np.int64]
Int32Array = npt.NDArray[np.int32]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True, slots=True)
class TurnGraph:
    """
    States (edges and restricted copies of edges) and the legal transitions between them.

    Attributes
    ----------
    n_edges
        Number of directed edges; states ``0..n_edges-1`` are the edges themselves.
    state_edge
        The edge each state drives (``state_edge[e] == e`` for ``e < n_edges``).
    trans_ptr, trans_to
        CSR of transitions: from state ``s`` the states ``trans_to[trans_ptr[s]:trans_ptr[s+1]]``
        may follow (their edges start where ``state_edge[s]`` ends).
    plain
        Per state: an original edge whose transitions are all the edges leaving its end node.
    copy_ptr, copy_state
        Restricted copies of edge ``e``: ``copy_state[copy_ptr[e]:copy_ptr[e + 1]]``.
    edge_u, edge_v
        The network's edge end nodes (the same arrays, not copies).
    """

    n_edges: int
    state_edge: Int32Array
    trans_ptr: IntArray
    trans_to: Int32Array
    plain: BoolArray
    copy_ptr: IntArray
    copy_state: Int32Array
    edge_u: Int32Array
    edge_v: Int32Array

    @property
    def n_states(self) -> int:
        """Number of states (edges plus restricted copies)."""
        return len(self.state_edge)

    @property
    def nbytes(self) -> int:
        """Memory held by the arrays."""
        arrays = (self.state_edge, self.trans_ptr, self.trans_to, self.plain)
        return sum(a.nbytes for a in arrays) + self.copy_ptr.nbytes + self.copy_state.nbytes

    def successors(self, state: int) -> tuple[IntArray, IntArray]:
        """
        The states that may follow ``state``, and their edges.

        Walking a drive edge by edge from ``state = first_edge`` and taking, at each step, the
        successor whose edge is the next edge driven keeps track of every restriction (a
        via-way restriction is remembered through the copies); an edge missing among the
        successors is a banned move.
        """
        lo, hi = int(self.trans_ptr[state]), int(self.trans_ptr[state + 1])
        states = self.trans_to[lo:hi].astype(np.int64)
        return states, self.state_edge[states].astype(np.int64)

    def transition_edges(self) -> tuple[IntArray, IntArray]:
        """The edge each transition leaves and the edge it enters (aligned with ``trans_to``)."""
        owner = np.repeat(np.arange(self.n_states, dtype=np.int64), np.diff(self.trans_ptr))
        return (
            self.state_edge[owner].astype(np.int64),
            self.state_edge[self.trans_to].astype(np.int64),
        )

    def first_banned(self, edges: Sequence[int]) -> int:
        """
        Index of the first edge of a drive that a restriction forbids there, or -1.

        ``edges`` must be connected (each edge starting where the previous one ends).

        Raises
        ------
        ValueError
            Two consecutive edges do not connect.
        """
        if len(edges) == 0:
            return -1
        state = int(edges[0])
        for i in range(1, len(edges)):
            states, next_edges = self.successors(state)
            hit = np.flatnonzero(next_edges == int(edges[i]))
            if len(hit) == 0:
                if not self._connects(int(edges[i - 1]), int(edges[i])):
                    msg = (
                        f"edges[{i - 1}] = {edges[i - 1]} and edges[{i}] = {edges[i]} do not "
                        "connect; pass a drive whose edges follow each other"
                    )
                    raise ValueError(msg)
                return i
            state = int(states[hit[0]])
        return -1

    def _connects(self, a: int, b: int) -> bool:
        """Whether edge ``b`` leaves the node edge ``a`` ends at (banned or not)."""
        return bool(self.edge_v[a] == self.edge_u[b])


def build_turn_graph(arrays: NetworkArrays) -> TurnGraph:
    """
    Compile the network's transitions, banned pairs and banned sequences into a turn graph.

    Vectorised over the edges; only the (few) via-way restrictions are walked in Python.
    """
    n_edges = arrays.n_edges
    v = arrays.edge_v.astype(np.int64)
    degree = arrays.out_ptr[v + 1] - arrays.out_ptr[v]
    owner = np.repeat(np.arange(n_edges, dtype=np.int64), degree)
    start = np.repeat(arrays.out_ptr[v], degree)
    within = np.arange(len(owner), dtype=np.int64) - np.repeat(np.cumsum(degree) - degree, degree)
    target = arrays.out_edge[start + within].astype(np.int64)

    banned_key = arrays.banned_in.astype(np.int64) * n_edges + arrays.banned_out
    allowed = ~np.isin(owner * n_edges + target, banned_key)
    owner, target = owner[allowed], target[allowed]
    banned_pairs = set(zip(arrays.banned_in.tolist(), arrays.banned_out.tolist(), strict=True))

    sequences = [
        tuple(arrays.banned_seq_edge[lo:hi].tolist())
        for lo, hi in zip(arrays.banned_seq_ptr[:-1], arrays.banned_seq_ptr[1:], strict=True)
    ]
    prefixes: dict[tuple[int, ...], int] = {}
    for seq in sequences:
        for k in range(2, len(seq)):
            prefixes.setdefault(seq[:k], n_edges + len(prefixes))
    full = set(sequences)

    # original edges that start a restricted prefix enter its copy instead of the edge
    redirect = {(p[0], p[1]): state for p, state in prefixes.items() if len(p) == 2}
    target_state = target.copy()
    if redirect:
        keys = owner * n_edges + target
        for (a, b), state in redirect.items():
            target_state[keys == a * n_edges + b] = state

    copy_owner: list[int] = []
    copy_target: list[int] = []
    for prefix, state in prefixes.items():
        last = prefix[-1]
        for b in arrays.out_edge[arrays.out_ptr[v[last]] : arrays.out_ptr[v[last] + 1]].tolist():
            if (last, b) in banned_pairs:
                continue
            seq = (*prefix, b)
            if any(seq[k:] in full for k in range(len(seq) - 2)):
                continue
            nxt = next((prefixes[seq[k:]] for k in range(len(seq) - 1) if seq[k:] in prefixes), b)
            copy_owner.append(state)
            copy_target.append(nxt)

    n_states = n_edges + len(prefixes)
    all_owner = np.concatenate((owner, np.array(copy_owner, dtype=np.int64)))
    all_target = np.concatenate((target_state, np.array(copy_target, dtype=np.int64)))
    order = np.argsort(all_owner, kind="stable")
    counts = np.bincount(all_owner, minlength=n_states)
    trans_ptr = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)

    state_edge = np.concatenate(
        (np.arange(n_edges), np.array([p[-1] for p in prefixes], dtype=np.int64))
    ).astype(np.int32)
    plain = np.zeros(n_states, dtype=np.bool_)
    plain[:n_edges] = True
    plain[arrays.banned_in] = False
    plain[np.array([a for a, _ in redirect], dtype=np.int64)] = False

    copies: dict[int, list[int]] = defaultdict(list)
    for prefix, state in prefixes.items():
        copies[prefix[-1]].append(state)
    copy_count = np.zeros(n_edges, dtype=np.int64)
    for edge, states in copies.items():
        copy_count[edge] = len(states)
    copy_ptr = np.concatenate(([0], np.cumsum(copy_count))).astype(np.int64)
    copy_state = np.array(
        [s for edge in sorted(copies) for s in sorted(copies[edge])], dtype=np.int32
    )
    return TurnGraph(
        n_edges=n_edges,
        state_edge=state_edge,
        trans_ptr=trans_ptr,
        trans_to=all_target[order].astype(np.int32),
        plain=plain,
        copy_ptr=copy_ptr,
        copy_state=copy_state,
        edge_u=arrays.edge_u,
        edge_v=arrays.edge_v,
    )
