"""Map matching of fused vehicle positions onto OpenStreetMap road networks.

>>> import roadnets, mapmatch                                   # doctest: +SKIP
>>> net = roadnets.load()                                       # doctest: +SKIP
>>> trace = mapmatch.Trace.from_file("trip.csv")                # doctest: +SKIP
>>> result = mapmatch.match(trace, net)                         # doctest: +SKIP
>>> result.matched_length_m, result.distance_check.verdict      # doctest: +SKIP
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from mapmatch.config import OVERRIDABLE, MatchConfig, Param, parameters
from mapmatch.distance import DistanceCheck
from mapmatch.errors import (
    ConfigError,
    DeadlineExceededError,
    InvalidTraceError,
    MapMatchError,
    NoCandidatesError,
    RoadNetworkError,
    TraceFileError,
)
from mapmatch.result import (
    Diagnostics,
    MatchedEdge,
    MatchedPoints,
    MatchResult,
    MatchStats,
    Segment,
)

if TYPE_CHECKING:
    from mapmatch.batch.many import match_many
    from mapmatch.matcher import match
    from mapmatch.online import OnlineMatcher
    from mapmatch.trace import Trace, TraceReport, read_traces

#: Names imported when first used, so ``import mapmatch`` stays light (the matcher's compiled
#: kernels and the trace readers' pandas load on the first match or trace): name -> module.
_LAZY = {
    "match": "mapmatch.matcher",
    "OnlineMatcher": "mapmatch.online",
    "match_many": "mapmatch.batch.many",
    "Trace": "mapmatch.trace",
    "TraceReport": "mapmatch.trace",
    "read_traces": "mapmatch.trace",
}


def __getattr__(name: str) -> Any:
    """Import a lazily exported name on first use (PEP 562)."""
    module = _LAZY.get(name)
    if module is None:
        msg = f"module 'mapmatch' has no attribute {name!r}"
        raise AttributeError(msg)
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


__all__ = [
    "OVERRIDABLE",
    "ConfigError",
    "DeadlineExceededError",
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
    "OnlineMatcher",
    "Param",
    "RoadNetworkError",
    "Segment",
    "Trace",
    "TraceFileError",
    "TraceReport",
    "match",
    "match_many",
    "parameters",
    "read_traces",
]
