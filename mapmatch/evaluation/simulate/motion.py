"""
How a simulated car moves along its route: target speeds, stops, the true 10 Hz trajectory.

The speed profile respects the speed limits, slows for turns (lateral acceleration), brakes
for and pulls away from stops; a stop's dwell is spent standing still. :func:`drive_route`
turns it into the dense trajectory every observation is sampled from.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from mapmatch.evaluation.simulate.routes import route_polyline, turn_deg

if TYPE_CHECKING:
    from mapmatch.evaluation.simulate.config import SimulationConfig
    from mapmatch.types import BoolArray, FloatArray
    from roadnets import RoadNetwork

__all__ = ["DENSE_HZ", "Drive", "drive_route"]

#: Rate of the true trajectory, Hz.
DENSE_HZ = 10.0


@dataclass(frozen=True, slots=True)
class Drive:
    """
    One trip's true motion along its route (trip-relative seconds, metres along the route).

    ``edge_start`` where each route edge begins; ``x``/``y``/``s_vert`` the route's vertices
    (projected metres) and their distance along it, ``total_m`` its length; ``grid``/``v_grid``
    the target speed on a 1 m grid; ``stops`` ``(distance, dwell seconds)``, one per node;
    ``arrive`` the arrival time at each grid point, ``knot_t``/``knot_s`` time and distance
    knots with each dwell standing still; ``dense_*`` the trajectory at :data:`DENSE_HZ`.
    """

    route: list[int]
    edge_start: FloatArray
    x: FloatArray
    y: FloatArray
    s_vert: FloatArray
    total_m: float
    grid: FloatArray
    v_grid: FloatArray
    stops: list[tuple[float, float]]
    arrive: FloatArray
    knot_t: FloatArray
    knot_s: FloatArray
    dense_t: FloatArray
    dense_s: FloatArray
    dense_v: FloatArray
    dense_x: FloatArray
    dense_y: FloatArray
    dense_heading: FloatArray

    def arrive_s(self, at: float) -> float:
        """Seconds from the start until the car reaches ``at`` metres along the route."""
        return float(np.interp(at, self.grid, self.arrive))

    def distance_at(self, t: float) -> float:
        """Metres along the route at ``t`` seconds from the start."""
        return float(np.interp(t, self.knot_t, self.knot_s))


def drive_route(
    net: RoadNetwork,
    route: list[int],
    cfg: SimulationConfig,
    rng: np.random.Generator,
    extra: np.random.Generator,
) -> Drive:
    """
    Drive ``route``: the speed profile and its stops, then the true trajectory at 10 Hz.

    ``rng`` draws the speed-limit share and the brief stops, ``extra`` the junction stops
    (see :func:`_speed_profile`).
    """
    a = net.arrays
    lengths = a.edge_length_m[np.asarray(route)]
    edge_start = np.concatenate(([0.0], np.cumsum(lengths)[:-1]))
    x, y, s_vert = route_polyline(net, route)
    total = float(s_vert[-1])
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
    dense_t = np.arange(0.0, knot_t[-1], 1.0 / DENSE_HZ)
    # the 1 m grid runs up to a metre past the route's end: the car stops at the end
    dense_s = np.minimum(np.interp(dense_t, knot_t, knot_s), total)
    dense_v = np.interp(dense_s, grid, v_grid)
    dense_x, dense_y = np.interp(dense_s, s_vert, x), np.interp(dense_s, s_vert, y)
    ahead_x = np.interp(np.minimum(dense_s + 1.0, total), s_vert, x)
    ahead_y = np.interp(np.minimum(dense_s + 1.0, total), s_vert, y)
    back_x = np.interp(np.maximum(dense_s - 1.0, 0.0), s_vert, x)
    back_y = np.interp(np.maximum(dense_s - 1.0, 0.0), s_vert, y)
    dense_heading = np.degrees(np.arctan2(ahead_x - back_x, ahead_y - back_y)) % 360.0
    return Drive(
        route=route,
        edge_start=edge_start,
        x=x,
        y=y,
        s_vert=s_vert,
        total_m=total,
        grid=grid,
        v_grid=v_grid,
        stops=stops,
        arrive=arrive,
        knot_t=knot_t,
        knot_s=knot_s,
        dense_t=dense_t,
        dense_s=dense_s,
        dense_v=dense_v,
        dense_x=dense_x,
        dense_y=dense_y,
        dense_heading=dense_heading,
    )


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
        turn = np.radians(turn_deg(net, route[i - 1], route[i]))
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


def _junction_nodes(net: RoadNetwork) -> BoolArray:
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
