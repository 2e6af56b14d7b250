"""The path of each solved piece, walked transition by transition (compiled).

:mod:`mapmatch.hmm.assemble` describes the rules: the path only moves forward from its front,
a held fix leaves it where it is, a move that starts behind the front and turns off before it
cuts the path back, a mid-road U-turn turns where the fixes in between reached. This module
is those rules as one compiled walk over every piece of a solution (:func:`walk_pieces`),
its stretches kept in flat arrays instead of lists; the Python functions in
:mod:`mapmatch.hmm.assemble` and :mod:`mapmatch.hmm.loops` read what it gives.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from mapmatch.hmm.geometry import project_kernel, stretch_vertices
from mapmatch.hmm.loops import collapse_kernel
from mapmatch.hmm.observations import TRUSTED_SLACK_FRAC, between_kernel
from mapmatch.hmm.routes import ROUTE_SAME_EDGE, ROUTE_STANDSTILL, ROUTE_UTURN
from mapmatch.hmm.transition import _pair_routes

__all__ = ["EPS_M", "walk_pieces"]

#: Two places this close (metres) along a road are one.
EPS_M = 1e-6


@njit(cache=True, nogil=True)
def _farthest_reached(edge, from_m, x, y, radius, geom):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Farthest offset along ``edge`` (beyond ``from_m``) that fixes within their radius reach."""
    if len(x) == 0:
        return from_m
    length = geom[0][edge]
    one = np.array([edge])
    vx, vy, va = stretch_vertices(one, np.array([0.0]), np.array([length]), geom)
    n = len(x)
    along, dist = project_kernel(x, y, np.full(n, from_m), np.full(n, length), vx, vy, va)
    best = -np.inf
    for i in range(n):
        if dist[i] <= radius[i] and along[i] > best:
            best = along[i]
    return best if best > -np.inf else from_m


@njit(cache=True, nogil=True, inline="always")
def _gap_s(ftime, first, stop):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """Longest time between consecutive fixes ``first..stop - 1`` (0 for one fix)."""
    gap = 0.0
    for i in range(first, stop - 1):
        gap = max(gap, ftime[i + 1] - ftime[i])
    return gap


@njit(cache=True, nogil=True)
def _end_in_time(  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    t, start, stop, ea, eb, oa, ob, length, speed,
    c_ptr, c_edge, c_off, states, o_first, o_stop, used, ftime,
):  # fmt: skip
    """
    Whether a car that turns round on dead-end edge ``ea`` had time to reach its end.

    The step ``t -> t + 1`` goes out on ``ea`` (at ``oa``) and back on its twin ``eb`` (at
    ``ob``). The car may have turned between those observations' fixes, but also within
    either of them (fixes on the way out and back that merged into one place), or, when the
    fix beside the turn was already on its way back or still on its way out (a fix on a
    two-way road is as near either direction, and one that seems to hold still may be the
    car coming back), one observation earlier or later. It had time when, in one of those
    gaps between two consecutive fixes, a car at ``speed`` (the road's limit) gets from the
    fix before it out to the end and back to the fix after it. Without times: no.
    """
    a, b = used[t], used[t + 1]
    # how far fix a lies from the end (on either way) is length - oa, fix b's is ob
    back_a = length - oa
    # (distance out to the end and back, time between the fixes around the turn)
    if back_a + ob <= speed * (ftime[o_first[b]] - ftime[o_stop[a] - 1]):
        return True
    if 2.0 * back_a <= speed * _gap_s(ftime, o_first[a], o_stop[a]):
        return True
    if 2.0 * ob <= speed * _gap_s(ftime, o_first[b], o_stop[b]):
        return True
    if t > start:
        r = c_ptr[t - 1] + states[t - 1]
        before = used[t - 1]
        if c_edge[r] == ea and (length - c_off[r]) + back_a <= speed * (
            ftime[o_first[a]] - ftime[o_stop[before] - 1]
        ):
            return True
    if t + 2 < stop:
        r = c_ptr[t + 2] + states[t + 2]
        after = used[t + 2]
        if c_edge[r] == eb and ob + c_off[r] <= speed * (
            ftime[o_first[after]] - ftime[o_stop[b] - 1]
        ):
            return True
    return False


