"""Synthetic trips with ground truth on a real road network.

A trip is a random drive along the directed graph (one-ways and turn restrictions obeyed, no
U-turns but at dead ends, straight on preferred), a speed profile that respects the speed
limits, slows for turns and stops at some junctions, and fused-looking observations: positions
with Gaussian noise (optionally correlated in time), occasional outliers and outages, heading
and speed with their own noise, and an odometer with a small scale error.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from mapmatch.errors import ConfigError
from mapmatch.evaluation.scoring import count_turnbacks
from mapmatch.trace import Trace

if TYPE_CHECKING:
    import os
    from collections.abc import Callable, Iterable

    import pandas as pd

    from roadnets import RoadNetwork

__all__ = [
    "INPUT_CLASSES",
    "TRUE_COLUMNS",
    "SimulatedTrip",
    "SimulationConfig",
    "TruthEdge",
    "TruthEvent",
    "simulate_trip",
    "simulate_trips",
    "strip_to_class",
    "with_columns",
    "write_trips",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

_DENSE_HZ = 10.0
_EPOCH_S = 1.7e9  # simulated trips start at this epoch second


#: The trace columns each input class keeps besides time and position; each class adds to the
#: one before it: plain GPS, + the receiver's accuracy, + heading and speed, + the odometer.
INPUT_CLASSES: dict[str, tuple[str, ...]] = {
    "positions": (),
    "accuracy": ("accuracy",),
    "heading_speed": ("accuracy", "heading", "speed"),
    "odometer": ("accuracy", "heading", "speed", "odometer"),
}
#: The optional trace columns a simulated trip carries.
TRUE_COLUMNS = ("heading", "speed", "accuracy", "odometer")


@dataclass(frozen=True, slots=True, kw_only=True)
class SimulationConfig:
    """
    How trips are driven and observed.

    Every realistic-noise option below is off by default; :meth:`realistic` switches them on
    with the values of a phone or a low-cost telematics box in a city, :meth:`noise_free`
    gives the exact truth.

    Sampling and route
        ``interval_s`` sampling interval (0.1 gives the 10 Hz truth); ``route_length_m``
        target length of each trip; ``route`` how trips are chosen: ``fastest`` (the fastest
        route between a random start and a random end about ``route_length_m`` away, as real
        trips are; no U-turn but at a dead end) or ``random_walk`` (meandering: straight on
        preferred at every junction).
    Position noise
        ``noise_m`` stationary 1-sigma position error per axis. White by default; correlated
        in time as an AR(1) process when ``noise_correlation_per_s`` (correlation of the error
        one second apart, e.g. 0.95 for raw GNSS, whose error wanders slowly) or, the same
        thing as a time constant, ``noise_correlation_s`` (tau: correlation ``exp(-dt / tau)``;
        a few seconds looks like a Kalman filter's output) is set; give at most one. The
        stationary std stays ``noise_m`` whatever the correlation and the gaps between fixes.
        ``outlier_rate`` share of fixes displaced by ``outlier_m`` in a random direction.
    Urban canyons
        ``canyon_per_km`` stretches per km of route (0: none) where multipath pulls every fix
        ``canyon_bias_m`` to one side of the road (perpendicular to the driving direction,
        the side drawn per stretch, constant over it), for a duration drawn uniformly from
        ``canyon_s`` seconds. The reported ``accuracy`` does not see the bias.
    Stops
        ``junction_stop_share`` share of the route's real junctions (nodes joining three or
        more neighbours) where the car stops: it brakes at ``decel_mps2``, stands for a
        duration drawn uniformly from ``junction_stop_s`` seconds while the receiver keeps
        reporting noisy fixes (true speed 0, position fixed), and pulls away at
        ``accel_mps2``. ``stop_probability`` / ``stop_s``: the older, brief stops at any node
        between two edges (junction or not), 2 s up to ``stop_s``.
    Heading and speed
        ``heading_noise_deg`` / ``speed_noise_mps`` 1-sigma noise; ``heading_noise_slow_deg``
        adds ``heading_noise_slow_deg * exp(-v / 1 m/s)`` to the heading's 1-sigma, so a slow
        or standing car's heading is nearly random (3 + 87 exp(-v) degrees: a GNSS course
        over ground degrades below walking speed).
    Outages
        ``outage_per_km`` outages per km of route (0: none) of a duration drawn uniformly from
        ``outage_range_s`` seconds without fixes (tunnels, garages); the older
        ``outage_rate`` is the chance per minute of an outage of ``outage_s``.
    Odometer
        The odometer reads ``1 + odometer_bias + U(-odometer_scale_error,
        +odometer_scale_error)`` times the distance driven (``odometer_bias`` 0.02: a meter
        2 % high; the random part is drawn per trip).
    Columns
        ``input_class`` which optional columns the trace keeps (:data:`INPUT_CLASSES`:
        ``positions``, ``accuracy``, ``heading_speed``, ``odometer`` = all); the truth is the
        same whatever it strips.
    """

    interval_s: float = 1.0
    noise_m: float = 5.0
    noise_correlation_s: float = 0.0
    noise_correlation_per_s: float = 0.0
    outlier_rate: float = 0.0
    outlier_m: float = 40.0
    outage_rate: float = 0.0
    outage_s: float = 30.0
    outage_per_km: float = 0.0
    outage_range_s: tuple[float, float] = (20.0, 60.0)
    canyon_per_km: float = 0.0
    canyon_s: tuple[float, float] = (10.0, 30.0)
    canyon_bias_m: float = 20.0
    heading_noise_deg: float = 5.0
    heading_noise_slow_deg: float = 0.0
    speed_noise_mps: float = 0.3
    odometer_scale_error: float = 0.005
    odometer_bias: float = 0.0
    route_length_m: float = 3000.0
    stop_probability: float = 0.15
    stop_s: float = 20.0
    junction_stop_share: float = 0.0
    junction_stop_s: tuple[float, float] = (5.0, 40.0)
    accel_mps2: float = 1.5
    decel_mps2: float = 2.5
    lateral_accel_mps2: float = 2.0
    route: str = "fastest"
    input_class: str = "odometer"

    def __post_init__(self) -> None:
        for name in ("interval_s", "route_length_m", "accel_mps2", "decel_mps2"):
            if not getattr(self, name) > 0:
                msg = f"{name} must be > 0 (got {getattr(self, name)!r})"
                raise ConfigError(msg)
        for name in ("outlier_rate", "stop_probability", "junction_stop_share"):
            if not 0 <= getattr(self, name) <= 1:
                msg = f"{name} must be within 0..1 (got {getattr(self, name)!r})"
                raise ConfigError(msg)
        for name in (
            "noise_m",
            "outage_rate",
            "noise_correlation_s",
            "outage_per_km",
            "canyon_per_km",
            "canyon_bias_m",
            "heading_noise_deg",
            "heading_noise_slow_deg",
            "speed_noise_mps",
            "odometer_scale_error",
        ):
            if not getattr(self, name) >= 0:
                msg = f"{name} must be >= 0 (got {getattr(self, name)!r})"
                raise ConfigError(msg)
        for name in ("outage_range_s", "canyon_s", "junction_stop_s"):
            lo, hi = getattr(self, name)
            if not 0 < lo <= hi:
                msg = f"{name} must be a range (low, high) with 0 < low <= high (got {(lo, hi)!r})"
                raise ConfigError(msg)
        if not 0 <= self.noise_correlation_per_s < 1:
            msg = (
                "noise_correlation_per_s must be within 0..1 (1 excluded: the error would never "
                f"change; got {self.noise_correlation_per_s!r})"
            )
            raise ConfigError(msg)
        if self.noise_correlation_per_s > 0 and self.noise_correlation_s > 0:
            msg = (
                "give noise_correlation_per_s or noise_correlation_s, not both (got "
                f"{self.noise_correlation_per_s!r} and {self.noise_correlation_s!r}); "
                "correlation per second rho = exp(-1 / tau)"
            )
            raise ConfigError(msg)
        if not self.odometer_bias > -1:
            msg = f"odometer_bias must be > -1 (got {self.odometer_bias!r}); 0.02 is 2 % high"
            raise ConfigError(msg)
        if self.route not in ("fastest", "random_walk"):
            msg = f"route must be 'fastest' or 'random_walk' (got {self.route!r})"
            raise ConfigError(msg)
        if self.input_class not in INPUT_CLASSES:
            msg = f"input_class must be one of {sorted(INPUT_CLASSES)} (got {self.input_class!r})"
            raise ConfigError(msg)

    @property
    def correlation_time_s(self) -> float:
        """Time constant tau of the position error's AR(1) process (0: white noise)."""
        if self.noise_correlation_per_s > 0:
            return -1.0 / math.log(self.noise_correlation_per_s)
        return self.noise_correlation_s

    def replace(self, **changes: Any) -> SimulationConfig:
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)

    @classmethod
    def noise_free(cls, **changes: Any) -> SimulationConfig:
        """
        Exact observations; ``changes`` set other fields (``interval_s`` ...).

        No position, heading or speed noise, no outliers or outages, an exact odometer, every
        column. The ``accuracy`` column then reads 1 m (the smallest it reports). Stops stay as
        configured: a stop is driving, not noise.

        Examples
        --------
        >>> cfg = SimulationConfig.noise_free(interval_s=15.0)
        >>> cfg.noise_m, cfg.heading_noise_deg, cfg.odometer_scale_error, cfg.interval_s
        (0.0, 0.0, 0.0, 15.0)
        """
        exact: dict[str, Any] = {
            "noise_m": 0.0,
            "outlier_rate": 0.0,
            "outage_rate": 0.0,
            "outage_per_km": 0.0,
            "canyon_per_km": 0.0,
            "heading_noise_deg": 0.0,
            "heading_noise_slow_deg": 0.0,
            "speed_noise_mps": 0.0,
            "odometer_scale_error": 0.0,
            "odometer_bias": 0.0,
        }
        return cls(**{**exact, **changes})

    @classmethod
    def realistic(cls, **changes: Any) -> SimulationConfig:
        """
        Raw-GNSS-like city observations; ``changes`` set other fields (``interval_s`` ...).

        AR(1) position error with correlation 0.95 per second and 6 m stationary std per
        axis; 2 % outliers of 40 m; urban canyons 0.5 per km of 10-30 s pulling the fixes
        20 m to one side; stops at a third of the junctions of 5-40 s (no other stops);
        heading noise 3 + 87 exp(-v) degrees, speed noise 0.3 m/s; outages 0.3 per km of
        20-60 s; the odometer reads exactly 2 % high.

        Examples
        --------
        >>> cfg = SimulationConfig.realistic(interval_s=15.0)
        >>> cfg.noise_correlation_per_s, cfg.odometer_bias, cfg.interval_s
        (0.95, 0.02, 15.0)
        """
        rough: dict[str, Any] = {
            "noise_m": 6.0,
            "noise_correlation_per_s": 0.95,
            "outlier_rate": 0.02,
            "canyon_per_km": 0.5,
            "canyon_s": (10.0, 30.0),
            "canyon_bias_m": 20.0,
            "stop_probability": 0.0,
            "junction_stop_share": 1.0 / 3.0,
            "junction_stop_s": (5.0, 40.0),
            "heading_noise_deg": 3.0,
            "heading_noise_slow_deg": 87.0,
            "speed_noise_mps": 0.3,
            "outage_per_km": 0.3,
            "outage_range_s": (20.0, 60.0),
            "odometer_bias": 0.02,
            "odometer_scale_error": 0.0,
        }
        return cls(**{**rough, **changes})


