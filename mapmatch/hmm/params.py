"""The matcher parameters the compiled stages read, as one float array per configuration.

The kernels of :mod:`mapmatch.hmm` take the parameters they need as ``params[P_...]`` from
:func:`model_params` (numba reads the ``P_`` indices as constants), so that a stage call passes
one array instead of a dozen floats.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig
    from mapmatch.types import FloatArray

__all__ = ["PARAMS", "model_params", "params_of"]

#: The fields of :class:`~mapmatch.config.MatchConfig` in the parameter array, in order.
PARAMS = (
    "max_emission_penalty",
    "heading_sigma_deg",
    "heading_min_speed_mps",
    "heading_full_speed_mps",
    "heading_max_penalty",
    "candidate_margin",
    "max_candidates",
    "nominal_speed_mps",
    "beta_m",
    "beta_per_s",
    "beta_per_sigma",
    "speed_factor",
    "speed_margin_mps",
    "speed_sigma_mps",
    "travel_tolerance_m",
    "travel_tolerance_frac",
    "travel_beta_m",
    "uturn_penalty",
    "uturn_evidence_penalty",
    "standstill_m",
    "standstill_sigmas",
    "min_log_transition",
    "route_factor",
    "route_slack_m",
    "route_reach_mps",
    "travel_accel_mps2",
    "uturn_speed_mps",
    "course_prune_deg",
    "service_penalty",
    "service_speed_mps",
    "search_radius_m",
    "core_radius_sigmas",
    "far_candidates",
)
(
    P_MAX_EMISSION_PENALTY,
    P_HEADING_SIGMA,
    P_HEADING_MIN_SPEED,
    P_HEADING_FULL_SPEED,
    P_HEADING_MAX_PENALTY,
    P_CANDIDATE_MARGIN,
    P_MAX_CANDIDATES,
    P_NOMINAL_SPEED,
    P_BETA_M,
    P_BETA_PER_S,
    P_BETA_PER_SIGMA,
    P_SPEED_FACTOR,
    P_SPEED_MARGIN,
    P_SPEED_SIGMA,
    P_TRAVEL_TOLERANCE_M,
    P_TRAVEL_TOLERANCE_FRAC,
    P_TRAVEL_BETA,
    P_UTURN_PENALTY,
    P_UTURN_EVIDENCE_PENALTY,
    P_STANDSTILL_M,
    P_STANDSTILL_SIGMAS,
    P_MIN_LOG_TRANSITION,
    P_ROUTE_FACTOR,
    P_ROUTE_SLACK,
    P_ROUTE_REACH,
    P_ACCEL,
    P_UTURN_SPEED,
    P_COURSE_PRUNE,
    P_SERVICE_PENALTY,
    P_SERVICE_SPEED,
    P_SEARCH_RADIUS,
    P_CORE_RADIUS_SIGMAS,
    P_FAR_CANDIDATES,
) = range(len(PARAMS))

_CACHE: dict[tuple[int, tuple[str, ...]], tuple[MatchConfig, FloatArray]] = {}


def params_of(config: MatchConfig, names: tuple[str, ...]) -> FloatArray:
    """
    The values of the fields ``names`` of ``config``, in that order, as one float array.

    Made once per configuration object and list of names, read-only: the kernels read their
    parameters from such arrays, and a match asks for them several times.

    Examples
    --------
    >>> from mapmatch.config import MatchConfig
    >>> params_of(MatchConfig(beta_m=4.0), ("beta_m", "sigma_m")).tolist()
    [4.0, 5.0]
    """
    key = (id(config), names)
    found = _CACHE.get(key)
    if found is not None and found[0] is config:
        return found[1]
    params = np.array([float(getattr(config, name)) for name in names], dtype=np.float64)
    params.flags.writeable = False
    if len(_CACHE) >= 64:
        _CACHE.pop(next(iter(_CACHE)))
    _CACHE[key] = (config, params)
    return params


def model_params(config: MatchConfig) -> FloatArray:
    """
    The parameter array of ``config``: :func:`params_of` the :data:`PARAMS`.

    Examples
    --------
    >>> from mapmatch.config import MatchConfig
    >>> float(model_params(MatchConfig(beta_m=4.0))[P_BETA_M])
    4.0
    """
    return params_of(config, PARAMS)
