"""
Live trips of the HTTP service: one :class:`mapmatch.OnlineMatcher` per vehicle trip.

``POST /v1/trips`` opens a trip, ``POST /v1/trips/{id}/fixes`` feeds it one fix or a batch
and answers what settled (with the provisional position and the running distance check),
``GET /v1/trips/{id}`` tells where it stands, ``DELETE /v1/trips/{id}`` closes it and answers
its match as ``POST /v1/match`` does (:mod:`api.routes.trips`).

Where a trip lives
------------------
A trip's state (its unsettled fixes, its window, what settled so far) lives in the memory of the
worker process that opened it; nothing is shared between workers or written anywhere. So:

- **Routing.** Every request of a trip must reach the worker that opened it. ``mapmatch serve
  --workers N`` runs N processes behind one socket, and the kernel hands each *connection* to
  any of them: a client that keeps one connection alive per trip stays with its worker, one
  that reconnects may land elsewhere and get 404 ``unknown_trip``. To scale out, run one worker
  per port (or per host) and route by trip id (or by vehicle id, with trip ids that start with
  it) at the load balancer: a consistent hash (nginx ``hash $trip consistent``, HAProxy
  ``balance uri``/``hdr``, Envoy's ring hash) keeps a trip on one worker while the workers
  stay up. A state store (Redis and the like) would let any worker serve any trip, at the cost
  of reading and writing the trip's state at every request (tens of kilobytes at 1 Hz); it is
  not built in.
- **Restarts.** A worker that stops loses its open trips: what had not been fetched is gone
  (the settled path and points already answered to the client are the client's; the
  unsettled tail, the provisional position and the running check are lost). The client sees
  404 ``unknown_trip`` and opens a new trip; a client that keeps the fixes it sent can replay
  them into the new one, or send them to ``POST /v1/match`` as one trace.
- **Expiry and caps.** A trip without a request for ``MAPMATCH_TRIP_IDLE_S`` (600 s) expires and
  is forgotten. A worker holds at most ``MAPMATCH_MAX_TRIPS`` (10 000) open trips; one more is
  refused with 503 ``too_many_trips`` (after expired trips are swept). A trip holding more than
  ``MAPMATCH_TRIP_MAX_BYTES`` (8 MB: about 20 hours of settled fixes at 1 Hz) takes no more
  fixes (413 ``trip_too_large``): close it and open the next. The lag a trip may ask for is at
  most ``MAPMATCH_TRIP_MAX_LAG_S`` (an unbounded lag would hold the whole trip unsettled).

Pushing a trip's fixes runs in the service's match threads, under the same time budget and
pool limits as ``POST /v1/match``; one trip's requests run one at a time (a lock per trip).
"""

from __future__ import annotations

import secrets
import threading
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Final

from prometheus_client import Counter

from api.errors import RequestFieldError, TripsFullError, TripTooLargeError, UnknownTripError
from mapmatch.online import OnlineMatcher

if TYPE_CHECKING:
    from collections.abc import Callable

    from api.metrics import ServiceMetrics
    from api.settings import Settings
    from mapmatch import MatchConfig
    from roadnets import RoadNetwork

__all__ = ["Trip", "TripMetrics", "TripRegistry"]

_SWEEP_EVERY_S: Final = 1.0


class TripMetrics:
    """The live trips' counters, in the app's registry (summed over workers like the rest)."""

    def __init__(self, metrics: ServiceMetrics) -> None:
        self.trips = Counter(
            "mapmatch_live_trips",
            "Live trips by event: opened, closed (deleted by the client), expired (idle).",
            ("event",),
            registry=metrics.registry,
        )
        self.fixes = Counter(
            "mapmatch_live_fixes",
            "Fixes sent to live trips, by outcome: accepted, merged (a repeat), rejected.",
            ("outcome",),
            registry=metrics.registry,
        )
        self.settled = Counter(
            "mapmatch_live_fixes_settled",
            "Fixes of live trips that settled (their place final) before the trip closed.",
            registry=metrics.registry,
        )


@dataclass(slots=True)
class Trip:
    """One open live trip: its matcher, the lock its requests take, and when it was last used."""

    trip_id: str
    network: str
    matcher: OnlineMatcher
    opened_at: float  # epoch seconds
    last_seen: float  # time.monotonic()
    lock: threading.Lock = field(default_factory=threading.Lock)

    def idle_s(self, now: float) -> float:
        """Seconds since the trip's last request."""
        return now - self.last_seen