def with_columns(trace: Trace, columns: Iterable[str]) -> Trace:
    """
    A copy of ``trace`` that keeps only the named optional columns.

    ``columns`` names any of ``heading``, ``speed``, ``accuracy``, ``odometer``; the rest are
    dropped (a column the trace does not have stays absent). Time, position and id are kept.

    Raises
    ------
    ConfigError
        An unknown column name.
    """
    keep = set(columns)
    unknown = sorted(keep - set(TRUE_COLUMNS))
    if unknown:
        msg = f"unknown column(s) {unknown}; a trace's optional columns are {list(TRUE_COLUMNS)}"
        raise ConfigError(msg)
    return Trace(
        time=trace.time_s,
        lon=trace.lon,
        lat=trace.lat,
        heading=trace.heading_deg if "heading" in keep else None,
        speed=trace.speed_mps if "speed" in keep else None,
        accuracy=trace.accuracy_m if "accuracy" in keep else None,
        odometer=trace.odometer_m if "odometer" in keep else None,
        trace_id=trace.trace_id,
    )


def strip_to_class(trace: Trace, input_class: str) -> Trace:
    """
    ``trace`` with the columns of one input class of :data:`INPUT_CLASSES` only.

    Raises
    ------
    ConfigError
        An unknown input class.

    Examples
    --------
    >>> tr = Trace(time=[0, 1], lon=[7.42, 7.43], lat=[43.73] * 2, speed=[5, 6], odometer=[0, 6])
    >>> plain = strip_to_class(tr, "positions")
    >>> plain.speed_mps is None, plain.odometer_m is None
    (True, True)
    """
    if input_class not in INPUT_CLASSES:
        msg = f"input class must be one of {sorted(INPUT_CLASSES)} (got {input_class!r})"
        raise ConfigError(msg)
    return with_columns(trace, INPUT_CLASSES[input_class])


