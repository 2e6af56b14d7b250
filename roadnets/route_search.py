"""The compiled kernels of the edge-based router (:mod:`roadnets.routes`): search and look-up.

(Over 400 lines on purpose: the search kernels share one scratch layout, and why the pruning is
exact only shows when they are read together.)

One bounded Dijkstra per source over the states of a :class:`~roadnets.turns.TurnGraph`.
Two things keep it close to a node-based Dijkstra in cost:

- Pruning at plain nodes: at a node, only the first arrival (lowest key) needs to settle every
  leaving edge; a later arrival can only improve the twin of the first arrival's edge (the
  first arrival pays the U-turn cost there, a later one does not), so the second arrival
  settles that one edge and later ones nothing. Arrivals on edges with a restriction, and
  restricted copies, always use all their transitions.
- Early stop: given the target edges of each source, a search stops once they are all
  settled instead of exploring its whole bound.

The heap is a plain binary heap on two arrays; the search is one function without helper
calls that take arrays (numba counts references to every array passed on each call, which
cost more than the search itself).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
from numba import njit

from roadnets.prefetch import prefetch
from roadnets.record_index import find_record, first_slot

__all__ = [
    "gather",
    "group_pairs",
    "new_group_scratch",
    "new_workspace",
    "route_pairs_kernel",
    "search_bounds",
    "search_many",
    "table_records",
    "table_routes",
]


@njit(cache=True, nogil=True, inline="always")
def _push(hk, hv, size, key, val):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    i = size
    while i > 0:
        parent = (i - 1) >> 1
        if hk[parent] <= key:
            break
        hk[i] = hk[parent]
        hv[i] = hv[parent]
        i = parent
    hk[i] = key
    hv[i] = val
    return size + 1


@njit(cache=True, nogil=True, inline="always")
def _pop(hk, hv, size):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    key, val = hk[0], hv[0]
    size -= 1
    if size > 0:
        last_k, last_v = hk[size], hv[size]
        i = 0
        while True:
            c = 2 * i + 1
            if c >= size:
                break
            if c + 1 < size and hk[c + 1] < hk[c]:
                c += 1
            if hk[c] >= last_k:
                break
            hk[i] = hk[c]
            hv[i] = hv[c]
            i = c
        hk[i] = last_k
        hv[i] = last_v
    return key, val, size


def new_workspace(
    n_states: int, n_nodes: int, n_edges: int, n_trans: int, max_out: int
) -> tuple[npt.NDArray[Any], ...]:
    """
    Scratch arrays for :func:`search_many`, in the clean state a search leaves them in.

    A search marks what it touches and puts it back before it returns, so one workspace
    serves every later search of a network no larger (:func:`roadnets.routes.workspace`
    keeps one per thread): allocating and clearing these arrays, sized by the whole
    network, cost more than a short search itself.
    """
    heap_cap = n_trans + 2 * n_states + 1  # one push per settle or U-turn at most
    return (
        np.full(n_states, np.inf),  # tent: queued key of a move onto the state
        np.zeros(n_states),  # t_dist
        np.zeros(n_states),  # t_time
        np.zeros(n_states, dtype=np.int16),  # t_turn
        np.full(n_states, -1, dtype=np.int64),  # t_pred
        np.full(n_states, -1, dtype=np.int64),  # srec: the state's record, once settled
        np.empty(n_states, dtype=np.int64),  # touched
        np.full(n_nodes, -1, dtype=np.int64),  # first
        np.full(n_nodes, np.inf),  # first_key
        np.zeros(n_nodes, dtype=np.bool_),  # second
        np.full(n_nodes, np.inf),  # q1: the two lowest keys of arrivals queued at a node
        np.full(n_nodes, np.inf),  # q2
        np.empty(n_nodes, dtype=np.int64),  # touched_nodes
        np.full(n_edges, -1, dtype=np.int64),  # want
        np.empty(n_states, dtype=np.int32),  # b_state
        np.empty(n_states),  # b_dist
        np.empty(n_states),  # b_time
        np.empty(n_states, dtype=np.int16),  # b_turn
        np.empty(n_states, dtype=np.int64),  # b_pred
        np.empty(max_out + 1, dtype=np.int64),  # pend
        np.empty(heap_cap),  # hk
        np.empty(heap_cap, dtype=np.int64),  # hv
    )


@njit(cache=True, nogil=True)
def search_many(  # type: ignore[no-untyped-def]  # pragma: no cover
    trans_ptr,
    trans_to,
    state_edge,
    plain,
    edge_v,
    edge_twin,
    edge_len,
    edge_time,
    edge_key,
    trans_key,
    sources,
    bounds,
    uturn_cost,
    target_ptr,
    target_edge,
    ws,
):
    """
    Bounded edge-based Dijkstra from each source state; every settled state is a record.

    A source with targets (``target_edge[target_ptr[i]:target_ptr[i + 1]]``, distinct edges)
    stops once a state of each is settled; one without explores its whole bound. Records
    are ``(state, length, time, U-turns, predecessor record)`` in settling (key) order, those
    of source ``i`` at ``ptr[i]:ptr[i + 1]``; ``target_rec`` gives each target's record.
    ``ws`` is a workspace of :func:`new_workspace` at least as large as the network; it is
    left clean.

    Keys grow by ``edge_key`` per edge (the length, or another cost), ``uturn_cost`` per
    U-turn and, when ``trans_key`` is not empty, ``trans_key[k]`` for transition ``k`` (then
    no state may be ``plain``: the pruning below assumes the U-turn is the only costed move).

    Heap items are arrivals at the end of a state's edge (item ``s``) and queued moves onto a
    state (item ``n_states + t``). An arrival with key ``k`` settles at once every next state
    reached at no extra cost (``k`` is the lowest key queued, so it is final) and queues the
    others (a U-turn: ``k + uturn_cost``). At a plain state's node only the first
    arrival does this for every leaving edge; the second settles just the twin of the
    first's edge (the first reaches it only by a U-turn), later ones nothing, so at most two
    arrivals per plain node are queued.
    """
    n_states = len(state_edge)
    turn_costs = len(trans_key) > 0
    (
        tent,
        t_dist,
        t_time,
        t_turn,
        t_pred,
        srec,
        touched,
        first,
        first_key,
        second,
        q1,
        q2,
        touched_nodes,
        want,
        b_state,
        b_dist,
        b_time,
        b_turn,
        b_pred,
        pend,
        hk,
        hv,
    ) = ws
    target_local = np.full(max(len(target_edge), 1), -1, dtype=np.int64)
    cap = max(1024, 16 * len(sources))
    r_state = np.empty(cap, dtype=np.int32)
    r_dist = np.empty(cap)
    r_time = np.empty(cap)
    r_turn = np.empty(cap, dtype=np.int16)
    r_pred = np.empty(cap, dtype=np.int64)
    ptr = np.zeros(len(sources) + 1, dtype=np.int64)
    target_rec = np.full(len(target_edge), -1, dtype=np.int64)
    count = 0
    for i in range(len(sources)):
        bound = bounds[i]
        lo, hi = target_ptr[i], target_ptr[i + 1]
        remaining = hi - lo
        for j in range(lo, hi):
            want[target_edge[j]] = j - lo
            target_local[j - lo] = -1
        n_touched, n_nodes_touched, size, n_rec = 0, 0, 0, 0
        # the source arrives at its end node with key 0; it is not settled itself, only
        # by a loop back to its start
        item = sources[i]
        key, dist, time, turns, rec = 0.0, 0.0, 0.0, 0, -1
        node = edge_v[state_edge[item]]
        if plain[item]:
            touched_nodes[0] = node
            n_nodes_touched = 1
            q1[node] = 0.0
        seed = True
        while True:
            n_pend = 0
            if item >= n_states:  # a queued U-turn (or costed turn)
                t = item - n_states
                if srec[t] < 0 and key <= tent[t]:
                    pend[0] = t
                    n_pend = 1
                    dist, time, turns, rec = t_dist[t], t_time[t], t_turn[t], t_pred[t]
            else:  # an arrival at the end of state ``item``'s edge
                e = state_edge[item]
                if not seed:
                    rec = srec[item]
                    dist = b_dist[rec] + edge_len[e]
                    time = b_time[rec] + edge_time[e]
                    turns = b_turn[rec]
                seed = False
                every = True
                if plain[item]:
                    node = edge_v[e]
                    if first[node] >= 0:
                        every = False
                        if first[node] != item and not second[node]:
                            second[node] = True
                            t = edge_twin[state_edge[first[node]]]
                            if t >= 0 and srec[t] < 0 and key < first_key[node] + uturn_cost:
                                pend[0] = t
                                n_pend = 1
                    else:
                        first[node] = item
                        first_key[node] = key
                if every:
                    twin = edge_twin[e]
                    for k in range(trans_ptr[item], trans_ptr[item + 1]):
                        t = trans_to[k]
                        if srec[t] >= 0:
                            continue
                        back = state_edge[t] == twin
                        extra = trans_key[k] if turn_costs else 0.0
                        if not back and extra == 0.0:
                            pend[n_pend] = t
                            n_pend += 1
                            continue
                        u_key = key + extra + uturn_cost if back else key + extra
                        if u_key <= bound and u_key < tent[t]:
                            if tent[t] == np.inf:
                                touched[n_touched] = t
                                n_touched += 1
                            tent[t] = u_key
                            t_dist[t] = dist
                            t_time[t] = time
                            t_turn[t] = turns + 1 if back else turns
                            t_pred[t] = rec
                            size = _push(hk, hv, size, u_key, n_states + t)
            for q in range(n_pend):  # settle with key ``key`` and the label above
                t = pend[q]
                if tent[t] == np.inf:
                    touched[n_touched] = t
                    n_touched += 1
                tent[t] = key
                srec[t] = n_rec
                b_state[n_rec] = t
                b_dist[n_rec] = dist
                b_time[n_rec] = time
                b_turn[n_rec] = turns
                b_pred[n_rec] = rec
                e = state_edge[t]
                if want[e] >= 0:
                    target_local[want[e]] = n_rec
                    want[e] = -1
                    remaining -= 1
                n_rec += 1
                arrive = key + edge_key[e]
                if arrive > bound:
                    continue
                if plain[t]:
                    # a plain node uses its first arrival, and a second one only when it
                    # comes less than the U-turn cost after the first
                    m = edge_v[e]
                    if arrive < q1[m]:
                        if q1[m] == np.inf:
                            touched_nodes[n_nodes_touched] = m
                            n_nodes_touched += 1
                        q2[m] = q1[m]
                        q1[m] = arrive
                    elif arrive < q2[m] and arrive < q1[m] + uturn_cost:
                        q2[m] = arrive
                    else:
                        continue
                size = _push(hk, hv, size, arrive, t)
            if size == 0 or (hi > lo and remaining <= 0):
                break
            key, item, size = _pop(hk, hv, size)
        while count + n_rec > cap:
            grow = cap
            cap *= 2
            r_state = np.concatenate((r_state, np.empty(grow, dtype=np.int32)))
            r_dist = np.concatenate((r_dist, np.empty(grow)))
            r_time = np.concatenate((r_time, np.empty(grow)))
            r_turn = np.concatenate((r_turn, np.empty(grow, dtype=np.int16)))
            r_pred = np.concatenate((r_pred, np.empty(grow, dtype=np.int64)))
        for k in range(n_rec):
            r_state[count + k] = b_state[k]
            r_dist[count + k] = b_dist[k]
            r_time[count + k] = b_time[k]
            r_turn[count + k] = b_turn[k]
            r_pred[count + k] = b_pred[k] + count if b_pred[k] >= 0 else -1
        for j in range(lo, hi):
            want[target_edge[j]] = -1
            if target_local[j - lo] >= 0:
                target_rec[j] = target_local[j - lo] + count
        count += n_rec
        ptr[i + 1] = count
        for j in range(n_touched):
            tent[touched[j]] = np.inf
            srec[touched[j]] = -1
        for j in range(n_nodes_touched):
            m = touched_nodes[j]
            first[m] = -1
            first_key[m] = np.inf
            second[m] = False
            q1[m] = np.inf
            q2[m] = np.inf
    return (
        ptr,
        r_state[:count],
        r_dist[:count],
        r_time[:count],
        r_turn[:count],
        r_pred[:count],
        target_rec,
    )


@njit(cache=True, nogil=True, inline="always")
def _best_record(ptr, state, index_ptr, slots, copy_ptr, copy_state, rank, to_edge):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Record of the best route to ``to_edge`` in block ``rank`` (-1: none).

    The record of the edge's own state, or of a restricted copy of it reached with a lower key
    (records of one source are in settling order, which is key order).
    """
    best = find_record(ptr, state, index_ptr, slots, rank, to_edge)
    for c in range(copy_ptr[to_edge], copy_ptr[to_edge + 1]):
        found = find_record(ptr, state, index_ptr, slots, rank, copy_state[c])
        if found >= 0 and (best < 0 or found < best):
            best = found
    return best


