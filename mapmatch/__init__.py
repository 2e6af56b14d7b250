"""Map matching of fused vehicle positions onto OpenStreetMap road networks.

>>> import roadnets, mapmatch                                   # doctest: +SKIP
>>> net = roadnets.load()                                       # doctest: +SKIP
>>> trace = mapmatch.Trace.from_file("trip.csv")                # doctest: +SKIP
>>> result = mapmatch.match(trace, net)                         # doctest: +SKIP
>>> result.matched_length_m, result.distance_check.verdict      # doctest: +SKIP
"""

from __future__ import annotations

from mapmatch.config import OVERRIDABLE, MatchConfig, Param, parameters
from mapmatch.distance import DistanceCheck
from mapmatch.errors import (
    ConfigError,
    InvalidTraceError,
    MapMatchError,
    NoCandidatesError,
    RoadNetworkError,
    TraceFileError,
)
from mapmatch.matcher import match
from mapmatch.result import (
    Diagnostics,
    MatchedEdge,
    MatchedPoints,
    MatchResult,
    MatchStats,
    Segment,
)
from mapmatch.trace import Trace, TraceReport, read_traces

__all__ = [
    "OVERRIDABLE",
    "ConfigError",
    "Diagnostics",
    "DistanceCheck",
    "InvalidTraceError",
    "MapMatchError",
    "MatchConfig",
    "MatchResult",
    "MatchStats",
    "MatchedEdge",
    "MatchedPoints",
    "NoCandidatesError",
    "Param",
    "RoadNetworkError",
    "Segment",
    "Trace",
    "TraceFileError",
    "TraceReport",
    "match",
    "parameters",
    "read_traces",
]