@dataclass(frozen=True, slots=True)
class TruthEvent:
    """
    A stretch of a trip the truth records: a stop, an outage or an urban canyon.

    ``start_s``/``end_s`` epoch seconds (as the trace's times); ``first_fix``/``last_fix``
    the trace indices inside it (a stop's standing fixes, a canyon's biased ones; -1 when no
    fix fell inside), for an outage the last fix before and the first after it (-1 at the
    trace's ends); ``distance_m`` where along the route it began; ``side`` a canyon's side
    (+1 right, -1 left of the driving direction) and ``bias_m`` its lateral pull.
    """

    kind: str
    start_s: float
    end_s: float
    first_fix: int
    last_fix: int
    distance_m: float
    side: int = 0
    bias_m: float = 0.0

    @property
    def duration_s(self) -> float:
        """Seconds from start to end."""
        return self.end_s - self.start_s

    def to_dict(self) -> dict[str, Any]:
        """As ``truth.jsonl`` writes it."""
        out: dict[str, Any] = {
            "time": [round(self.start_s, 3), round(self.end_s, 3)],
            "fixes": [self.first_fix, self.last_fix],
            "distance_m": round(self.distance_m, 3),
        }
        if self.kind == "canyon":
            out["side"] = "right" if self.side > 0 else "left"
            out["bias_m"] = self.bias_m
        return out


@dataclass(frozen=True, slots=True)
class TruthEdge:
    """One directed edge of the true route and the stretch of it driven (metres)."""

    edge: int
    u: int
    v: int
    key: int
    osm_way_id: int
    length_m: float
    start_offset_m: float
    end_offset_m: float

    def to_dict(self) -> dict[str, Any]:
        """As the output schema writes edges."""
        return {
            "u": self.u,
            "v": self.v,
            "key": self.key,
            "osm_way_ids": [self.osm_way_id],
            "length_m": round(self.length_m, 3),
            "start_offset_m": round(self.start_offset_m, 3),
            "end_offset_m": round(self.end_offset_m, 3),
        }