@njit(cache=True, nogil=True, inline="always")
def _source_rank(sources, edge):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Where ``edge`` sits among a table's sorted ``sources`` (-1: not a source).

    A binary search written out: numba's ``np.searchsorted`` is a call that counts references
    on ``sources`` each time (two atomic operations per distinct source of a trace's pairs).
    """
    lo, hi = 0, len(sources)
    while lo < hi:  # sources are distinct: the place of the one equal to the edge
        mid = (lo + hi) >> 1
        source = sources[mid]
        if source == edge:
            return mid
        if source < edge:
            lo = mid + 1
        else:
            hi = mid
    return -1


@njit(cache=True, nogil=True)
def table_records(sources, ptr, state, index, copy_ptr, copy_state, from_edge, to_edge):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Record of the best route of each ``(from, to)`` pair in a table (-1: none).

    See :func:`_best_record`. ``index`` is the table's
    :func:`~roadnets.record_index.record_index`.
    """
    index_ptr, slots = index
    n = len(from_edge)
    out = np.full(n, -1, dtype=np.int64)
    last_from, rank = -1, -1  # the matcher's pairs come in runs of one from edge: one look-up a run
    for i in range(n):
        a = from_edge[i]
        if a != last_from:
            last_from = a
            rank = _source_rank(sources, a)
        if rank >= 0:
            out[i] = _best_record(
                ptr, state, index_ptr, slots, copy_ptr, copy_state, rank, to_edge[i]
            )
    return out


@njit(cache=True, nogil=True, inline="always")
def _largest_bounds(from_edge, bounds, slot):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    The largest bound of each distinct ``from`` edge's pairs, and where each edge's is.

    The bound a search from that edge would run with (:func:`group_pairs`); ``slot[e]`` is the
    edge's place in what this returns until :func:`_clear_slots` sets it back to -1.
    """
    largest = np.empty(len(from_edge))
    n_src = 0
    for i in range(len(from_edge)):
        e = from_edge[i]
        if slot[e] < 0:
            slot[e] = n_src
            largest[n_src] = bounds[i]
            n_src += 1
        else:
            largest[slot[e]] = max(largest[slot[e]], bounds[i])
    return largest


@njit(cache=True, nogil=True, inline="always")
def _clear_slots(from_edge, slot):  # type: ignore[no-untyped-def]  # pragma: no cover
    for i in range(len(from_edge)):
        slot[from_edge[i]] = -1


@njit(cache=True, nogil=True)
def search_bounds(from_edge, bounds, slot):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    The bound of the search each ``(from, to)`` pair's route comes from.

    A search runs per distinct ``from`` edge with the largest bound of its pairs
    (:func:`group_pairs`): routing some of the pairs, each with this bound, answers them as
    routing all of them does. ``slot`` as in :func:`table_routes` (-1 throughout, left so).
    """
    largest = _largest_bounds(from_edge, bounds, slot)
    out = np.empty(len(from_edge))
    for i in range(len(from_edge)):
        out[i] = largest[slot[from_edge[i]]]
    _clear_slots(from_edge, slot)
    return out


@njit(cache=True, nogil=True)
def searches_within(from_edge, bounds, limit, slot):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Whether the search each ``(from, to)`` pair's route comes from runs within ``limit``.

    A search runs per distinct ``from`` edge with the largest bound of its pairs
    (:func:`group_pairs`), so a table of every route within ``limit`` answers exactly those
    pairs as the searches would (:func:`table_routes`), and the others are searched alone with
    the same bounds. ``slot`` as in :func:`table_routes` (-1 throughout, left so).
    """
    largest = _largest_bounds(from_edge, bounds, slot)
    within = np.empty(len(from_edge), dtype=np.bool_)
    for i in range(len(from_edge)):
        within[i] = largest[slot[from_edge[i]]] <= limit
    _clear_slots(from_edge, slot)
    return within


@njit(cache=True, nogil=True)
def table_routes(table, state_edge, from_edge, to_edge, bounds, uturn_cost, slot):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Routes of ``(from, to)`` edge pairs from a complete table, as bounded searches would find them.

    The record of each pair (:func:`table_records`), less those a search with these bounds
    would not have settled: a search runs per distinct ``from`` edge with the largest bound of
    its pairs (:func:`group_pairs`) and settles a state when its key (length plus U-turn
    costs) fits, so a record of a complete table counts only within that bound, and the table
    then answers exactly what the searches would. With each route its length, time and
    U-turns (as :func:`gather`) and the edge it drives onto its target edge from (its last
    edge before the target, ``from`` itself when the target follows at once; -1 without a
    route).

    The pairs are memory-bound on the table (a trace's records are seldom in the caches: the
    rest of its match has run since the last trace's), so the look-up runs in stages, each
    asking for the next stage's loads of every pair before any is read (:func:`prefetch`):
    the index slot a pair's record is looked for in first, then that record's columns, then
    the record before it on the route (its arrival edge). One pass reading each record's
    columns together is 10-20 % faster than a pass per column; the stages take 13-21 % off
    that pass on a trace read right after another (3-6 us a trace slower with warm caches).

    ``table`` is ``(sources, ptr, state, index, distance, time, uturns, pred, copy_ptr,
    copy_state)`` (``index`` the table's :func:`~roadnets.record_index.record_index`);
    ``slot`` is :func:`group_pairs`' first scratch array (-1 throughout, left so).

    Returns ``record, distance, time, uturns, arrival`` per pair (-1, ``inf``, ``inf``, 0,
    -1 where there is none).
    """
    sources, ptr, state, index, distance, time, uturns, pred, copy_ptr, copy_state = table
    index_ptr, slots = index
    n = len(from_edge)
    largest = _largest_bounds(from_edge, bounds, slot)
    # stage 1: each pair's source block and first index slot
    rank = np.empty(n, dtype=np.int64)
    first = np.empty(n, dtype=np.int64)
    last_from, block = -1, -1  # pairs come in runs of one from edge
    for i in range(n):
        if from_edge[i] != last_from:
            last_from = from_edge[i]
            block = _source_rank(sources, last_from)
        rank[i] = block
        if block >= 0:
            first[i] = first_slot(index_ptr, block, to_edge[i])
            prefetch(slots, first[i])
    # stage 2: the record that slot names (most often the pair's own)
    for i in range(n):
        if rank[i] >= 0:
            place = np.int64(slots[first[i]])
            if place != 0:
                r = ptr[rank[i]] + place - 1
                prefetch(state, r)
                prefetch(distance, r)
                prefetch(uturns, r)
                prefetch(time, r)
                prefetch(pred, r)
    # stage 3: the records, their bound check and columns; the record before each on its route
    rec = np.full(n, -1, dtype=np.int64)
    dist_out = np.full(n, np.inf)
    time_out = np.full(n, np.inf)
    turns_out = np.zeros(n, dtype=np.int64)
    before = np.empty(n, dtype=np.int64)
    for i in range(n):
        if rank[i] < 0:
            continue
        a = from_edge[i]
        r = _best_record(ptr, state, index_ptr, slots, copy_ptr, copy_state, rank[i], to_edge[i])
        if r < 0 or distance[r] + uturn_cost * uturns[r] > largest[slot[a]]:
            continue
        rec[i] = r
        dist_out[i] = distance[r]
        time_out[i] = time[r]
        turns_out[i] = uturns[r]
        before[i] = pred[r]
        if before[i] >= 0:
            prefetch(state, before[i])
    # stage 4: the arrival edges
    arrival = np.full(n, -1, dtype=np.int64)
    for i in range(n):
        if rec[i] >= 0:
            arrival[i] = from_edge[i] if before[i] < 0 else state_edge[state[before[i]]]
    _clear_slots(from_edge, slot)
    return rec, dist_out, time_out, turns_out, arrival


@njit(cache=True, nogil=True)
def route_pairs_kernel(graph, from_edge, to_edge, bounds, uturn_cost, ws, scratch):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    The best route of each ``(from, to)`` pair: :func:`group_pairs`, then :func:`search_many`.

    ``graph`` holds :func:`search_many`'s first ten arguments
    (:func:`roadnets.routes.search_graph`).

    Returns the searches (``sources, source bounds, ptr, state, distance, time, U-turns,
    predecessor``), their targets (``target_ptr, target_edge, target_rec``) and per pair its
    record, length, time and U-turns (``inf, inf, 0`` where there is none).
    """
    src, src_bound, target_ptr, target_edge, pair_target = group_pairs(
        from_edge, to_edge, bounds, scratch
    )
    trans_ptr, trans_to, state_edge, plain, edge_v, edge_twin, edge_len, edge_time = graph[:8]
    edge_key, trans_key = graph[8], graph[9]
    ptr, state, dist, time, turns, pred, target_rec = search_many(
        trans_ptr,
        trans_to,
        state_edge,
        plain,
        edge_v,
        edge_twin,
        edge_len,
        edge_time,
        edge_key,
        trans_key,
        src,
        src_bound,
        uturn_cost,
        target_ptr,
        target_edge,
        ws,
    )
    rec = target_rec[pair_target]
    pair_dist, pair_time, pair_turns = gather(rec, dist, time, turns)
    return (
        src,
        src_bound,
        ptr,
        state,
        dist,
        time,
        turns,
        pred,
        target_ptr,
        target_edge,
        target_rec,
        rec,
        pair_dist,
        pair_time,
        pair_turns,
    )


@njit(cache=True, nogil=True)
def group_pairs(from_edge, to_edge, bounds, scratch):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Group edge pairs by source for :func:`search_many`, in ``O(pairs)``.

    Returns the sorted distinct sources, each one's largest bound, the CSR of its distinct
    target edges, and for each pair the index of its target in that CSR. ``scratch`` is
    ``(slot, mark, position)``, three arrays of one entry per edge, the first two -1
    throughout (:func:`new_group_scratch`); they are left so.
    """
    n = len(from_edge)
    slot, mark, position = scratch
    found = np.empty(n, dtype=np.int64)
    n_src = 0
    for i in range(n):
        if slot[from_edge[i]] < 0:
            slot[from_edge[i]] = n_src
            found[n_src] = from_edge[i]
            n_src += 1
    order = np.argsort(found[:n_src])
    rank = np.empty(n_src, dtype=np.int64)
    rank[order] = np.arange(n_src)
    sources = found[:n_src][order]
    src_bound = np.full(n_src, -np.inf)
    start = np.zeros(n_src + 1, dtype=np.int64)
    for i in range(n):
        r = rank[slot[from_edge[i]]]
        start[r + 1] += 1
        src_bound[r] = max(src_bound[r], bounds[i])
    start = np.cumsum(start)
    fill = start[:-1].copy()
    by_source = np.empty(n, dtype=np.int64)
    for i in range(n):
        r = rank[slot[from_edge[i]]]
        by_source[fill[r]] = i
        fill[r] += 1
    target_ptr = np.zeros(n_src + 1, dtype=np.int64)
    target_edge = np.empty(n, dtype=np.int64)
    pair_target = np.empty(n, dtype=np.int64)
    count = 0
    for r in range(n_src):
        for k in range(start[r], start[r + 1]):
            i = by_source[k]
            e = to_edge[i]
            if mark[e] != r:
                mark[e] = r
                position[e] = count
                target_edge[count] = e
                count += 1
            pair_target[i] = position[e]
        target_ptr[r + 1] = count
    for i in range(n):
        slot[from_edge[i]] = -1
        mark[to_edge[i]] = -1
    return sources, src_bound, target_ptr, target_edge[:count], pair_target


def new_group_scratch(n_edges: int) -> tuple[npt.NDArray[np.int64], ...]:
    """The scratch arrays of :func:`group_pairs` for a network of ``n_edges`` edges."""
    return (
        np.full(n_edges, -1, dtype=np.int64),
        np.full(n_edges, -1, dtype=np.int64),
        np.empty(n_edges, dtype=np.int64),
    )


@njit(cache=True, nogil=True)
def gather(rec, distance, time, uturns):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Length, time and U-turns of each record (``inf``, ``inf``, 0 for -1)."""
    n = len(rec)
    dist_out = np.full(n, np.inf)
    time_out = np.full(n, np.inf)
    turns_out = np.zeros(n, dtype=np.int64)
    for i in range(n):
        r = rec[i]
        if r >= 0:
            dist_out[i] = distance[r]
            time_out[i] = time[r]
            turns_out[i] = uturns[r]
    return dist_out, time_out, turns_out