@njit(cache=True, nogil=True)
def _ensure(e, lo, hi, size):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """The row arrays grown to hold ``size`` rows."""
    if size <= len(e):
        return e, lo, hi
    cap = max(2 * len(e), size)
    e2 = np.empty(cap, dtype=np.int64)
    lo2 = np.empty(cap)
    hi2 = np.empty(cap)
    e2[: len(e)] = e
    lo2[: len(e)] = lo
    hi2[: len(e)] = hi
    return e2, lo2, hi2


@njit(cache=True, nogil=True)
def _stretches(size):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """Empty ``(edge, lo, hi)`` arrays of ``size`` stretches."""
    return np.empty(size, dtype=np.int64), np.empty(size), np.empty(size)


@njit(cache=True, nogil=True, inline="always")
def _route_length(rec, r_pred):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """How many edges lie strictly between a route's ends (its record's predecessors)."""
    count = 0
    r = r_pred[rec]
    while r >= 0:
        count += 1
        r = r_pred[r]
    return count


@njit(cache=True, nogil=True)
def _route_edges(rec, count, r_state, r_pred, state_edge, out):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    The ``count`` edges strictly between a route's ends (:func:`_route_length`), into ``out``.

    ``out`` never grows here: the caller sizes it from the routes' lengths first.
    """
    if count > len(out):
        msg = "route longer than its buffer"
        raise ValueError(msg)
    r = r_pred[rec]
    k = count - 1
    while r >= 0:
        out[k] = state_edge[r_state[r]]
        k -= 1
        r = r_pred[r]
    return count


@njit(cache=True, nogil=True)
def _behind(edge, offset, front_edge, front, limit, edge_len, routing):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Whether a place lies at most ``limit`` behind the path's front along the road."""
    if edge == front_edge:
        return offset <= front + EPS_M
    ahead = edge_len[edge] - offset + front
    if ahead > limit:
        return False
    graph, ws, scratch, uturn_cost_m, table = routing
    _, _, _, dist, _, _, _ = _pair_routes(
        graph, ws, scratch, uturn_cost_m, table,
        np.array([edge]), np.array([front_edge]), np.array([limit - ahead]),
    )  # fmt: skip
    return ahead + dist[0] <= limit


