"""
Which road a simulated trip drives: a fastest route or a random walk, on the network's router.

Both choose among the legal moves of the network's turn graph (:attr:`RoadNetwork.turns`:
one-ways and every turn restriction obeyed, via-way ones included), the same graph the matcher
routes on, so the truth never drives a turn the matcher could not.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mapmatch.errors import ConfigError

if TYPE_CHECKING:
    from mapmatch.evaluation.simulate.config import SimulationConfig
    from mapmatch.types import FloatArray
    from roadnets import RoadNetwork

__all__ = ["draw_route", "route_polyline", "turn_deg"]


def draw_route(net: RoadNetwork, cfg: SimulationConfig, rng: np.random.Generator) -> list[int]:
    """
    The edges of one trip's route as ``cfg.route`` says, drawn from ``rng``.

    Up to 50 tries; a network too small for ``cfg.route_length_m`` gets the longest fastest
    routes it has in the last ten.

    Raises
    ------
    ConfigError
        No try found a route (a network without connected roads).
    """
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
    return route


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
        turn = np.array([turn_deg(net, edge, int(edges[i])) for i in options])
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


def turn_deg(net: RoadNetwork, into: int, out: int) -> float:
    """How far a car turns from the end of edge ``into`` onto edge ``out``: 0..180 degrees."""
    diff = _edge_bearing(net, out, False) - _edge_bearing(net, into, True)
    return abs((diff + 180.0) % 360.0 - 180.0)


def route_polyline(net: RoadNetwork, route: list[int]) -> tuple[FloatArray, FloatArray, FloatArray]:
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