class TripRegistry:
    """
    The open live trips of one worker (see the module docstring).

    Parameters
    ----------
    settings
        Caps: ``max_trips``, ``trip_idle_s``, ``trip_max_bytes``, ``trip_max_lag_s``.
    metrics
        The app's metrics, for the trips' counters.
    clock
        ``time.monotonic`` (a test may give another).
    """

    def __init__(
        self,
        settings: Settings,
        metrics: ServiceMetrics,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.max_trips = settings.max_trips
        self.idle_s = settings.trip_idle_s
        self.max_bytes = settings.trip_max_bytes
        self.max_lag_s = settings.trip_max_lag_s
        self.metrics = TripMetrics(metrics)
        self._clock = clock
        self._trips: dict[str, Trip] = {}
        self._lock = threading.Lock()
        self._swept = -float("inf")

    def __len__(self) -> int:
        return len(self._trips)

    def open(
        self,
        trip_id: str | None,
        net: RoadNetwork,
        config: MatchConfig,
        lag_s: float,
        max_lag_s: float | None = None,
    ) -> Trip:
        """
        Open a trip (a fresh id unless one is given) with these lags.

        Raises
        ------
        TripsFullError
            ``max_trips`` trips are open, expired ones swept.
        RequestFieldError
            A trip of the given id is open already.
        """
        now = self._clock()
        self.sweep(force=True)
        with self._lock:
            if len(self._trips) >= self.max_trips:
                msg = (
                    f"this worker holds {len(self._trips):,} open live trips, its limit "
                    "(MAPMATCH_MAX_TRIPS); close finished trips (DELETE /v1/trips/{id}) or "
                    "retry shortly"
                )
                raise TripsFullError(msg)
            name = trip_id or f"trip-{secrets.token_hex(8)}"
            if name in self._trips:
                msg = (
                    f"a live trip {name!r} is open already; give another trip_id, or none "
                    "for a fresh one"
                )
                raise RequestFieldError(msg, field="trip_id")
            if max_lag_s is not None:
                max_lag_s = max(max_lag_s, lag_s)
            matcher = OnlineMatcher(net, config, lag=lag_s, max_lag=max_lag_s, trip_id=name)
            trip = Trip(name, net.network_id, matcher, time.time(), now)
            self._trips[name] = trip
        self.metrics.trips.labels(event="opened").inc()
        return trip

    def get(self, trip_id: str) -> Trip:
        """
        The open trip of that id, marked as used now.

        Raises
        ------
        UnknownTripError
            None is open in this worker.
        """
        self.sweep()
        with self._lock:
            trip = self._trips.get(trip_id)
            if trip is None:
                msg = (
                    f"no live trip {trip_id!r} is open here: it was never opened, was closed, "
                    f"expired after {self.idle_s:g} s without a request, or is open on another "
                    "worker (route a trip's requests to one worker; see the docs)"
                )
                raise UnknownTripError(msg, field="trip_id")
            trip.last_seen = self._clock()
            return trip

    def remove(self, trip_id: str) -> Trip:
        """Take the trip of that id out of the registry (see :meth:`get` for the errors)."""
        trip = self.get(trip_id)
        with self._lock:
            self._trips.pop(trip_id, None)
        return trip

    def check_size(self, trip: Trip) -> None:
        """
        Refuse more fixes for a trip that holds ``max_bytes`` already.

        Raises
        ------
        TripTooLargeError
            It does.
        """
        held = trip.matcher.nbytes
        if held > self.max_bytes:
            msg = (
                f"live trip {trip.trip_id!r} holds {held:,} bytes, more than this service "
                f"keeps for one trip ({self.max_bytes:,}, MAPMATCH_TRIP_MAX_BYTES); close it "
                "(DELETE) and open the next"
            )
            raise TripTooLargeError(msg, field="trip_id")

    def sweep(self, *, force: bool = False) -> int:
        """Forget the trips idle for ``idle_s`` or more (at most once a second unless forced)."""
        now = self._clock()
        if not force and now - self._swept < _SWEEP_EVERY_S:
            return 0
        self._swept = now
        with self._lock:
            stale = [k for k, t in self._trips.items() if t.idle_s(now) >= self.idle_s]
            for key in stale:
                del self._trips[key]
        if stale:
            self.metrics.trips.labels(event="expired").inc(len(stale))
        return len(stale)