@njit(cache=True, nogil=True)
def walk_pieces(  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    solution, obs, fixes, travel, net, routing, hold_limit, loops
):
    """
    The stretches driven through every piece of a solution, and where each fix of it is.

    ``solution`` is ``(cand ptr, edge, offset, states, kinds, piece starts, piece stops,
    used, pair records, route states, route predecessors)``, ``obs`` the observations'
    ``(first, stop, time)``, ``fixes`` every fix's ``(x, y, radius, time)``
    (``time`` NaN throughout without usable times), ``travel`` the
    observations' travel arrays, ``net`` ``(edge_len, edge_speed, edge_u, edge_v, edge_twin,
    out_ptr, state_edge, geom)`` (``geom`` as :func:`stretch_vertices` reads it).

    ``loops`` is ``(log_emission, x, y, sigma, params, loop_penalty, network, scatter,
    chosen distance)`` for :func:`~mapmatch.hmm.loops.collapse_kernel`, run on each piece's
    path.

    Returns ``(row_ptr, edge, lo, hi, along, jumps, loops)``: the stretches of piece ``p``
    are rows ``row_ptr[p]:row_ptr[p + 1]``, ``along`` holds the distance along its path of
    each of its used observations (in solution order), ``jumps`` the moves drawn as jumps,
    ``loops`` the loops taken out, per piece.
    """
    c_ptr, c_edge, c_off, states, kinds, p_lo, p_hi, used, pair_rec, r_state, r_pred = solution
    o_first, o_stop, o_time = obs
    fx, fy, fradius, ftime = fixes
    edge_len, edge_speed, edge_u, edge_v, _, out_ptr, state_edge, geom = net
    odometer, speed_m, slack_m, unknown_lo, unknown_hi = travel
    n_pieces = len(p_lo)
    n_used = len(used)
    # the pair index of each step's first pair (pairs: by step, then a, then b)
    pair_first = np.zeros(max(n_used, 1), dtype=np.int64)
    for t in range(n_used - 1):
        pair_first[t + 1] = pair_first[t] + (c_ptr[t + 1] - c_ptr[t]) * (
            c_ptr[t + 2] - c_ptr[t + 1]
        )
    row_ptr = np.zeros(n_pieces + 1, dtype=np.int64)
    out_e, out_lo, out_hi = np.empty(64, dtype=np.int64), np.empty(64), np.empty(64)
    along_all = np.empty(n_used)
    jumps = np.zeros(n_pieces, dtype=np.int64)
    removed = np.zeros(n_pieces, dtype=np.int64)
    em_pad, ox, oy, osigma, params, loop_penalty, loop_net, scatter, chosen_dist = loops
    # the buffers of one piece's walk, sized ahead from its routes: an array that may grow
    # inside the walk's loop makes the loop several times slower (numba)
    # (each routed step's record and its number of edges between the ends, read by the walk)
    step_rec = np.full(max(n_used - 1, 0), -1, dtype=np.int64)
    step_via = np.zeros(max(n_used - 1, 0), dtype=np.int64)
    longest, grows = 0, 0
    for p in range(n_pieces):
        piece = 0
        for t in range(p_lo[p], p_hi[p] - 1):
            move = kinds[t, states[t], states[t + 1]]
            if move != ROUTE_STANDSTILL and move != ROUTE_SAME_EDGE and move != ROUTE_UTURN:
                step_rec[t] = pair_rec[
                    pair_first[t] + states[t] * (c_ptr[t + 2] - c_ptr[t + 1]) + states[t + 1]
                ]
                step_via[t] = _route_length(step_rec[t], r_pred)
            longest = max(longest, step_via[t])
            piece += step_via[t] + 4  # a step adds at most its move (via + 2) and the front's end
        grows = max(grows, piece)
    via = np.empty(max(longest, 1), dtype=np.int64)
    move_e, move_lo, move_hi = _stretches(longest + 2)
    tail_e, tail_lo, tail_hi = _stretches(longest + 4)
    path_e, path_lo, path_hi = _stretches(grows + 1)
    n_out = 0
    has_travel = len(odometer) > 0 or len(speed_m) > 0
    for p in range(n_pieces):
        start, stop = p_lo[p], p_hi[p]
        # the travel between consecutive observations, only where it says something
        piece_travel = np.full(max(stop - start - 1, 0), np.nan)
        if has_travel:
            dist_t, slack_t = between_kernel(
                used[start:stop], odometer, speed_m, slack_m, unknown_lo, unknown_hi
            )
            for k in range(len(piece_travel)):
                if slack_t[k] <= TRUSTED_SLACK_FRAC * dist_t[k]:
                    piece_travel[k] = dist_t[k]
        row0 = c_ptr[start] + states[start]
        n_path = 1
        path_e[0], path_lo[0], path_hi[0] = c_edge[row0], c_off[row0], c_off[row0]
        done = 0.0
        along_all[start] = 0.0
        for t in range(start, stop - 1):
            ra, rb = c_ptr[t] + states[t], c_ptr[t + 1] + states[t + 1]
            ea, eb = c_edge[ra], c_edge[rb]
            oa, ob = c_off[ra], c_off[rb]
            move = kinds[t, states[t], states[t + 1]]
            front_edge, front = path_e[n_path - 1], path_hi[n_path - 1]
            # the move's stretches
            n_move = 0
            if move == ROUTE_STANDSTILL:
                n_move = 0
            elif move == ROUTE_SAME_EDGE:
                move_e[0], move_lo[0], move_hi[0] = ea, oa, ob
                n_move = 1
            elif move == ROUTE_UTURN:
                length = edge_len[ea]
                turn = max(oa, length - ob)
                if front_edge == ea:
                    turn = max(turn, front)
                lo_f, hi_f = o_first[used[t]], o_stop[used[t + 1]]
                turn = max(
                    turn,
                    _farthest_reached(
                        ea, turn, fx[lo_f:hi_f], fy[lo_f:hi_f], fradius[lo_f:hi_f], geom
                    ),
                )
                node = edge_v[ea]
                travel_t = piece_travel[t - start]
                if np.isfinite(travel_t):  # out to the turn and back covers the travel
                    turn = max(turn, 0.5 * (travel_t + oa + length - ob))
                dead_end = out_ptr[node + 1] - out_ptr[node] <= 1
                if dead_end and length - turn > hold_limit:
                    # where the travel is known it says where the car turned; else the time
                    dead_end = not np.isfinite(travel_t) and _end_in_time(
                        t, start, stop, ea, eb, oa, ob, length, edge_speed[ea],
                        c_ptr, c_edge, c_off, states, o_first, o_stop, used, ftime,
                    )  # fmt: skip
                if dead_end:
                    # a dead end is driven to its end, where there is room to turn, unless the
                    # time between the fixes is too short to get there and back at its limit
                    # (_end_in_time); fixes that stop short of the end by less than a held
                    # car's scatter (hold_limit) cannot tell a turn there from one at the end
                    turn = length
                turn = min(turn, length)
                move_e[0], move_lo[0], move_hi[0] = ea, oa, turn
                move_e[1], move_lo[1], move_hi[1] = eb, length - turn, ob
                n_move = 2
            else:  # a route: the step's record and length from the sizing pass above
                n_via = _route_edges(step_rec[t], step_via[t], r_state, r_pred, state_edge, via)
                move_e[0], move_lo[0], move_hi[0] = ea, oa, edge_len[ea]
                for k in range(n_via):
                    e = via[k]
                    move_e[k + 1], move_lo[k + 1], move_hi[k + 1] = e, 0.0, edge_len[e]
                move_e[n_via + 1], move_lo[n_via + 1], move_hi[n_via + 1] = eb, 0.0, ob
                n_move = n_via + 2
            if n_move:
                status, n_tail = _continue_from(
                    path_e[n_path - 1], path_lo[n_path - 1], path_hi[n_path - 1],
                    move_e, move_lo, move_hi, n_move, tail_e, tail_lo, tail_hi,
                    edge_len, edge_u, edge_v,
                )  # fmt: skip
                # a move that ends at most the hold limit behind the front as it was before
                # any cut has no tail: the car holds (asked here, not inside the call above,
                # so that the routing arrays are handed over only when a move needs them)
                if status < 0 and _behind(
                    move_e[n_move - 1], move_hi[n_move - 1], front_edge, front, hold_limit,
                    edge_len, routing,
                ):  # fmt: skip
                    status, n_tail = 0, 0
                if status < 0:  # the move starts behind the front and turns off before it
                    n_path, done = _retract(
                        path_e, path_lo, path_hi, n_path, done, move_e[0], move_lo[0], hold_limit
                    )
                    # (the same move is no nearer the front than before: no hold this time)
                    status, n_tail = _continue_from(
                        path_e[n_path - 1], path_lo[n_path - 1], path_hi[n_path - 1],
                        move_e, move_lo, move_hi, n_move, tail_e, tail_lo, tail_hi,
                        edge_len, edge_u, edge_v,
                    )  # fmt: skip
                if status < 0:  # nowhere on the path: drawn as a jump
                    jumps[p] += 1
                    tail_e[0], tail_lo[0], tail_hi[0] = (
                        path_e[n_path - 1],
                        path_lo[n_path - 1],
                        path_hi[n_path - 1],
                    )
                    for k in range(n_move):
                        tail_e[k + 1], tail_lo[k + 1], tail_hi[k + 1] = (
                            move_e[k],
                            move_lo[k],
                            move_hi[k],
                        )
                    n_tail = n_move + 1
                    status = 0
                drop = status == 1
                if drop and n_tail:  # leave the front's node on another edge
                    if n_path > 1:
                        n_path -= 1
                        done -= path_hi[n_path - 1] - path_lo[n_path - 1]
                        for k in range(n_tail, 0, -1):
                            tail_e[k], tail_lo[k], tail_hi[k] = (
                                tail_e[k - 1],
                                tail_lo[k - 1],
                                tail_hi[k - 1],
                            )
                        tail_e[0], tail_lo[0], tail_hi[0] = (
                            path_e[n_path - 1],
                            path_lo[n_path - 1],
                            path_hi[n_path - 1],
                        )
                        n_tail += 1
                    else:
                        path_e[0], path_lo[0], path_hi[0] = tail_e[0], tail_lo[0], tail_hi[0]
                if n_tail:
                    path_hi[n_path - 1] = tail_hi[0]
                    if n_path + n_tail > len(path_e):
                        msg = "path longer than its buffer"
                        raise ValueError(msg)
                    for k in range(1, n_tail):
                        done += path_hi[n_path - 1] - path_lo[n_path - 1]
                        path_e[n_path], path_lo[n_path], path_hi[n_path] = (
                            tail_e[k],
                            tail_lo[k],
                            tail_hi[k],
                        )
                        n_path += 1
            along_all[t + 1] = done + path_hi[n_path - 1] - path_lo[n_path - 1]
        # loops the fixes do not support taken out (hmm/loops.py)
        model = (
            start, used, states, em_pad, ox, oy, o_time, osigma, params, loop_penalty,
            scatter, chosen_dist,
        )  # fmt: skip
        e, lo, hi, along_p, removed[p] = collapse_kernel(
            path_e[:n_path].copy(), path_lo[:n_path].copy(), path_hi[:n_path].copy(),
            along_all[start:stop], model, travel, loop_net,
        )  # fmt: skip
        along_all[start:stop] = along_p
        out_e, out_lo, out_hi = _ensure(out_e, out_lo, out_hi, n_out + len(e))
        out_e[n_out : n_out + len(e)] = e
        out_lo[n_out : n_out + len(e)] = lo
        out_hi[n_out : n_out + len(e)] = hi
        n_out += len(e)
        row_ptr[p + 1] = n_out
    return (
        row_ptr,
        out_e[:n_out].copy(),
        out_lo[:n_out].copy(),
        out_hi[:n_out].copy(),
        along_all,
        jumps,
        removed,
    )


