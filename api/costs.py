"""
What one match will cost in memory, estimated before it starts, held against a budget.

The matcher's memory grows with the points and with the square of the candidates per point:
the trellis is padded to the widest point (``w`` candidates: two ``(n, w, w)`` arrays, the
log-transitions and the route kinds), and every pair of candidates of consecutive points is
routed and scored (about ``c^2`` pairs per step for ``c`` candidates per point). How many
candidates a point has depends on the request (``max_candidates``, ``search_radius_m``,
``sigma_m``, the points' accuracies) and on the road density around it, so the estimate uses
both:

- :class:`CandidateDensity` samples the network once when it is loaded: for a set of radii,
  the mean and the largest number of directed edges within that radius of points on and near
  its roads (the same R-tree query the matcher runs);
- :func:`match_cost` takes the request's options and trace: the radius a point's candidates
  can come from (the search radius, widened by a poor accuracy; narrowed by the emission
  margin, ``sigma x sqrt(1 + 2 x candidate_margin)``), the widest point ``w = min(2k,
  largest count)`` and a typical one ``c = min(2k, mean count)`` (``k`` road places are kept,
  and a place of a two-way road is two directed edges), and returns

  ``bytes = points x (PER_POINT + PER_PADDED_PAIR x w^2 + PER_ROUTED_PAIR x c^2)``.

The three constants were measured: peak RSS of single matches of 3,000 and 6,000 points on the
embedded network with every fix kept (``thinning_sigmas=0``: a trace whose fixes are spread
out is not thinned), options across their bounds. Per point: 41 KB at the defaults, 137 KB
with 64 candidates, 152 KB with 32 in 100 m at sigma 20, 754 KB with 64 in 200 m at sigma 50;
the constants are the smallest round ones the model never falls below
(``benchmarks/bench_service.py --cost-model`` measures again and prints model against
measurement). A request over ``MAPMATCH_MEMORY_BUDGET_MB``
answers 413 ``over_budget`` naming the option that weighs most, before any matching.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

import numpy as np

from api.errors import OverBudgetError
from mapmatch.hmm.candidates import edges_searched, radius_of_sigma

if TYPE_CHECKING:
    from mapmatch import MatchConfig, Trace
    from roadnets import RoadNetwork

__all__ = [
    "PER_PADDED_PAIR",
    "PER_POINT",
    "PER_ROUTED_PAIR",
    "CandidateDensity",
    "MatchCost",
    "check_budget",
    "match_cost",
]

#: Bytes per point that do not depend on the candidates (fixes, observations, result).
PER_POINT: Final = 24_000
#: Bytes per point per (widest point's candidates)^2: the padded trellis arrays and their
#: temporaries in Viterbi and forward-backward.
PER_PADDED_PAIR: Final = 100
#: Bytes per point per (typical candidates)^2: the routed candidate pairs and their scores.
PER_ROUTED_PAIR: Final = 90
#: Radii the density is sampled at, metres (up to the widest a poor accuracy may ask for).
RADII_M: Final = (5.0, 10.0, 20.0, 35.0, 50.0, 75.0, 100.0, 150.0, 200.0, 300.0, 500.0)
_SAMPLES: Final = 400


@dataclass(frozen=True, slots=True)
class CandidateDensity:
    """
    Directed edges within each radius of points near the network's roads.

    Attributes
    ----------
    radii_m
        The radii, metres, increasing.
    mean
        Mean count of directed edges within each radius.
    most
        Largest count seen within each radius.
    """

    radii_m: tuple[float, ...]
    mean: tuple[float, ...]
    most: tuple[float, ...]

    @classmethod
    def of(cls, net: RoadNetwork, *, seed: int = 0) -> CandidateDensity:
        """Sample ``net``: points on its edges' vertices, shifted up to 10 m at random."""
        a = net.arrays
        rng = np.random.default_rng(seed)
        count = len(a.geom_x)
        if count == 0:
            zeros = tuple(0.0 for _ in RADII_M)
            return cls(RADII_M, zeros, zeros)
        pick = rng.integers(0, count, size=min(_SAMPLES, count))
        x = np.asarray(a.geom_x, dtype=np.float64)[pick] + rng.uniform(-10, 10, pick.size)
        y = np.asarray(a.geom_y, dtype=np.float64)[pick] + rng.uniform(-10, 10, pick.size)
        widest = net.nearby_edges(x, y, RADII_M[-1])
        mean: list[float] = []
        most: list[float] = []
        for radius in RADII_M:
            inside = widest.distance_m <= radius
            per_point = np.bincount(widest.point[inside], minlength=pick.size)
            mean.append(float(per_point.mean()))
            most.append(float(per_point.max()))
        return cls(RADII_M, tuple(mean), tuple(most))

    def at(self, radius_m: float) -> tuple[float, float]:
        """``(mean, most)`` within ``radius_m``: the next sampled radius up (or scaled up)."""
        radii = self.radii_m
        i = int(np.searchsorted(radii, radius_m))
        if i < len(radii):
            return self.mean[i], self.most[i]
        area = (radius_m / radii[-1]) ** 2  # beyond the samples: edges grow with the area
        return self.mean[-1] * area, self.most[-1] * area


