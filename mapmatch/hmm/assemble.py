"""Turn the solved HMM into segments of driven edges and per-fix positions.

The path of a piece is built transition by transition from the chosen candidates, and it only
ever moves forward: a fix that the model holds still (a slow or stopped car's fix scattered a
little backwards, :data:`~mapmatch.hmm.routes.ROUTE_STANDSTILL`) leaves the path where it is, and
the next move starts from the farthest point reached, not from the scattered fix. So noise
around a stop never adds length. A U-turn in the middle of a road turns at the farthest point
the fixes in between reached along the road (a dead end's end, when the fixes got there).

Fixes left out of the model (a stopped car's repeats, outliers, fixes dropped to join a break)
are placed at the nearest point of the path between their neighbours' positions; one whose
nearest point is farther than its search radius stays unmatched.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from mapmatch.hmm.loops import collapse_loops
from mapmatch.hmm.routes import ROUTE_SAME_EDGE, ROUTE_STANDSTILL, ROUTE_UTURN
from mapmatch.result import MatchedPoints, Segment

if TYPE_CHECKING:
    from collections.abc import Callable

    from mapmatch.config import MatchConfig
    from mapmatch.hmm.observations import Observations
    from mapmatch.hmm.solution import Solution
    from mapmatch.trace import Trace
    from mapmatch.types import BoolArray, FloatArray, IntArray
    from roadnets import RoadNetwork

__all__ = ["Assembled", "assemble"]


_EPS_M = 1e-6


@dataclass(frozen=True, slots=True)
class Assembled:
    """Segments and per-fix outcome of a solved trace."""

    segments: list[Segment]
    points: MatchedPoints
    jumps: int  # moves that could not continue from the path's front (drawn as a jump)
    loops: int  # loops the fixes did not support, taken out


@dataclass(frozen=True, slots=True)
class _PiecePath:
    edge: IntArray
    start_m: FloatArray
    end_m: FloatArray
    along_m: FloatArray  # distance along the path of each used fix of the piece
    jumps: int
    loops: int  # loops taken out (:mod:`mapmatch.hmm.loops`)


@njit(cache=True, nogil=True)
def _project_kernel(px, py, lo, hi, vx, vy, va):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Nearest point of a polyline (vertices ``vx, vy`` at distances ``va``) within [lo, hi]."""
    n = len(px)
    along = np.empty(n)
    dist = np.empty(n)
    nv = len(va)
    for i in range(n):
        best_d = np.inf
        best_a = lo[i]
        k0 = max(np.searchsorted(va, lo[i], side="right") - 1, 0)
        k1 = min(np.searchsorted(va, hi[i], side="left"), nv - 1)
        if nv == 1 or k0 >= k1:
            k = min(k0, nv - 1)
            best_a = min(max(va[k], lo[i]), hi[i])
            best_d = np.hypot(px[i] - vx[k], py[i] - vy[k])
        for k in range(k0, k1):
            seg = va[k + 1] - va[k]
            ax, ay = vx[k], vy[k]
            dx, dy = vx[k + 1] - ax, vy[k + 1] - ay
            d2 = dx * dx + dy * dy
            t = ((px[i] - ax) * dx + (py[i] - ay) * dy) / d2 if d2 > 0 and seg > 0 else 0.0
            a = va[k] + min(max(t, 0.0), 1.0) * seg
            a = min(max(a, lo[i]), hi[i])
            f = (a - va[k]) / seg if seg > 0 else 0.0
            qx, qy = ax + f * dx, ay + f * dy
            d = np.hypot(px[i] - qx, py[i] - qy)
            if d < best_d:
                best_d = d
                best_a = a
        along[i] = best_a
        dist[i] = best_d
    return along, dist


