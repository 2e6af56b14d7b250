"""
``OnlineMatcher``: a vehicle's fixes matched as they arrive, with the distance so far.

(Over 400 lines on purpose: the settling rules (when a round runs, where the path is cut, what
settles) act on one trip state and read best together; the stages live in ``tail`` and
``window``.)

Design
------
Three ways to match a stream with an HMM were weighed:

- **Fixed-lag Viterbi**: what is older than ``lag`` is decided, whatever later fixes say.
  Latency and memory are bounded; but two parallel roads, or a road and its service lane, can
  look alike for longer than any lag worth waiting (on the Melbourne extract a trip ran 60 s
  on the wrong of two, a stop included, before a junction told them apart), and a fixed lag
  then settles the wrong one.
- **Convergence-point detection**: an observation is settled once every surviving Viterbi path
  agrees on it. No lag to choose, but neither latency nor memory is bounded (the two parallel
  roads keep two paths alive as long as they run side by side), and here it would not be exact
  anyway: the stages around Viterbi look further than one step. The outlier test judges an
  observation by the ones around it, the grouping of a stopped car's fixes looks two fixes
  ahead, loops and spurs are priced on the assembled path after Viterbi
  (:mod:`mapmatch.hmm.loops`), the path's front is held against fixes scattered behind it.
- **Windowed re-solve**: run the offline stages again over a window of recent fixes, the
  settled prefix's last state as the window's prior. It is the offline model itself, so it
  treats breaks, outliers, stops, U-turns and loops as :func:`mapmatch.match` does, at the cost
  of running the stages often.

This matcher is the windowed re-solve, with the lag as a fixed-lag smoother's and agreement
as the convergence test's, and with the costly stages run only when they can change something:

- **The tail** (:mod:`mapmatch.online.tail`): the unsettled fixes, and a few settled
  observations before them for context, go through the input stages
  (:func:`~mapmatch.hmm.fixes.fixes_of`, the grouping into observations, the outlier test) as
  a trace does. A whole round runs once a few observations have become final (a cheap count
  of the grouping alone tells); candidates are searched once per observation.
- **The window** (:mod:`mapmatch.online.window`): the settled prefix's last observation (the
  *anchor*, its candidates cut down to the place it settled at: the prior) and the unsettled
  observations in use, solved by :func:`~mapmatch.hmm.trellis.solve`, its breaks repaired,
  assembled by :func:`~mapmatch.hmm.assemble.assemble`; then the path is cut at the newest
  observation that may settle, and what lies before the cut settles.

**Settled** means: the path up to the observation and its fixes' places are final; they never
change, and the next window starts from there. An observation may settle once it is ``lag``
seconds old (trip time, against the newest fix), ``LOOKAHEAD_OBSERVATIONS`` final observations
follow it (the outlier verdicts around it are final, and a break after it has been seen from
both sides; a stopped car makes no new observations, so age alone is not enough), and the
window is sure of its place: at least ``SETTLE_CONFIDENCE`` of its posterior
(forward-backward over the window) on candidates the chosen path passes where it does, which
is the posterior's form of "every surviving path agrees"; the end of one edge and the start of
the next at a junction count as one place. Past ``max_lag`` (four lags unless given) it may
settle whatever the window says. Viterbi's best path to a settled state does not depend on
what comes after it, so the history before the cut is settled with it. The cut is made where
the path passes the observation, with the observations' resolution (``thinning_sigmas`` x
sigma) of room from either end of its edge, and not at a stop (so that the next window neither
trims a sliver off its start, nor starts inside a loop or a stop's scatter that the stages
price as one). Settling runs at most every 5 s of trip time, to share one
assembly between several observations.

With an unbounded lag (``lag=None``), or one longer than the trip, nothing settles before
:meth:`OnlineMatcher.close`, whose window is then the whole trip: the same stages over the same
fixes, so the result equals :func:`mapmatch.match` on the trace of all the fixes (edges,
lengths, points).

Breaks, outliers, stops and U-turns are the offline stages' own: a stretch without roads or a
transition no route explains breaks the path into a new segment (repaired as offline where
leaving out one observation joins it); outliers are left out of the model and placed on the
path afterwards; a stopped car's fixes are one observation; U-turns cost and count as offline.
Two bounds keep a trip's memory finite whatever it does: a stop open for the larger of
``max_lag`` and 10 minutes (a parked car reporting on) is cut there, and a window whose start
has waited a minute past ``max_lag`` settles where it can (the newest observation past
``max_lag`` the path passes, else the newest it agrees on; fixes with no road near them and
nothing to follow settle unmatched).

Memory per trip: the tail (the lag's fixes, the look-ahead and the context: a few hundred
fixes at 1 Hz, about 80 bytes each), each tail observation's candidates, and the settled
record: every settled fix's outcome (about 100 bytes) and every settled stretch of path, which
:meth:`~OnlineMatcher.close` returns.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Final

import numpy as np

from mapmatch.config import MatchConfig
from mapmatch.distance import DistanceCheck, check_distance, chord_length_m, measured_span
from mapmatch.errors import ConfigError, InputTypeError, InvalidTraceError, NoCandidatesError
from mapmatch.hmm.emission import emissions
from mapmatch.hmm.ends import odometer_ends
from mapmatch.hmm.fixes import hold_limit_m
from mapmatch.hmm.routes import ROUTE_STANDSTILL
from mapmatch.hmm.selection import find_displaced
from mapmatch.hmm.trellis import cuts, isolated, solve
from mapmatch.matcher import _evidence, _uturns
from mapmatch.online.fixes import OPTIONAL_FIELDS, LiveFix, read_fix
from mapmatch.online.record import Record, empty_points
from mapmatch.online.tail import (
    CONTEXT_OBSERVATIONS,
    LOOKAHEAD_OBSERVATIONS,
    Tail,
    TailModel,
    rows,
)
from mapmatch.online.window import path_confidence, place_on_path, solve_window
from mapmatch.result import EdgeAttributes, MatchedEdge, MatchedPoints, MatchResult, MatchStats

if TYPE_CHECKING:
    from collections.abc import Iterable, Mapping

    from mapmatch.distance import Evidence
    from mapmatch.hmm.candidates import Candidates
    from mapmatch.online.window import WindowSolve
    from mapmatch.types import BoolArray, FloatArray, IntArray
    from roadnets import RoadNetwork

__all__ = [
    "DEFAULT_LAG_S",
    "SETTLE_CONFIDENCE",
    "LiveDistance",
    "LivePosition",
    "LiveUpdate",
    "OnlineMatcher",
    "RejectedFix",
]

#: Default lag, seconds: at 1 Hz it settles within 0.5 % of the offline length on the
#: benchmark's trips (``benchmarks/bench_online.py`` measures accuracy against the lag).
DEFAULT_LAG_S: Final = 30.0
_SETTLE_EVERY_S: Final = 5.0  # settle in steps of this much trip time (one assembly each)
_STALL_S: Final = 60.0  # unsettled this long past max_lag: settle wherever the path allows
_MAX_LAG_FACTOR: Final = 4.0  # max_lag, when not given, in lags
#: Share of the window's posterior an observation must have on the chosen path where it lies
#: (:func:`~mapmatch.online.window.path_confidence`) to settle before ``max_lag``.
SETTLE_CONFIDENCE: Final = 0.999
_SPLIT_MIN_S: Final = 600.0  # a stop is cut after the larger of max_lag and this
_CONTEXT_FIXES: Final = 100  # settled context kept before the anchor: at most so many fixes
_ROUND_EVERY: Final = 3  # observations become final between two rounds of the stages


@dataclass(frozen=True, slots=True)
class RejectedFix:
    """A fix of a batch that was refused: its place in the batch, the field and why."""

    index: int
    field: str | None
    message: str


@dataclass(frozen=True, slots=True)
class LivePosition:
    """
    Where the vehicle is now, provisionally: the newest observation's most likely road place.

    ``fix`` is the trip number of the newest fix that has a road near it and ``time_s`` its
    time; ``lon``/``lat`` the place on the road (WGS84), on network edge ``edge`` (OSM
    ``u``, ``v``, ``key``) at ``offset_m`` from its start; ``distance_m`` from the newest
    observation (the centroid of its fixes) to it;
    ``confidence`` the probability of that road place given the trip so far (the filtered
    posterior; it may still change as fixes arrive).
    """

    fix: int
    time_s: float
    lon: float
    lat: float
    edge: int
    u: int
    v: int
    key: int
    offset_m: float
    distance_m: float
    confidence: float


@dataclass(frozen=True, slots=True)
class LiveDistance:
    """
    The running distance check: matched road distance against fused distance, settled part.

    ``check`` is the :class:`~mapmatch.distance.DistanceCheck` of the settled part (its
    ``fused_length_m`` the odometer's increase from the first fix to the last settled
    observation, else the chord sum over those fixes); ``settled_fixes`` of ``fixes`` have
    settled, up to trip time ``settled_until_s`` of a trip that runs from ``start_s`` to
    ``newest_s`` so far.
    """

    check: DistanceCheck
    settled_fixes: int
    fixes: int
    start_s: float
    settled_until_s: float
    newest_s: float

    @property
    def coverage(self) -> float:
        """Share of the trip's time so far that the check covers (0 .. 1)."""
        span = self.newest_s - self.start_s
        if not self.settled_fixes:
            return 0.0
        if span <= 0:
            return 1.0
        return float(min(max((self.settled_until_s - self.start_s) / span, 0.0), 1.0))

    def to_dict(self) -> dict[str, object]:
        """JSON-ready members."""
        return {
            **self.check.to_dict(),
            "settled_fixes": self.settled_fixes,
            "fixes": self.fixes,
            "settled_until_s": None if math.isnan(self.settled_until_s) else self.settled_until_s,
            "coverage": round(self.coverage, 4),
        }


