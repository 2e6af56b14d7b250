"""Which observations enter the HMM: displaced ones (outliers, bursts of multipath) are left out.

The tests run compiled (one call per trace, :func:`find_displaced`); :func:`find_outliers` and
:func:`find_off_road_runs` are the same tests on given arrays.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from mapmatch.hmm.observations import between_kernel, travel_arrays
from mapmatch.hmm.params import params_of

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig
    from mapmatch.hmm.candidates import Candidates
    from mapmatch.hmm.fixes import Fixes
    from mapmatch.hmm.observations import Observations
    from mapmatch.types import BoolArray, FloatArray

__all__ = ["find_displaced", "find_off_road_runs", "find_outliers"]


#: Fixes merged into one observation (a stop) that make it more than a stray when on a road.
_BACKED_FIXES = 3


#: The outlier parameters, in the order the kernels read them.
_OUTLIER_PARAMS = (
    "outlier_sigmas",
    "outlier_max_gap_s",
    "outlier_detour_ratio",
    "max_emission_penalty",
    "outlier_max_run",
    "travel_accel_mps2",
    "end_outlier_sigmas",
)


def _params(config: MatchConfig) -> FloatArray:
    """The outlier parameters of ``config`` (:data:`_OUTLIER_PARAMS`), made once per config."""
    return params_of(config, _OUTLIER_PARAMS)


@njit(cache=True, nogil=True)
def _outliers(x, y, sigma, gaps, travel_m, slack_m, backed, params):  # type: ignore[no-untyped-def]  # pragma: no cover
    """:func:`find_outliers` (``travel_m`` empty: no travel known; ``backed``: never outliers)."""
    n = len(x)
    out = np.zeros(n, dtype=np.bool_)
    sigmas, max_gap, ratio = params[0], params[1], params[2]
    if n < 3 or sigmas <= 0:
        return out
    detour = np.empty(n)
    for i in range(1, n - 1):
        d_prev = np.hypot(x[i] - x[i - 1], y[i] - y[i - 1])
        d_next = np.hypot(x[i + 1] - x[i], y[i + 1] - y[i])
        detour[i] = d_prev + d_next - np.hypot(x[i + 1] - x[i - 1], y[i + 1] - y[i - 1])
    detour[0] = detour[n - 1] = 0.0
    for i in range(1, n - 1):
        d_prev = np.hypot(x[i] - x[i - 1], y[i] - y[i - 1])
        d_next = np.hypot(x[i + 1] - x[i], y[i + 1] - y[i])
        d_skip = np.hypot(x[i + 1] - x[i - 1], y[i + 1] - y[i - 1])
        close = not gaps[i - 1] > max_gap and not gaps[i] > max_gap
        sharp = d_prev + d_next > ratio * d_skip
        # a good fix next to an outlier makes a detour too; blame only the local worst
        worst = detour[i] >= detour[i - 1] and detour[i] >= detour[i + 1]
        far = 0.5 * (d_prev + d_next) > sigmas * sigma[i]
        out[i] = close and far and sharp and worst and not (len(backed) and backed[i])
    if len(travel_m):
        for end, inner, step in ((0, 1, 0), (n - 1, n - 2, n - 2)):
            gap = np.hypot(x[end] - x[inner], y[end] - y[inner])
            allowed = travel_m[step] + slack_m[step] + sigmas * sigma[end]
            quick = gaps[min(end, inner)] <= max_gap
            if quick and not out[inner] and gap > allowed:
                out[end] = True
    return out


@njit(cache=True, nogil=True)
def _end_miss(kept, x, y, sigma, mid, gap, fixes, end, params):  # type: ignore[no-untyped-def]  # pragma: no cover
    """How much farther than allowed observation ``end`` lies from where the next fix puts it."""
    max_gap, accel, sigmas = params[1], params[5], params[6]
    fix_x, fix_y, fix_time, first, stop = fixes
    m = len(kept)
    direction = 1 if end == 0 else -1
    inner = end + direction
    if not gap[min(end, inner)] <= max_gap:
        return np.nan
    o = kept[inner]
    near = first[o] if direction > 0 else stop[o] - 1  # its fix next to the end
    far = inner
    k = inner + direction
    while 0 <= k < m and gap[min(k, k - direction)] <= max_gap:
        if abs(mid[kept[k]] - fix_time[near]) > max_gap:
            break
        far = k
        k += direction
    e, j = kept[end], kept[far]
    span = abs(mid[j] - fix_time[near])
    if not span > 0:
        return np.nan
    lead = abs(fix_time[near] - mid[e])
    spread = 2.0 * np.sqrt(2.0) * max(sigma[o], sigma[j])  # twice the chord's own noise
    vx, vy = x[j] - fix_x[near], y[j] - fix_y[near]
    chord = np.hypot(vx, vy)
    # how far the velocity's change can carry it off: the chord's mean is half its span away
    drift = 0.5 * accel * lead * (span + lead)
    reach = (chord + spread) / span * lead + drift  # how far behind it may lie
    allowed = sigmas * sigma[e]
    if reach > allowed:  # it may have turned a corner and come from farther aside than that
        return np.nan
    rx, ry = x[e] - fix_x[near], y[e] - fix_y[near]
    if chord <= spread:  # hardly moving: the direction says nothing
        return max(np.hypot(rx, ry) - reach, 0.0) - allowed
    ux, uy = vx / chord, vy / chord
    behind = -(rx * ux + ry * uy)
    aside = abs(rx * uy - ry * ux) - abs(behind) * spread / chord  # less the direction's noise
    return np.hypot(max(behind - reach, -behind, 0.0), max(aside, 0.0)) - allowed


@njit(cache=True, nogil=True)
def _end_spikes(kept, x, y, sigma, mid, gap, fixes, params):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    End observations far from where the next fixes' own motion puts them.

    With neither speeds nor an odometer, the car's velocity next to an end is the chord from
    the next observation's fix nearest the end to the last observation within
    ``outlier_max_gap_s`` of it, over its time (an observation's time is the middle of its
    fixes'). The end should lie behind that fix along the chord, by at most that speed (plus
    twice the chord's own noise, ``sqrt(2)`` sigma, and what ``travel_accel_mps2`` can change
    the velocity by since the chord's middle) times their interval, and beside the line only
    by the direction's noise (:func:`_end_miss`). One farther than ``end_outlier_sigmas``
    sigma from that is a spike: a first fix 40 m off at 1 s on a road that happens to pass
    there, which nothing else in the model tells from a start 40 m earlier. Only ends the
    car can have driven from in less than that many sigmas are judged: a turn between them
    cannot then put the end farther aside (a sparse trace's end fix on a corner stays), and
    the trip's slow start and end at 1 s are where it matters.
    """
    m = len(kept)
    out = np.zeros(m, dtype=np.bool_)
    if m < 3 or params[6] <= 0:
        return out
    for end in (0, m - 1):
        out[end] = _end_miss(kept, x, y, sigma, mid, gap, fixes, end, params) > 0
    return out


