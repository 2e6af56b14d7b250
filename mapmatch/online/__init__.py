"""
Live matching: a vehicle's fixes matched as they arrive, with the distance so far.

:class:`OnlineMatcher` takes one trip's fixes one at a time (or in batches) and answers what
has settled (the path and the fixes' places, which never change afterwards), a provisional
position now, and the running distance check; :meth:`OnlineMatcher.close` gives the trip's
:class:`~mapmatch.MatchResult`. ``matcher`` argues the design; ``fixes`` validates one fix,
``tail`` runs the input stages over the unsettled part of the trip, ``window`` holds its
trellis and solves it, ``record`` keeps what settled.
"""

from __future__ import annotations

from mapmatch.online.fixes import LiveFix, read_fix
from mapmatch.online.matcher import (
    DEFAULT_LAG_S,
    LiveDistance,
    LivePosition,
    LiveUpdate,
    OnlineMatcher,
    RejectedFix,
)

__all__ = [
    "DEFAULT_LAG_S",
    "LiveDistance",
    "LiveFix",
    "LivePosition",
    "LiveUpdate",
    "OnlineMatcher",
    "RejectedFix",
    "read_fix",
]
