"""Edge-based bounded shortest routes that obey turn restrictions, many sources at once.

(Over 400 lines on purpose: the router's public calls, its per-thread scratch and its answer
object belong together.)

The search runs over the states of a :class:`~roadnets.turns.TurnGraph` (edges, plus restricted
copies for via-way restrictions), so a route never takes a banned turn nor drives a banned
sequence. A route from edge ``a`` to edge ``b`` starts where ``a`` ends and stops where ``b``
starts: its length is the sum of the edges strictly between them, 0 when ``b`` directly
follows ``a``. ``b == a`` asks for the shortest loop from the end of ``a`` back to its start.

A *U-turn* is a move from an edge onto its reverse twin at a node (``b == edge_twin[a]``
right away, or anywhere on the route). U-turns are allowed (dead ends need them) but each one
adds ``uturn_cost_m`` to the search key, not to the reported length, so that a route without a
U-turn is preferred when it is at most that much longer. A search explores routes whose key
(length plus U-turn costs) is within its bound.

Search costs: by default the key is the route length plus ``uturn_cost_m`` per U-turn.
``edge_cost`` (one per edge, e.g. free-flow seconds) replaces the lengths in the key; bounds
and ``uturn_cost_m`` are then in its unit, while reported lengths and times stay metres and
seconds. ``turn_cost`` (one per transition of the turn graph, aligned with ``trans_to``;
:meth:`~roadnets.turns.TurnGraph.transition_edges` names their edges) adds a cost to chosen
moves, e.g. sharp turns; junctions are then searched without pruning, so it is slower.

A search starts from the source edge itself, not from the way it was entered: a via-way
restriction whose sequence begins before the source edge is not known to it (a matcher that
routes fix to fix and lands a fix on a via edge could chain a banned sequence over two steps).

The searches are compiled with numba (:mod:`roadnets.route_search`: pruned at junctions without
restrictions, stopped early once the targets are reached), so that an edge-based search costs
about what a node-based one does.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from roadnets.record_index import record_index
from roadnets.route_search import (
    gather,
    new_group_scratch,
    new_workspace,
    route_pairs_kernel,
    search_many,
    table_records,
    table_routes,
)
from roadnets.turns import DEFAULT_UTURN_COST_M

if TYPE_CHECKING:
    from roadnets.arrays import NetworkArrays
    from roadnets.turns import TurnGraph

__all__ = [
    "DEFAULT_UTURN_COST_M",
    "EdgeRoutes",
    "RouteTable",
    "edge_routes_of",
    "route_pairs",
    "route_table",
    "scratch",
    "search_graph",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
Int32Array = npt.NDArray[np.int32]
Int16Array = npt.NDArray[np.int16]
IndexArray = npt.NDArray[np.integer[Any]]


@dataclass(frozen=True, slots=True)
class RouteTable:
    """
    Shortest routes from a set of source edges, as records of the searches' settled states.

    A record is the best route from the end of a source edge to the start of one state
    (an edge, or a restricted copy of one): its length, free-flow time and U-turn count, and
    the record of the state before it on the route (-1 when it follows the source directly).

    Attributes
    ----------
    sources
        Source edges, sorted, distinct.
    bounds_m
        Search bound of each source: routes whose length plus U-turn costs fits in it.
    complete
        Whether each source's search explored its whole bound (else it stopped once the
        target edges it was asked for were settled, and other edges may be missing).
    uturn_cost_m
        The search-key cost of a U-turn the table was built with.
    weighted
        Whether the search keys were costs given by the caller (``edge_cost``, ``turn_cost``)
        instead of lengths.
    ptr
        Records of ``sources[i]`` are ``ptr[i]:ptr[i + 1]``, in the order they were settled.
    state, distance_m, time_s, uturns, pred
        Per record: the state reached, route length (m) and free-flow time (s) from the end
        of the source to the start of the state's edge, U-turns on the route (the move onto
        the state's edge included), the predecessor record or -1.
    turns
        The turn graph searched (maps states to edges).
    """

    sources: IntArray
    bounds_m: FloatArray
    complete: bool
    uturn_cost_m: float
    weighted: bool
    ptr: IntArray
    state: Int32Array
    distance_m: FloatArray
    time_s: FloatArray
    uturns: Int16Array
    pred: Int32Array
    turns: TurnGraph = field(repr=False)
    _index: list[npt.NDArray[np.integer[Any]]] = field(
        default_factory=list, init=False, repr=False, compare=False
    )

    def lookup_columns(self) -> tuple[Any, ...]:
        """
        The table's columns as :func:`~roadnets.route_search.table_routes` reads them.

        ``(sources, ptr, state, index, distance_m, time_s, uturns, pred, copy_ptr,
        copy_state)``, the index made on first use (:meth:`index`), the restricted copies
        from :attr:`turns`.
        """
        return (
            self.sources, self.ptr, self.state, self.index(), self.distance_m, self.time_s,
            self.uturns, self.pred, self.turns.copy_ptr, self.turns.copy_state,
        )  # fmt: skip

    def records(self, from_edges: IndexArray, to_edges: IndexArray) -> IntArray:
        """
        Record of the best route for each ``(from, to)`` edge pair, -1 where the table has none.

        "None" means unreachable within the source's bound, or (``complete`` false) not
        settled before the source's own targets were.
        """
        a = np.ascontiguousarray(from_edges, dtype=np.int64).ravel()
        b = np.ascontiguousarray(to_edges, dtype=np.int64).ravel()
        turns = self.turns
        args = (self.sources, self.ptr, self.state, self.index())
        best = table_records(*args, turns.copy_ptr, turns.copy_state, a, b)
        return np.asarray(best, dtype=np.int64)

    def lookup(
        self, from_edges: IndexArray, to_edges: IndexArray
    ) -> tuple[FloatArray, FloatArray, IntArray]:
        """
        Route length (m), free-flow time (s) and U-turn count for arrays of edge pairs.

        Length and time run from the end of ``from`` to the start of ``to`` (0 when ``to``
        directly follows); ``inf``, ``inf`` and 0 where the table holds no route.
        """
        rec = self.records(from_edges, to_edges)
        return _gather(self, rec)

    def edges(self, from_edge: int, to_edge: int) -> list[int]:
        """
        Edges strictly between ``from_edge`` and ``to_edge`` on the route, in driving order.

        Raises
        ------
        KeyError
            The table holds no route for this pair.
        """
        rec = int(self.records(np.array([from_edge]), np.array([to_edge]))[0])
        if rec < 0:
            raise KeyError((from_edge, to_edge))
        return self.path(rec)

    def path(self, record: int) -> list[int]:
        """Edges strictly between the source and the record's state, in driving order."""
        out: list[int] = []
        rec = int(self.pred[record])
        while rec >= 0:
            out.append(int(self.turns.state_edge[self.state[rec]]))
            rec = int(self.pred[rec])
        out.reverse()
        return out

    @property
    def nbytes(self) -> int:
        """Memory held by the table's arrays (not the turn graph)."""
        arrays: list[npt.NDArray[Any]] = [self.sources, self.bounds_m, self.ptr, self.state]
        arrays += [self.distance_m, self.time_s, self.uturns, self.pred, *self._index]
        return sum(a.nbytes for a in arrays)

    def index(self) -> tuple[IndexArray, IndexArray]:
        """
        ``(index_ptr, slots)``: where each source's block holds each state, made on first use.

        See :func:`~roadnets.record_index.record_index`; a stored table brings its own.
        """
        if not self._index:
            self._index.extend(record_index(self.ptr, self.state))
        index_ptr, slots = self._index
        return index_ptr, slots