@njit(cache=True, nogil=True)
def _off_road(nearest, sigma, gaps, params):  # type: ignore[no-untyped-def]  # pragma: no cover
    """:func:`find_off_road_runs`."""
    n = len(nearest)
    out = np.zeros(n, dtype=np.bool_)
    sigmas, max_gap, max_run = params[0], params[1], params[4]
    if n < 3 or sigmas <= 0:
        return out
    # beyond the emission floor's distance no road explains the fix better than another
    floor = np.sqrt(2.0 * max(params[3], 2.0))
    start = 0
    while start < n:
        if not nearest[start] > floor * sigma[start]:
            start += 1
            continue
        stop = start
        while stop < n and nearest[stop] > floor * sigma[stop]:
            stop += 1
        inside = start > 0 and stop < n and stop - start <= max_run
        if (
            inside
            and nearest[start - 1] <= 2.0 * sigma[start - 1]
            and nearest[stop] <= 2.0 * sigma[stop]
        ):
            short = True
            for k in range(start - 1, stop):
                short = short and not gaps[k] > max_gap  # NaN (no times) counts as short
            if short:
                out[start:stop] = True
        start = stop
    return out


@njit(cache=True, nogil=True, inline="always")
def _gaps(points, first, stop, fix_time):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """Seconds from each of the observations ``points`` to the next: last fix to first fix."""
    gaps = np.empty(max(len(points) - 1, 0))
    for k in range(len(points) - 1):
        gaps[k] = fix_time[first[points[k + 1]]] - fix_time[stop[points[k]] - 1]
    return gaps


