"""Which fixes enter the HMM: outliers and near-duplicates of a stopped car are left out."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from numba import njit

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig

__all__ = ["find_off_road_runs", "find_outliers", "thin_fixes"]

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


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


@njit(cache=True, nogil=True)
def _thin_kernel(x, y, radius, index, keep):  # type: ignore[no-untyped-def]  # pragma: no cover
    last = index[0]
    for k in range(1, len(index) - 1):
        i = index[k]
        if np.hypot(x[i] - x[last], y[i] - y[last]) < radius[i]:
            keep[i] = False
        else:
            last = i


def thin_fixes(
    x: FloatArray, y: FloatArray, sigma_m: FloatArray, usable: BoolArray, config: MatchConfig
) -> BoolArray:
    """
    Usable fixes to keep: each at least ``thinning_sigmas`` x sigma from the last kept one.

    The first and last usable fixes are always kept.

    Examples
    --------
    >>> from mapmatch.config import MatchConfig
    >>> x = np.array([0.0, 3.0, 6.0, 20.0, 22.0])
    >>> keep = thin_fixes(x, np.zeros(5), np.full(5, 5.0), np.ones(5, bool), MatchConfig())
    >>> keep.tolist()
    [True, False, False, True, True]
    """
    keep = usable.copy()
    index = np.flatnonzero(usable)
    if config.thinning_sigmas <= 0 or len(index) <= 2:
        return keep
    radius = config.thinning_sigmas * np.asarray(sigma_m, dtype=np.float64)
    _thin_kernel(np.asarray(x, np.float64), np.asarray(y, np.float64), radius, index, keep)
    return keep


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