@dataclass(frozen=True, slots=True)
class EdgeRoutes:
    """
    The best route for each of an array of ``(from edge, to edge)`` pairs.

    Attributes
    ----------
    from_edge, to_edge
        The pairs, as asked.
    distance_m, time_s
        Route length and free-flow time from the end of ``from`` to the start of ``to``
        (0 when ``to`` directly follows ``from``); ``inf`` where there is no route within the
        pair's bound.
    uturns
        U-turns at nodes on the route (turning from an edge onto its reverse twin, the move
        onto ``to`` included; 0 where there is no route).
    record
        Each pair's record in :attr:`table` (-1 where there is no route).
    table
        The searches' records, for the routes' edges.
    targets
        The searches' targets: ``(ptr, edge, record)``, the distinct target edges of
        ``table.sources[i]`` at ``ptr[i]:ptr[i + 1]`` and their records (``None`` when a
        precomputed table answered).
    """

    from_edge: IntArray
    to_edge: IntArray
    distance_m: FloatArray
    time_s: FloatArray
    uturns: IntArray
    record: IntArray
    table: RouteTable = field(repr=False)
    targets: tuple[IntArray, IntArray, IntArray] | None = field(default=None, repr=False)

    def edges(self, from_edge: int, to_edge: int) -> list[int]:
        """
        Edges strictly between ``from_edge`` and ``to_edge`` on the pair's route, in order.

        Raises
        ------
        KeyError
            The pair was not asked for, or has no route.
        """
        if self.targets is None:  # answered by a complete table: look the pair up there
            rec = int(self.table.records(np.array([from_edge]), np.array([to_edge]))[0])
        else:  # the searches' own targets, grouped by source
            ptr, edge, records = self.targets
            rank = int(np.searchsorted(self.table.sources, from_edge))
            if rank == len(self.table.sources) or self.table.sources[rank] != from_edge:
                raise KeyError((from_edge, to_edge))
            lo, hi = int(ptr[rank]), int(ptr[rank + 1])
            hit = np.flatnonzero(edge[lo:hi] == to_edge)
            rec = int(records[lo + hit[0]]) if len(hit) else -1
        if rec < 0:
            raise KeyError((from_edge, to_edge))
        return self.table.path(rec)