@njit(cache=True, nogil=True)
def _displaced(ptr, distance, fix_time, first, stop, x, y, sigma, travel, fix_xy, params):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    :func:`find_displaced` over arrays.

    ``travel``: the five arrays of a Travel, or empty; ``fix_xy``: the fixes' own positions.
    """
    n = len(first)
    nearest = np.full(n, np.inf)
    n_near = 0
    near = np.empty(n, dtype=np.int64)
    for k in range(n):
        if ptr[k + 1] > ptr[k]:
            nearest[k] = distance[ptr[k]]  # rows of a fix are nearest first
            near[n_near] = k
            n_near += 1
    gaps = _gaps(np.arange(n), first, stop, fix_time)
    outlier = _off_road(nearest, sigma, gaps, params)
    # a stop's observation, several fixes that agree and lie on a road, is where the car
    # was, not a stray: at a dead end's end a car that turns back makes the same spike
    backed = np.zeros(n, dtype=np.bool_)
    for k in range(n):
        backed[k] = stop[k] - first[k] >= _BACKED_FIXES and nearest[k] <= 2.0 * sigma[k]
    odometer, speed_m, slack_m, lo, hi = travel
    for attempt in range(3):
        m = 0
        kept = np.empty(n_near, dtype=np.int64)
        for k in range(n_near):
            if not outlier[near[k]]:
                kept[m] = near[k]
                m += 1
        kept = kept[:m]
        gap = _gaps(kept, first, stop, fix_time)
        if len(speed_m) or len(odometer):
            travel_m, slack = between_kernel(kept, odometer, speed_m, slack_m, lo, hi)
        else:
            travel_m, slack = np.empty(0), np.empty(0)
        found = _outliers(x[kept], y[kept], sigma[kept], gap, travel_m, slack, backed[kept], params)
        if not len(travel_m) and attempt == 0:  # one end spike at most: the next is no spike
            mid = 0.5 * (fix_time[first] + fix_time[stop - 1])  # each observation's time
            fixes = (fix_xy[0], fix_xy[1], fix_time, first, stop)
            # the pace next to an end is read from the fixes that are no spikes themselves:
            # a spike 40 m off within the last 5 s made the car look fast enough to have
            # come from anywhere, and a last fix 54 m off at 4 m/s was kept
            clean = kept[~found]
            clean_gap = _gaps(clean, first, stop, fix_time)
            spikes = _end_spikes(clean, x, y, sigma, mid, clean_gap, fixes, params)
            for end, inner in ((0, 1), (m - 1, m - 2)):
                at = 0 if end == 0 else len(clean) - 1
                if (
                    len(clean) >= 3  # and so m >= 3: clean is kept less the spikes
                    and not found[end]
                    and spikes[at]
                    and not found[inner]
                    and not backed[kept[end]]
                ):
                    found[end] = True
        if not found.any():
            break
        for k in range(m):
            if found[k]:
                outlier[kept[k]] = True
    return outlier


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
    f8 = np.float64
    gaps = np.diff(np.asarray(time_s, f8)) if gap_s is None else gap_s
    travel_m, slack_m = (np.empty(0), np.empty(0)) if travel is None else travel
    out = _outliers(
        np.ascontiguousarray(x, f8),
        np.ascontiguousarray(y, f8),
        np.ascontiguousarray(sigma_m, f8),
        np.ascontiguousarray(gaps, f8),
        np.ascontiguousarray(travel_m, f8),
        np.ascontiguousarray(slack_m, f8),
        np.zeros(0, dtype=np.bool_),
        _params(config),
    )
    return np.asarray(out, dtype=bool)


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
    f8 = np.float64
    out = _off_road(
        np.ascontiguousarray(nearest_m, f8),
        np.ascontiguousarray(sigma_m, f8),
        np.ascontiguousarray(gap_s, f8),
        _params(config),
    )
    return np.asarray(out, dtype=bool)


def find_displaced(
    fixes: Fixes, obs: Observations, cands: Candidates, config: MatchConfig
) -> BoolArray:
    """
    Displaced observations, judged among those near a road.

    Short runs far from every road between observations on a road are displaced
    (:func:`find_off_road_runs`). Then each is compared with where its neighbours put it
    (:func:`find_outliers`); of two displaced ones in a row only the worse is caught at first,
    so that test runs again without the ones found, up to three times. An observation merged
    from at least ``_BACKED_FIXES`` fixes within 2 sigma of a road is never such an outlier:
    several fixes agree on it, and a car that turns back at a dead end's end makes the same
    spike (1 s / 5 m matrix, positions only: trips within 1 % 95 -> 96 %, |error| p95
    0.97 -> 0.82 %). Where the trace says nothing of the distance travelled, an end
    observation is also tested against the inner ones' own motion (:func:`_end_spikes`, on
    the first pass only: the observation next to a spike is no spike); positions only,
    within 1 %: 1s-5m 96.4 -> 97.6 %, realistic-1s 90.9 -> 92.7 %.
    """
    out = _displaced(
        cands.ptr,
        cands.distance_m,
        np.ascontiguousarray(fixes.time_s, np.float64),
        obs.first,
        obs.stop,
        obs.x,
        obs.y,
        obs.sigma_m,
        travel_arrays(obs.travel),
        (np.ascontiguousarray(fixes.x, np.float64), np.ascontiguousarray(fixes.y, np.float64)),
        _params(config),
    )
    return np.asarray(out, dtype=bool)
