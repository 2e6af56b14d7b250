"""
The tail of a live trip: the fixes not yet settled, and enough settled ones before them.

(Over 400 lines on purpose: the tail's store, the input stages run on it and its trimming share
one data layout.)

The offline stages judge a fix by its neighbours: its speed from the fixes on either side,
its observation from the fixes that follow (a stray is a fix that one of the next two comes back
from), its outlier verdict from the observations around it. So the tail keeps, before the first
unsettled fix, ``CONTEXT_OBSERVATIONS`` settled observations and the fix before them, and runs
the stages over all of it: :func:`~mapmatch.hmm.fixes.fixes_of` and
:func:`~mapmatch.hmm.observations.merge_fixes` as :func:`mapmatch.match` runs them, on a view of
the tail's fixes in the shape of a trace. Their outcome for a fix does not depend on where the
tail starts, only on its neighbours, so the tail is as good as the whole trace wherever it has
both:

- **Observations.** The tail starts where an observation starts, after the fix before it (the
  grouping starts a new observation after a trace's first fix, so that fix, the *predecessor*,
  stands in for the settled fixes before it). An observation's fixes are final once its next
  observation has started three fixes before the newest (the grouping looks two fixes ahead,
  and a trace's last fix is always one of its own); at :meth:`Tail.model` with ``closing``,
  the newest fix is the trip's last, as in a trace, and every observation is final.
- **Candidates** are searched once per observation, when it is first seen, and kept for as
  long as it is in the tail (keyed by its fixes and its place, so an observation that changes
  is searched again).
- **Sigma.** A trip without accuracies has its position error estimated as a trace's is
  (:func:`~mapmatch.hmm.fixes.estimated_sigma_m`), from the observations of the tail.
- **Long stops.** With a finite lag, an observation still open after ``split_after_s`` (a
  parked car reporting on) is cut where the newest fix is, as a trace's known pieces are cut
  (``segment_starts``), so that the tail stays bounded; with an unbounded lag, never.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final, cast

import numpy as np

from mapmatch.hmm.candidates import Candidates, find_candidates
from mapmatch.hmm.fixes import Fixes, estimated_sigma_m, fixes_of, observations_of, with_sigma
from mapmatch.hmm.observations import Observations, Travel, group_fixes

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig
    from mapmatch.online.fixes import LiveFix
    from mapmatch.trace import Trace
    from mapmatch.types import FloatArray, IntArray
    from roadnets import RoadNetwork

__all__ = [
    "CONTEXT_OBSERVATIONS",
    "LOOKAHEAD_OBSERVATIONS",
    "FixStore",
    "ObsKey",
    "Tail",
    "TailModel",
    "TraceView",
    "rows",
]

#: Settled observations kept before the first unsettled one: the outlier test
#: (:func:`~mapmatch.hmm.selection.find_displaced`) looks two observations either side, three
#: times over, so its verdict on an observation depends on the six around it at most.
CONTEXT_OBSERVATIONS: Final = 8

#: Final observations that must follow one before it settles. The outlier verdicts of the
#: newest final observations are still provisional (an observation at the end of the tail is
#: judged as a trace's last fix is), and an observation's best state depends on which of those
#: later ones are in use; a stopped car makes no new observations, so the lag alone would
#: settle observations whose look-ahead is missing.
LOOKAHEAD_OBSERVATIONS: Final = 8

#: An observation's identity across rounds: its trip fixes ``first..stop`` and its place.
ObsKey = tuple[int, int, float, float, float]

#: The columns a fix store holds: a fix's fields (:meth:`LiveFix.values`), then its place in
#: the network's metres and the running chord sum.
_COLUMNS: Final = (
    "time_s",
    "lon",
    "lat",
    "heading",
    "speed",
    "accuracy",
    "odometer",
    "x",
    "y",
    "chord_m",
)


@dataclass(frozen=True, slots=True)
class TraceView:
    """
    The tail's fixes as a :class:`~mapmatch.trace.Trace` offers them to the stages.

    ``fixes_of`` and ``assemble`` read a trace's arrays and nothing else; this holds those
    arrays for the fixes of the tail (optional columns ``None`` when the trip has none).
    """

    trace_id: str
    time_s: FloatArray
    lon: FloatArray
    lat: FloatArray
    heading_deg: FloatArray | None
    speed_mps: FloatArray | None
    accuracy_m: FloatArray | None
    odometer_m: FloatArray | None
    segment_starts: IntArray
    has_time: bool = True

    def as_trace(self) -> Trace:
        """The view typed as the trace a stage asks for (the stages read only these arrays)."""
        return cast("Trace", self)

    def __len__(self) -> int:
        return len(self.time_s)


class FixStore:
    """
    A trip's fixes in columns, appended one at a time and dropped from the front.

    ``base`` is the trip number of the first fix held. ``columns`` names the optional
    fields the trip has (its first fix set them); the others are not kept. ``chord_m`` is
    the running sum of the straight steps from the trip's first fix.
    """

    def __init__(self, columns: frozenset[str]) -> None:
        self.columns = columns
        self.base = 0
        self._n = 0
        self._data = {name: np.empty(64) for name in _COLUMNS}

    def __len__(self) -> int:
        return self._n

    def append(self, fix: LiveFix, x: float, y: float) -> None:
        """Add a fix at the end (``x``/``y`` its position in the network's metres)."""
        if self._n == len(self._data["x"]):
            for name, values in self._data.items():
                grown = np.empty(2 * len(values))
                grown[: self._n] = values[: self._n]
                self._data[name] = grown
        chord = 0.0
        if self._n:
            last = self._n - 1
            step = np.hypot(x - self._data["x"][last], y - self._data["y"][last])
            chord = float(self._data["chord_m"][last] + step)
        for name, value in zip(_COLUMNS, (*fix.values(), x, y, chord), strict=True):
            self._data[name][self._n] = value
        self._n += 1

    def drop_front(self, count: int) -> None:
        """Forget the first ``count`` fixes (the newest is always kept: steps run from it)."""
        count = min(max(count, 0), self._n - 1)
        if not count:
            return
        for name, values in self._data.items():
            kept = np.empty(max(64, 2 * (self._n - count)))
            kept[: self._n - count] = values[count : self._n]
            self._data[name] = kept
        self._n -= count
        self.base += count

    def column(self, name: str) -> FloatArray:
        """The held values of one column (a view: valid until the next append or drop)."""
        return self._data[name][: self._n]

    def view(self, trip_id: str, segment_starts: IntArray) -> TraceView:
        """The held fixes as the stages read a trace."""

        def optional(field: str) -> FloatArray | None:
            return self.column(field) if field in self.columns else None

        return TraceView(
            trace_id=trip_id,
            time_s=self.column("time_s"),
            lon=self.column("lon"),
            lat=self.column("lat"),
            heading_deg=optional("heading"),
            speed_mps=optional("speed"),
            accuracy_m=optional("accuracy"),
            odometer_m=optional("odometer"),
            segment_starts=segment_starts,
        )

    @property
    def nbytes(self) -> int:
        """Bytes held by the columns."""
        return sum(v.nbytes for v in self._data.values())


@dataclass(frozen=True, slots=True)
class TailModel:
    """
    One round of the stages over the tail.

    ``fixes`` and ``obs`` cover every fix held (``obs[0]`` is the predecessor alone when
    ``first_real`` is 1); ``obs[:final]`` have their final fixes; ``keys`` identify every
    observation; ``sigma_m`` is the estimated position error in use (NaN: none).
    """

    view: TraceView
    fixes: Fixes
    obs: Observations
    final: int
    first_real: int
    keys: list[ObsKey]
    base: int
    sigma_m: float

    def trip_fix(self, index: int) -> int:
        """Trip number of the tail's fix ``index``."""
        return self.base + index


def rows(obs: Observations, lo: int, hi: int) -> Observations:
    """
    Observations ``lo..hi-1``: their per-observation arrays cut, the per-fix ones kept.

    Examples
    --------
    >>> from mapmatch.config import MatchConfig
    >>> from mapmatch.hmm.observations import merge_fixes
    >>> x = np.array([0.0, 1.0, 30.0, 60.0])
    >>> obs = merge_fixes(x, np.zeros(4), np.arange(4.0), np.full(4, 5.0), np.full(4, 50.0),
    ...                   np.full(4, np.nan), None, None, MatchConfig())
    >>> len(obs), len(rows(obs, 1, 3)), rows(obs, 1, 3).x.tolist()
    (4, 2, [1.0, 30.0])
    """

    def cut(values: FloatArray | IntArray | None) -> FloatArray | IntArray | None:
        return None if values is None else values[lo:hi]

    travel = None
    if obs.travel is not None:
        t = obs.travel
        travel = Travel(
            cast("FloatArray | None", cut(t.odometer_m)),
            cast("FloatArray | None", cut(t.speed_m)),
            cast("FloatArray | None", cut(t.slack_m)),
            cast("IntArray | None", cut(t.unknown_lo)),
            cast("IntArray | None", cut(t.unknown_hi)),
        )
    return dataclasses.replace(
        obs,
        first=obs.first[lo:hi],
        stop=obs.stop[lo:hi],
        rep=obs.rep[lo:hi],
        x=obs.x[lo:hi],
        y=obs.y[lo:hi],
        time_s=obs.time_s[lo:hi],
        sigma_m=obs.sigma_m[lo:hi],
        radius_m=obs.radius_m[lo:hi],
        speed_mps=obs.speed_mps[lo:hi],
        heading_deg=None if obs.heading_deg is None else obs.heading_deg[lo:hi],
        travel=travel,
    )


def _final_count(obs: Observations, n: int, closing: bool) -> int:
    """
    How many observations have their final fixes, of a tail of ``n`` fixes.

    An observation is final once the next one has started three fixes before the newest
    (see the module docstring); all are when the trip closes.
    """
    if closing:
        return len(obs)
    return int(np.searchsorted(obs.first[1:], n - 4, side="right"))


_CandRows = tuple["IntArray", "FloatArray", "FloatArray", "FloatArray", "FloatArray", "FloatArray"]


class Tail:
    """
    The fixes of a live trip not yet settled, with their context, and the stages over them.

    Parameters
    ----------
    net
        The road network.
    config
        Matcher parameters.
    trip_id
        The trip's name.
    columns
        The optional fields the trip has.
    split_after_s
        Cut an observation open this long (see the module docstring); ``None``: never.
    """

    def __init__(
        self,
        net: RoadNetwork,
        config: MatchConfig,
        trip_id: str,
        columns: frozenset[str],
        split_after_s: float | None,
    ) -> None:
        self.net, self.config, self.trip_id = net, config, trip_id
        self.store = FixStore(columns)
        self.has_pred = False
        self.split_after_s = split_after_s
        self._splits: list[int] = []  # trip numbers of fixes that start a cut piece
        self._cands: dict[ObsKey, _CandRows] = {}
        self.queries = 0  # candidate searches made (observations searched)

    def __len__(self) -> int:
        return len(self.store)

    def append(self, fix: LiveFix, x: float, y: float) -> None:
        """Add the trip's next fix."""
        self.store.append(fix, x, y)

    def newly_final(self, open_from: int, sigma_m: float) -> int:
        """
        How many observations from trip fix ``open_from`` on have become final since.

        ``open_from`` is the first fix of the first observation that was not final at the
        last :meth:`model`, ``sigma_m`` the estimated sigma then in use (NaN: none). A cheap
        count before a whole round: only the grouping, over the fixes from ``open_from`` on
        (each fix's sigma its accuracy or ``sigma_m``, as the model inputs have it). A stop
        open longer than ``split_after_s`` is cut here, and the count is then the tail's
        length, so that a round groups the fixes anew.
        """
        store = self.store
        n, lo = len(store), open_from - store.base
        time_s = store.column("time_s")
        if lo <= 0:  # nothing to look back on: every new fix may close an observation
            return max(n - 4, 0)
        if n - lo < 4:
            return 0
        part = slice(lo - 1, n)  # the fix before stands in for what is before, as in a round
        sigma = np.full(n - lo + 1, self.config.sigma_m)
        if "accuracy" in store.columns:
            sigma = np.fmax(sigma, store.column("accuracy")[part])
        if not np.isnan(sigma_m):
            sigma = np.fmax(sigma, sigma_m)
        starts = np.array([s - store.base - lo + 1 for s in self._splits], np.int64)
        group, _ = group_fixes(
            store.column("x")[part],
            store.column("y")[part],
            sigma,
            self.config,
            starts[(starts > 0) & (starts < n - lo + 1)],
            time_s[part],
        )
        # group 1 is the observation that was open; each later group that starts at least
        # three fixes before the newest closes the one before it
        begins = np.flatnonzero(np.diff(group) != 0) + 1 + (lo - 1)
        # the observation still open is the one the fix before the newest is in (the newest
        # is always one of its own, as a trace's last fix)
        holding = begins[begins <= n - 2]
        if len(holding) and self._split_due(int(holding[-1])):
            self._splits.append(store.base + n - 1)
            return n  # a cut: the round that follows groups the fixes anew
        return int(np.count_nonzero(begins[1:] <= n - 4))

    def _split_due(self, opened: int) -> bool:
        """Whether the observation open since tail fix ``opened`` is to be cut at the newest."""
        if self.split_after_s is None:
            return False
        store = self.store
        time_s = store.column("time_s")
        since = opened
        if self._splits and self._splits[-1] - store.base > since:
            since = self._splits[-1] - store.base  # cut already: count from that cut
        return float(time_s[-1] - time_s[since]) > self.split_after_s

    def model(self, *, closing: bool = False) -> TailModel:
        """
        The stages over the tail: the fixes' model inputs and their observations.

        With ``closing`` the newest fix is the trip's last, and every observation is final.
        """
        store = self.store
        n = len(store)
        starts = np.array([s - store.base for s in self._splits if s > store.base], np.int64)
        view = store.view(self.trip_id, starts[starts < n])
        x, y = store.column("x"), store.column("y")
        fixes = fixes_of(view.as_trace(), x, y, self.config)
        obs = observations_of(fixes, self.config)
        first_real = 1 if self.has_pred else 0
        final = _final_count(obs, n, closing)
        sigma = float("nan")
        keys = live = self._keys(obs)
        if view.accuracy_m is None and self.config.estimate_sigma and final > first_real:
            own = np.arange(first_real, final)
            sigma = estimated_sigma_m(rows(obs, first_real, final), self.candidates(obs, live, own))
            if sigma > 1.25 * self.config.sigma_m:  # noisier than assumed: look again, wider
                fixes = with_sigma(fixes, sigma, self.config)
                obs = observations_of(fixes, self.config)
                final = _final_count(obs, n, closing)
                keys = self._keys(obs)
            else:
                sigma = float("nan")
        if not closing and n >= 2 and self._split_due(int(obs.first[obs.of_fix[n - 2]])):
            self._splits.append(store.base + n - 1)
        self._forget(set(live) | set(keys))
        return TailModel(view, fixes, obs, final, first_real, keys, store.base, sigma)

    def _keys(self, obs: Observations) -> list[ObsKey]:
        base = self.store.base
        return [
            (base + int(f), base + int(s), float(x), float(y), float(r))
            for f, s, x, y, r in zip(
                obs.first.tolist(),
                obs.stop.tolist(),
                obs.x.tolist(),
                obs.y.tolist(),
                obs.radius_m.tolist(),
                strict=True,
            )
        ]

    def candidates(self, obs: Observations, keys: list[ObsKey], index: IntArray) -> Candidates:
        """Candidates of observations ``index`` (in that order), searched once per observation."""
        missing = [int(i) for i in index if keys[int(i)] not in self._cands]
        if missing:
            rows = np.array(missing, dtype=np.int64)
            found = find_candidates(
                self.net, obs.x[rows], obs.y[rows], obs.radius_m[rows], self.config
            )
            self.queries += len(rows)
            for k, i in enumerate(missing):
                lo, hi = int(found.ptr[k]), int(found.ptr[k + 1])
                self._cands[keys[i]] = (
                    found.edge[lo:hi],
                    found.offset_m[lo:hi],
                    found.distance_m[lo:hi],
                    found.x[lo:hi],
                    found.y[lo:hi],
                    found.bearing_deg[lo:hi],
                )
        parts = [self._cands[keys[int(i)]] for i in index]
        counts = np.array([len(p[0]) for p in parts], dtype=np.int64)
        ptr = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
        if not parts:
            empty = np.empty(0)
            return Candidates(ptr, np.empty(0, np.int64), *(empty,) * 5)
        columns = [np.concatenate([p[c] for p in parts]) for c in range(6)]
        return Candidates(
            ptr,
            columns[0].astype(np.int64),
            columns[1],
            columns[2],
            columns[3],
            columns[4],
            columns[5],
        )

    def _forget(self, live: set[ObsKey]) -> None:
        """Drop the candidates of observations no longer in the tail (now and then)."""
        if len(self._cands) > 2 * len(live) + 16:
            self._cands = {k: v for k, v in self._cands.items() if k in live}

    def trim(self, model: TailModel, first_kept_obs: int) -> None:
        """
        Forget the fixes before observation ``first_kept_obs``, keeping one before it.

        That fix becomes the tail's predecessor (see the module docstring).
        """
        start = int(model.obs.first[first_kept_obs])
        if start <= 1:  # at most the predecessor before it already
            return
        self.store.drop_front(start - 1)
        self.has_pred = True
        self._splits = [s for s in self._splits if s > self.store.base]

    @property
    def nbytes(self) -> int:
        """Bytes held: the fixes and the candidates kept."""
        cands = sum(sum(a.nbytes for a in rows) for rows in self._cands.values())
        return self.store.nbytes + cands + 200 * len(self._cands)
