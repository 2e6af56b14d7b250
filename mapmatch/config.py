"""Every matching parameter in one validated object."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from mapmatch.errors import ConfigError

if TYPE_CHECKING:
    from collections.abc import Callable, Mapping

__all__ = ["OVERRIDABLE", "MatchConfig"]


@dataclass(frozen=True, slots=True, kw_only=True)
class MatchConfig:
    """
    Matcher parameters; defaults suit fused car traces at 1-30 s sampling.

    Candidates
        ``search_radius_m`` (50 m): roads farther from a fix are not considered. A fix whose
        ``accuracy`` is poor widens its own radius to ``radius_accuracy_factor`` x accuracy,
        never beyond ``max_search_radius_m`` (200 m). ``max_candidates`` (16) directed edges
        are kept per fix; each direction of a two-way road counts, and every edge meeting at
        a junction is as near as the junction, so fewer loses the true road near junctions
        (8 tripled the route mismatch at 1 s on the Monaco extract).
    Emission
        ``sigma_m`` (5 m): 1-sigma position error of a fused fix (GNSS/INS loosely coupled
        filters reach 3-4 m at 1 Hz, reference paper section 7; Newson & Krumm estimated
        4.07 m for raw GNSS). A fix's own ``accuracy`` replaces it when larger.
        ``heading_sigma_deg`` (25 deg): spread of the fused heading around the road direction
        (about three times the 8 deg 1-sigma heading error of a smartphone GNSS/INS filter,
        leaving room for lane changes and curves). Its weight grows linearly from 0 at
        ``heading_min_speed_mps`` (1 m/s: a stopped car's heading means nothing) to 1 at
        ``heading_full_speed_mps`` (10 m/s); a wrong heading costs at most
        ``heading_max_penalty`` (12 nats), so a bad heading sample cannot veto the true road.
    Transition
        Exponential in ``|great-circle - route distance|`` with scale
        ``beta_m + beta_per_s * dt`` (3 m + 0.3 m/s): chords cut curves more the longer the
        sampling interval, so the scale grows with it (Newson & Krumm's beta grows with the
        interval likewise). Routes are searched up to ``route_factor * great-circle +
        route_slack_m`` (2 x + 300 m). Speed plausibility: the speed a path needs
        (route / dt, less twice sigma for noise) above ``speed_factor`` x the path's speed
        limit + ``speed_margin_mps`` (1.5 x + 5 m/s) costs a Gaussian penalty with
        ``speed_sigma_mps`` (5 m/s). A move backwards along the same edge of at most
        ``standstill_m`` (10 m) or ``standstill_sigmas`` x sigma (4, so 20 m at 5 m) is noise
        around a slow or stopped car, not a turn; a U-turn in the middle of a road
        costs ``uturn_penalty`` (6 nats). Fused traces know how far the car went between two
        fixes (odometer increments, else the mean reported speed x dt); with ``use_travel``
        a route that differs from that by more than ``travel_tolerance_m +
        travel_tolerance_frac * travel + travel_tolerance_mps * dt`` (5 m + 15 % + 0.5 m/s x
        dt) costs the excess / ``travel_beta_m`` (2 m). The tolerance is wide on purpose:
        the term rejects loops around a stopped car and detours, but never pulls the matched
        length towards the fused one, which the distance check must judge independently.
    Fix selection
        As Newson & Krumm do, a fix within ``thinning_sigmas`` x sigma (2) of the previous
        kept fix adds nothing but noise (a stopped or crawling car) and is left out of the
        model. A fix farther than ``outlier_sigmas`` x sigma (5) from where its neighbours put
        it (both at most ``outlier_max_gap_s``, 5 s, away) is an outlier and left out too.
        A transition less likely than ``min_log_transition`` (-50 nats: a loop around a block
        to go 30 m back, a detour of hundreds of metres) is taken as impossible: such moves
        come from a displaced fix, not from driving. Where the trace then breaks, up to
        ``max_break_repairs`` (8) times the fix at the break is left out if that joins the
        pieces. Left-out fixes get the position on the
        matched path interpolated by time, and are flagged in the output.
    Distance check
        ``distance_band`` (-4 % .. +1 %): the relative error of the fused trip distance against
        the matched road length that passes; the metering tolerance of JJG 517 taximeters.
    """

    search_radius_m: float = 50.0
    max_search_radius_m: float = 200.0
    radius_accuracy_factor: float = 4.0
    max_candidates: int = 16
    candidate_margin: float = 10.0
    sigma_m: float = 5.0
    estimate_sigma: bool = True
    max_emission_penalty: float = 8.0
    heading_sigma_deg: float = 25.0
    heading_min_speed_mps: float = 1.0
    heading_full_speed_mps: float = 10.0
    heading_max_penalty: float = 12.0
    beta_m: float = 3.0
    beta_per_s: float = 0.3
    beta_per_sigma: float = 0.3
    route_factor: float = 2.0
    route_slack_m: float = 300.0
    speed_factor: float = 1.5
    speed_margin_mps: float = 5.0
    speed_sigma_mps: float = 5.0
    standstill_m: float = 10.0
    standstill_sigmas: float = 4.0
    uturn_penalty: float = 10.0
    uturn_evidence_penalty: float = 3.0
    loop_penalty: float = 6.0
    use_travel: bool = True
    travel_tolerance_m: float = 5.0
    travel_tolerance_frac: float = 0.15
    travel_tolerance_mps: float = 0.5
    travel_beta_m: float = 2.0
    travel_accel_mps2: float = 3.0
    nominal_speed_mps: float = 10.0
    max_speed_mps: float = 50.0
    thinning_sigmas: float = 2.0
    outlier_sigmas: float = 5.0
    outlier_max_gap_s: float = 5.0
    outlier_detour_ratio: float = 2.0
    outlier_max_run: int = 3
    max_break_repairs: int = 8
    min_log_transition: float = -50.0
    distance_band: tuple[float, float] = (-0.04, 0.01)

    def __post_init__(self) -> None:
        positive = (
            "search_radius_m",
            "max_search_radius_m",
            "radius_accuracy_factor",
            "sigma_m",
            "heading_sigma_deg",
            "heading_full_speed_mps",
            "beta_m",
            "route_factor",
            "travel_beta_m",
            "speed_factor",
            "speed_sigma_mps",
            "nominal_speed_mps",
            "max_speed_mps",
        )
        non_negative = (
            "max_emission_penalty",
            "candidate_margin",
            "heading_min_speed_mps",
            "heading_max_penalty",
            "beta_per_s",
            "beta_per_sigma",
            "route_slack_m",
            "speed_margin_mps",
            "standstill_m",
            "standstill_sigmas",
            "uturn_penalty",
            "uturn_evidence_penalty",
            "loop_penalty",
            "travel_tolerance_m",
            "travel_tolerance_frac",
            "travel_tolerance_mps",
            "thinning_sigmas",
            "outlier_sigmas",
            "outlier_max_gap_s",
            "outlier_detour_ratio",
            "travel_accel_mps2",
        )
        for name in positive:
            _check(name, getattr(self, name), lambda v: v > 0, "must be > 0")
        for name in non_negative:
            _check(name, getattr(self, name), lambda v: v >= 0, "must be >= 0")
        if not (math.isfinite(self.min_log_transition) and self.min_log_transition < 0):
            msg = (
                f"min_log_transition must be a finite number < 0 (got {self.min_log_transition!r})"
            )
            raise ConfigError(msg)
        if not isinstance(self.max_break_repairs, int) or self.max_break_repairs < 0:
            msg = f"max_break_repairs must be an integer >= 0 (got {self.max_break_repairs!r})"
            raise ConfigError(msg)
        if not isinstance(self.max_candidates, int) or not 1 <= self.max_candidates <= 64:
            msg = f"max_candidates must be an integer in 1..64 (got {self.max_candidates!r})"
            raise ConfigError(msg)
        if self.search_radius_m > self.max_search_radius_m:
            msg = (
                f"search_radius_m must be <= max_search_radius_m "
                f"(got {self.search_radius_m:g} > {self.max_search_radius_m:g})"
            )
            raise ConfigError(msg)
        if self.max_search_radius_m > 5000:
            msg = f"max_search_radius_m must be <= 5000 (got {self.max_search_radius_m:g})"
            raise ConfigError(msg)
        if self.heading_min_speed_mps >= self.heading_full_speed_mps:
            msg = (
                "heading_min_speed_mps must be below heading_full_speed_mps "
                f"(got {self.heading_min_speed_mps:g} >= {self.heading_full_speed_mps:g})"
            )
            raise ConfigError(msg)
        low, high = self.distance_band
        if not (math.isfinite(low) and math.isfinite(high) and -1 < low <= 0 <= high < 10):
            msg = (
                f"distance_band must be (low <= 0, high >= 0) fractions (got {self.distance_band})"
            )
            raise ConfigError(msg)

    def replace(self, overrides: Mapping[str, object]) -> MatchConfig:
        """
        A copy with some fields changed; only names in :data:`OVERRIDABLE` are accepted.

        Raises
        ------
        ConfigError
            An unknown or non-overridable field, or a value that breaks a rule.
        """
        unknown = sorted(set(overrides) - OVERRIDABLE)
        if unknown:
            msg = f"unknown option(s) {unknown}; allowed: {sorted(OVERRIDABLE)}"
            raise ConfigError(msg)
        changes = dict(overrides)
        if "distance_band" in changes:
            band = changes["distance_band"]
            if not isinstance(band, list | tuple) or len(band) != 2:
                msg = f"distance_band must be a pair [low, high] (got {band!r})"
                raise ConfigError(msg)
            changes["distance_band"] = (float(band[0]), float(band[1]))
        return dataclasses.replace(self, **changes)  # type: ignore[arg-type]


def _check(name: str, value: object, rule: Callable[[float], bool], text: str) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        msg = f"{name} must be a finite number (got {value!r})"
        raise ConfigError(msg)
    if not rule(value):
        msg = f"{name} {text} (got {value:g})"
        raise ConfigError(msg)


#: Fields a single request (HTTP ``options``, CLI flags) may override.
OVERRIDABLE = frozenset(
    {
        "search_radius_m",
        "max_candidates",
        "sigma_m",
        "heading_sigma_deg",
        "beta_m",
        "beta_per_s",
        "uturn_penalty",
        "use_travel",
        "standstill_m",
        "thinning_sigmas",
        "outlier_sigmas",
        "distance_band",
    }
)