#: Per network (by the identity of its arrays and turn graph): the arrays a search reads.
_GRAPHS: dict[tuple[int, int], tuple[NetworkArrays, TurnGraph, tuple[npt.NDArray[Any], ...]]] = {}
_local = threading.local()


#: The turn costs of a search without any: empty and read-only, as given ones are made.
_NO_TURN_COSTS = np.zeros(0)
_NO_TURN_COSTS.flags.writeable = False


def search_graph(arrays: NetworkArrays, turns: TurnGraph) -> tuple[npt.NDArray[Any], ...]:
    """
    The network arrays :func:`~roadnets.route_search.search_many` reads, made once per network.

    ``(trans_ptr, trans_to, state_edge, plain, edge_v, edge_twin, edge_length_m, edge_time,
    edge_key, trans_key)`` for searches by length without turn costs (each edge's free-flow
    time computed once, not per search). Kept for the last few networks searched.
    """
    key = (id(arrays), id(turns))
    found = _GRAPHS.get(key)
    if found is not None and found[0] is arrays and found[1] is turns:
        return found[2]
    edge_time = arrays.edge_length_m / arrays.edge_speed_mps
    edge_time.flags.writeable = False
    graph = (
        turns.trans_ptr,
        turns.trans_to,
        turns.state_edge,
        turns.plain,
        arrays.edge_v,
        arrays.edge_twin,
        arrays.edge_length_m,
        edge_time,
        arrays.edge_length_m,
        _NO_TURN_COSTS,
    )
    if len(_GRAPHS) >= 8:
        _GRAPHS.pop(next(iter(_GRAPHS)))
    _GRAPHS[key] = (arrays, turns, graph)
    return graph


def scratch(
    arrays: NetworkArrays, turns: TurnGraph
) -> tuple[tuple[npt.NDArray[Any], ...], tuple[npt.NDArray[np.int64], ...]]:
    """
    The search workspace and pair-grouping scratch of the calling thread, for the network.

    One per thread (the searches run without the GIL, several threads at once), grown to
    the largest network searched; a search leaves it clean, so it is reused by every later
    search instead of allocating and clearing arrays of the network's size each time.
    """
    last = getattr(_local, "last", None)
    if last is not None and last[0] is turns and last[1] is arrays:
        found: tuple[tuple[npt.NDArray[Any], ...], tuple[npt.NDArray[np.int64], ...]] = last[2]
        return found
    need = (turns.n_states, arrays.n_nodes, arrays.n_edges, len(turns.trans_to), _max_out(turns))
    held = getattr(_local, "scratch", None)
    if held is None or any(n > h for n, h in zip(need, held[0], strict=True)):
        sizes = (
            need if held is None else tuple(max(n, h) for n, h in zip(need, held[0], strict=True))
        )
        held = _local.scratch = (sizes, new_workspace(*sizes), new_group_scratch(sizes[2]))
    _local.last = (turns, arrays, (held[1], held[2]))  # the network searched last
    return held[1], held[2]


#: Most transitions out of one state, per turn graph (by identity).
_MAX_OUT: dict[int, tuple[TurnGraph, int]] = {}


