"""Bounded shortest paths on the directed network, many sources at once.

Dijkstra runs compiled (numba) over the CSR adjacency; the result of many bounded searches is a
:class:`PathTable`, a sorted array of ``(source, target)`` keys that answers distance look-ups
for whole arrays of node pairs in one ``searchsorted`` and rebuilds the edge sequence of any
pair it holds. A table over every node with one bound is the precomputed upper-bounded
origin-destination table batch matchers use.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
from numba import njit

if TYPE_CHECKING:
    from roadnets.arrays import NetworkArrays

__all__ = ["PathTable", "shortest_path_table"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
IndexArray = npt.NDArray[np.integer[Any]]


@njit(cache=True, nogil=True)
def _bounded_dijkstra_many(  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    out_ptr, out_edge, edge_v, edge_len, edge_time, sources, bounds, n_nodes
):
    dist = np.full(n_nodes, np.inf)
    time = np.zeros(n_nodes)
    pred = np.full(n_nodes, -1, dtype=np.int64)
    first = np.full(n_nodes, -1, dtype=np.int64)
    settled = np.zeros(n_nodes, dtype=np.bool_)
    touched = np.empty(n_nodes, dtype=np.int64)
    cap = max(1024, 8 * len(sources))
    r_node = np.empty(cap, dtype=np.int64)
    r_dist = np.empty(cap)
    r_time = np.empty(cap)
    r_pred = np.empty(cap, dtype=np.int64)
    r_first = np.empty(cap, dtype=np.int64)
    ptr = np.zeros(len(sources) + 1, dtype=np.int64)
    count = 0
    for i in range(len(sources)):
        source = sources[i]
        bound = bounds[i]
        dist[source] = 0.0
        time[source] = 0.0
        pred[source] = -1
        first[source] = -1
        n_touched = 1
        touched[0] = source
        heap = [(0.0, source)]
        while len(heap) > 0:
            d, node = heapq.heappop(heap)
            if settled[node] or d > dist[node]:
                continue
            settled[node] = True
            if count == cap:
                cap *= 2
                r_node = np.concatenate((r_node, np.empty(cap - count, dtype=np.int64)))
                r_dist = np.concatenate((r_dist, np.empty(cap - count)))
                r_time = np.concatenate((r_time, np.empty(cap - count)))
                r_pred = np.concatenate((r_pred, np.empty(cap - count, dtype=np.int64)))
                r_first = np.concatenate((r_first, np.empty(cap - count, dtype=np.int64)))
            r_node[count] = node
            r_dist[count] = d
            r_time[count] = time[node]
            r_pred[count] = pred[node]
            r_first[count] = first[node]
            count += 1
            for k in range(out_ptr[node], out_ptr[node + 1]):
                e = out_edge[k]
                nxt = np.int64(edge_v[e])
                nd = d + edge_len[e]
                if nd <= bound and nd < dist[nxt]:
                    if dist[nxt] == np.inf:
                        touched[n_touched] = nxt
                        n_touched += 1
                    dist[nxt] = nd
                    time[nxt] = time[node] + edge_time[e]
                    pred[nxt] = e
                    first[nxt] = e if node == source else first[node]
                    heapq.heappush(heap, (nd, nxt))
        for j in range(n_touched):
            dist[touched[j]] = np.inf
            settled[touched[j]] = False
        ptr[i + 1] = count
    return ptr, r_node[:count], r_dist[:count], r_time[:count], r_pred[:count], r_first[:count]


@dataclass(frozen=True, slots=True)
class PathTable:
    """
    Shortest paths from a set of source nodes to every node within each source's bound.

    Attributes
    ----------
    n_nodes
        Number of nodes of the network (keys are ``source * n_nodes + target``).
    keys
        Sorted ``(source, target)`` keys.
    distance_m, time_s, pred_edge, first_edge
        Per key: path length, free-flow time at the edges' speed limits, and the last and
        first edges of the path (-1 when source == target).
    """

    n_nodes: int
    keys: IntArray
    distance_m: FloatArray
    time_s: FloatArray
    pred_edge: IntArray
    first_edge: IntArray

    def lookup(
        self, source: IndexArray, target: IndexArray
    ) -> tuple[FloatArray, FloatArray, IntArray, IntArray]:
        """
        Path length, free-flow time, first and last edge for arrays of node pairs.

        Length and time are ``inf`` (edges -1) where the table has no path (unreachable, or
        beyond the bound the source was searched with); the edges are -1 for an empty path.
        """
        wanted = np.asarray(source, np.int64) * self.n_nodes + np.asarray(target, np.int64)
        where = np.searchsorted(self.keys, wanted)
        where_c = np.minimum(where, len(self.keys) - 1) if len(self.keys) else where
        found = (
            (where < len(self.keys)) & (self.keys[where_c] == wanted)
            if len(self.keys)
            else (np.zeros(len(wanted), dtype=bool))
        )
        dist = np.full(len(wanted), np.inf)
        time = np.full(len(wanted), np.inf)
        first = np.full(len(wanted), -1, dtype=np.int64)
        last = np.full(len(wanted), -1, dtype=np.int64)
        hit = where_c[found]
        dist[found] = self.distance_m[hit]
        time[found] = self.time_s[hit]
        first[found] = self.first_edge[hit]
        last[found] = self.pred_edge[hit]
        return dist, time, first, last

    def edges(self, source: int, target: int, edge_u: IndexArray) -> list[int]:
        """
        Edge indices of the path from ``source`` to ``target`` in driving order.

        Raises
        ------
        KeyError
            The table holds no path for this pair.
        """
        path: list[int] = []
        node = target
        while node != source:
            key = source * self.n_nodes + node
            i = int(np.searchsorted(self.keys, key))
            if i >= len(self.keys) or self.keys[i] != key:
                raise KeyError((source, target))
            edge = int(self.pred_edge[i])
            path.append(edge)
            node = int(edge_u[edge])
        path.reverse()
        return path

    @property
    def nbytes(self) -> int:
        """Memory held by the table's arrays."""
        arrays = (self.keys, self.distance_m, self.time_s, self.pred_edge, self.first_edge)
        return sum(a.nbytes for a in arrays)


def shortest_path_table(
    arrays: NetworkArrays, sources: IndexArray, bounds_m: FloatArray
) -> PathTable:
    """
    Run a bounded Dijkstra from every source and gather the results in one table.

    Parameters
    ----------
    arrays
        The compiled network.
    sources
        Source node indices (duplicates are searched once, with their largest bound).
    bounds_m
        Search bound per source: nodes farther than this along the road are not reached.
    """
    sources = np.asarray(sources, dtype=np.int64)
    bounds = np.broadcast_to(np.asarray(bounds_m, dtype=np.float64), sources.shape)
    order = np.lexsort((-bounds, sources))
    sources, bounds = sources[order], bounds[order]
    first = np.ones(len(sources), dtype=bool)
    first[1:] = sources[1:] != sources[:-1]
    sources, bounds = sources[first], np.ascontiguousarray(bounds[first])
    edge_time = arrays.edge_length_m / arrays.edge_speed_mps
    ptr, node, dist, time, pred, first = _bounded_dijkstra_many(
        arrays.out_ptr,
        arrays.out_edge,
        arrays.edge_v,
        arrays.edge_length_m,
        edge_time,
        sources,
        bounds,
        arrays.n_nodes,
    )
    src = np.repeat(sources, np.diff(ptr))
    keys = src * arrays.n_nodes + node
    order = np.argsort(keys, kind="stable")
    return PathTable(
        arrays.n_nodes, keys[order], dist[order], time[order], pred[order], first[order]
    )
