"""A trace solved by the matcher's stages up to the HMM, for tests that read its trellis."""

from __future__ import annotations

from typing import TYPE_CHECKING

from mapmatch.hmm.fixes import fixes_of, observe
from mapmatch.hmm.selection import find_displaced
from mapmatch.hmm.trellis import model_fixes, solve

if TYPE_CHECKING:
    import mapmatch
    import roadnets
    from mapmatch.hmm.candidates import Candidates
    from mapmatch.hmm.observations import Observations
    from mapmatch.hmm.solution import Solution


def solved(
    net: roadnets.RoadNetwork, trace: mapmatch.Trace, config: mapmatch.MatchConfig
) -> tuple[Observations, Candidates, Solution]:
    """The observations, every candidate found, and the solution over the model fixes."""
    x, y = net.project(trace.lon, trace.lat)
    fixes = fixes_of(trace, x, y, config)
    obs, cands = observe(net, fixes, config)
    outlier = find_displaced(fixes, obs, cands, config)
    used, _, cut_after = model_fixes(cands, outlier, fixes.segment_starts, obs.first)
    return obs, cands, solve(net, obs, cands, used, cut_after, config)
