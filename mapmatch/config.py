"""Every matching parameter in one validated object."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from mapmatch.errors import ConfigError

__all__ = ["OVERRIDABLE", "MatchConfig"]


@dataclass(frozen=True, slots=True, kw_only=True)
class MatchConfig:
    """
    Matcher parameters; defaults suit fused car traces at 1-30 s sampling.

    Candidates
        ``search_radius_m`` (50 m): roads farther from a fix are not considered. A fix whose
        ``accuracy`` is poor widens its own radius to ``radius_accuracy_factor`` x accuracy,
        never beyond ``max_search_radius_m`` (200 m). ``max_candidates`` (8) directed edges are
        kept per fix; each direction of a two-way road counts, so 8 means four roads.
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
        ``standstill_m`` (15 m) is noise around a stopped car; a U-turn in the middle of a road
        costs ``uturn_penalty`` (6 nats).
    Distance check
        ``distance_band`` (-4 % .. +1 %): the relative error of the fused trip distance against
        the matched road length that passes; the metering tolerance of JJG 517 taximeters.
    """

    search_radius_m: float = 50.0
    max_search_radius_m: float = 200.0
    radius_accuracy_factor: float = 4.0
    max_candidates: int = 8
    sigma_m: float = 5.0
    heading_sigma_deg: float = 25.0
    heading_min_speed_mps: float = 1.0
    heading_full_speed_mps: float = 10.0
    heading_max_penalty: float = 12.0
    beta_m: float = 3.0
    beta_per_s: float = 0.3
    route_factor: float = 2.0
    route_slack_m: float = 300.0
    speed_factor: float = 1.5
    speed_margin_mps: float = 5.0
    speed_sigma_mps: float = 5.0
    standstill_m: float = 15.0
    uturn_penalty: float = 6.0
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
            "speed_factor",
            "speed_sigma_mps",
        )
        non_negative = (
            "heading_min_speed_mps",
            "heading_max_penalty",
            "beta_per_s",
            "route_slack_m",
            "speed_margin_mps",
            "standstill_m",
            "uturn_penalty",
        )
        for name in positive:
            _check(name, getattr(self, name), lambda v: v > 0, "must be > 0")
        for name in non_negative:
            _check(name, getattr(self, name), lambda v: v >= 0, "must be >= 0")
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
            msg = f"distance_band must be (low <= 0, high >= 0) fractions (got {self.distance_band})"
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
        "standstill_m",
        "distance_band",
    }
)