def _max_out(turns: TurnGraph) -> int:
    """Most transitions out of one state of ``turns``."""
    cached = _MAX_OUT.get(id(turns))
    if cached is not None and cached[0] is turns:
        return cached[1]
    value = int(np.max(np.diff(turns.trans_ptr))) if turns.n_states else 0
    if len(_MAX_OUT) >= 8:
        _MAX_OUT.pop(next(iter(_MAX_OUT)))
    _MAX_OUT[id(turns)] = (turns, value)
    return value


def _gather(table: RouteTable, rec: IntArray) -> tuple[FloatArray, FloatArray, IntArray]:
    dist, time, turns = gather(rec, table.distance_m, table.time_s, table.uturns)
    return dist, time, turns


def _search_arrays(
    arrays: NetworkArrays,
    turns: TurnGraph,
    cost: tuple[float, FloatArray | None, FloatArray | None],
) -> tuple[tuple[npt.NDArray[Any], ...], float]:
    """The ten network arrays a search reads, for these costs, and the U-turn cost (checked)."""
    uturn_cost_m, edge_cost, turn_cost = cost
    if not np.isfinite(uturn_cost_m) or uturn_cost_m < 0:
        msg = f"uturn_cost_m = {uturn_cost_m!r}: give a finite cost >= 0"
        raise ValueError(msg)
    graph = search_graph(arrays, turns)
    if edge_cost is None and turn_cost is None:
        return graph, float(uturn_cost_m)
    edge_key = _costs(edge_cost, arrays.n_edges, "edge_cost", arrays.edge_length_m)
    trans_key = _costs(turn_cost, len(turns.trans_to), "turn_cost", _NO_TURN_COSTS)
    # the pruning at junctions assumes a U-turn is the only move with a cost of its own
    plain = turns.plain if turn_cost is None else np.zeros(turns.n_states, dtype=np.bool_)
    return (*graph[:3], plain, *graph[4:8], edge_key, trans_key), float(uturn_cost_m)


def _table(
    turns: TurnGraph,
    cost: tuple[float, FloatArray | None, FloatArray | None],
    sources: IntArray,
    bounds: FloatArray,
    complete: bool,
    records: tuple[npt.NDArray[Any], ...],
) -> RouteTable:
    """The :class:`RouteTable` of searches' records ``(ptr, state, dist, time, U-turns, pred)``."""
    ptr, state, dist, time, uturns, pred = records
    if len(state) >= 2**31:
        msg = (
            f"{len(state):,} route records do not fit one table; search fewer sources or "
            "with a smaller bound at a time"
        )
        raise MemoryError(msg)
    return RouteTable(
        sources=sources,
        bounds_m=bounds,
        complete=complete,
        uturn_cost_m=float(cost[0]),
        weighted=cost[1] is not None or cost[2] is not None,
        ptr=ptr,
        state=state,
        distance_m=dist,
        time_s=time,
        uturns=uturns,
        pred=pred.astype(np.int32),
        turns=turns,
    )


def _costs(given: FloatArray | None, size: int, name: str, default: FloatArray) -> FloatArray:
    """The caller's costs checked, as a read-only view (as the network's own arrays are)."""
    if given is None:
        return default
    out = np.ascontiguousarray(given, dtype=np.float64).view()
    out.flags.writeable = False
    if out.shape != (size,):
        msg = f"{name} has shape {out.shape}; give one cost per entry, shape ({size},)"
        raise ValueError(msg)
    bad = np.flatnonzero(~np.isfinite(out) | (out < 0))
    if len(bad):
        msg = f"{name}[{bad[0]}] = {float(out[bad[0]])}: costs must be finite and >= 0"
        raise ValueError(msg)
    return out


def _edges_in(arrays: NetworkArrays, edges: IndexArray, name: str) -> IntArray:
    out = np.asarray(edges, dtype=np.int64).ravel()
    bad = np.flatnonzero((out < 0) | (out >= arrays.n_edges))
    if len(bad):
        msg = (
            f"{name}[{bad[0]}] = {out[bad[0]]} is not an edge of the network "
            f"(0..{arrays.n_edges - 1})"
        )
        raise ValueError(msg)
    return out