@njit(cache=True, nogil=True)
def _continue_from(  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    edge, front_lo, front, move_e, move_lo, move_hi, n_move, tail_e, tail_lo, tail_hi,
    edge_len, edge_u, edge_v,
):  # fmt: skip
    """
    The part of a move beyond the path's front ``(edge, front_lo, front)``, into ``tail``.

    The front is a place on an edge; at the edge's start or end it is also the node there,
    which a move may pass on other edges. Returns ``(status, n_tail)``: status 1 when the
    front's own (empty) stretch is to be dropped (the move leaves the front's node on another
    edge), 0 when not, -1 when the move never passes the front; the tail's first stretch
    continues the front's.
    """
    at_start = front <= EPS_M and front_lo <= EPS_M
    at_end = front >= edge_len[edge] - EPS_M
    for k in range(n_move):
        ek, start, end = move_e[k], move_lo[k], move_hi[k]
        if ek == edge and start - EPS_M <= front <= end + EPS_M:
            tail_e[0], tail_lo[0], tail_hi[0] = ek, front, max(front, end)
            n = 1
            for j in range(k + 1, n_move):
                tail_e[n], tail_lo[n], tail_hi[n] = move_e[j], move_lo[j], move_hi[j]
                n += 1
            return 0, n
        if at_end and start <= EPS_M and edge_u[ek] == edge_v[edge]:
            tail_e[0], tail_lo[0], tail_hi[0] = edge, front, front
            n = 1
            for j in range(k, n_move):
                tail_e[n], tail_lo[n], tail_hi[n] = move_e[j], move_lo[j], move_hi[j]
                n += 1
            return 0, n
        if at_start and end >= edge_len[ek] - EPS_M and edge_v[ek] == edge_u[edge]:
            n = 0
            for j in range(k + 1, n_move):
                tail_e[n], tail_lo[n], tail_hi[n] = move_e[j], move_lo[j], move_hi[j]
                n += 1
            return 1, n
    return -1, 0


@njit(cache=True, nogil=True)
def _retract(path_e, path_lo, path_hi, n_path, done, edge, offset, limit):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Cut the path back to where a move starts, if that place is on it: ``(n_path, done)``.

    A move that starts behind the path's front and turns off before reaching it shows that
    the stretch beyond its start came from a scattered fix: the car never drove it.
    """
    cut = 0.0  # length of path beyond the place looked at
    for k in range(n_path - 1, -1, -1):
        lo, hi = path_lo[k], path_hi[k]
        if path_e[k] == edge and lo - EPS_M <= offset <= hi + EPS_M:
            if cut + hi - offset > limit:
                break
            path_hi[k] = max(lo, offset)
            total = 0.0
            for j in range(k):
                total += path_hi[j] - path_lo[j]
            return k + 1, total
        cut += hi - lo
        if cut > limit:
            break
    return n_path, done
