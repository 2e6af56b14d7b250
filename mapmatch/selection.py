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
    Fixes far from where their neighbours put them.

    For each fix with neighbours at most ``outlier_max_gap_s`` away on both sides (``gap_s``:
    the time from each point to the next, when points are groups of fixes; the time steps
    otherwise), the
    position interpolated in time between the neighbours is the prediction; a fix farther
    than ``outlier_sigmas`` x its sigma from it, and worse predicted than both neighbours, is
    an outlier. Over a few seconds a car moves nearly straight, so a good fix stays within
    about 1.2 sigma of the prediction. A run of
    displaced fixes is not caught here (its members predict each other); the matcher's break
    repair handles those.

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
    dt_before, dt_after = time_s[1:-1] - time_s[:-2], time_s[2:] - time_s[1:-1]
    timed = np.isfinite(dt_before) & np.isfinite(dt_after) & (dt_before + dt_after > 0)
    gaps = np.diff(time_s) if gap_s is None else gap_s
    gap_before, gap_after = gaps[:-1], gaps[1:]
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.where(timed, dt_before / (dt_before + dt_after), 0.5)
    px = x[:-2] + w * (x[2:] - x[:-2])
    py = y[:-2] + w * (y[2:] - y[:-2])
    residual = np.hypot(x[1:-1] - px, y[1:-1] - py)
    gap = config.outlier_max_gap_s
    close = ~timed | ((gap_before <= gap) & (gap_after <= gap))
    # a car turning a corner between its neighbours leaves their chord by up to half its
    # length (a right angle); only a fix sticking out farther than that is a spike
    chord = np.hypot(x[2:] - x[:-2], y[2:] - y[:-2])
    limit = np.maximum(config.outlier_sigmas * sigma_m[1:-1], config.outlier_chord_ratio * chord)
    # a good fix next to an outlier is predicted badly too; blame only the local worst
    padded = np.concatenate(([0.0], residual, [0.0]))
    worst = (residual >= padded[:-2]) & (residual >= padded[2:])
    out[1:-1] = close & (residual > limit) & worst
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
