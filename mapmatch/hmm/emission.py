"""Log emission of every candidate: distance to the road, and heading agreement at speed.

Gaussian in the distance (Newson & Krumm), floored so that an outlier cannot veto the true
road; plus a Gaussian on the angle between the reported heading and the road direction whose
weight rises with speed (reference paper, section 6, eq. 23).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig
    from mapmatch.hmm.candidates import Candidates
    from mapmatch.hmm.observations import Observations
    from mapmatch.types import FloatArray, IntArray

__all__ = ["distance_emission", "emissions", "heading_weight", "log_emission", "log_heading"]


def log_emission(distance_m: FloatArray, *, sigma_m: FloatArray | float) -> FloatArray:
    """
    Log-likelihood of seeing each fix ``distance_m`` away from its candidate.

    Gaussian position error. The normalising constant is dropped because it is the same for
    every candidate of one fix.

    Parameters
    ----------
    distance_m
        Distance from each fix to its candidate road position, in metres.
    sigma_m
        Standard deviation of the position error, in metres (one value or one per candidate).

    Examples
    --------
    >>> log_emission(np.array([5.0, 10.0]), sigma_m=5.0)
    array([-0.5, -2. ])
    """
    return -0.5 * (distance_m / sigma_m) ** 2


def distance_emission(
    distance_m: FloatArray, sigma_m: FloatArray, config: MatchConfig
) -> FloatArray:
    """Gaussian log emission of a distance to the road, floored at ``-max_emission_penalty``."""
    em = log_emission(distance_m, sigma_m=sigma_m)
    if config.max_emission_penalty > 0:
        em = np.logaddexp(em, -config.max_emission_penalty)
    return em


def heading_weight(speed_mps: FloatArray, config: MatchConfig) -> FloatArray:
    """
    How much the heading counts at each speed: 0 when (nearly) stopped, 1 at road speeds.

    Examples
    --------
    >>> from mapmatch.config import MatchConfig
    >>> heading_weight(np.array([0.0, 5.5, 20.0, np.nan]), MatchConfig())
    array([0. , 0.5, 1. , 0. ])
    """
    lo, hi = config.heading_min_speed_mps, config.heading_full_speed_mps
    weight = np.clip((speed_mps - lo) / (hi - lo), 0.0, 1.0)
    return np.nan_to_num(weight, nan=0.0)


def log_heading(
    heading_deg: FloatArray, bearing_deg: FloatArray, weight: FloatArray, config: MatchConfig
) -> FloatArray:
    """
    Log-likelihood of the reported heading given the road direction at the candidate.

    A Gaussian on the angle between them (``heading_sigma_deg``), scaled by the speed weight
    and floored at ``-heading_max_penalty``. Unknown headings (NaN) score 0.

    Examples
    --------
    >>> from mapmatch.config import MatchConfig
    >>> log_heading(np.array([90.0, 90.0]), np.array([90.0, 270.0]), np.ones(2), MatchConfig())
    array([ -0., -12.])
    """
    diff = np.abs((heading_deg - bearing_deg + 180.0) % 360.0 - 180.0)
    score = np.maximum(-0.5 * (diff / config.heading_sigma_deg) ** 2, -config.heading_max_penalty)
    return np.nan_to_num(weight * score, nan=0.0)


def emissions(
    fixes: Observations, cands: Candidates, fix_of: IntArray, config: MatchConfig
) -> FloatArray:
    """Log emission of every candidate: distance to the road, and heading when known."""
    em = distance_emission(cands.distance_m, fixes.sigma_m[fix_of], config)
    if fixes.heading_deg is not None:
        weight = heading_weight(fixes.speed_mps, config)
        em += log_heading(fixes.heading_deg[fix_of], cands.bearing_deg, weight[fix_of], config)
    return em
