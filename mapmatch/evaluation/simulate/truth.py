"""
The truth behind a simulated trip: its route edges, stretches (stops, outages, canyons), trace.

:class:`SimulatedTrip` holds the observed trace and everything true about it;
:meth:`SimulatedTrip.truth_record` is one line of ``truth.jsonl``, the record
:func:`mapmatch.evaluation.scoring.score_geojson` scores a match against.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from mapmatch.trace import Trace
    from mapmatch.types import FloatArray, IntArray

__all__ = ["EPOCH_S", "SimulatedTrip", "TruthEdge", "TruthEvent", "fixes_inside"]

#: Simulated trips start at this epoch second.
EPOCH_S = 1.7e9


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

    def ends_error(self) -> float:
        """
        The relative length error of the true route cut where the first and last fix lie.

        Each end fix's position error along the true driving direction there moves the end
        of any match by as much, so ``(along_last - along_first) / length_m`` is the error a
        matcher that found the exact route would still make from those two fixes alone: at
        sparse sampling, where the neighbouring fixes say nothing of an end, the floor of
        the length error. (At 1 s, fixes near the ends can average it away.)
        """
        if self.length_m <= 0 or len(self.trace) == 0:
            return float("nan")
        along = [self._along_error_m(i) for i in (0, len(self.trace) - 1)]
        return (along[1] - along[0]) / self.length_m

    def _along_error_m(self, i: int) -> float:
        """Fix ``i``'s position error along the true heading at its time, metres (ahead > 0)."""
        from roadnets.projection import EARTH_RADIUS_M

        j = int(np.argmin(np.abs(self.dense_time_s - self.trace.time_s[i])))
        lat0 = np.radians(self.true_lat[i])
        east = np.radians(self.trace.lon[i] - self.true_lon[i]) * np.cos(lat0) * EARTH_RADIUS_M
        north = np.radians(self.trace.lat[i] - self.true_lat[i]) * EARTH_RADIUS_M
        heading = np.radians(self.dense_heading_deg[j])
        return float(east * np.sin(heading) + north * np.cos(heading))

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


def fixes_inside(t: FloatArray, start: float, end: float) -> tuple[int, int]:
    """First and last index of ``t`` within ``[start, end]``, ``(-1, -1)`` if none."""
    idx = np.flatnonzero((t >= start) & (t <= end))
    return (int(idx[0]), int(idx[-1])) if len(idx) else (-1, -1)