@dataclass(frozen=True, slots=True)
class LiveUpdate:
    """
    What one :meth:`~OnlineMatcher.push` (or ``push_many``) accepted and settled.

    ``accepted`` fixes were added, ``merged`` were repeats of the fix before them, and
    ``rejected`` were refused (a batch only: one fix raises instead). ``points`` is the
    outcome of the fixes that settled, trip numbers ``first_fix`` on; ``edges`` the path's
    stretches that settled, in driving order, ``segments`` the segment of each (a stretch may
    carry on the last one settled before it, on the same edge). ``distance`` is the running
    check after the update.
    """

    accepted: int
    merged: int
    rejected: tuple[RejectedFix, ...]
    first_fix: int
    points: MatchedPoints
    edges: tuple[MatchedEdge, ...]
    segments: tuple[int, ...]
    distance: LiveDistance

    @property
    def settled_fixes(self) -> int:
        """Fixes that settled in this update."""
        return len(self.points.time_s)


@dataclass(frozen=True, slots=True)
class _Anchor:
    """The settled prefix's last observation: the state the next window starts from."""

    edge: int  # the place on the road it settled at
    offset_m: float


@dataclass(frozen=True, slots=True)
class _Cut:
    """Where a window's path is cut: at an observation, at a place on the path."""

    piece: int
    position: int  # the observation's place in the window
    stretch: int  # the stretch of the piece's path holding the place
    edge: int
    offset_m: float


@dataclass(frozen=True, slots=True)
class _Round:
    """The tail's stages at one moment, and the window they give."""

    model: TailModel
    cands: Candidates  # every tail observation's (none for unfinal ones)
    outlier: BoolArray
    missing_before: IntArray
    used: IntArray  # the window: the anchor, then the unsettled final observations in use
    anchor_at: int  # tail index of the anchor, -1 without
    fixes: int  # the trip's fixes when it ran


