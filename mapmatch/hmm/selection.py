"""Which observations enter the HMM: displaced ones (outliers, bursts of multipath) are left out."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig
    from mapmatch.hmm.candidates import Candidates
    from mapmatch.hmm.fixes import Fixes
    from mapmatch.hmm.observations import Observations
    from mapmatch.types import BoolArray, FloatArray

__all__ = ["find_displaced", "find_off_road_runs", "find_outliers"]


def find_outliers(
    x: FloatArray,
    y: FloatArray,
    time_s: FloatArray,
    sigma_m: FloatArray,
    config: MatchConfig,
    travel: tuple[FloatArray, FloatArray] | None = None,
    gap_s: FloatArray | None = None,
) -> BoolArray:
    """
    Fixes that stick out from their neighbours: a spike, not a drive.

    For each fix with neighbours at most ``outlier_max_gap_s`` away on both sides (``gap_s``:
    the time from each point to the next, when points are groups of fixes; the time steps
    otherwise; without times every neighbour counts), the detour through it is how much
    longer the way from the previous fix to the next is when it passes through this one. A
    fix farther than ``outlier_sigmas`` x its sigma from its neighbours (on average), that
    sticks out farther than they are apart (the way through it more than
    ``outlier_detour_ratio`` times their distance: a turn of more than about 120 degrees),
    and whose detour is the largest of its neighbours', is an outlier. A car turning a
    corner between its neighbours makes a detour too, but a gentle one (a right angle is
    1.41 times the chord), so sparse traces keep their corner fixes. A run of displaced
    fixes is caught by calling again without the ones found, or by
    :func:`find_off_road_runs`.

    The first and last fix have one neighbour only. When the trace says how far the car went
    (``travel``: distance and extra slack per step, as the transition model uses it), an end
    fix farther from its neighbour than that travel + slack + ``outlier_sigmas`` x sigma is an
    outlier (unless the neighbour is one itself).

    Examples
    --------
    >>> from mapmatch.config import MatchConfig
    >>> x = np.array([0.0, 10.0, 60.0, 30.0, 40.0])
    >>> find_outliers(x, np.zeros(5), np.arange(5.0), np.full(5, 5.0), MatchConfig()).tolist()
    [False, False, True, False, False]
    """
    n = len(x)
    out = np.zeros(n, dtype=bool)
    if n < 3 or config.outlier_sigmas <= 0:
        return out
    gaps = np.diff(time_s) if gap_s is None else gap_s
    gap_before, gap_after = gaps[:-1], gaps[1:]
    close = ~(gap_before > config.outlier_max_gap_s) & ~(gap_after > config.outlier_max_gap_s)
    d_prev = np.hypot(x[1:-1] - x[:-2], y[1:-1] - y[:-2])
    d_next = np.hypot(x[2:] - x[1:-1], y[2:] - y[1:-1])
    d_skip = np.hypot(x[2:] - x[:-2], y[2:] - y[:-2])
    detour = d_prev + d_next - d_skip
    sharp = d_prev + d_next > config.outlier_detour_ratio * d_skip
    # a good fix next to an outlier makes a detour too; blame only the local worst
    padded = np.concatenate(([0.0], detour, [0.0]))
    worst = (detour >= padded[:-2]) & (detour >= padded[2:])
    far = 0.5 * (d_prev + d_next) > config.outlier_sigmas * sigma_m[1:-1]
    out[1:-1] = close & far & sharp & worst
    if travel is not None:
        travel_m, slack_m = travel
        for end, inner, step in ((0, 1, 0), (n - 1, n - 2, n - 2)):
            gap = float(np.hypot(x[end] - x[inner], y[end] - y[inner]))
            allowed = travel_m[step] + slack_m[step] + config.outlier_sigmas * sigma_m[end]
            quick = gaps[min(end, inner)] <= config.outlier_max_gap_s
            if quick and not out[inner] and gap > allowed:
                out[end] = True
    return out


def find_off_road_runs(
    nearest_m: FloatArray, sigma_m: FloatArray, gap_s: FloatArray, config: MatchConfig
) -> BoolArray:
    """
    Short runs of fixes far from every road between fixes on a road: displaced fixes.

    A run of at most ``outlier_max_run`` consecutive fixes each farther from its nearest
    road than where the emission floor starts (``sqrt(2 * max_emission_penalty)`` x sigma: 4
    sigma), with a fix within 2 sigma of a road right before and right after it, none of
    them more than ``outlier_max_gap_s`` apart, is a burst of multipath, not a drive: a car
    that leaves the mapped roads (a car park, an unmapped street) does so gradually, and its
    fixes stay off the road. ``nearest_m`` is each fix's distance to its nearest road
    (``inf`` with none in reach), ``gap_s`` the time from each fix to the next (NaN unknown:
    any gap counts as short).

    Examples
    --------
    >>> from mapmatch.config import MatchConfig
    >>> d = np.array([1.0, 2.0, 30.0, 35.0, 3.0, 1.0])
    >>> find_off_road_runs(d, np.full(6, 5.0), np.ones(5), MatchConfig()).tolist()
    [False, False, True, True, False, False]

    """
    n = len(nearest_m)
    out = np.zeros(n, dtype=bool)
    if n < 3 or config.outlier_sigmas <= 0:
        return out
    # beyond the emission floor's distance no road explains the fix better than another
    far = nearest_m > np.sqrt(2.0 * max(config.max_emission_penalty, 2.0)) * sigma_m
    on_road = nearest_m <= 2.0 * sigma_m
    short = ~(gap_s > config.outlier_max_gap_s)  # NaN (no times) counts as short
    edges = np.flatnonzero(np.diff(np.concatenate(([0], far.astype(np.int8), [0]))))
    for start, stop in zip(edges[0::2].tolist(), edges[1::2].tolist(), strict=True):
        if start == 0 or stop == n or stop - start > config.outlier_max_run:
            continue
        if on_road[start - 1] and on_road[stop] and bool(short[start - 1 : stop].all()):
            out[start:stop] = True
    return out


def find_displaced(
    fixes: Fixes, obs: Observations, cands: Candidates, config: MatchConfig
) -> BoolArray:
    """
    Displaced observations, judged among those near a road.

    Short runs far from every road between observations on a road are displaced
    (:func:`find_off_road_runs`). Then each is compared with where its neighbours put it
    (:func:`find_outliers`); of two displaced ones in a row only the worse is caught at first,
    so that test runs again without the ones found, up to three times.
    """
    near = np.flatnonzero(cands.counts > 0)
    nearest = np.full(len(obs), np.inf)
    nearest[near] = cands.distance_m[cands.ptr[near]]  # rows of a fix are nearest first
    gaps = fixes.time_s[obs.first[1:]] - fixes.time_s[obs.stop[:-1] - 1]
    outlier = find_off_road_runs(nearest, obs.sigma_m, gaps, config)
    for _ in range(3):
        kept = near[~outlier[near]]
        travel = obs.travel.between(kept) if obs.travel is not None else None
        gap = fixes.time_s[obs.first[kept[1:]]] - fixes.time_s[obs.stop[kept[:-1]] - 1]
        found = find_outliers(
            obs.x[kept], obs.y[kept], obs.time_s[kept], obs.sigma_m[kept], config, travel, gap
        )
        if not found.any():
            break
        outlier[kept[found]] = True
    return outlier