@dataclass(frozen=True, slots=True)
class SimulatedTrip:
    """
    A simulated trip: the observed trace and the truth behind it.

    ``true_edge``/``true_offset_m`` give the true directed edge and offset of every fix of
    ``trace`` (``true_uvk`` the edge as OSM ``u, v, key``); ``dense_*`` the true trajectory at
    10 Hz (time, lon, lat, heading, speed and cumulative distance), for the fusion front-end;
    ``edges`` the driven route from the first fix to the last and ``length_m`` its length.
    ``stops``, ``outages`` and ``canyons`` list those stretches of the trip;
    ``uturns`` and ``loops`` count the true route's own U-turns (only at dead ends) and
    directed edges driven more than once, as
    :func:`mapmatch.evaluation.scoring.count_turnbacks` counts them on a match, so a
    benchmark can tell a spurious one from a driven one.
    """

    trace: Trace
    edges: list[TruthEdge]
    length_m: float
    true_edge: IntArray
    true_uvk: IntArray
    true_offset_m: FloatArray
    true_lon: FloatArray
    true_lat: FloatArray
    dense_time_s: FloatArray
    dense_lon: FloatArray
    dense_lat: FloatArray
    dense_heading_deg: FloatArray
    dense_speed_mps: FloatArray
    dense_distance_m: FloatArray
    odometer_scale: float
    geometry_lon: FloatArray
    geometry_lat: FloatArray
    stops: tuple[TruthEvent, ...] = ()
    outages: tuple[TruthEvent, ...] = ()
    canyons: tuple[TruthEvent, ...] = ()
    uturns: int = 0
    loops: int = 0

    def truth_record(self) -> dict[str, Any]:
        """
        The truth as one JSON object (a line of ``truth.jsonl``).

        ``edges`` the driven route, ``point_edges`` each fix's true ``[u, v, key]``;
        ``columns`` the optional columns the trace carries; ``stops`` / ``outages`` /
        ``canyons`` the stretches (``time`` epoch-second range, ``fixes`` index range, see
        :class:`TruthEvent`); ``uturns`` / ``loops`` the true route's own.
        """
        coords = np.column_stack((self.geometry_lon, self.geometry_lat)).round(7).tolist()
        columns = [
            name
            for name, values in (
                ("heading", self.trace.heading_deg),
                ("speed", self.trace.speed_mps),
                ("accuracy", self.trace.accuracy_m),
                ("odometer", self.trace.odometer_m),
            )
            if values is not None
        ]
        return {
            "trace_id": self.trace.trace_id,
            "length_m": round(self.length_m, 3),
            "odometer_scale": self.odometer_scale,
            "columns": columns,
            "geometry": {"type": "LineString", "coordinates": coords},
            "edges": [e.to_dict() for e in self.edges],
            "point_edges": self.true_uvk.tolist(),
            "stops": [e.to_dict() for e in self.stops],
            "outages": [e.to_dict() for e in self.outages],
            "canyons": [e.to_dict() for e in self.canyons],
            "uturns": self.uturns,
            "loops": self.loops,
        }


def _random_route(net: RoadNetwork, rng: np.random.Generator, length_m: float) -> list[int] | None:
    """
    Edges of a random drive of about ``length_m``; ``None`` if it got stuck at once.

    At every junction a legal move (the router's turn graph: every restriction obeyed, via-way
    ones included) is drawn, straight on preferred, U-turns only where nothing else is left,
    the edges of the last 30 moves avoided where possible.
    """
    a = net.arrays
    weights = a.edge_length_m / a.edge_length_m.sum()
    state = int(rng.choice(a.n_edges, p=weights))
    route = [state]
    total = float(a.edge_length_m[state])
    while total < length_m and len(route) < 10_000:
        states, edges = net.turns.successors(state)
        edge = route[-1]
        forward = [i for i, e in enumerate(edges.tolist()) if e != a.edge_twin[edge]]
        recent = set(route[-30:])
        fresh = [i for i in forward if int(edges[i]) not in recent]
        options = fresh or forward or list(range(len(edges)))
        if not options:
            break
        turn = np.array([_turn_deg(net, edge, int(edges[i])) for i in options])
        preference = np.exp(-turn / 45.0) + 0.05
        pick = options[int(rng.choice(len(options), p=preference / preference.sum()))]
        state = int(states[pick])
        route.append(int(edges[pick]))
        total += float(a.edge_length_m[route[-1]])
    return route if total >= min(length_m, 200.0) else None


def _turn_costs_s(net: RoadNetwork) -> FloatArray:
    """
    Search cost of every legal move of the turn graph for the fastest route, seconds.

    5 s for a turn of more than 45 degrees; a U-turn costs more than any trip (so routes
    never turn round) except at a dead end, where it is the only way on; even there it costs
    60 s, so a route turns in a dead end only when it must (it started into one), not to
    avoid a banned turn, as drivers go round the block instead.
    """
    a = net.arrays
    into, out = net.turns.transition_edges()
    end_dx, end_dy, start_dx, start_dy = _edge_end_directions(net)
    bearing_in = np.degrees(np.arctan2(end_dx[into], end_dy[into]))
    bearing_out = np.degrees(np.arctan2(start_dx[out], start_dy[out]))
    turn = np.abs((bearing_out - bearing_in + 180.0) % 360.0 - 180.0)
    cost = np.where(turn > 45.0, 5.0, 0.0)
    node = a.edge_v[into]
    dead_end = (a.out_ptr[node + 1] - a.out_ptr[node]) <= 1
    uturn = a.edge_twin[into] == out
    return np.where(uturn, np.where(dead_end, 60.0, 1e7), cost)


def _edge_end_directions(net: RoadNetwork) -> tuple[FloatArray, ...]:
    """Direction vectors of every edge's last and first geometry segment (metres)."""
    a = net.arrays
    lo, hi = a.edge_geom_ptr[:-1], a.edge_geom_ptr[1:]
    return (
        a.geom_x[hi - 1] - a.geom_x[hi - 2],
        a.geom_y[hi - 1] - a.geom_y[hi - 2],
        a.geom_x[lo + 1] - a.geom_x[lo],
        a.geom_y[lo + 1] - a.geom_y[lo],
    )


