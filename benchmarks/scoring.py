"""Geometric route-mismatch scoring, the same for every matcher (ours and the peers).

This is the Newson & Krumm (2009) route mismatch fraction measured on geometry instead of on edge
ids, so that matchers with different graph representations (osmnx edges, Valhalla tiles, our
compiled network) are judged alike:

* both the true path and the matched polylines are projected to a local metric plane and cut
  into pieces of at most ``step_m`` (1 m) carrying their length and driving direction;
* a matched piece is **correct** when a true piece lies within ``tolerance_m`` of it and the two
  directions differ by at most ``max_angle_deg`` (45 degrees); a true piece is **covered** when a
  correct matched piece pairs with it;
* pairs must follow both routes in driving order (a weighted longest increasing chain), so a road
  driven twice by the truth needs two matched passes to be covered twice, and a matched loop over
  a road the truth drove once is counted once (the other pass is *added*);
* ``added = matched - correct``, ``missed = true - covered``,
  ``mismatch = (added + missed) / true``, ``precision = correct / matched``,
  ``recall = covered / true``.

Why ``tolerance_m = 5``: every matcher here snaps to the same OSM centre lines as the truth, so a
correct match coincides with the truth up to coordinate rounding (< 0.2 m) and the choice of where
a path starts and ends on its first and last edge. 5 m absorbs that and small differences in how
a tool encodes geometry, while a parallel road, a service road beside a main road or the other
carriageway of a dual road (8 m or more away, and for the latter the opposite direction) is still
told apart.

Pure numpy + shapely; importable without the project installed.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import shapely

DEFAULT_TOLERANCE_M = 5.0
DEFAULT_MAX_ANGLE_DEG = 45.0
DEFAULT_STEP_M = 1.0
# how far back along the other route consecutive pairs may step (nearest-piece jitter on curves);
# also the most a road driven twice can be double counted
_BACKTRACK_M = 2.0

_WGS84_A = 6_378_137.0
_WGS84_E2 = 6.694_379_990_14e-3

Polyline = Sequence[Sequence[float]]


@dataclass(frozen=True, slots=True)
class RouteScore:
    """Geometric comparison of one matched route with its true route (lengths in metres)."""

    true_length_m: float
    matched_length_m: float
    correct_m: float
    covered_m: float

    @property
    def added_m(self) -> float:
        """Matched length that is not on the true route (or on it in the wrong direction)."""
        return max(self.matched_length_m - self.correct_m, 0.0)

    @property
    def missed_m(self) -> float:
        """True route length that no correct matched piece covers."""
        return max(self.true_length_m - self.covered_m, 0.0)

    @property
    def mismatch(self) -> float:
        """Route mismatch fraction ``(added + missed) / true length`` (0 is perfect)."""
        if self.true_length_m <= 0:
            return 0.0 if self.matched_length_m <= 0 else math.inf
        return (self.added_m + self.missed_m) / self.true_length_m

    @property
    def precision(self) -> float:
        """Share of the matched length that is correct (NaN when nothing was matched)."""
        if self.matched_length_m <= 0:
            return math.nan
        return self.correct_m / self.matched_length_m

    @property
    def recall(self) -> float:
        """Share of the true length that is covered."""
        if self.true_length_m <= 0:
            return math.nan
        return self.covered_m / self.true_length_m


class LocalProjection:
    """Equirectangular projection around a reference point, scaled by the WGS84 radii there.

    Over the few kilometres of a trace its scale error stays below 0.2 %, far inside what the
    scoring can resolve.
    """

    def __init__(self, lon0_deg: float, lat0_deg: float) -> None:
        phi = math.radians(lat0_deg)
        w = 1.0 - _WGS84_E2 * math.sin(phi) ** 2
        meridional = _WGS84_A * (1.0 - _WGS84_E2) / w**1.5
        normal = _WGS84_A / math.sqrt(w)
        self.lon0_deg = lon0_deg
        self.lat0_deg = lat0_deg
        self._kx = math.radians(1.0) * normal * math.cos(phi)
        self._ky = math.radians(1.0) * meridional

    def to_xy(self, lonlat: np.ndarray) -> np.ndarray:
        """Project an ``(n, 2)`` array of lon/lat degrees to metres."""
        a = np.asarray(lonlat, dtype=float).reshape(-1, 2)
        return np.column_stack(
            [(a[:, 0] - self.lon0_deg) * self._kx, (a[:, 1] - self.lat0_deg) * self._ky]
        )

    def to_lonlat(self, xy: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`to_xy`."""
        a = np.asarray(xy, dtype=float).reshape(-1, 2)
        return np.column_stack(
            [a[:, 0] / self._kx + self.lon0_deg, a[:, 1] / self._ky + self.lat0_deg]
        )