@dataclass(slots=True)
class _Settled:
    """What one settling step produced, for the update."""

    first_fix: int
    points: list[MatchedPoints]
    edges: list[tuple[int, int, int]]  # (segment, first stretch, stop stretch) added

    @classmethod
    def none(cls, first_fix: int) -> _Settled:
        return cls(first_fix, [], [])


class OnlineMatcher:
    """
    Match one vehicle's fixes as they arrive (see the module docstring for the design).

    Parameters
    ----------
    net
        The road network, from :func:`roadnets.load`.
    config
        Matcher parameters; the defaults of :class:`~mapmatch.MatchConfig` otherwise.
    lag
        Seconds of trip time after which an observation settles; ``None`` for an unbounded
        lag (nothing settles before :meth:`close`, which then equals :func:`mapmatch.match`
        on the whole trace).
    trip_id
        The trip's name, used in messages and in the result.

    Examples
    --------
    >>> import roadnets                                                   # doctest: +SKIP
    >>> live = OnlineMatcher(roadnets.load(), lag=30.0, trip_id="cab-7")  # doctest: +SKIP
    >>> update = live.push({"time": 1.7e9, "lat": 43.7384, "lon": 7.4246})  # doctest: +SKIP
    >>> live.position(), live.distance().check.verdict                    # doctest: +SKIP
    >>> result = live.close()                                             # doctest: +SKIP
    """

    def __init__(
        self,
        net: RoadNetwork,
        config: MatchConfig | None = None,
        *,
        lag: float | None = DEFAULT_LAG_S,
        max_lag: float | None = None,
        trip_id: str = "trip",
    ) -> None:
        from roadnets import RoadNetwork

        if not isinstance(net, RoadNetwork):
            msg = (
                f"net must be a roadnets.RoadNetwork, not a {type(net).__name__}; load one "
                "with roadnets.load(path)"
            )
            raise InputTypeError(msg)
        if config is not None and not isinstance(config, MatchConfig):
            msg = f"config must be a MatchConfig, not a {type(config).__name__}"
            raise InputTypeError(msg)
        for name, value in (("lag", lag), ("max_lag", max_lag)):
            if value is not None and (
                isinstance(value, bool) or not isinstance(value, int | float)
            ):
                msg = f"{name} must be a number of seconds or None, not a {type(value).__name__}"
                raise InputTypeError(msg)
            if value is not None and not value >= 0:
                msg = f"{name} must be >= 0 seconds, or None for no bound (got {value!r})"
                raise ConfigError(msg, field=name)
        if lag is not None and max_lag is not None and max_lag < lag:
            msg = f"max_lag ({max_lag:g} s) must be at least lag ({lag:g} s)"
            raise ConfigError(msg, field="max_lag")
        self.net = net
        self.config = config or MatchConfig()
        self.lag_s = None if lag is None or math.isinf(lag) else float(lag)
        self.max_lag_s: float | None = None
        if self.lag_s is not None:
            cap = _MAX_LAG_FACTOR * self.lag_s if max_lag is None else float(max_lag)
            self.max_lag_s = None if math.isinf(cap) else cap
        self.trip_id = str(trip_id)
        self._tail: Tail | None = None
        self._record = Record(net.arrays.edge_twin)  # as the assembly reads it (one variant)
        self._anchor: _Anchor | None = None
        self._open_fix = 0  # trip number of the first unsettled fix
        self._segment = -1  # the segment the settled path ends in
        self._last: LiveFix | None = None
        self._round_cache: _Round | None = None
        self._blocked: _Round | None = None  # the round whose window could not be cut
        self._blocked_at_s = -math.inf
        self._open_group = 0  # trip number of the first fix of the first unfinal observation
        self._sigma_est = math.nan  # the tail's estimated sigma at the last round
        self._closed = False
        self._result: MatchResult | None = None
        self._failure: NoCandidatesError | None = None
        # counts and running figures
        self.fixes = 0
        self.merged = 0
        self.rejected = 0
        self._shared_time = 0
        self._ignored: dict[str, int] = {}
        self._candidates = 0
        self._model_points = 0
        self._repairs = 0
        self._sigma_max = 0.0
        self._speed_seen = False
        self._odometer = (math.nan, math.nan)  # first and last known readings
        self._settled_odometer_m = math.nan
        self._settled_chord_m = 0.0
        self._settled_until_s = math.nan
        self._settled_at_s = -math.inf  # trip time of the newest fix at the last settling
        self._start_s = math.nan
        self._busy_s = 0.0

    # ------------------------------------------------------------------ input

    def push(self, fix: Mapping[str, object]) -> LiveUpdate:
        """
        Add the trip's next fix; return what settled.

        Raises
        ------
        InvalidTraceError
            The fix breaks a rule (named in the message); the trip is unchanged.
        RuntimeError
            The trip is closed.
        """
        clock = time.perf_counter()
        self._check_open()
        before = self._open_fix
        accepted, merged = self._accept(fix)
        settled = self._advance(closing=False, defer=True) if accepted else _Settled.none(before)
        update = self._update(settled, accepted, merged, ())
        self._busy_s += time.perf_counter() - clock
        return update

    def push_many(self, fixes: Iterable[Mapping[str, object]]) -> LiveUpdate:
        """
        Add the trip's next fixes in order; return what settled.

        A fix that breaks a rule is refused (listed in ``rejected`` with its place in the
        batch and the reason) and the others are added: one bad fix never loses a trip.
        """
        clock = time.perf_counter()
        self._check_open()
        before = self._open_fix
        accepted = merged = 0
        rejected: list[RejectedFix] = []
        for index, fix in enumerate(fixes):
            try:
                a, m = self._accept(fix)
            except InvalidTraceError as error:
                rejected.append(RejectedFix(index, error.field, str(error)))
                self.rejected += 1
                continue
            accepted += a
            merged += m
        settled = self._advance(closing=False, defer=False) if accepted else None
        update = self._update(settled or _Settled.none(before), accepted, merged, rejected)
        self._busy_s += time.perf_counter() - clock
        return update

    def _check_open(self) -> None:
        if self._closed:
            msg = f"trip {self.trip_id!r} is closed; start a new OnlineMatcher for a new trip"
            raise RuntimeError(msg)

    def _accept(self, fix: Mapping[str, object]) -> tuple[int, int]:
        """Validate and add one fix: ``(1, 0)`` added, ``(0, 1)`` merged as a repeat."""
        live, repeat = read_fix(
            fix,
            trip_id=self.trip_id,
            index=self.fixes,
            previous=self._last,
            last_odometer_m=self._odometer[1],
        )
        if repeat:
            self.merged += 1
            return 0, 1
        if self._tail is None:
            columns = frozenset(f for f in OPTIONAL_FIELDS if live.has(f))
            split = None if self.max_lag_s is None else max(self.max_lag_s, _SPLIT_MIN_S)
            self._tail = Tail(self.net, self.config, self.trip_id, columns, split)
            self._start_s = live.time_s
        tail = self._tail
        for name in OPTIONAL_FIELDS:
            if name not in tail.store.columns and live.has(name):
                self._ignored[name] = self._ignored.get(name, 0) + 1
        if self._last is not None and live.time_s == self._last.time_s:
            self._shared_time += 1
        x, y = self.net.project(np.array([live.lon]), np.array([live.lat]))
        tail.append(live, float(x[0]), float(y[0]))
        if not math.isnan(live.odometer_m) and "odometer" in tail.store.columns:
            first = self._odometer[0] if not math.isnan(self._odometer[0]) else live.odometer_m
            self._odometer = (first, live.odometer_m)
        self._last = live
        self.fixes += 1
        return 1, 0

    # ------------------------------------------------------------------ the model

    def _round(self, *, closing: bool) -> _Round:
        """Run the tail's stages and find the window."""
        tail = self._tail
        assert tail is not None
        model = tail.model(closing=closing)
        obs, first, final = model.obs, model.first_real, model.final
        own = np.arange(first, final, dtype=np.int64)
        cands_own = tail.candidates(obs, model.keys, own)
        cands = cands_own.spread(own, len(obs))
        outlier = np.zeros(len(obs), dtype=bool)
        if final > first:
            outlier[first:final] = find_displaced(
                model.fixes, rows(obs, first, final), cands_own, self.config
            )
        has = cands.counts > 0
        missing = np.zeros(len(obs), dtype=bool)
        missing[first:final] = ~has[first:final] & ~isolated(~has[first:final])
        missing_before = np.cumsum(missing, dtype=np.int64)
        anchor_at = -1
        if self._anchor is not None:
            # the observation of the last settled fix (grouped anew when the tail's sigma
            # estimate changed, it may hold unsettled fixes too: they settle with the next cut)
            at = int(obs.of_fix[self._open_fix - 1 - model.base])
            if first <= at < final and cands.counts[at] > 0:
                anchor_at = at
            else:
                self._anchor = None  # nothing to start from: the path starts afresh
        open_first = self._open_fix - model.base
        unsettled = own[obs.first[own] >= open_first]
        in_use = unsettled[has[unsettled] & ~outlier[unsettled]]
        used = np.concatenate(([anchor_at], in_use)).astype(np.int64) if anchor_at >= 0 else in_use
        self._sigma_max = max(self._sigma_max, float(model.fixes.sigma_m.max()))
        self._speed_seen = self._speed_seen or bool(np.isfinite(model.fixes.speed_mps).any())
        opened = int(obs.first[final]) if final < len(obs) else len(model.fixes.time_s)
        self._open_group = model.trip_fix(opened)
        self._sigma_est = model.sigma_m
        return _Round(model, cands, outlier, missing_before, used, anchor_at, self.fixes)

    def _advance(self, *, closing: bool, defer: bool) -> _Settled:
        """
        Bring the window up to date after new fixes; settle what is due.

        Two steps cost a few tenths of a millisecond each, most of it the fixed cost of the
        stages' calls: a whole round of the input stages over the tail, and settling (the
        window solved and assembled). With ``defer`` (one fix) a push takes at most one of
        them: a round once ``_ROUND_EVERY`` observations have become final (a cheap count
        tells, :meth:`Tail.newly_final`) or when settling is due and some have, else settling
        when it is due. Without (a batch,
        closing) it takes both. Until a round runs, the last one still describes every final
        observation.
        """
        tail = self._tail
        assert tail is not None
        rnd = self._round_cache
        out = _Settled.none(self._open_fix)
        newly = 0 if closing or rnd is None else tail.newly_final(self._open_group, self._sigma_est)
        if closing or rnd is None or newly >= _ROUND_EVERY or (newly and self._due(rnd)):
            rnd = self._round(closing=closing)  # settling works from the newest final ones
            self._round_cache = rnd
            if defer:
                return out
        if not (closing or self._due(rnd)):
            return out
        return self._settle(rnd, closing=closing)

    def _newest_s(self) -> float:
        assert self._last is not None
        return self._last.time_s

    def _stalled(self, model: TailModel) -> bool:
        """Whether the first unsettled fix has waited ``_STALL_S`` past the longest lag."""
        if self.max_lag_s is None:
            return False
        open_first = self._open_fix - model.base
        times = model.fixes.time_s
        limit = self._newest_s() - self.max_lag_s - _STALL_S
        return open_first < len(times) and float(times[open_first]) <= limit

    def _due(self, rnd: _Round) -> bool:
        """Whether to try settling: something is old enough, and not tried on this round."""
        if self.lag_s is None:
            return False
        model = rnd.model
        if rnd is self._blocked and self._newest_s() - self._blocked_at_s < _SETTLE_EVERY_S:
            return False  # no cut was possible on this round lately: wait
        if self._stalled(model):
            return True
        if self._newest_s() - self._settled_at_s < _SETTLE_EVERY_S:
            return False
        waiting = rnd.used[1:] if rnd.anchor_at >= 0 else rnd.used
        ready = waiting[waiting + LOOKAHEAD_OBSERVATIONS < model.final]
        return bool(len(ready)) and (
            float(model.obs.time_s[ready[0]]) <= self._newest_s() - self.lag_s
        )

    def _hold_limit_m(self, model: TailModel) -> float:
        whole = model.base == 0 and not self._record.fixes  # the tail is the whole trip
        sigma = float(model.fixes.sigma_m.max()) if whole else self._sigma_max
        return hold_limit_m(
            dataclasses.replace(model.fixes, sigma_m=np.array([sigma])), self.config
        )

    def _anchored(self, rnd: _Round, cands: Candidates) -> Candidates:
        """
        The tail's candidates with the anchor's cut down to the place it settled at.

        That is one of its candidates, unless the anchor settled where the path was held
        ahead of it: then that place on the road stands in for its candidates.
        """
        if rnd.anchor_at < 0:
            return cands
        anchor = self._anchor
        assert anchor is not None
        a = rnd.anchor_at
        rows_ = np.arange(len(cands))
        mine = (rows_ >= cands.ptr[a]) & (rows_ < cands.ptr[a + 1])
        settled = mine & (cands.edge == anchor.edge)
        settled &= np.abs(cands.offset_m - anchor.offset_m) <= 1e-9
        if settled.any():
            return cands.take(~mine | settled)
        keep = ~mine
        keep[int(cands.ptr[a])] = True  # one row of the anchor's, to hold the place
        out = cands.take(keep)
        i = int(out.ptr[a])
        px, py = self.net.point_on_edge(np.array([anchor.edge]), np.array([anchor.offset_m]))
        obs = rnd.model.obs
        out.edge[i], out.offset_m[i] = anchor.edge, anchor.offset_m
        out.x[i], out.y[i] = float(px[0]), float(py[0])
        out.distance_m[i] = float(np.hypot(px[0] - obs.x[a], py[0] - obs.y[a]))
        return out

    def _solve(self, rnd: _Round) -> WindowSolve:
        return solve_window(
            self.net,
            self.config,
            rnd.model,
            self._anchored(rnd, rnd.cands),
            rnd.used,
            rnd.missing_before,
            rnd.outlier,
            self._hold_limit_m(rnd.model),
        )

    # ------------------------------------------------------------------ settling

    def _settle(self, rnd: _Round, *, closing: bool) -> _Settled:
        """Settle the window up to the newest observation older than the lag (all: closing)."""
        model = rnd.model
        out = _Settled.none(self._open_fix)
        if not len(rnd.used):
            return self._settle_unmatched(rnd, out, closing=closing)
        if len(rnd.used) == 1 and not closing:
            return self._settle_unmatched(rnd, out, closing=False)  # nothing to cut yet
        ws = self._solve(rnd)
        sol = ws.solution
        cut = _Cut(len(sol.pieces) - 1, len(sol.used) - 1, -1, -1, 0.0) if closing else None
        if cut is None:
            cut = self._choose_cut(rnd, ws)
        if cut is None:
            self._blocked, self._blocked_at_s = rnd, self._newest_s()
            return self._settle_unmatched(rnd, out, closing=False)
        piece, t, stretch = cut.piece, cut.position, cut.stretch
        self._settled_at_s = self._newest_s()
        base_segment = self._segment if rnd.anchor_at >= 0 else self._segment + 1
        obs = model.obs
        asm = ws.assembled
        for p in range(piece + 1):
            seg = asm.segments[p]
            edge, lo, hi = seg.edge, seg.start_offset_m, seg.end_offset_m
            last_fix = model.trip_fix(seg.last)
            if p == piece and not closing:
                edge, lo = edge[: stretch + 1], lo[: stretch + 1]
                hi = np.append(hi[:stretch], max(cut.offset_m, float(lo[-1])))
                last_fix = model.trip_fix(int(obs.stop[sol.used[t]]) - 1)
            segment = base_segment + p
            begin, end = self._record.add_path(
                segment, model.trip_fix(seg.first), last_fix, edge, lo, hi
            )
            out.edges.append((segment, begin, end))
        stop = len(model.fixes.time_s) if closing else int(obs.stop[sol.used[t]])
        open_first = self._open_fix - model.base
        points = _slice_points(asm.points, open_first, stop)
        of = points.segment
        points = dataclasses.replace(points, segment=np.where(of >= 0, of + base_segment, -1))
        self._record.add_points(
            points, _readings(model, open_first, stop), model.fixes.radius_m[open_first:stop]
        )
        out.points.append(points)
        self._count(rnd, ws, open_first, stop)
        self._segment = base_segment + piece
        self._settled_until(model, stop)
        self._open_fix = model.trip_fix(stop)
        if closing:
            self._anchor = None
            return out
        a = int(sol.used[t])
        self._anchor = _Anchor(cut.edge, cut.offset_m)
        self._forget(model, a)
        return out

    def _choose_cut(self, rnd: _Round, ws: WindowSolve) -> _Cut | None:
        """
        Where to cut the window's path.

        At the newest observation that may settle (see the module docstring): ``lag`` old,
        ``LOOKAHEAD_OBSERVATIONS`` final observations after it, the window sure of its place
        on the path (``SETTLE_CONFIDENCE``) or ``max_lag`` old, passed by the path with room
        from either end of its edge, and not held. When the window is stalled (its start has
        waited ``_STALL_S`` past ``max_lag``), the newest one ``max_lag`` old, else the newest
        agreed one, each first with room, then without; an observation the path was held ahead
        of is then cut where the path was held (the front it lies behind). ``None`` when none
        can take the cut yet.
        """
        assert self.lag_s is not None
        assert self.max_lag_s is not None
        model, sol = rnd.model, ws.solution
        obs = model.obs
        newest = self._newest_s()
        stalled = self._stalled(model)
        lengths = self.net.arrays.edge_length_m
        reach = self.config.thinning_sigmas
        tolerance = reach * self.config.sigma_m  # the resolution of an observation
        first = 1 if rnd.anchor_at >= 0 else 0
        best: _Cut | None = None
        # when stalled: the newest observation max_lag old, else the newest agreed one, each
        # first with room from the ends of its edge (True), then without
        old: dict[bool, _Cut | None] = {True: None, False: None}
        sure: dict[bool, _Cut | None] = {True: None, False: None}
        last = len(sol.used) - 1
        for p, (start, stop) in enumerate(sol.pieces):
            if p + 1 < len(sol.pieces) and not stalled:
                after = int(sol.used[sol.pieces[p + 1][0]])
                if after + LOOKAHEAD_OBSERVATIONS >= model.final:
                    break  # a break too new to be sure of: what leads up to it waits
            ts = np.arange(start, stop)
            row = sol.cands.ptr[ts] + sol.states[ts]
            seg = ws.assembled.segments[p]
            path = (seg.edge, seg.start_offset_m, seg.end_offset_m)
            where = place_on_path(path, sol.cands.edge[row], sol.cands.offset_m[row])
            front: tuple[int, int, float] | None = None  # the last place the path passed
            for t, j, r in zip(ts.tolist(), where, row.tolist(), strict=True):
                on_path = j >= 0
                if on_path:
                    front = (j, int(sol.cands.edge[r]), float(sol.cands.offset_m[r]))
                k = int(sol.used[t])
                age = newest - float(obs.time_s[k])
                if front is None or t == last or t < first or age < self.lag_s:
                    continue
                place = _Cut(p, t, *front)
                lo, hi = int(sol.cands.ptr[t]), int(sol.cands.ptr[t + 1])
                agreed = age >= self.max_lag_s or (
                    path_confidence(
                        path,
                        place.stretch,
                        sol.cands.edge[lo:hi],
                        sol.cands.offset_m[lo:hi],
                        sol.post[t, : hi - lo],
                        tolerance,
                    )
                    >= SETTLE_CONFIDENCE
                )
                room = min(place.offset_m, float(lengths[place.edge]) - place.offset_m)
                roomy = room >= reach * float(obs.sigma_m[k])
                if age >= self.max_lag_s:
                    old[roomy] = place
                if agreed:
                    sure[roomy] = place
                if not (on_path and agreed and roomy) or k + LOOKAHEAD_OBSERVATIONS >= model.final:
                    continue
                held = (
                    t > start
                    and sol.kinds[t - 1, sol.states[t - 1], sol.states[t]] == ROUTE_STANDSTILL
                ) or (
                    t + 1 < stop
                    and sol.kinds[t, sol.states[t], sol.states[t + 1]] == ROUTE_STANDSTILL
                )  # a stop begins or goes on here: its scatter lies on both sides
                if not held:
                    best = place
        if best is not None or not stalled:
            return best
        return old[True] or sure[True] or old[False] or sure[False]

    def _settle_unmatched(self, rnd: _Round, out: _Settled, *, closing: bool) -> _Settled:
        """
        Settle fixes that no observation in use follows: a stretch without roads.

        When the trip closes, every fix left. Otherwise only when the window has been stuck
        past ``max_lag`` for ``_STALL_S`` and none of its final observations older than
        ``max_lag`` is in use (none could take a cut) while one of them has no road near it:
        their fixes settle unmatched, and the path starts afresh after them, as after a
        stretch without roads in a trace.
        """
        model = rnd.model
        obs, first, final = model.obs, model.first_real, model.final
        open_first = self._open_fix - model.base
        if closing:
            stop = len(model.fixes.time_s)
        else:
            if not self._stalled(model):
                return out
            assert self.max_lag_s is not None
            limit = self._newest_s() - self.max_lag_s
            waiting = rnd.used[1:] if rnd.anchor_at >= 0 else rnd.used
            old = [
                k
                for k in range(first, final)
                if obs.first[k] >= open_first and float(obs.time_s[k]) <= limit
            ]
            if waiting[:1].size and old and int(waiting[0]) <= old[-1]:
                return out  # an observation in use could anchor: it has to wait for its cut
            if not old or not (rnd.cands.counts[old] == 0).any():
                return out
            stop = int(obs.stop[old[-1]])
        points = _unmatched_points(model, rnd.outlier[model.obs.of_fix], open_first, stop)
        self._record.add_points(
            points, _readings(model, open_first, stop), model.fixes.radius_m[open_first:stop]
        )
        out.points.append(points)
        self._candidates += int(
            rnd.cands.counts[(obs.first >= open_first) & (obs.stop <= stop)].sum()
        )
        self._settled_until(model, stop)
        self._open_fix = model.trip_fix(stop)
        self._anchor = None
        if not closing:
            k = int(np.searchsorted(obs.stop, stop, side="left"))
            self._forget(model, min(k, final - 1))
        return out

    def _count(self, rnd: _Round, ws: WindowSolve, lo: int, hi: int) -> None:
        """Add the settled observations to the counts of the result's stats."""
        obs = rnd.model.obs
        settled = (obs.first >= lo) & (obs.stop <= hi)
        self._candidates += int(rnd.cands.counts[settled].sum())
        used = ws.solution.used
        self._model_points += int(
            np.count_nonzero((obs.first[used] >= lo) & (obs.stop[used] <= hi))
        )
        self._repairs += ws.repairs

    def _settled_until(self, model: TailModel, stop: int) -> None:
        """Record the running figures at the last settled fix (tail index ``stop - 1``)."""
        view = model.view
        last = stop - 1
        self._settled_until_s = float(view.time_s[last])
        self._settled_chord_m = (
            float(self._tail.store.column("chord_m")[last]) if self._tail else 0.0
        )
        if view.odometer_m is not None:
            k = int(model.obs.of_fix[last])
            lo, hi = int(model.obs.first[k]), int(model.obs.stop[k])
            member = ~model.obs.stray[lo:hi]
            readings = view.odometer_m[lo:hi][member]
            known = readings[np.isfinite(readings)]
            if len(known):  # the observation's place along the road, as the model has it
                self._settled_odometer_m = float(known.mean())
            else:
                before = view.odometer_m[:stop]
                seen = before[np.isfinite(before)]
                if len(seen):
                    self._settled_odometer_m = float(seen[-1])

    def _forget(self, model: TailModel, anchor: int) -> None:
        """Drop what lies before the context of the new anchor (tail index ``anchor``)."""
        assert self._tail is not None
        keep = max(model.first_real, anchor - CONTEXT_OBSERVATIONS + 1)
        first = model.obs.first
        while keep < anchor and first[anchor] - first[keep] > _CONTEXT_FIXES:
            keep += 1  # long observations (a parked car's): fewer of them
        self._tail.trim(model, keep)
        self._round_cache = None

    # ------------------------------------------------------------------ output

    def _update(
        self,
        settled: _Settled,
        accepted: int,
        merged: int,
        rejected: Iterable[RejectedFix],
    ) -> LiveUpdate:
        edges: list[MatchedEdge] = []
        segments: list[int] = []
        for segment, begin, end in settled.edges:
            if end <= begin:
                continue
            edge, lo, hi = self._record.stretches(segment, begin, end)
            attrs = EdgeAttributes.of_edges(self.net, edge)
            for i in range(len(edge)):
                edges.append(_matched_edge(attrs, i, int(edge[i]), float(lo[i]), float(hi[i])))
                segments.append(segment)
        points = settled.points[0] if len(settled.points) == 1 else None
        if points is None:
            from mapmatch.online.record import concat_points

            points = concat_points(settled.points) if settled.points else empty_points()
        return LiveUpdate(
            accepted,
            merged,
            tuple(rejected),
            settled.first_fix,
            points,
            tuple(edges),
            tuple(segments),
            self.distance(),
        )

    def _evidence(self) -> Evidence:
        rnd = self._round_cache
        if rnd is None or self._tail is None:
            return "positions"
        seen = np.array([1.0 if self._speed_seen else np.nan])
        fixes = dataclasses.replace(rnd.model.fixes, speed_mps=seen)
        return _evidence(rnd.model.view.as_trace(), fixes, self.config)

    def distance(self) -> LiveDistance:
        """The running distance check over the settled part of the trip (:class:`LiveDistance`)."""
        newest = self._last.time_s if self._last is not None else math.nan
        if self._result is not None:
            check = self._result.distance_check
            return LiveDistance(check, self.fixes, self.fixes, self._start_s, newest, newest)
        record = self._record
        odometer = None
        if not math.isnan(self._odometer[0]) and not math.isnan(self._settled_odometer_m):
            odometer = np.array([self._odometer[0], self._settled_odometer_m])
        check = check_distance(
            trace_id=self.trip_id,
            matched_length_m=record.length_m,
            complete=record.segment_count == 1 and record.first_matched,
            band=self.config.distance_band,
            odometer_m=odometer,
            fused_distance_m=None,
            chord_m=self._settled_chord_m,
            evidence=self._evidence(),
            uturns=record.uturns,
            log=False,
        )
        return LiveDistance(
            check, record.fixes, self.fixes, self._start_s, self._settled_until_s, newest
        )

    def position(self) -> LivePosition | None:
        """
        The vehicle's provisional place now (see :class:`LivePosition`).

        The newest observation near a road, at the road place the window's Viterbi gives it;
        ``None`` before the first fix near a road.
        """
        if self._tail is None or self._closed:
            return None
        rnd = self._round_cache
        if rnd is None or rnd.fixes != self.fixes:
            rnd = self._round(closing=False)
            self._round_cache = rnd
        model = rnd.model
        obs, final = model.obs, model.final
        newer = np.arange(final, len(obs), dtype=np.int64)
        window = np.concatenate((np.arange(model.first_real, final), newer)).astype(np.int64)
        tail = self._tail
        cands_all = tail.candidates(obs, model.keys, window).spread(window, len(obs))
        newer = newer[cands_all.counts[newer] > 0]
        used = np.concatenate((rnd.used, newer)).astype(np.int64)
        if not len(used):
            return None
        cands_all = self._anchored(rnd, cands_all)
        if len(used) == 1:  # one observation: its emissions are the whole model
            wc = cands_all.subset(used)
            em = emissions(model.obs, wc, np.zeros(len(wc), np.int64) + used[0], self.config)
            t, row = 0, int(np.argmax(em))
            confidence = float(1.0 / np.exp(em - em[row]).sum())
        else:
            cut_after = cuts(used, rnd.missing_before)  # unchanged past the final ones
            sol = solve(self.net, model.obs, cands_all, used, cut_after, self.config)
            t = int(np.flatnonzero(sol.states >= 0)[-1])
            wc = sol.cands
            row = int(wc.ptr[t] + sol.states[t])
            confidence = float(sol.post[t, sol.states[t]])
        k = int(used[t])
        edge = int(wc.edge[row])
        lon, lat = self.net.unproject(wc.x[row : row + 1], wc.y[row : row + 1])
        u, v, key = self.net.edge_osm_ids(np.array([edge]))
        last_fix = int(obs.stop[k]) - 1
        return LivePosition(
            fix=model.trip_fix(last_fix),
            time_s=float(model.fixes.time_s[last_fix]),
            lon=float(lon[0]),
            lat=float(lat[0]),
            edge=edge,
            u=int(u[0]),
            v=int(v[0]),
            key=int(key[0]),
            offset_m=float(wc.offset_m[row]),
            distance_m=float(wc.distance_m[row]),
            confidence=confidence,
        )

    def close(self, *, fused_distance_m: float | None = None) -> MatchResult:
        """
        Settle everything and return the trip's :class:`~mapmatch.MatchResult`.

        With an unbounded lag this is :func:`mapmatch.match` on the trace of the trip's
        fixes. ``fused_distance_m`` is the trip distance the vehicle reported, for the
        distance check when the trip has no odometer (as ``match`` takes it).

        Raises
        ------
        InvalidTraceError
            The trip has fewer than 2 fixes.
        NoCandidatesError
            No fix of the trip has a road within its search radius.
        """
        if self._result is not None:
            return self._result
        if self._failure is not None:
            raise self._failure
        clock = time.perf_counter()
        if self.fixes < 2 or self._tail is None:
            msg = (
                f"trip {self.trip_id!r}: {self.fixes} fix(es); a trip needs at least 2 to be "
                "matched"
            )
            raise InvalidTraceError(msg, trace_id=self.trip_id)
        self._advance(closing=True, defer=False)
        self._closed = True
        model = self._round_cache.model if self._round_cache else None
        if self._candidates == 0:
            radius = float(model.fixes.radius_m.max()) if model else self.config.search_radius_m
            self._failure = NoCandidatesError(self.trip_id, radius)
            raise self._failure
        readings = self._record.odometer_m()
        segments, points = odometer_ends(
            self.net,
            self._record.segments(self.net),
            self._record.points(),
            readings,
            self.config,
            self._record.radius_m(),
        )
        matched_length = float(sum(s.length_m for s in segments))
        span, complete, odometer = measured_span(
            points.matched, points.outlier, len(segments), readings
        )
        store = self._tail.store
        chord = self._settled_chord_m
        if store.base == 0 and model is not None:  # the whole trip is at hand: as match sums it
            chord = chord_length_m(store.column("x")[span], store.column("y")[span])
        check = check_distance(
            trace_id=self.trip_id,
            matched_length_m=matched_length,
            complete=complete,
            band=self.config.distance_band,
            odometer_m=odometer,
            fused_distance_m=fused_distance_m,
            chord_m=chord,
            evidence=self._evidence(),
            uturns=_uturns(self.net, segments),
        )
        self._busy_s += time.perf_counter() - clock
        stats = MatchStats(
            points=self.fixes,
            matched_points=int(points.matched.sum()),
            candidates=self._candidates,
            reordered_rows=0,
            timings_s={"total": self._busy_s},
            warnings=self._warnings(),
            model_points=self._model_points,
            outliers=int(points.outlier.sum()),
            break_repairs=self._repairs,
            input_rows=self.fixes + self.merged + self.rejected,
            merged_rows=self.merged,
            shared_time_rows=self._shared_time,
            dropped_rows=self.rejected,
        )
        self._result = MatchResult(
            trace_id=self.trip_id,
            network={
                "id": self.net.network_id,
                "source": Path(self.net.source).name,
                "crs": self.net.crs,
            },
            segments=segments,
            points=points,
            breaks=[s.first for s in segments[1:]],
            matched_length_m=matched_length,
            distance_check=check,
            stats=stats,
            config=self.config,
        )
        self._tail = None
        self._round_cache = None
        return self._result

    def _warnings(self) -> tuple[str, ...]:
        out = []
        if self.rejected:
            out.append(f"{self.rejected} fix(es) were refused (see each push's rejected list)")
        for name, count in sorted(self._ignored.items()):
            out.append(
                f"{count} fix(es) carried {name}, which the trip's first fix did not: ignored "
                "(a trip's fields are those of its first fix)"
            )
        return tuple(out)

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` has been called."""
        return self._closed

    @property
    def settled_fixes(self) -> int:
        """Fixes settled so far."""
        return self._record.fixes

    @property
    def tail_fixes(self) -> int:
        """Fixes the matcher holds to work on: the unsettled ones and their context."""
        return len(self._tail) if self._tail is not None else 0

    @property
    def nbytes(self) -> int:
        """Bytes the trip holds (approximately): its tail and its settled record."""
        tail = self._tail.nbytes if self._tail is not None else 0
        return tail + self._record.nbytes + 4000


def _matched_edge(attrs: EdgeAttributes, i: int, edge: int, lo: float, hi: float) -> MatchedEdge:
    return MatchedEdge(
        edge=edge,
        u=int(attrs.u[i]),
        v=int(attrs.v[i]),
        key=int(attrs.key[i]),
        osm_way_ids=(int(attrs.way_id[i]),),
        length_m=float(attrs.length_m[i]),
        start_offset_m=lo,
        end_offset_m=hi,
        name=attrs.name[i],
        road_class=attrs.road_class[i],
        speed_limit_kph=float(attrs.speed_limit_kph[i]),
    )


def _readings(model: TailModel, lo: int, hi: int) -> FloatArray | None:
    """The odometer readings of fixes ``lo..hi-1`` of the tail (``None``: the trip has none)."""
    odometer = model.view.odometer_m
    return None if odometer is None else odometer[lo:hi]


def _slice_points(points: MatchedPoints, lo: int, hi: int) -> MatchedPoints:
    return MatchedPoints(
        **{f.name: getattr(points, f.name)[lo:hi].copy() for f in dataclasses.fields(points)}
    )


def _unmatched_points(model: TailModel, outlier: BoolArray, lo: int, hi: int) -> MatchedPoints:
    """The outcome of fixes ``lo..hi-1`` of the tail that settle unmatched."""
    n = hi - lo
    view = model.view
    nan = np.full(n, np.nan)
    none = np.full(n, -1, dtype=np.int64)
    return MatchedPoints(
        time_s=view.time_s[lo:hi].copy(),
        raw_lon=view.lon[lo:hi].copy(),
        raw_lat=view.lat[lo:hi].copy(),
        matched=np.zeros(n, dtype=bool),
        edge=none,
        u=none.copy(),
        v=none.copy(),
        key=none.copy(),
        offset_m=nan,
        distance_m=nan.copy(),
        lon=nan.copy(),
        lat=nan.copy(),
        confidence=np.zeros(n),
        segment=none.copy(),
        interpolated=np.zeros(n, dtype=bool),
        outlier=outlier[lo:hi].copy(),
    )