@dataclass(frozen=True, slots=True)
class MatchCost:
    """The estimate of one match: bytes, and what it rests on."""

    points: int
    widest: int
    typical: float
    radius_m: float
    bytes: float

    @property
    def megabytes(self) -> float:
        """:attr:`bytes` in MB (10^6)."""
        return self.bytes / 1e6


def match_cost(trace: Trace, config: MatchConfig, density: CandidateDensity) -> MatchCost:
    """
    The memory one match of ``trace`` with ``config`` will need, estimated.

    Examples
    --------
    >>> from mapmatch import MatchConfig, Trace
    >>> flat = CandidateDensity(RADII_M, tuple(2.0 for _ in RADII_M), tuple(4.0 for _ in RADII_M))
    >>> trace = Trace(time=[0.0, 1.0], lon=[7.42, 7.4201], lat=[43.73, 43.73])
    >>> cost = match_cost(trace, MatchConfig(), flat)
    >>> (cost.points, cost.widest, cost.typical)
    (2, 4, 2.0)
    """
    n = len(trace)
    sigma = config.sigma_m
    if trace.accuracy_m is not None and np.isfinite(trace.accuracy_m).any():
        sigma = max(sigma, float(np.nanmax(trace.accuracy_m)))
    radius = radius_of_sigma(sigma, config)
    margin_m = sigma * math.sqrt(1.0 + 2.0 * config.candidate_margin)
    reach = min(radius, margin_m) if config.candidate_margin > 0 else radius
    mean, most = density.at(reach)
    kept = edges_searched(config)  # the trellis is never wider than the edges searched
    widest = max(1, min(kept, math.ceil(most)))
    typical = max(1.0, min(float(kept), mean))
    total = n * (PER_POINT + PER_PADDED_PAIR * widest**2 + PER_ROUTED_PAIR * typical**2)
    return MatchCost(points=n, widest=widest, typical=typical, radius_m=reach, bytes=total)


def check_budget(cost: MatchCost, budget_mb: float, overrides: dict[str, object]) -> None:
    """
    Refuse a match that would need more than ``budget_mb``.

    The error names what to change: the first of ``max_candidates``, ``search_radius_m`` and
    ``sigma_m`` the request raised (under ``options.``), else the points.

    Raises
    ------
    OverBudgetError
        413 ``over_budget``.
    """
    if cost.megabytes <= budget_mb:
        return
    raised = [
        name for name in ("max_candidates", "search_radius_m", "sigma_m") if name in overrides
    ]
    field = f"options.{raised[0]}" if raised else "points"
    fix = (
        f"lower {', '.join(raised)} or send fewer points"
        if raised
        else f"split the trace (about {max(2, int(cost.points * budget_mb / cost.megabytes)):,} "
        "points fit)"
    )
    msg = (
        f"matching this request would need about {cost.megabytes:,.0f} MB ({cost.points:,} "
        f"points, up to {cost.widest} candidates each within {cost.radius_m:.0f} m), more than "
        f"this service's budget of {budget_mb:,.0f} MB per match; {fix}"
    )
    raise OverBudgetError(msg, field=field)