def route_table(
    arrays: NetworkArrays,
    turns: TurnGraph,
    sources: IndexArray,
    bounds_m: float | FloatArray,
    *,
    uturn_cost_m: float = DEFAULT_UTURN_COST_M,
    edge_cost: FloatArray | None = None,
    turn_cost: FloatArray | None = None,
) -> RouteTable:
    """
    Every best route from each source edge within its bound (complete search trees).

    Parameters
    ----------
    arrays, turns
        The network and its turn graph.
    sources
        Source edges (duplicates are searched once, with their largest bound).
    bounds_m
        One bound, or one per source: routes whose length plus U-turn costs exceed it are
        not explored.
    uturn_cost_m, edge_cost, turn_cost
        The search costs (module docstring, "Search costs").

    Raises
    ------
    ValueError
        A source is not an edge, or a cost is negative, not finite or of the wrong shape.
    """
    src = _edges_in(arrays, sources, "sources")
    bounds = np.broadcast_to(np.asarray(bounds_m, dtype=np.float64), src.shape)
    order = np.lexsort((-bounds, src))
    src, bounds = src[order], bounds[order]
    first = np.ones(len(src), dtype=bool)
    first[1:] = src[1:] != src[:-1]
    sources, bounds = src[first], np.ascontiguousarray(bounds[first])
    cost = (uturn_cost_m, edge_cost, turn_cost)
    graph, uturn = _search_arrays(arrays, turns, cost)
    empty = np.zeros(len(sources) + 1, dtype=np.int64)
    nothing = np.zeros(0, dtype=np.int64)
    args = (*graph, sources, bounds, uturn, empty, nothing, scratch(arrays, turns)[0])
    *records, _ = search_many(*args)
    return _table(turns, cost, sources, bounds, True, tuple(records))


def route_pairs(
    arrays: NetworkArrays,
    turns: TurnGraph,
    from_edges: IndexArray,
    to_edges: IndexArray,
    bounds_m: float | FloatArray,
    *,
    uturn_cost_m: float = DEFAULT_UTURN_COST_M,
    edge_cost: FloatArray | None = None,
    turn_cost: FloatArray | None = None,
    table: RouteTable | None = None,
) -> EdgeRoutes:
    """
    The best route for each ``(from, to)`` edge pair: one search per distinct ``from`` edge.

    Each search runs with the largest bound of its pairs and stops as soon as all its ``to``
    edges are settled, so a pair may get a route longer than its own bound (never one worse
    than the shortest). ``table`` (a complete :class:`RouteTable` built with the same U-turn
    cost and bounds at least these) answers instead of searching, with the same routes.

    Parameters
    ----------
    arrays, turns
        The network and its turn graph.
    from_edges, to_edges
        Edge pairs, same length.
    bounds_m
        One bound, or one per pair (metres of length plus U-turn costs).
    uturn_cost_m, edge_cost, turn_cost
        The search costs (module docstring, "Search costs").
    table
        A precomputed table to answer from (the costs are then not used).

    Raises
    ------
    ValueError
        An index is not an edge, the arrays differ in length, or a cost is bad.
    """
    a = _edges_in(arrays, from_edges, "from_edges")
    b = _edges_in(arrays, to_edges, "to_edges")
    if len(a) != len(b):
        msg = f"from_edges has {len(a)} entries but to_edges {len(b)}; give one per pair"
        raise ValueError(msg)
    bounds = np.broadcast_to(np.asarray(bounds_m, dtype=np.float64), a.shape)
    if table is not None:
        rec, dist, time, uturns, _ = table_routes(
            table.lookup_columns(),
            turns.state_edge,
            a,
            b,
            np.ascontiguousarray(bounds),
            table.uturn_cost_m,
            scratch(arrays, turns)[1][0],
        )
        return EdgeRoutes(a, b, dist, time, uturns, rec, table)
    cost = (uturn_cost_m, edge_cost, turn_cost)
    graph, uturn = _search_arrays(arrays, turns, cost)
    out = route_pairs_kernel(
        graph, a, b, np.ascontiguousarray(bounds), uturn, *scratch(arrays, turns)
    )
    return edge_routes_of(turns, cost, a, b, out)


def edge_routes_of(
    turns: TurnGraph,
    cost: tuple[float, FloatArray | None, FloatArray | None],
    from_edges: IntArray,
    to_edges: IntArray,
    found: tuple[npt.NDArray[Any], ...],
) -> EdgeRoutes:
    """The :class:`EdgeRoutes` of what :func:`~roadnets.route_search.route_pairs_kernel` found."""
    src, src_bound, *records = found[:8]
    target_ptr, target_edge, target_rec, rec, dist, time, uturns = found[8:]
    table = _table(turns, cost, src, src_bound, len(target_edge) == 0, tuple(records))
    targets = (target_ptr, target_edge, target_rec)
    return EdgeRoutes(from_edges, to_edges, dist, time, uturns, rec, table, targets)