@dataclass(frozen=True, slots=True)
class _Pieces:
    xy: np.ndarray  # (n, 2) piece midpoints, metres
    direction: np.ndarray  # (n, 2) unit driving direction
    length_m: np.ndarray  # (n,) piece lengths
    to_start_m: np.ndarray  # (n,) distance from the midpoint back to its polyline's start
    to_end_m: np.ndarray  # (n,) distance from the midpoint on to its polyline's end

    @property
    def position_m(self) -> np.ndarray:
        """Distance of each piece's midpoint from the start, along all polylines in order."""
        return np.cumsum(self.length_m) - 0.5 * self.length_m

    @property
    def total_m(self) -> float:
        return float(self.length_m.sum())


def densify(polylines_xy: Iterable[np.ndarray], step_m: float = DEFAULT_STEP_M) -> _Pieces:
    """Cut metric polylines (in driving order) into pieces of at most ``step_m`` metres."""
    mids: list[np.ndarray] = []
    dirs: list[np.ndarray] = []
    lens: list[np.ndarray] = []
    starts: list[np.ndarray] = []
    ends: list[np.ndarray] = []
    for line in polylines_xy:
        p = np.asarray(line, dtype=float).reshape(-1, 2)
        if len(p) < 2:
            continue
        d = np.diff(p, axis=0)
        seg = np.hypot(d[:, 0], d[:, 1])
        ok = seg > 1e-9
        p0, d, seg = p[:-1][ok], d[ok], seg[ok]
        if len(seg) == 0:
            continue
        k = np.maximum(np.ceil(seg / step_m).astype(np.int64), 1)
        rep = np.repeat(np.arange(len(seg)), k)
        first = np.repeat(np.cumsum(k) - k, k)
        frac = (np.arange(int(k.sum())) - first + 0.5) / k[rep]
        mids.append(p0[rep] + d[rep] * frac[:, None])
        dirs.append((d / seg[:, None])[rep])
        piece = (seg / k)[rep]
        lens.append(piece)
        pos = np.cumsum(piece) - 0.5 * piece
        starts.append(pos)
        ends.append(float(piece.sum()) - pos)
    if not mids:
        empty = np.zeros((0, 2))
        return _Pieces(empty, empty, np.zeros(0), np.zeros(0), np.zeros(0))
    return _Pieces(
        np.concatenate(mids),
        np.concatenate(dirs),
        np.concatenate(lens),
        np.concatenate(starts),
        np.concatenate(ends),
    )