def _stretch_vertices(
    net: RoadNetwork, edge: IntArray, start_m: FloatArray, end_m: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Vertices of a path of edge stretches with their distance along the path (metres)."""
    a = net.arrays
    sizes = a.edge_geom_ptr[edge + 1] - a.edge_geom_ptr[edge]
    owner = np.repeat(np.arange(len(edge)), sizes)
    vertex = np.repeat(a.edge_geom_ptr[edge] - np.cumsum(sizes) + sizes, sizes) + np.arange(
        int(sizes.sum())
    )
    offset = a.geom_cum_m[vertex]
    inner = (offset > start_m[owner]) & (offset < end_m[owner])
    base = np.concatenate(([0.0], np.cumsum(end_m - start_m)[:-1]))
    n = len(edge)
    ends_x, ends_y = net.point_on_edge(
        np.concatenate((edge, edge)), np.concatenate((start_m, end_m))
    )
    x = np.concatenate((ends_x[:n], a.geom_x[vertex[inner]], ends_x[n:]))
    y = np.concatenate((ends_y[:n], a.geom_y[vertex[inner]], ends_y[n:]))
    along = np.concatenate(
        (base, base[owner[inner]] + offset[inner] - start_m[owner[inner]], base + end_m - start_m)
    )
    order = np.argsort(along, kind="stable")
    return x[order], y[order], along[order]


def _project_onto(
    vertices: tuple[FloatArray, FloatArray, FloatArray],
    px: FloatArray,
    py: FloatArray,
    lo: FloatArray,
    hi: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """Distance along a polyline of the nearest point to each ``(px, py)`` within [lo, hi]."""
    vx, vy, va = vertices
    along, dist = _project_kernel(
        np.ascontiguousarray(px, dtype=np.float64),
        np.ascontiguousarray(py, dtype=np.float64),
        np.ascontiguousarray(lo, dtype=np.float64),
        np.ascontiguousarray(hi, dtype=np.float64),
        vx,
        vy,
        va,
    )
    return np.asarray(along, dtype=np.float64), np.asarray(dist, dtype=np.float64)


def _farthest_reached(
    net: RoadNetwork, edge: int, from_m: float, x: FloatArray, y: FloatArray, radius_m: FloatArray
) -> float:
    """Farthest offset along ``edge`` (beyond ``from_m``) that fixes within their radius reach."""
    if len(x) == 0:
        return from_m
    length = float(net.arrays.edge_length_m[edge])
    vertices = _stretch_vertices(
        net, np.array([edge], dtype=np.int64), np.array([0.0]), np.array([length])
    )
    along, dist = _project_onto(vertices, x, y, np.full(len(x), from_m), np.full(len(x), length))
    near = dist <= radius_m
    return float(along[near].max()) if near.any() else from_m


def _route_pieces(
    net: RoadNetwork,
    solution: Solution,
    t: int,
    frontier: list[float],
    fixes_between: tuple[FloatArray, FloatArray, FloatArray],
    travel_m: float,
    dt_s: float,
    hold_limit_m: float,
) -> list[list[float]]:
    """Edge stretches ``[edge, start, end]`` of the move from used fix ``t`` to ``t + 1``."""
    arrays = net.arrays
    edge_len = arrays.edge_length_m
    cands, states = solution.cands, solution.states
    ra, rb = cands.ptr[t] + states[t], cands.ptr[t + 1] + states[t + 1]
    ea, eb = int(cands.edge[ra]), int(cands.edge[rb])
    oa, ob = float(cands.offset_m[ra]), float(cands.offset_m[rb])
    move = solution.kinds[t, states[t], states[t + 1]]
    if move == ROUTE_STANDSTILL:
        return []
    if move == ROUTE_SAME_EDGE:
        return [[ea, oa, ob]]
    if move == ROUTE_UTURN:
        length = float(edge_len[ea])
        turn = max(oa, length - ob)
        if int(frontier[0]) == ea:
            turn = max(turn, frontier[2])
        turn = max(turn, _farthest_reached(net, ea, turn, *fixes_between))
        node = int(arrays.edge_v[ea])
        to_end = (length - oa) + ob  # out to the end and back to b
        timed_reach = float(arrays.edge_speed_mps[ea]) * dt_s  # NaN without times
        if np.isfinite(travel_m):  # out to the turn and back covers the distance travelled
            turn = max(turn, 0.5 * (travel_m + oa + length - ob))
            timed_reach = np.nan  # the travel says where it turned
        if arrays.out_ptr[node + 1] - arrays.out_ptr[node] <= 1 and (
            length - turn <= 0.5 * hold_limit_m or to_end <= timed_reach
        ):
            # a dead end is driven to its end, where there is room to turn, unless the
            # time between the fixes is too short to get there and back at its speed limit
            turn = length
        turn = min(turn, length)
        return [[ea, oa, turn], [eb, length - turn, ob]]
    via = solution.routes.edges(ea, eb)
    return (
        [[ea, oa, float(edge_len[ea])]]
        + [[float(e), 0.0, float(edge_len[e])] for e in via]
        + [[eb, 0.0, ob]]
    )


def _continue_from(
    net: RoadNetwork,
    frontier: list[float],
    pieces: list[list[float]],
    behind: Callable[[int, float], bool],
) -> tuple[bool, list[list[float]]] | None:
    """
    The part of a move beyond the path's front, or ``None`` when the move never passes it.

    The front is a place on an edge; at the edge's start or end it is also the node there,
    which a move may pass on other edges. Returns whether the front's own (empty) stretch is
    to be dropped (the move leaves the front's node on another edge) and the stretches to
    add, the first of which continues the front's; ``[]`` when the move ends behind the front
    (``behind(edge, offset)``): the car holds.
    """
    arrays = net.arrays
    edge, front = int(frontier[0]), frontier[2]
    at_start = front <= _EPS_M and frontier[1] <= _EPS_M
    at_end = front >= arrays.edge_length_m[edge] - _EPS_M
    for k, (e, start, end) in enumerate(pieces):
        ek = int(e)
        if ek == edge and start - _EPS_M <= front <= end + _EPS_M:
            return False, [[e, front, max(front, end)], *pieces[k + 1 :]]
        if at_end and start <= _EPS_M and arrays.edge_u[ek] == arrays.edge_v[edge]:
            return False, [[edge, front, front], *pieces[k:]]
        if (
            at_start
            and end >= arrays.edge_length_m[ek] - _EPS_M
            and arrays.edge_v[ek] == arrays.edge_u[edge]
        ):
            return True, pieces[k + 1 :]
    last = pieces[-1]
    if behind(int(last[0]), last[2]):
        return False, []
    return None


def _behind_front(
    net: RoadNetwork, frontier: list[float], limit_m: float
) -> Callable[[int, float], bool]:
    """Whether a place lies at most ``limit_m`` behind the path's front along the road."""
    arrays = net.arrays
    front_edge, front = int(frontier[0]), frontier[2]

    def behind(edge: int, offset: float) -> bool:
        if edge == front_edge:
            return offset <= front + _EPS_M
        ahead = arrays.edge_length_m[edge] - offset + front
        if ahead > limit_m:
            return False
        one = np.array([edge], dtype=np.int64), np.array([front_edge], dtype=np.int64)
        mid = float(net.edge_routes(*one, limit_m - ahead).distance_m[0])
        return bool(ahead + mid <= limit_m)

    return behind


def _retract(entries: list[list[float]], done: float, start: list[float], limit_m: float) -> float:
    """
    Cut the path back to where a move starts, if that place is on it; the new ``done``.

    A move that starts behind the path's front and turns off before reaching it shows that
    the stretch beyond its start came from a scattered fix: the car never drove it.
    """
    edge, offset = int(start[0]), start[1]
    cut = 0.0  # length of path beyond the place looked at
    for k in range(len(entries) - 1, -1, -1):
        e, lo, hi = entries[k]
        if int(e) == edge and lo - _EPS_M <= offset <= hi + _EPS_M:
            if cut + hi - offset > limit_m:
                break
            del entries[k + 1 :]
            entries[k][2] = max(lo, offset)
            return float(sum(hi_ - lo_ for _, lo_, hi_ in entries[:-1]))
        cut += hi - lo
        if cut > limit_m:
            break
    return done


def _piece_path(
    net: RoadNetwork,
    obs: Observations,
    solution: Solution,
    start: int,
    stop: int,
    x: FloatArray,
    y: FloatArray,
    radius_m: FloatArray,
    hold_limit_m: float,
    config: MatchConfig,
) -> _PiecePath:
    """Edges driven between the chosen candidates of used fixes ``start..stop-1``."""
    cands, states, used = solution.cands, solution.states, solution.used
    piece_obs = used[start:stop]
    travel = np.full(max(len(piece_obs) - 1, 0), np.nan)
    if obs.travel is not None:  # only where it says something: an odometer, dense speeds
        distance, slack = obs.travel.between(piece_obs)
        with np.errstate(invalid="ignore"):
            travel = np.where(slack <= 0.25 * distance, distance, np.nan)
    first = cands.ptr[start] + states[start]
    offset0 = float(cands.offset_m[first])
    entries: list[list[float]] = [[float(cands.edge[first]), offset0, offset0]]
    done = 0.0  # length of the entries before the last one
    along = [0.0]
    jumps = 0
    for t in range(start, stop - 1):
        between = slice(int(obs.first[used[t]]), int(obs.stop[used[t + 1]]))
        pieces = _route_pieces(
            net,
            solution,
            t,
            entries[-1],
            (x[between], y[between], radius_m[between]),
            float(travel[t - start]),
            float(obs.time_s[used[t + 1]] - obs.time_s[used[t]]),
            hold_limit_m,
        )
        if pieces:
            behind = _behind_front(net, entries[-1], hold_limit_m)
            found = _continue_from(net, entries[-1], pieces, behind)
            if found is None:  # the move starts behind the front and turns off before it
                done = _retract(entries, done, pieces[0], hold_limit_m)
                found = _continue_from(net, entries[-1], pieces, behind)
            if found is None:  # nowhere on the path: drawn as a jump
                jumps += 1
                found = False, [entries[-1][:], *pieces]
            drop, tail = found
            if drop and tail:  # leave the front's node on another edge
                if len(entries) > 1:
                    entries.pop()
                    done -= entries[-1][2] - entries[-1][1]
                    tail = [entries[-1][:], *tail]
                else:
                    entries[0] = tail[0][:]
            if tail:
                entries[-1][2] = tail[0][2]
                for entry in tail[1:]:
                    done += entries[-1][2] - entries[-1][1]
                    entries.append(entry)
        last = entries[-1]
        along.append(done + last[2] - last[1])
    entries, along_m, loops = collapse_loops(
        net, obs, solution, start, entries, np.array(along, dtype=np.float64), config
    )
    # an end fix within the observations' resolution (thinning_sigmas x sigma) of a junction
    # cannot tell which side of it the car was: the path starts and ends at the junction
    reach = config.thinning_sigmas * float(obs.sigma_m[used[start:stop]].min())
    entries, along_m = _trim_ends(entries, along_m, reach)
    table = np.array(entries, dtype=np.float64).reshape(-1, 3)
    return _PiecePath(table[:, 0].astype(np.int64), table[:, 1], table[:, 2], along_m, jumps, loops)


def _trim_ends(
    entries: list[list[float]], along_m: FloatArray, reach_m: float
) -> tuple[list[list[float]], FloatArray]:
    """
    Drop a sliver of a next (or previous) edge at either end of a path.

    A first or last fix a metre past a junction cannot be told from the junction itself:
    a stretch shorter than ``reach_m`` at an end of the path, on an edge of its own, is taken
    as the junction, so the path neither starts nor ends on a road it never
    drove along.
    """
    if len(entries) > 1 and entries[-1][2] - entries[-1][1] < reach_m:
        cut = entries[-1][2] - entries[-1][1]
        entries = entries[:-1]
        along_m = np.minimum(along_m, along_m.max() - cut)
    if len(entries) > 1 and entries[0][2] - entries[0][1] < reach_m:
        cut = entries[0][2] - entries[0][1]
        entries = entries[1:]
        along_m = np.maximum(along_m - cut, 0.0)
    return entries, along_m


def _segment(net: RoadNetwork, index: int, first: int, last: int, path: _PiecePath) -> Segment:
    # attributes and geometry are read from the network when a result is serialised
    return Segment(index, first, last, path.edge, path.start_m, path.end_m, net=net)


def _locate(path: _PiecePath, along_m: FloatArray) -> tuple[IntArray, FloatArray]:
    """Edge and offset at distances along a piece's path."""
    driven = path.end_m - path.start_m
    cum_end = np.cumsum(driven)
    i = np.minimum(np.searchsorted(cum_end, along_m, side="left"), len(driven) - 1)
    before = cum_end[i] - driven[i]
    offset = np.clip(path.start_m[i] + (along_m - before), path.start_m[i], path.end_m[i])
    return path.edge[i], offset


def assemble(
    net: RoadNetwork,
    trace: Trace,
    x: FloatArray,
    y: FloatArray,
    obs: Observations,
    solution: Solution,
    outlier: BoolArray,
    radius_m: FloatArray,
    hold_limit_m: float,
    config: MatchConfig,
) -> Assembled:
    """
    Segments of the solved pieces, and every fix's matched position.

    The path of a piece runs through its observations' chosen candidates (held ones stay at
    the front, see the module docstring). Every fix of the piece, and the outliers just before
    or after it, is then placed at the nearest point of the path between the observations
    around it (its own included); a fix that did not enter the model (a stray, an outlier, a
    fix dropped to join a break) farther from that point than its search radius ``radius_m``
    stays unmatched, as do fixes outside every piece. Fixes that entered the model have their
    observation's confidence, the others the lower of their neighbours'.
    """
    n = len(x)
    matched = np.zeros(n, dtype=bool)
    in_model = np.zeros(n, dtype=bool)
    edge = np.full(n, -1, dtype=np.int64)
    offset = np.full(n, np.nan)
    confidence = np.zeros(n)
    segment_of = np.full(n, -1, dtype=np.int64)
    segments: list[Segment] = []
    jumps = loops = 0
    used, states = solution.used, solution.states
    post = solution.post[np.arange(len(used)), np.maximum(states, 0)]
    for index, (start, stop) in enumerate(solution.pieces):
        path = _piece_path(net, obs, solution, start, stop, x, y, radius_m, hold_limit_m, config)
        jumps += path.jumps
        loops += path.loops
        piece_obs = used[start:stop]
        first, last = int(obs.first[piece_obs[0]]), int(obs.stop[piece_obs[-1]]) - 1
        segments.append(_segment(net, index, first, last, path))
        lo, hi = first, last  # outliers just before or after the piece join it
        while lo > 0 and outlier[lo - 1] and segment_of[lo - 1] < 0:
            lo -= 1
        while hi < n - 1 and outlier[hi + 1]:
            hi += 1
        fixes = np.arange(lo, hi + 1)
        own = obs.of_fix[fixes]
        slot = np.searchsorted(piece_obs, own)  # the piece's observation at or after each fix
        at = np.clip(slot, 0, len(piece_obs) - 1)
        is_used = piece_obs[at] == own
        member = is_used & ~obs.stray[fixes]
        last_along = path.along_m[-1]
        before = np.where(slot > 0, path.along_m[np.clip(slot - 1, 0, None)], 0.0)
        after_slot = np.where(is_used, slot + 1, slot)
        after = np.where(
            after_slot < len(piece_obs),
            path.along_m[np.clip(after_slot, 0, len(piece_obs) - 1)],
            last_along,
        )
        vertices = _stretch_vertices(net, path.edge, path.start_m, path.end_m)
        along, dist = _project_onto(vertices, x[fixes], y[fixes], before, after)
        # a fix that is an observation of its own sits where the model put it
        alone = is_used & (obs.stop[own] - obs.first[own] == 1)
        along = np.where(alone, path.along_m[at], along)
        near = member | (dist <= radius_m[fixes])
        edge[fixes], offset[fixes] = _locate(path, along)
        conf = post[start:stop]
        neighbour = np.clip(slot, 1, max(len(piece_obs) - 1, 1))
        lower = np.minimum(conf[neighbour - 1], conf[np.minimum(neighbour, len(conf) - 1)])
        confidence[fixes] = np.where(member, conf[at], lower)
        matched[fixes] = near
        in_model[fixes] = member
        segment_of[fixes] = np.where(near, index, -1)
    safe = np.where(matched, edge, 0)
    px, py = net.point_on_edge(safe, np.where(matched, offset, 0.0))
    lon, lat = net.unproject(px, py)
    u, v, key = net.edge_osm_ids(safe)
    nan = np.full(n, np.nan)
    edge = np.where(matched, edge, -1)
    return Assembled(
        segments=segments,
        points=MatchedPoints(
            time_s=trace.time_s,
            raw_lon=trace.lon,
            raw_lat=trace.lat,
            matched=matched,
            edge=edge,
            u=np.where(matched, u, -1),
            v=np.where(matched, v, -1),
            key=np.where(matched, key, -1).astype(np.int64),
            offset_m=np.where(matched, offset, nan),
            distance_m=np.where(matched, np.hypot(px - x, py - y), nan),
            lon=np.where(matched, lon, nan),
            lat=np.where(matched, lat, nan),
            confidence=np.where(matched, np.clip(confidence, 0.0, 1.0), 0.0),
            segment=segment_of,
            interpolated=matched & ~in_model,
            outlier=outlier,
        ),
        jumps=jumps,
        loops=loops,
    )
