"""Turn the solved HMM into segments of driven edges and per-fix positions.

The path of a piece is built transition by transition from the chosen candidates, and it only
ever moves forward: a fix that the model holds still (a slow or stopped car's fix scattered a
little backwards, :data:`~mapmatch.hmm.routes.ROUTE_STANDSTILL`) leaves the path where it is, and
the next move starts from the farthest point reached, not from the scattered fix. So noise
around a stop never adds length. A U-turn in the middle of a road turns at the farthest point
the fixes in between reached along the road, or a dead end's end when the fixes got within a
held car's scatter of it or the time between them left the car time to get there and back.

Fixes left out of the model (a stopped car's repeats, outliers, fixes dropped to join a break)
are placed at the nearest point of the path between their neighbours' positions; one whose
nearest point is farther than its search radius stays unmatched. A fix of the model that the
path holds farther than its search radius (a loop or a spur taken out, a turn cut short, a
crawl held as a stop) is placed as those are, between the fixes around it that the path
explains; one still beyond its radius is unmatched too, and reported as displaced.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from mapmatch._measure import measure_kernel
from mapmatch._sums import path_length_m
from mapmatch._timing import SegmentPaths
from mapmatch.frozen import quick_init
from mapmatch.hmm.geometry import point_on_edge, project_kernel, stretch_vertices
from mapmatch.hmm.loops import chosen_scatter_kernel
from mapmatch.hmm.network_inputs import network_inputs
from mapmatch.hmm.observations import travel_arrays
from mapmatch.hmm.params import model_params
from mapmatch.hmm.pathwalk import walk_pieces
from mapmatch.readonly import kernel_array
from mapmatch.result import MatchedPoints, PlacedArrays
from roadnets.tmerc import inverse_kernel

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig
    from mapmatch.hmm.observations import Observations
    from mapmatch.hmm.solution import Solution
    from mapmatch.result import Segment
    from mapmatch.trace import Trace
    from mapmatch.types import BoolArray, FloatArray
    from roadnets import RoadNetwork

__all__ = ["Assembled", "assemble", "fixes_on_piece", "path_uturns"]


@quick_init
@dataclass(frozen=True, slots=True)
class Assembled:
    """
    Segments (as arrays: :attr:`segments` made when read) and per-fix outcome of a solved trace.

    With them what the result's numbers read of them, computed in the assembly's call: the
    matched and flagged fixes' counts and the distance check's span over the fixes
    (:func:`~mapmatch._measure.measure_kernel`'s ``(lo, hi, complete, chord)``).
    """

    placed: PlacedArrays
    points: MatchedPoints
    jumps: int  # moves that could not continue from the path's front (drawn as a jump)
    loops: int  # loops the fixes did not support, taken out
    uturns: int  # U-turns on the segments' paths (:func:`path_uturns`)
    matched_points: int
    outliers: int
    span: tuple[int, int, bool, float]

    @property
    def segments(self) -> list[Segment]:
        """The connected pieces (made on first use)."""
        return self.placed.segments()


@njit(cache=True, nogil=True)
def path_uturns(edge_twin, edge, lo, hi):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """U-turns on the path ``edge[lo:hi]``: an edge followed by its reverse (node or mid-road)."""
    count = 0
    for k in range(lo, hi - 1):
        if edge_twin[edge[k]] == edge[k + 1]:
            count += 1
    return count


@njit(cache=True, nogil=True)
def _locate(edge, start_m, end_m, along):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Edge and offset at a distance along a path of stretches."""
    n = len(edge)
    acc = 0.0
    for i in range(n):
        driven = end_m[i] - start_m[i]
        acc += driven
        if along <= acc or i == n - 1:
            before = acc - driven
            return edge[i], min(max(start_m[i] + (along - before), start_m[i]), end_m[i])
    return -1, np.nan


@njit(cache=True, nogil=True)
def _assemble_kernel(  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    network, walk, place, loops, tail
):
    """
    :func:`walk_pieces`, then :func:`_place` on its paths: one call (argument tuples of each).

    Then what the result's numbers read of them (:func:`_tail`; ``tail`` is
    ``(has_odometer, inverse)``).

    ``network`` is the network's :func:`~mapmatch.hmm.network_inputs.network_inputs`: the
    network arrays of each tuple are taken from it.

    ``place[3]`` is the padded posterior of the solution; :func:`_place` is given the chosen
    candidate's. ``place[5]`` the candidates' distances, of which the chosen ones give the
    scatter the fixes show (:func:`~mapmatch.hmm.loops.chosen_scatter_kernel`), which
    ``loops`` and ``_place`` are given last.
    """
    solution, obs, fixes, travel, hold_limit = walk
    chosen_m, scatter = chosen_scatter_kernel(
        solution[0], place[5], solution[3], solution[7], obs[0], obs[1]
    )
    log_em, ox, oy, sigma, params, loop_penalty = loops
    row_ptr, w_edge, w_lo, w_hi, along, jumps, removed = walk_pieces(
        solution, obs, fixes, travel, network.walk_net, network.routing, hold_limit,
        (log_em, ox, oy, sigma, params, loop_penalty, network.loop_net, scatter, chosen_m),
    )  # fmt: skip
    pieces, obs_place, fix_place, post_pad, thinning, _ = place
    geom, ids = network.geom, network.ids
    states = solution[3]
    post = np.empty(len(states))
    for i in range(len(states)):
        post[i] = post_pad[i, max(states[i], 0)]
    placed = _place(
        (row_ptr, w_edge, w_lo, w_hi, along),
        pieces,
        obs_place,
        fix_place,
        post,
        (thinning[0], thinning[1], scatter),
        geom,
        ids,
    )
    t_ptr, t_edge = placed[0][0], placed[0][1]
    uturns = 0
    for p in range(len(t_ptr) - 1):
        uturns += path_uturns(network.walk_net[4], t_edge, t_ptr[p], t_ptr[p + 1])
    return placed, jumps.sum(), removed.sum(), uturns, _tail(placed, fixes[0], fixes[1], *tail)


@njit(cache=True, nogil=True)
def _tail(placed, x, y, has_odometer, inverse):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    What the result's numbers read of the placed paths and the fixes, in the assembly's call.

    Each segment's length, the matched and flagged counts, the distance check's span
    (:func:`~mapmatch._measure.measure_kernel`) and the matched places in lon/lat
    (``inverse``: whether the network's CRS has a compiled projection, then its
    :attr:`~roadnets.tmerc.TransverseMercator.inverse_parameters`; empty without one). The
    same functions compute them as where they are read otherwise
    (:attr:`~mapmatch.result.Segment.length_m`, :func:`~mapmatch.distance.measured_chord`,
    :meth:`~roadnets.RoadNetwork.unproject`), so the numbers agree to the bit.
    """
    (t_ptr, _, t_lo, t_hi), _, _, per_fix, flagged = placed
    matched, px, py = per_fix[0], per_fix[6], per_fix[7]
    lengths = np.empty(len(t_ptr) - 1)
    for s in range(len(lengths)):
        lengths[s] = path_length_m(t_lo, t_hi, t_ptr[s], t_ptr[s + 1])
    span = measure_kernel(matched, flagged, len(lengths), has_odometer, x, y)
    known, lon_0, northing_0, scale, from_gauss, to_sphere = inverse
    if known:
        lon, lat = inverse_kernel(px, py, lon_0, northing_0, scale, from_gauss, to_sphere)
    else:
        lon, lat = np.empty(0), np.empty(0)
    return lengths, matched.sum(), flagged.sum(), span, lon, lat


#: ``_tail``'s ``inverse`` for a network whose CRS has no compiled projection: the same types
#: as one's (``(True, *TransverseMercator.inverse_parameters)``), so one compiled variant.
_NO_INVERSE = (False, 0.0, 0.0, 1.0, np.zeros(1), np.zeros(1))


@njit(cache=True, nogil=True)
def fixes_on_piece(segment_of, first, last, piece):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """
    ``first..last`` narrowed to the first and the last fix still on ``piece``.

    ``segment_of`` is every fix's piece (-1: unmatched); a fix taken off the path at either
    end no longer bounds it. Compiled, for :func:`_place`; callable from Python too.
    """
    while first < last and segment_of[first] != piece:
        first += 1
    while last > first and segment_of[last] != piece:
        last -= 1
    return first, last


@njit(cache=True, nogil=True)
def _replace_held(places, lower, fx, fy, radius, matched, in_model, confidence, path):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Fixes of a piece that the path holds farther than their radius, placed as left-out ones.

    A loop or a spur taken out of the path, or a crawl the model held as a stop, leaves its
    fixes where the path was held, which can be hundreds of metres behind them while the path
    itself drives past them. Each such fix moves to the nearest point of the path between the
    fixes around it that the path does explain (``places``: every fix's distance along the
    path, in order); there it is interpolated (out of the model, the lower of its neighbours'
    confidence). One still beyond its radius stays where it was, and is left unmatched.
    """
    vx, vy, va = path
    _, held_m = project_kernel(fx, fy, places, places, vx, vy, va)
    far = matched & (held_m > radius)
    if not far.any():
        return
    n = len(places)
    for j in range(n):
        if not far[j]:
            continue
        lo, hi = va[0], va[-1]
        for q in range(j - 1, -1, -1):
            if matched[q] and not far[q]:
                lo = places[q]
                break
        for q in range(j + 1, n):
            if matched[q] and not far[q]:
                hi = places[q]
                break
        window_lo = np.array([min(lo, hi)])
        window_hi = np.array([max(lo, hi)])
        a, d = project_kernel(fx[j : j + 1], fy[j : j + 1], window_lo, window_hi, vx, vy, va)
        if d[0] <= radius[j]:
            places[j] = a[0]
            in_model[j] = False
            confidence[j] = lower[j]


@njit(cache=True, nogil=True)
def _place(  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    walked, pieces, obs, fix, post, end_reach, geom, ids
):
    """
    The pieces' paths trimmed at their ends, and every fix placed on them.

    ``walked`` is ``(row_ptr, edge, lo, hi, along)`` of :func:`walk_pieces` (after the loops
    were priced), ``pieces`` ``(starts, stops, used)``, ``obs`` the observations' ``(first,
    stop, of_fix, stray, sigma)``, ``fix`` every fix's ``(x, y, radius, outlier)``, ``post``
    the chosen candidate's posterior per used observation, ``ids`` ``(node_osm_id, edge_u,
    edge_v, edge_key)``. Returns the trimmed rows ``(row_ptr, edge, lo, hi)``, each piece's
    first and last fix, and per fix ``(matched, interpolated, edge, offset, confidence,
    segment, x, y, distance, u, v, key)`` (interpolated: matched but not a fix of the model;
    position NaN for unmatched fixes), and the outliers: those given, and the fixes of the
    model the path holds farther than their search radius (unmatched).
    """
    row_ptr, w_edge, w_lo, w_hi, along_all = walked
    p_lo, p_hi, used = pieces
    o_first, o_stop, of_fix, stray, o_sigma = obs
    fx, fy, fradius, outlier = fix
    node_osm, edge_u, edge_v, edge_key = ids
    n = len(fx)
    n_pieces = len(p_lo)
    matched = np.zeros(n, dtype=np.bool_)
    in_model = np.zeros(n, dtype=np.bool_)
    f_edge = np.full(n, -1, dtype=np.int64)
    f_off = np.full(n, np.nan)
    confidence = np.zeros(n)
    segment_of = np.full(n, -1, dtype=np.int64)
    t_ptr = np.zeros(n_pieces + 1, dtype=np.int64)
    t_edge = np.empty(len(w_edge), dtype=np.int64)
    t_lo = np.empty(len(w_edge))
    t_hi = np.empty(len(w_edge))
    first_fix = np.empty(n_pieces, dtype=np.int64)
    last_fix = np.empty(n_pieces, dtype=np.int64)
    m = 0
    for p in range(n_pieces):
        start, stop = p_lo[p], p_hi[p]
        size = stop - start
        r0, r1 = row_ptr[p], row_ptr[p + 1]
        along = along_all[start:stop].copy()
        # an end fix within the observations' resolution (thinning_sigmas x sigma) of a
        # junction cannot tell which side of it the car was: the path ends at the junction;
        # but no farther than a held car's scatter reaches (standstill_m): with sparse, noisy
        # fixes the resolution grows to tens of metres, and cutting that much off each end of
        # every trip is a bias of its own. Sigma is the assumed one, or the scatter the fixes
        # show about their roads when that is smaller (exact fixes resolve every junction)
        thinning, reach_cap, scatter = end_reach
        low = scatter
        for k in range(start, stop):
            low = min(low, o_sigma[used[k]])
        reach = min(thinning * low, reach_cap)
        if r1 - r0 > 1 and w_hi[r1 - 1] - w_lo[r1 - 1] < reach:
            cut = w_hi[r1 - 1] - w_lo[r1 - 1]
            r1 -= 1
            top = along.max() - cut
            for k in range(size):
                along[k] = min(along[k], top)
        if r1 - r0 > 1 and w_hi[r0] - w_lo[r0] < reach:
            cut = w_hi[r0] - w_lo[r0]
            r0 += 1
            for k in range(size):
                along[k] = max(along[k] - cut, 0.0)
        count = r1 - r0
        t_edge[m : m + count] = w_edge[r0:r1]
        t_lo[m : m + count] = w_lo[r0:r1]
        t_hi[m : m + count] = w_hi[r0:r1]
        path_e, path_lo, path_hi = t_edge[m : m + count], t_lo[m : m + count], t_hi[m : m + count]
        m += count
        t_ptr[p + 1] = m
        piece_obs = used[start:stop]
        first, last = o_first[piece_obs[0]], o_stop[piece_obs[-1]] - 1
        first_fix[p], last_fix[p] = first, last
        lo, hi = first, last  # outliers just before or after the piece join it
        while lo > 0 and outlier[lo - 1] and segment_of[lo - 1] < 0:
            lo -= 1
        while hi < n - 1 and outlier[hi + 1]:
            hi += 1
        k_fix = hi + 1 - lo
        before = np.empty(k_fix)
        after = np.empty(k_fix)
        slots = np.empty(k_fix, dtype=np.int64)
        for j in range(k_fix):
            own = of_fix[lo + j]
            slot = np.searchsorted(piece_obs, own)  # the observation at or after the fix
            slots[j] = slot
            is_used = piece_obs[min(max(slot, 0), size - 1)] == own
            before[j] = along[slot - 1] if slot > 0 else 0.0
            after_slot = slot + 1 if is_used else slot
            after[j] = along[min(after_slot, size - 1)] if after_slot < size else along[size - 1]
        vx, vy, va = stretch_vertices(path_e, path_lo, path_hi, geom)
        placed, dist = project_kernel(fx[lo : hi + 1], fy[lo : hi + 1], before, after, vx, vy, va)
        places = np.empty(k_fix)
        lower = np.empty(k_fix)
        for j in range(k_fix):
            f = lo + j
            own = of_fix[f]
            slot = slots[j]
            at = min(max(slot, 0), size - 1)
            is_used = piece_obs[at] == own
            member = is_used and not stray[f]
            a = placed[j]
            if is_used and o_stop[own] - o_first[own] == 1:
                a = along[at]  # a fix that is an observation of its own sits where the model put it
            near = member or dist[j] <= fradius[f]
            places[j] = a
            neighbour = min(max(slot, 1), max(size - 1, 1))
            lower[j] = min(post[start + neighbour - 1], post[start + min(neighbour, size - 1)])
            confidence[f] = post[start + at] if member else lower[j]
            matched[f] = near
            in_model[f] = member
            segment_of[f] = p if near else -1
        _replace_held(places, lower, fx[lo : hi + 1], fy[lo : hi + 1], fradius[lo : hi + 1],
                      matched[lo : hi + 1], in_model[lo : hi + 1], confidence[lo : hi + 1],
                      (vx, vy, va))  # fmt: skip
        for j in range(k_fix):
            f_edge[lo + j], f_off[lo + j] = _locate(path_e, path_lo, path_hi, places[j])
    px = np.empty(n)
    py = np.empty(n)
    distance = np.full(n, np.nan)
    u = np.full(n, -1, dtype=np.int64)
    v = np.full(n, -1, dtype=np.int64)
    key = np.full(n, -1, dtype=np.int64)
    displaced = np.zeros(n, dtype=np.bool_)
    for f in range(n):
        e = f_edge[f] if matched[f] else 0
        px[f], py[f] = point_on_edge(e, f_off[f] if matched[f] else 0.0, *geom)
        away = np.hypot(px[f] - fx[f], py[f] - fy[f])
        if matched[f] and away > fradius[f]:
            # a fix of the model that the path holds farther than its search radius, where
            # _replace_held found no place for it: the path does not explain it, and says so
            matched[f] = False
            displaced[f] = True
            in_model[f] = False
            segment_of[f] = -1
        if matched[f]:
            distance[f] = away
            u[f], v[f], key[f] = node_osm[edge_u[e]], node_osm[edge_v[e]], edge_key[e]
            confidence[f] = min(max(confidence[f], 0.0), 1.0)
        else:
            f_edge[f] = -1
            f_off[f] = np.nan
            confidence[f] = 0.0
    for p in range(n_pieces):  # each piece runs from its first to its last fix still on it
        first_fix[p], last_fix[p] = fixes_on_piece(segment_of, first_fix[p], last_fix[p], p)
    interpolated = np.empty(n, dtype=np.bool_)
    flagged = np.empty(n, dtype=np.bool_)
    for f in range(n):
        interpolated[f] = matched[f] and not in_model[f]
        flagged[f] = outlier[f] or displaced[f]
        if not matched[f]:
            px[f] = np.nan
            py[f] = np.nan
    return (
        (t_ptr, t_edge[:m], t_lo[:m], t_hi[:m]),
        first_fix, last_fix,
        (matched, interpolated, f_edge, f_off, confidence, segment_of, px, py, distance, u, v, key),
        flagged,
    )  # fmt: skip


def assemble(
    net: RoadNetwork,
    trace: Trace,
    x: FloatArray,
    y: FloatArray,
    obs: Observations,
    solution: Solution,
    outlier: BoolArray,
    radius_m: FloatArray,
    time_s: FloatArray,
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
    stays unmatched, as do fixes outside every piece; a fix of the model that the path holds
    farther than its radius is unmatched and marked an outlier. Fixes that entered the model
    have their observation's confidence, the others the lower of their neighbours'.
    ``time_s`` is every fix's time (NaN throughout without usable times): whether a car turning
    round had time to reach a dead end's end is read from the gaps between fixes.
    """
    c, used, states = solution.cands, solution.used, solution.states
    f8 = np.float64
    x, y = kernel_array(x), kernel_array(y)  # read-only, whichever caller's (one variant)
    radius = np.ascontiguousarray(radius_m, f8)
    p_lo, p_hi = solution.piece_start, solution.piece_stop
    record, record_state, record_pred = solution.route_records
    sigma = np.ascontiguousarray(obs.sigma_m, f8)
    walk = (
        (c.ptr, c.edge, c.offset_m, states, solution.kinds, p_lo, p_hi, used,
         record, record_state, record_pred),
        (obs.first, obs.stop, np.ascontiguousarray(obs.time_s, f8)),
        (x, y, radius, np.ascontiguousarray(time_s, f8)),
        travel_arrays(obs.travel),
        float(hold_limit_m),
    )  # fmt: skip
    loops = (
        np.ascontiguousarray(solution.log_emission, f8),
        np.ascontiguousarray(obs.x, f8),
        np.ascontiguousarray(obs.y, f8),
        sigma,
        model_params(config),
        float(config.loop_penalty),
    )
    place = (
        (p_lo, p_hi, used),
        (obs.first, obs.stop, obs.of_fix, obs.stray, sigma),
        (x, y, radius, np.ascontiguousarray(outlier, np.bool_)),
        np.ascontiguousarray(solution.post, f8),
        (float(config.thinning_sigmas), float(config.standstill_m)),
        c.distance_m,
    )
    compiled = net.projector.compiled
    inverse = _NO_INVERSE if compiled is None else (True, *compiled.inverse_parameters)
    placed, jumps, removed, uturns, numbers = _assemble_kernel(
        network_inputs(net), walk, place, loops, (trace.odometer_m is not None, inverse)
    )
    (t_ptr, t_edge, t_lo, t_hi), first_fix, last_fix, per_fix, flagged = placed
    matched, interpolated, edge, offset, confidence, segment_of, px, py, distance, u, v, key = (
        per_fix
    )
    lengths, matched_points, outliers, span, lon, lat = numbers
    if compiled is None:  # a CRS the kernels cannot unproject
        lon, lat = net.unproject(px, py)
    paths = SegmentPaths(np.arange(len(t_ptr) - 1), first_fix, last_fix, t_ptr, t_edge, t_lo, t_hi)
    return Assembled(
        placed=PlacedArrays(paths, lengths, net),
        points=MatchedPoints(
            time_s=trace.time_s, raw_lon=trace.lon, raw_lat=trace.lat, matched=matched,
            edge=edge, u=u, v=v, key=key, offset_m=offset, distance_m=distance, lon=lon,
            lat=lat, confidence=confidence, segment=segment_of, interpolated=interpolated,
            outlier=flagged,
        ),
        jumps=int(jumps),
        loops=int(removed),
        uturns=int(uturns),
        matched_points=int(matched_points),
        outliers=int(outliers),
        span=(int(span[0]), int(span[1]), bool(span[2]), float(span[3])),
    )  # fmt: skip