def _fastest_route(
    net: RoadNetwork, rng: np.random.Generator, length_m: float, *, allow_short: bool = False
) -> list[int] | None:
    """
    The fastest route from a random edge to a random edge about ``length_m`` of road away.

    Found by the network's router (:meth:`~roadnets.RoadNetwork.route_table`), the one the
    matcher routes with, on free-flow time plus 5 s per turn of more than 45 degrees, every
    turn restriction obeyed, no U-turn but at a dead end. ``None`` when no edge that far can
    be reached; with ``allow_short`` (a network too small for that length) the farthest
    reachable edge instead, unless even that is closer than ``min(0.3 * length_m, 200 m)``.
    """
    a = net.arrays
    weights = a.edge_length_m / a.edge_length_m.sum()
    start = int(rng.choice(a.n_edges, p=weights))
    time_s = a.edge_length_m / a.edge_speed_mps
    slowest = float(a.edge_speed_mps.min())
    bound_s = 1.6 * length_m / slowest + 5.0 * 1.6 * length_m / 20.0  # beyond 1.6 x length
    table = net.route_table(
        np.array([start]),
        bound_s,
        uturn_cost_m=0.0,
        edge_cost=time_s,
        turn_cost=_turn_costs_s(net),
    )
    records = np.arange(int(table.ptr[0]), int(table.ptr[1]))
    edges = net.turns.state_edge[table.state[records]].astype(np.int64)
    road = a.edge_length_m[start] + table.distance_m[records] + a.edge_length_m[edges]
    fine = (road >= 0.7 * length_m) & (road <= 1.3 * length_m) & (edges != start)
    if fine.any():
        pick = int(rng.choice(np.flatnonzero(fine)))
    elif allow_short and len(records):  # a small network: the farthest place the start reaches
        pick = int(np.argmax(road))
        if road[pick] < min(0.3 * length_m, 200.0):
            return None
    else:
        return None
    return [start, *table.path(int(records[pick])), int(edges[pick])]


def _edge_bearing(net: RoadNetwork, edge: int, at_end: bool) -> float:
    a = net.arrays
    lo, hi = int(a.edge_geom_ptr[edge]), int(a.edge_geom_ptr[edge + 1])
    i = hi - 2 if at_end else lo
    return float(
        np.degrees(np.arctan2(a.geom_x[i + 1] - a.geom_x[i], a.geom_y[i + 1] - a.geom_y[i]))
    )


def _turn_deg(net: RoadNetwork, into: int, out: int) -> float:
    diff = _edge_bearing(net, out, False) - _edge_bearing(net, into, True)
    return abs((diff + 180.0) % 360.0 - 180.0)


