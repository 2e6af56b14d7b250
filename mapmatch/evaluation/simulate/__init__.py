"""
Synthetic trips with ground truth on a real road network.

A trip is a drive along the directed graph (one-ways and turn restrictions obeyed, no U-turns
but at dead ends, straight on preferred), a speed profile that respects the speed limits, slows
for turns and stops at some junctions, and fused-looking observations: positions with Gaussian
noise (optionally correlated in time), occasional outliers and outages, heading and speed with
their own noise, and an odometer with a small scale error.

One job per module: ``config`` (:class:`SimulationConfig` and its presets), ``columns`` (input
classes, :func:`strip_to_class`), ``routes`` (route choice on the network's router),
``motion`` (speed profile, stops, the true 10 Hz trajectory), ``noise`` (what the receiver and
sensors report), ``truth`` (:class:`SimulatedTrip` and its truth record), ``trip``
(:func:`simulate_trip`: the stages in order) and ``files`` (:func:`write_trips`).
"""

from __future__ import annotations

from mapmatch.evaluation.simulate.columns import (
    INPUT_CLASSES,
    TRUE_COLUMNS,
    strip_to_class,
    with_columns,
)
from mapmatch.evaluation.simulate.config import SimulationConfig
from mapmatch.evaluation.simulate.files import write_trips
from mapmatch.evaluation.simulate.trip import simulate_trip, simulate_trips
from mapmatch.evaluation.simulate.truth import SimulatedTrip, TruthEdge, TruthEvent

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
