"""Turn the solved HMM into segments of driven edges and per-fix positions."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from mapmatch.models import ROUTE_SAME_EDGE, ROUTE_UTURN
from mapmatch.result import MatchedEdge, MatchedPoints, Segment

if TYPE_CHECKING:
    from mapmatch.matcher import Solution
    from mapmatch.trace import Trace
    from roadnets import RoadNetwork

__all__ = ["Assembled", "assemble"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True, slots=True)
class Assembled:
    """Segments and per-fix outcome of a solved trace."""

    segments: list[Segment]
    points: MatchedPoints


@dataclass(frozen=True, slots=True)
class _PiecePath:
    edge: IntArray
    start_m: FloatArray
    end_m: FloatArray
    along_m: FloatArray  # distance along the path of each used fix of the piece


def _piece_path(net: RoadNetwork, solution: Solution, start: int, stop: int) -> _PiecePath:
    """Edges driven between the chosen candidates of used fixes ``start..stop-1``."""
    arrays = net.arrays
    edge_len = arrays.edge_length_m
    cands, states = solution.cands, solution.states
    rows = cands.ptr[start:stop] + states[start:stop]
    first = rows[0]
    entries: list[list[float]] = [
        [float(cands.edge[first]), float(cands.offset_m[first]), float(cands.offset_m[first])]
    ]
    done = 0.0  # length of the entries before the last one
    along = [0.0]
    for t in range(start, stop - 1):
        ra, rb = rows[t - start], rows[t - start + 1]
        ea, eb = int(cands.edge[ra]), int(cands.edge[rb])
        ob = float(cands.offset_m[rb])
        move = solution.kinds[t, states[t], states[t + 1]]
        current = entries[-1]
        if move == ROUTE_SAME_EDGE:
            current[2] = max(current[2], ob)
        else:
            if move == ROUTE_UTURN:
                turn = max(current[2], float(edge_len[ea]) - ob)
                current[2] = turn
                tail = [[float(eb), float(edge_len[ea]) - turn, ob]]
            else:
                current[2] = float(edge_len[ea])
                via = solution.table.edges(
                    int(arrays.edge_v[ea]), int(arrays.edge_u[eb]), arrays.edge_u
                )
                tail = [[float(e), 0.0, float(edge_len[e])] for e in via]
                tail.append([float(eb), 0.0, ob])
            for entry in entries[-1:] + tail[:-1]:
                done += entry[2] - entry[1]
            entries.extend(tail)
        last = entries[-1]
        along.append(done + ob - last[1])
    table = np.array(entries, dtype=np.float64).reshape(-1, 3)
    return _PiecePath(
        table[:, 0].astype(np.int64), table[:, 1], table[:, 2], np.array(along, dtype=np.float64)
    )


def _segment(net: RoadNetwork, index: int, first: int, last: int, path: _PiecePath) -> Segment:
    arrays = net.arrays
    u, v, key = net.edge_osm_ids(path.edge)
    way = arrays.edge_way_id[path.edge]
    length = arrays.edge_length_m[path.edge]
    edges = [
        MatchedEdge(
            edge=int(e),
            u=int(u[i]),
            v=int(v[i]),
            key=int(key[i]),
            osm_way_ids=(int(way[i]),),
            length_m=float(length[i]),
            start_offset_m=float(path.start_m[i]),
            end_offset_m=float(path.end_m[i]),
        )
        for i, e in enumerate(path.edge.tolist())
    ]
    lon, lat = net.unproject(*net.path_polyline(path.edge, path.start_m, path.end_m))
    return Segment(index=index, first=first, last=last, edges=edges, lon=lon, lat=lat)


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
    solution: Solution,
    outlier: BoolArray,
) -> Assembled:
    """
    Segments of the solved pieces, and every fix's matched position.

    Fixes in the model take their chosen candidate; fixes left out (outliers, the thinned
    fixes of a stopped car, fixes dropped to join a break) that lie inside a piece get the
    position along its path interpolated by time, with the lower of their neighbours'
    confidences; fixes outside every piece are unmatched.
    """
    n = len(x)
    matched = np.zeros(n, dtype=bool)
    interpolated = np.zeros(n, dtype=bool)
    edge = np.full(n, -1, dtype=np.int64)
    offset = np.full(n, np.nan)
    confidence = np.zeros(n)
    segment_of = np.full(n, -1, dtype=np.int64)
    segments: list[Segment] = []
    used, cands, states = solution.used, solution.cands, solution.states
    post = solution.post[np.arange(len(used)), np.maximum(states, 0)]
    for index, (start, stop) in enumerate(solution.pieces):
        path = _piece_path(net, solution, start, stop)
        first, last = int(used[start]), int(used[stop - 1])
        segments.append(_segment(net, index, first, last, path))
        lo, hi = first, last  # outliers just before or after the piece join it, clamped
        while lo > 0 and outlier[lo - 1] and segment_of[lo - 1] < 0:
            lo -= 1
        while hi < n - 1 and outlier[hi + 1]:
            hi += 1
        fixes = np.arange(lo, hi + 1)
        piece_used = used[start:stop]
        along = np.interp(trace.time_s[fixes], trace.time_s[piece_used], path.along_m)
        edge[fixes], offset[fixes] = _locate(path, along)
        rows = cands.ptr[start:stop] + states[start:stop]
        edge[piece_used], offset[piece_used] = cands.edge[rows], cands.offset_m[rows]
        conf = post[start:stop]
        slot = np.clip(np.searchsorted(piece_used, fixes), 1, max(len(piece_used) - 1, 1))
        lower = np.minimum(conf[slot - 1], conf[np.minimum(slot, len(conf) - 1)])
        confidence[fixes] = lower
        confidence[piece_used] = conf
        matched[fixes] = True
        interpolated[fixes] = True
        interpolated[piece_used] = False
        segment_of[fixes] = index
    safe = np.where(matched, edge, 0)
    px, py = net.point_on_edge(safe, np.where(matched, offset, 0.0))
    lon, lat = net.unproject(px, py)
    u, v, key = net.edge_osm_ids(safe)
    nan = np.full(n, np.nan)
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
            confidence=np.clip(confidence, 0.0, 1.0),
            segment=segment_of,
            interpolated=interpolated,
            outlier=outlier,
        ),
    )