def _candidate_pairs(
    a: _Pieces, b: _Pieces, tolerance_m: float, min_cos: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pairs (i of a, j of b) within tolerance, agreeing in direction, alongside each other."""
    if len(a.xy) == 0 or len(b.xy) == 0:
        z = np.zeros(0, dtype=np.int64)
        return z, z, np.zeros(0)
    tree = shapely.STRtree(shapely.points(b.xy))
    ia, ib = tree.query(shapely.points(a.xy), predicate="dwithin", distance=tolerance_m)
    cos = np.einsum("ij,ij->i", a.direction[ia], b.direction[ib])
    # a's midpoint must not lie beyond the start or the end of b's polyline: the tolerance must
    # not stretch a route (or a piece before a break) by another tolerance_m at its ends
    along = np.einsum("ij,ij->i", a.xy[ia] - b.xy[ib], b.direction[ib])
    beyond = (along < -b.to_start_m[ib] - 1e-6) | (along > b.to_end_m[ib] + 1e-6)
    keep = (cos >= min_cos) & ~beyond
    ia, ib = ia[keep], ib[keep]
    dist = np.hypot(*(a.xy[ia] - b.xy[ib]).T)
    order = np.lexsort((ib, ia))
    return ia[order].astype(np.int64), ib[order].astype(np.int64), dist[order]


def _local_minima(ia: np.ndarray, ib: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Mask of pairs whose distance is a local minimum along b for the same i (one per pass)."""
    n = len(ia)
    if n == 0:
        return np.zeros(0, dtype=bool)
    left = np.full(n, np.inf)
    right = np.full(n, np.inf)
    adj = (ia[1:] == ia[:-1]) & (ib[1:] == ib[:-1] + 1)
    left[1:][adj] = dist[:-1][adj]
    right[:-1][adj] = dist[1:][adj]
    return (dist <= left) & (dist < right)


def _ordered_chain_length(
    ia: np.ndarray, ib: np.ndarray, weight: np.ndarray, b: _Pieces, backtrack_m: float
) -> float:
    """Largest weight of pairs taken in driving order along both routes.

    Pairs are sorted by ``ia``; the chain takes at most one pair per ``ia`` with ``ia`` strictly
    increasing and the position along b never going back by more than ``backtrack_m`` (which
    absorbs the jitter of nearest pieces on tight curves), so a stretch of b pairs with only one
    pass of a. Weighted longest increasing subsequence with a Fenwick tree of prefix maxima.
    """
    if len(ia) == 0:
        return 0.0
    pos_m = b.position_m
    # 1-based Fenwick slot of piece j, and the last slot a predecessor of j may occupy
    limit = np.searchsorted(pos_m, pos_m + backtrack_m, side="right").tolist()
    size = len(pos_m)
    tree = [0.0] * (size + 1)

    def query(pos: int) -> float:
        best = 0.0
        while pos > 0:
            best = max(best, tree[pos])
            pos -= pos & -pos
        return best

    def update(pos: int, value: float) -> None:
        while pos <= size:
            if tree[pos] < value:
                tree[pos] = value
            pos += pos & -pos

    best = 0.0
    ia_l = ia.tolist()
    ib_l = ib.tolist()
    w_l = weight.tolist()
    k = 0
    n = len(ia_l)
    while k < n:
        g = k
        while g < n and ia_l[g] == ia_l[k]:
            g += 1
        vals = [(ib_l[m] + 1, w_l[m] + query(limit[ib_l[m]])) for m in range(k, g)]
        for slot, val in vals:
            update(slot, val)
            best = max(best, val)
        k = g
    return best


def score_route(
    truth_lonlat: Polyline,
    matched_lonlat: Sequence[Polyline],
    *,
    tolerance_m: float = DEFAULT_TOLERANCE_M,
    max_angle_deg: float = DEFAULT_MAX_ANGLE_DEG,
    step_m: float = DEFAULT_STEP_M,
) -> RouteScore:
    """Score a matched route against the true route.

    Parameters
    ----------
    truth_lonlat
        The true driven path, ``[[lon, lat], ...]`` in driving order.
    matched_lonlat
        The matched path as a list of polylines (pieces between breaks) in driving order.
    tolerance_m
        Largest distance between a matched piece and the true route for it to count as correct.
    max_angle_deg
        Largest difference between matched and true driving direction.
    step_m
        Densification step.

    Returns
    -------
    RouteScore
        Lengths from which mismatch, precision and recall follow.
    """
    truth = np.asarray(truth_lonlat, dtype=float).reshape(-1, 2)
    if len(truth) == 0:
        msg = "truth geometry is empty; give the true path as [[lon, lat], ...]"
        raise ValueError(msg)
    proj = LocalProjection(float(truth[:, 0].mean()), float(truth[:, 1].mean()))
    t = densify([proj.to_xy(truth)], step_m)
    m = densify([proj.to_xy(np.asarray(p, dtype=float)) for p in matched_lonlat if len(p)], step_m)
    min_cos = math.cos(math.radians(max_angle_deg))

    # correct matched length: one pair per matched piece, in order along both routes
    im, it, dist = _candidate_pairs(m, t, tolerance_m, min_cos)
    keep = _local_minima(im, it, dist)
    correct = _ordered_chain_length(im[keep], it[keep], m.length_m[im[keep]], t, _BACKTRACK_M)

    # covered true length: the same with the roles swapped
    it2, im2, dist2 = _candidate_pairs(t, m, tolerance_m, min_cos)
    keep2 = _local_minima(it2, im2, dist2)
    covered = _ordered_chain_length(it2[keep2], im2[keep2], t.length_m[it2[keep2]], m, _BACKTRACK_M)
    return RouteScore(
        true_length_m=t.total_m,
        matched_length_m=m.total_m,
        correct_m=min(correct, m.total_m),
        covered_m=min(covered, t.total_m),
    )


@dataclass(frozen=True, slots=True)
class ScoreSummary:
    """Aggregate of many route scores (mismatch per trace; precision/recall length-weighted)."""

    traces: int
    mismatch_mean: float
    mismatch_median: float
    precision: float
    recall: float


def summarize(scores: Sequence[RouteScore]) -> ScoreSummary:
    """Aggregate route scores: mean and median mismatch, length-weighted precision and recall."""
    if not scores:
        return ScoreSummary(0, math.nan, math.nan, math.nan, math.nan)
    mm = np.array([s.mismatch for s in scores])
    matched = sum(s.matched_length_m for s in scores)
    true = sum(s.true_length_m for s in scores)
    return ScoreSummary(
        traces=len(scores),
        mismatch_mean=float(mm.mean()),
        mismatch_median=float(np.median(mm)),
        precision=sum(s.correct_m for s in scores) / matched if matched > 0 else math.nan,
        recall=sum(s.covered_m for s in scores) / true if true > 0 else math.nan,
    )
