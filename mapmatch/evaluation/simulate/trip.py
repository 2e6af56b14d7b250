"""
One simulated trip from its seed: route, drive, observation, then the truth of every fix.

:func:`simulate_trip` runs the stages in a fixed order on two random streams (``seed``: the
route, the speed profile and the older noise options; ``[seed, 1]``: the realistic options'
stretches), so the same seed gives the same trip and switching a realistic option on keeps the
route and every older draw.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from mapmatch.evaluation.scoring import count_turnbacks
from mapmatch.evaluation.simulate.motion import drive_route
from mapmatch.evaluation.simulate.noise import observe
from mapmatch.evaluation.simulate.routes import draw_route
from mapmatch.evaluation.simulate.truth import (
    EPOCH_S,
    SimulatedTrip,
    TruthEdge,
    TruthEvent,
    fixes_inside,
)

if TYPE_CHECKING:
    from mapmatch.evaluation.simulate.config import SimulationConfig
    from mapmatch.evaluation.simulate.motion import Drive
    from mapmatch.evaluation.simulate.noise import Observation
    from roadnets import RoadNetwork

__all__ = ["simulate_trip", "simulate_trips"]


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

    Raises
    ------
    ConfigError
        No drivable route on ``net``.
    """
    rng = np.random.default_rng(seed)
    route = draw_route(net, cfg, rng)
    extra = np.random.default_rng([seed, 1])  # the realistic-noise options' own stream
    drive = drive_route(net, route, cfg, rng, extra)
    seen = observe(net, drive, cfg, rng, extra, trace_id=trace_id)
    return _truth(net, drive, seen)


def simulate_trips(
    net: RoadNetwork, cfg: SimulationConfig, *, count: int, seed: int, prefix: str = "trip"
) -> list[SimulatedTrip]:
    """``count`` trips with seeds ``seed, seed + 1, ...`` and ids ``<prefix>-<n>``."""
    return [
        simulate_trip(net, cfg, seed=seed + i, trace_id=f"{prefix}-{i:04d}") for i in range(count)
    ]


def _truth(net: RoadNetwork, drive: Drive, seen: Observation) -> SimulatedTrip:
    """The trip: the observed trace, each fix's true edge and offset, the route and stretches."""
    a = net.arrays
    route, edge_start, s, sample_t = drive.route, drive.edge_start, seen.distance_m, seen.time_s
    true_lon, true_lat = net.unproject(seen.true_x, seen.true_y)
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
    for at, dwell in sorted(drive.stops):
        start = drive.arrive_s(round(at))
        first_fix, last_fix = fixes_inside(sample_t, start, start + dwell)
        stop_events.append(TruthEvent("stop", start, start + dwell, first_fix, last_fix, at))
    outage_events = []
    for start, end, at in sorted(seen.outages):
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
    inside = (drive.s_vert > s[0]) & (drive.s_vert < s[-1])
    gx = np.concatenate(([seen.true_x[0]], drive.x[inside], [seen.true_x[-1]]))
    gy = np.concatenate(([seen.true_y[0]], drive.y[inside], [seen.true_y[-1]]))
    geom_lon, geom_lat = net.unproject(gx, gy)
    dense_lon, dense_lat = net.unproject(drive.dense_x, drive.dense_y)
    return SimulatedTrip(
        trace=seen.trace,
        edges=truth_edges,
        length_m=float(s[-1] - s[0]),
        true_edge=true_edge,
        true_uvk=true_uvk,
        true_offset_m=true_offset,
        true_lon=true_lon,
        true_lat=true_lat,
        dense_time_s=drive.dense_t + EPOCH_S,
        dense_lon=dense_lon,
        dense_lat=dense_lat,
        dense_heading_deg=drive.dense_heading,
        dense_speed_mps=drive.dense_v,
        dense_distance_m=drive.dense_s,
        odometer_scale=seen.odometer_scale,
        geometry_lon=geom_lon,
        geometry_lat=geom_lat,
        stops=tuple(_shift(e) for e in stop_events),
        outages=tuple(_shift(e) for e in outage_events),
        canyons=tuple(_shift(e) for e in seen.canyons),
        uturns=turnbacks.uturns,
        loops=turnbacks.loops,
    )


def _shift(event: TruthEvent) -> TruthEvent:
    """The event with trip-relative times made epoch seconds, as the trace's."""
    return dataclasses.replace(event, start_s=event.start_s + EPOCH_S, end_s=event.end_s + EPOCH_S)