def _route_polyline(
    net: RoadNetwork, route: list[int]
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """
    x, y and distance along the route of its vertices, in the network's own measure.

    Distances are the edges' own vertex offsets (``geom_cum_m``, true lengths) added up, so a
    place on the route maps to an edge offset exactly as the network measures it.
    """
    a = net.arrays
    xs, ys, ss = [], [], []
    base = 0.0
    for i, e in enumerate(route):
        lo, hi = int(a.edge_geom_ptr[e]), int(a.edge_geom_ptr[e + 1])
        first = lo if i == 0 else lo + 1
        xs.append(a.geom_x[first:hi])
        ys.append(a.geom_y[first:hi])
        ss.append(base + a.geom_cum_m[first:hi])
        base += float(a.edge_length_m[e])
    return np.concatenate(xs), np.concatenate(ys), np.concatenate(ss)


def _speed_profile(
    net: RoadNetwork,
    route: list[int],
    edge_start: FloatArray,
    total_m: float,
    cfg: SimulationConfig,
    rng: np.random.Generator,
    extra: np.random.Generator,
) -> tuple[FloatArray, FloatArray, list[tuple[float, float]]]:
    """
    Target speed on a 1 m grid along the route, and the stops (distance, seconds).

    ``rng`` draws what the older options always drew (so their trips stay as they were);
    ``extra`` draws the junction stops.
    """
    a = net.arrays
    junction = _junction_nodes(net) if cfg.junction_stop_share > 0 else None
    grid = np.arange(0.0, total_m + 1.0, 1.0)
    edge_idx = np.clip(np.searchsorted(edge_start, grid, side="right") - 1, 0, len(route) - 1)
    limit = a.edge_speed_mps[np.asarray(route)][edge_idx] * rng.uniform(0.75, 0.95)
    cap = limit.copy()
    stops: list[tuple[float, float]] = []
    for i in range(1, len(route)):
        at = edge_start[i]
        turn = np.radians(_turn_deg(net, route[i - 1], route[i]))
        if turn > np.radians(20):
            radius = 12.0 / max(np.tan(turn / 2.0), 1e-3) + 3.0
            v_turn = float(np.sqrt(cfg.lateral_accel_mps2 * radius))
            cap[round(at)] = min(cap[round(at)], max(v_turn, 3.0))
        if rng.random() < cfg.stop_probability:
            cap[round(at)] = 0.0
            stops.append((float(at), float(rng.uniform(2.0, cfg.stop_s))))
        if (
            junction is not None
            and junction[a.edge_v[route[i - 1]]]
            and extra.random() < cfg.junction_stop_share
        ):
            cap[round(at)] = 0.0
            stops.append((float(at), float(extra.uniform(*cfg.junction_stop_s))))
    cap[0] = 0.0
    cap[-1] = 0.0
    v2 = cap**2
    for i in range(1, len(v2)):  # accelerate
        v2[i] = min(v2[i], v2[i - 1] + 2 * cfg.accel_mps2)
    for i in range(len(v2) - 2, -1, -1):  # brake ahead
        v2[i] = min(v2[i], v2[i + 1] + 2 * cfg.decel_mps2)
    return grid, np.sqrt(v2), stops


def _junction_nodes(net: RoadNetwork) -> npt.NDArray[np.bool_]:
    """Nodes joined to three or more distinct neighbours (in or out): real junctions."""
    a = net.arrays
    u, v = a.edge_u.astype(np.int64), a.edge_v.astype(np.int64)
    pairs = np.unique(np.column_stack((np.concatenate((u, v)), np.concatenate((v, u)))), axis=0)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    return np.bincount(pairs[:, 0], minlength=a.n_nodes) >= 3


def _standing_knots(
    grid: FloatArray, t_grid: FloatArray, stops: list[tuple[float, float]]
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """
    Time knots of the drive with each stop's dwell as a standstill.

    Returns the arrival time at each grid point (dwells before it included) and the knots
    ``(time, distance)`` to interpolate the position by time: a stop at grid point ``k``
    holds the distance at ``grid[k]`` from arrival to departure, so the car stands still
    (speed 0) instead of creeping.
    """
    if not stops:
        return t_grid, t_grid, grid
    index = np.array([round(at) for at, _ in stops], dtype=np.int64)
    dwell = np.array([d for _, d in stops])
    order = np.argsort(index)
    index, dwell = index[order], dwell[order]
    shift = np.zeros(len(grid))
    later = index + 1 < len(grid)
    np.add.at(shift, index[later] + 1, dwell[later])
    arrive = t_grid + np.cumsum(shift)
    knot_t = np.insert(arrive, index + 1, arrive[index] + dwell)
    knot_s = np.insert(grid, index + 1, grid[index])
    return arrive, knot_t, knot_s


def _events_along(
    rng: np.random.Generator,
    per_km: float,
    duration_s: tuple[float, float],
    total_m: float,
    arrive_s: Callable[[float], float],
    distance_at: Callable[[float], float],
) -> list[tuple[float, float, float]]:
    """
    Stretches placed along the route as a Poisson process: ``(start_s, end_s, distance_m)``.

    Starts are ``per_km`` per km of road apart on average (exponential gaps, counted from the
    end of the previous stretch, so stretches never overlap); each lasts a duration drawn
    uniformly from ``duration_s``.
    """
    out: list[tuple[float, float, float]] = []
    if per_km <= 0:
        return out
    at = 0.0
    while True:
        at += float(rng.exponential(1000.0 / per_km))
        if at >= total_m:
            return out
        start = arrive_s(at)
        end = start + float(rng.uniform(*duration_s))
        out.append((start, end, at))
        at = distance_at(end)


def _inside(t: FloatArray, start: float, end: float) -> tuple[int, int]:
    """First and last index of ``t`` within ``[start, end]``, ``(-1, -1)`` if none."""
    idx = np.flatnonzero((t >= start) & (t <= end))
    return (int(idx[0]), int(idx[-1])) if len(idx) else (-1, -1)


def simulate_trip(
    net: RoadNetwork, cfg: SimulationConfig, *, seed: int, trace_id: str = "trip"
) -> SimulatedTrip:
    """
    Drive one random trip on ``net`` and observe it as ``cfg`` says.

    Parameters
    ----------
    net
        The road network.
    cfg
        Driving and observation settings.
    seed
        Seed of the random generator: the same seed gives the same trip.
    trace_id
        Id of the trace.
    """
    rng = np.random.default_rng(seed)
    route = None
    for attempt in range(50):
        if cfg.route == "fastest":
            # a network too small for the length gets the longest routes it has, at the end
            route = _fastest_route(net, rng, cfg.route_length_m, allow_short=attempt >= 40)
        else:
            route = _random_route(net, rng, cfg.route_length_m)
        if route is not None:
            break
    if route is None:
        msg = "could not find a drivable route on this network; is it connected?"
        raise ConfigError(msg)
    a = net.arrays
    lengths = a.edge_length_m[np.asarray(route)]
    edge_start = np.concatenate(([0.0], np.cumsum(lengths)[:-1]))
    x, y, s_vert = _route_polyline(net, route)
    total = float(s_vert[-1])
    extra = np.random.default_rng([seed, 1])  # the realistic-noise options' own stream
    grid, v_grid, stops = _speed_profile(net, route, edge_start, total, cfg, rng, extra)
    at_node: dict[int, list[float]] = {}  # both kinds of stop at one node: one longer stop
    for at, dwell in stops:
        at_node.setdefault(round(at), [at, 0.0])[1] += dwell
    stops = [(at, dwell) for at, dwell in at_node.values()]

    # time along the grid; creeping speed near stops, then each stop's dwell standing still
    dt_grid = 1.0 / np.maximum(0.5 * (v_grid[:-1] + v_grid[1:]), 0.3)
    arrive, knot_t, knot_s = _standing_knots(
        grid, np.concatenate(([0.0], np.cumsum(dt_grid))), stops
    )
    dense_t = np.arange(0.0, knot_t[-1], 1.0 / _DENSE_HZ)
    # the 1 m grid runs up to a metre past the route's end: the car stops at the end
    dense_s = np.minimum(np.interp(dense_t, knot_t, knot_s), total)
    dense_v = np.interp(dense_s, grid, v_grid)
    dense_x, dense_y = np.interp(dense_s, s_vert, x), np.interp(dense_s, s_vert, y)
    ahead_x = np.interp(np.minimum(dense_s + 1.0, total), s_vert, x)
    ahead_y = np.interp(np.minimum(dense_s + 1.0, total), s_vert, y)
    back_x = np.interp(np.maximum(dense_s - 1.0, 0.0), s_vert, x)
    back_y = np.interp(np.maximum(dense_s - 1.0, 0.0), s_vert, y)
    dense_heading = np.degrees(np.arctan2(ahead_x - back_x, ahead_y - back_y)) % 360.0

    def arrive_s(at: float) -> float:
        return float(np.interp(at, grid, arrive))

    def distance_at(t: float) -> float:
        return float(np.interp(t, knot_t, knot_s))

    sample_t = np.arange(0.0, dense_t[-1], cfg.interval_s)
    # stretches that begin after the last fix are left out; an outage must end before it
    canyon_spans = _events_along(
        extra, cfg.canyon_per_km, cfg.canyon_s, total, arrive_s, distance_at
    )
    canyon_sides = [1 if extra.random() < 0.5 else -1 for _ in canyon_spans]
    seen = [c[0] < sample_t[-1] for c in canyon_spans]
    canyon_spans = [c for c, ok in zip(canyon_spans, seen, strict=True) if ok]
    canyon_sides = [d for d, ok in zip(canyon_sides, seen, strict=True) if ok]
    outage_spans = _events_along(
        extra, cfg.outage_per_km, cfg.outage_range_s, total, arrive_s, distance_at
    )
    outage_spans = [o for o in outage_spans if o[1] < sample_t[-1]]
    keep = np.ones(len(sample_t), dtype=bool)
    legacy_outages: list[tuple[float, float, float]] = []
    if cfg.outage_rate > 0:
        for start in sample_t[rng.random(len(sample_t)) < cfg.outage_rate * cfg.interval_s / 60]:
            keep &= ~((sample_t > start) & (sample_t <= start + cfg.outage_s))
            legacy_outages.append((float(start), float(start) + cfg.outage_s, distance_at(start)))
    if outage_spans:
        dark = np.zeros(len(sample_t), dtype=bool)
        for start, end, _ in outage_spans:
            dark |= (sample_t > start) & (sample_t < end)
        dark[0] = False  # the trip's first fix is always seen
        keep &= ~dark
    sample_t = sample_t[keep]
    s = np.interp(sample_t, dense_t, dense_s)
    true_x, true_y = np.interp(s, s_vert, x), np.interp(s, s_vert, y)
    true_v = np.interp(sample_t, dense_t, dense_v)
    true_heading = _interp_angle(sample_t, dense_t, dense_heading)
    noise = _position_noise(rng, sample_t, cfg)
    outlier = rng.random(len(s)) < cfg.outlier_rate
    angle = rng.uniform(0, 2 * np.pi, len(s))
    obs_x = true_x + noise[:, 0] + outlier * cfg.outlier_m * np.sin(angle)
    obs_y = true_y + noise[:, 1] + outlier * cfg.outlier_m * np.cos(angle)
    canyons: list[TruthEvent] = []
    for (start, end, at), side in zip(canyon_spans, canyon_sides, strict=True):
        inside = (sample_t >= start) & (sample_t <= end)
        right = np.radians(true_heading[inside] + 90.0 * side)  # driving direction +- 90 deg
        obs_x[inside] += cfg.canyon_bias_m * np.sin(right)
        obs_y[inside] += cfg.canyon_bias_m * np.cos(right)
        first_fix, last_fix = _inside(sample_t, start, end)
        canyons.append(
            TruthEvent("canyon", start, end, first_fix, last_fix, at, side, cfg.canyon_bias_m)
        )
    lon, lat = net.unproject(obs_x, obs_y)
    heading_sigma = cfg.heading_noise_deg + cfg.heading_noise_slow_deg * np.exp(-true_v)
    heading = (true_heading + rng.normal(0, 1, len(s)) * heading_sigma) % 360.0
    speed = np.maximum(true_v + rng.normal(0, cfg.speed_noise_mps, len(s)), 0.0)
    scale = 1.0 + cfg.odometer_bias
    scale += float(rng.uniform(-cfg.odometer_scale_error, cfg.odometer_scale_error))
    odometer = s * scale
    full = Trace(
        time=sample_t + _EPOCH_S,
        lon=lon,
        lat=lat,
        heading=heading,
        speed=speed,
        accuracy=np.full(len(s), max(cfg.noise_m, 1.0)),
        odometer=odometer,
        trace_id=trace_id,
    )
    trace = strip_to_class(full, cfg.input_class) if cfg.input_class != "odometer" else full
    true_lon, true_lat = net.unproject(true_x, true_y)
    edge_of = np.clip(np.searchsorted(edge_start, s, side="right") - 1, 0, len(route) - 1)
    true_edge = np.asarray(route, dtype=np.int64)[edge_of]
    true_offset = s - edge_start[edge_of]
    true_uvk = np.column_stack(net.edge_osm_ids(true_edge)).astype(np.int64)

    first, last = int(edge_of[0]), int(edge_of[-1])
    u, v, key = net.edge_osm_ids(np.asarray(route[first : last + 1]))
    truth_edges = []
    for i in range(first, last + 1):
        e = route[i]
        lo = true_offset[0] if i == first else 0.0
        hi = true_offset[-1] if i == last else float(a.edge_length_m[e])
        truth_edges.append(
            TruthEdge(
                e,
                int(u[i - first]),
                int(v[i - first]),
                int(key[i - first]),
                int(a.edge_way_id[e]),
                float(a.edge_length_m[e]),
                float(lo),
                float(hi),
            )
        )
    turnbacks = count_turnbacks([e.to_dict() for e in truth_edges])
    stop_events = []
    for at, dwell in sorted(stops):
        start = arrive_s(round(at))
        first_fix, last_fix = _inside(sample_t, start, start + dwell)
        stop_events.append(TruthEvent("stop", start, start + dwell, first_fix, last_fix, at))
    outage_events = []
    for start, end, at in sorted(legacy_outages + outage_spans):
        before = np.flatnonzero(sample_t <= start)
        after = np.flatnonzero(sample_t >= end)
        outage_events.append(
            TruthEvent(
                "outage",
                start,
                end,
                int(before[-1]) if len(before) else -1,
                int(after[0]) if len(after) else -1,
                at,
            )
        )
    inside = (s_vert > s[0]) & (s_vert < s[-1])
    gx = np.concatenate(([true_x[0]], x[inside], [true_x[-1]]))
    gy = np.concatenate(([true_y[0]], y[inside], [true_y[-1]]))
    geom_lon, geom_lat = net.unproject(gx, gy)
    dense_lon, dense_lat = net.unproject(dense_x, dense_y)
    return SimulatedTrip(
        trace=trace,
        edges=truth_edges,
        length_m=float(s[-1] - s[0]),
        true_edge=true_edge,
        true_uvk=true_uvk,
        true_offset_m=true_offset,
        true_lon=true_lon,
        true_lat=true_lat,
        dense_time_s=dense_t + _EPOCH_S,
        dense_lon=dense_lon,
        dense_lat=dense_lat,
        dense_heading_deg=dense_heading,
        dense_speed_mps=dense_v,
        dense_distance_m=dense_s,
        odometer_scale=scale,
        geometry_lon=geom_lon,
        geometry_lat=geom_lat,
        stops=tuple(_shift(e) for e in stop_events),
        outages=tuple(_shift(e) for e in outage_events),
        canyons=tuple(_shift(e) for e in canyons),
        uturns=turnbacks.uturns,
        loops=turnbacks.loops,
    )


def _shift(event: TruthEvent) -> TruthEvent:
    """The event with trip-relative times made epoch seconds, as the trace's."""
    return dataclasses.replace(
        event, start_s=event.start_s + _EPOCH_S, end_s=event.end_s + _EPOCH_S
    )


def _interp_angle(t: FloatArray, tp: FloatArray, deg: FloatArray) -> FloatArray:
    rad = np.radians(deg)
    s = np.interp(t, tp, np.sin(rad))
    c = np.interp(t, tp, np.cos(rad))
    return np.degrees(np.arctan2(s, c)) % 360.0


def _position_noise(rng: np.random.Generator, t: FloatArray, cfg: SimulationConfig) -> FloatArray:
    white = rng.normal(0.0, cfg.noise_m, (len(t), 2))
    tau = cfg.correlation_time_s
    if tau <= 0 or len(t) < 2:
        return white
    noise = np.empty_like(white)
    noise[0] = white[0]
    rho = np.exp(-np.diff(t) / tau)
    for i in range(1, len(t)):
        noise[i] = rho[i - 1] * noise[i - 1] + np.sqrt(1 - rho[i - 1] ** 2) * white[i]
    return noise


def simulate_trips(
    net: RoadNetwork, cfg: SimulationConfig, *, count: int, seed: int, prefix: str = "trip"
) -> list[SimulatedTrip]:
    """``count`` trips with seeds ``seed, seed + 1, ...`` and ids ``<prefix>-<n>``."""
    return [
        simulate_trip(net, cfg, seed=seed + i, trace_id=f"{prefix}-{i:04d}") for i in range(count)
    ]


def write_trips(trips: list[SimulatedTrip], out_dir: str | os.PathLike[str]) -> tuple[Path, Path]:
    """
    Write ``traces.csv`` and ``truth.jsonl`` into ``out_dir``.

    ``traces.csv`` holds all traces in DESIGN.md's columns; ``truth.jsonl`` one JSON object
    per trace: true route edges, geometry and length.
    """
    import pandas as pd

    folder = Path(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    frames: list[pd.DataFrame] = []
    for trip in trips:
        frame = trip.trace.to_dataframe()
        frame.insert(0, "trace_id", trip.trace.trace_id)
        frames.append(frame)
    traces = folder / "traces.csv"
    tmp = traces.with_suffix(".csv.tmp")
    pd.concat(frames).to_csv(tmp, index=False, float_format="%.7f")
    tmp.replace(traces)
    truth = folder / "truth.jsonl"
    tmp = truth.with_suffix(".jsonl.tmp")
    tmp.write_text("".join(json.dumps(t.truth_record()) + "\n" for t in trips), encoding="utf-8")
    tmp.replace(truth)
    return traces, truth
