"""Synthetic trips with ground truth on a real road network.

A trip is a random drive along the directed graph (one-ways and turn restrictions obeyed, no
U-turns but at dead ends, straight on preferred), a speed profile that respects the speed
limits, slows for turns and stops at some junctions, and fused-looking observations: positions
with Gaussian noise (optionally correlated in time), occasional outliers and outages, heading
and speed with their own noise, and an odometer with a small scale error.
"""

from __future__ import annotations

import heapq
import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from mapmatch.errors import ConfigError
from mapmatch.trace import Trace

if TYPE_CHECKING:
    import os

    import pandas as pd

    from roadnets import RoadNetwork

__all__ = [
    "SimulatedTrip",
    "SimulationConfig",
    "TruthEdge",
    "simulate_trip",
    "simulate_trips",
    "write_trips",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

_DENSE_HZ = 10.0


@dataclass(frozen=True, slots=True, kw_only=True)
class SimulationConfig:
    """
    How trips are driven and observed.

    ``interval_s`` sampling interval; ``noise_m`` 1-sigma position error per axis;
    ``noise_correlation_s`` time constant of the position error (0: white, as raw GNSS; a few
    seconds looks like a Kalman filter's output); ``outlier_rate`` share of fixes displaced by
    ``outlier_m``; ``outage_rate`` chance per minute of an outage of ``outage_s`` without
    fixes; ``heading_noise_deg`` / ``speed_noise_mps`` 1-sigma noise; ``odometer_scale_error``
    maximum absolute scale error of the odometer (drawn uniformly per trip);
    ``route_length_m`` target length of each trip; ``route`` how trips are chosen:
    ``fastest`` (the fastest route between a random start and a random end about
    ``route_length_m`` away, as real trips are) or ``random_walk`` (meandering: straight on
    preferred at every junction); ``stop_probability`` chance of stopping at
    a junction, for ``stop_s`` seconds (drawn up to it).
    """

    interval_s: float = 1.0
    noise_m: float = 5.0
    noise_correlation_s: float = 0.0
    outlier_rate: float = 0.0
    outlier_m: float = 40.0
    outage_rate: float = 0.0
    outage_s: float = 30.0
    heading_noise_deg: float = 5.0
    speed_noise_mps: float = 0.3
    odometer_scale_error: float = 0.005
    route_length_m: float = 3000.0
    stop_probability: float = 0.15
    stop_s: float = 20.0
    accel_mps2: float = 1.5
    decel_mps2: float = 2.5
    lateral_accel_mps2: float = 2.0
    route: str = "fastest"

    def __post_init__(self) -> None:
        for name in ("interval_s", "route_length_m", "accel_mps2", "decel_mps2"):
            if not getattr(self, name) > 0:
                msg = f"{name} must be > 0 (got {getattr(self, name)!r})"
                raise ConfigError(msg)
        for name in ("outlier_rate", "stop_probability"):
            if not 0 <= getattr(self, name) <= 1:
                msg = f"{name} must be within 0..1 (got {getattr(self, name)!r})"
                raise ConfigError(msg)
        if self.route not in ("fastest", "random_walk"):
            msg = f"route must be 'fastest' or 'random_walk' (got {self.route!r})"
            raise ConfigError(msg)
        if self.noise_m < 0 or self.outage_rate < 0 or self.noise_correlation_s < 0:
            msg = "noise_m, outage_rate and noise_correlation_s must be >= 0"
            raise ConfigError(msg)


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

    def truth_record(self) -> dict[str, Any]:
        """The truth as one JSON object (a line of ``truth.jsonl``)."""
        coords = np.column_stack((self.geometry_lon, self.geometry_lat)).round(7).tolist()
        return {
            "trace_id": self.trace.trace_id,
            "length_m": round(self.length_m, 3),
            "odometer_scale": self.odometer_scale,
            "geometry": {"type": "LineString", "coordinates": coords},
            "edges": [e.to_dict() for e in self.edges],
            "point_edges": self.true_uvk.tolist(),
        }


def _random_route(net: RoadNetwork, rng: np.random.Generator, length_m: float) -> list[int] | None:
    """Edges of a random drive of about ``length_m``; ``None`` if it got stuck at once."""
    a = net.arrays
    weights = a.edge_length_m / a.edge_length_m.sum()
    edge = int(rng.choice(a.n_edges, p=weights))
    banned = set(zip(a.banned_in.tolist(), a.banned_out.tolist(), strict=True))
    route = [edge]
    total = float(a.edge_length_m[edge])
    while total < length_m and len(route) < 10_000:
        node = int(a.edge_v[edge])
        outs = [
            int(e)
            for e in a.out_edge[a.out_ptr[node] : a.out_ptr[node + 1]]
            if (edge, int(e)) not in banned
        ]
        forward = [e for e in outs if e != a.edge_twin[edge]]
        recent = set(route[-30:])
        fresh = [e for e in forward if e not in recent]
        options = fresh or forward or outs
        if not options:
            break
        turn = np.array([_turn_deg(net, edge, e) for e in options])
        preference = np.exp(-turn / 45.0) + 0.05
        edge = int(options[int(rng.choice(len(options), p=preference / preference.sum()))])
        route.append(edge)
        total += float(a.edge_length_m[edge])
    return route if total >= min(length_m, 200.0) else None


def _fastest_route(
    net: RoadNetwork, rng: np.random.Generator, length_m: float, *, allow_short: bool = False
) -> list[int] | None:
    """
    The fastest route from a random edge to a random edge about ``length_m`` of road away.

    Free-flow time plus 5 s per turn of more than 45 degrees, banned turns obeyed, no U-turn
    but at a dead end. ``None`` when no edge that far can be reached; with ``allow_short``
    (a network too small for that length) the farthest reachable edge instead, unless even
    that is closer than ``min(0.3 * length_m, 200 m)``.
    """
    a = net.arrays
    weights = a.edge_length_m / a.edge_length_m.sum()
    start = int(rng.choice(a.n_edges, p=weights))
    banned = set(zip(a.banned_in.tolist(), a.banned_out.tolist(), strict=True))
    time_s = a.edge_length_m / a.edge_speed_mps
    best: dict[int, float] = {start: 0.0}
    road: dict[int, float] = {start: float(a.edge_length_m[start])}
    previous: dict[int, int] = {}
    heap = [(0.0, start)]
    limit = 1.6 * length_m
    while heap:
        cost, edge = heapq.heappop(heap)
        if cost > best.get(edge, np.inf) or road[edge] > limit:
            continue
        node = int(a.edge_v[edge])
        outs = [
            int(e)
            for e in a.out_edge[a.out_ptr[node] : a.out_ptr[node + 1]]
            if (edge, int(e)) not in banned
        ]
        forward = [e for e in outs if e != a.edge_twin[edge]] or outs
        for nxt in forward:
            turn = 5.0 if _turn_deg(net, edge, nxt) > 45.0 else 0.0
            new = cost + float(time_s[nxt]) + turn
            if new < best.get(nxt, np.inf):
                best[nxt] = new
                road[nxt] = road[edge] + float(a.edge_length_m[nxt])
                previous[nxt] = edge
                heapq.heappush(heap, (new, nxt))
    ends = [e for e, r in road.items() if 0.7 * length_m <= r <= 1.3 * length_m]
    if ends:
        edge = ends[int(rng.integers(len(ends)))]
    elif allow_short:  # a small network: the farthest place the start can reach, if far enough
        edge = max(road, key=road.__getitem__)
        if road[edge] < min(0.3 * length_m, 200.0):
            return None
    else:
        return None
    route = [edge]
    while edge != start:
        edge = previous[edge]
        route.append(edge)
    return route[::-1]


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
    """x, y and cumulative distance of the route's vertices, and each edge's start distance."""
    xs, ys = [], []
    for i, e in enumerate(route):
        x, y = net.edge_polyline(e, 0.0, float(net.arrays.edge_length_m[e]))
        if i:
            x, y = x[1:], y[1:]
        xs.append(x)
        ys.append(y)
    x, y = np.concatenate(xs), np.concatenate(ys)
    s = np.concatenate(([0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))))
    return x, y, s


def _speed_profile(
    net: RoadNetwork,
    route: list[int],
    edge_start: FloatArray,
    total_m: float,
    cfg: SimulationConfig,
    rng: np.random.Generator,
) -> tuple[FloatArray, FloatArray, list[tuple[float, float]]]:
    """Target speed on a 1 m grid along the route, and the stops (distance, seconds)."""
    a = net.arrays
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
    cap[0] = 0.0
    cap[-1] = 0.0
    v2 = cap**2
    for i in range(1, len(v2)):  # accelerate
        v2[i] = min(v2[i], v2[i - 1] + 2 * cfg.accel_mps2)
    for i in range(len(v2) - 2, -1, -1):  # brake ahead
        v2[i] = min(v2[i], v2[i + 1] + 2 * cfg.decel_mps2)
    return grid, np.sqrt(v2), stops


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
    grid, v_grid, stops = _speed_profile(net, route, edge_start, total, cfg, rng)

    # time along the grid; creeping speed near stops, plus dwell time at each stop
    dt_grid = 1.0 / np.maximum(0.5 * (v_grid[:-1] + v_grid[1:]), 0.3)
    t_grid = np.concatenate(([0.0], np.cumsum(dt_grid)))
    for at, dwell in stops:
        t_grid[round(at) + 1 :] += dwell
    dense_t = np.arange(0.0, t_grid[-1], 1.0 / _DENSE_HZ)
    dense_s = np.interp(dense_t, t_grid, grid)
    dense_v = np.interp(dense_s, grid, v_grid)
    dense_x, dense_y = np.interp(dense_s, s_vert, x), np.interp(dense_s, s_vert, y)
    ahead_x = np.interp(np.minimum(dense_s + 1.0, total), s_vert, x)
    ahead_y = np.interp(np.minimum(dense_s + 1.0, total), s_vert, y)
    back_x = np.interp(np.maximum(dense_s - 1.0, 0.0), s_vert, x)
    back_y = np.interp(np.maximum(dense_s - 1.0, 0.0), s_vert, y)
    dense_heading = np.degrees(np.arctan2(ahead_x - back_x, ahead_y - back_y)) % 360.0

    sample_t = np.arange(0.0, dense_t[-1], cfg.interval_s)
    keep = np.ones(len(sample_t), dtype=bool)
    if cfg.outage_rate > 0:
        for start in sample_t[rng.random(len(sample_t)) < cfg.outage_rate * cfg.interval_s / 60]:
            keep &= ~((sample_t > start) & (sample_t <= start + cfg.outage_s))
    sample_t = sample_t[keep]
    s = np.interp(sample_t, dense_t, dense_s)
    true_x, true_y = np.interp(s, s_vert, x), np.interp(s, s_vert, y)
    noise = _position_noise(rng, sample_t, cfg)
    outlier = rng.random(len(s)) < cfg.outlier_rate
    angle = rng.uniform(0, 2 * np.pi, len(s))
    obs_x = true_x + noise[:, 0] + outlier * cfg.outlier_m * np.sin(angle)
    obs_y = true_y + noise[:, 1] + outlier * cfg.outlier_m * np.cos(angle)
    lon, lat = net.unproject(obs_x, obs_y)
    heading = _interp_angle(sample_t, dense_t, dense_heading)
    heading = (heading + rng.normal(0, cfg.heading_noise_deg, len(s))) % 360.0
    speed = np.maximum(
        np.interp(sample_t, dense_t, dense_v) + rng.normal(0, cfg.speed_noise_mps, len(s)), 0.0
    )
    scale = 1.0 + float(rng.uniform(-cfg.odometer_scale_error, cfg.odometer_scale_error))
    odometer = s * scale
    trace = Trace(
        time=sample_t + 1.7e9,
        lon=lon,
        lat=lat,
        heading=heading,
        speed=speed,
        accuracy=np.full(len(s), max(cfg.noise_m, 1.0)),
        odometer=odometer,
        trace_id=trace_id,
    )
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
        dense_time_s=dense_t + 1.7e9,
        dense_lon=dense_lon,
        dense_lat=dense_lat,
        dense_heading_deg=dense_heading,
        dense_speed_mps=dense_v,
        dense_distance_m=dense_s,
        odometer_scale=scale,
        geometry_lon=geom_lon,
        geometry_lat=geom_lat,
    )


def _interp_angle(t: FloatArray, tp: FloatArray, deg: FloatArray) -> FloatArray:
    rad = np.radians(deg)
    s = np.interp(t, tp, np.sin(rad))
    c = np.interp(t, tp, np.cos(rad))
    return np.degrees(np.arctan2(s, c)) % 360.0


def _position_noise(rng: np.random.Generator, t: FloatArray, cfg: SimulationConfig) -> FloatArray:
    white = rng.normal(0.0, cfg.noise_m, (len(t), 2))
    if cfg.noise_correlation_s <= 0 or len(t) < 2:
        return white
    noise = np.empty_like(white)
    noise[0] = white[0]
    rho = np.exp(-np.diff(t) / cfg.noise_correlation_s)
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
