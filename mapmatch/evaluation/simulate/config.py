"""
How simulated trips are driven and observed: :class:`SimulationConfig` and its presets.

One frozen dataclass, validated once; :meth:`SimulationConfig.realistic` and
:meth:`SimulationConfig.noise_free` are the two presets the accuracy matrix and the
``mapmatch simulate`` flags start from.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from mapmatch.errors import ConfigError
from mapmatch.evaluation.simulate.columns import INPUT_CLASSES

__all__ = ["SimulationConfig"]


@dataclass(frozen=True, slots=True, kw_only=True)
class SimulationConfig:
    """
    How trips are driven and observed.

    Every realistic-noise option below is off by default; :meth:`realistic` switches them on
    with the values of a phone or a low-cost telematics box in a city, :meth:`noise_free`
    gives the exact truth.

    Sampling and route
        ``interval_s`` sampling interval (0.1 gives the 10 Hz truth); ``route_length_m``
        target length of each trip; ``route`` how trips are chosen: ``fastest`` (the fastest
        route between a random start and a random end about ``route_length_m`` away, as real
        trips are; no U-turn but at a dead end) or ``random_walk`` (meandering: straight on
        preferred at every junction).
    Position noise
        ``noise_m`` stationary 1-sigma position error per axis. White by default; correlated
        in time as an AR(1) process when ``noise_correlation_per_s`` (correlation of the error
        one second apart, e.g. 0.95 for raw GNSS, whose error wanders slowly) or, the same
        thing as a time constant, ``noise_correlation_s`` (tau: correlation ``exp(-dt / tau)``;
        a few seconds looks like a Kalman filter's output) is set; give at most one. The
        stationary std stays ``noise_m`` whatever the correlation and the gaps between fixes.
        ``outlier_rate`` share of fixes displaced by ``outlier_m`` in a random direction.
    Urban canyons
        ``canyon_per_km`` stretches per km of route (0: none) where multipath pulls every fix
        ``canyon_bias_m`` to one side of the road (perpendicular to the driving direction,
        the side drawn per stretch, constant over it), for a duration drawn uniformly from
        ``canyon_s`` seconds. The reported ``accuracy`` does not see the bias.
    Stops
        ``junction_stop_share`` share of the route's real junctions (nodes joining three or
        more neighbours) where the car stops: it brakes at ``decel_mps2``, stands for a
        duration drawn uniformly from ``junction_stop_s`` seconds while the receiver keeps
        reporting noisy fixes (true speed 0, position fixed), and pulls away at
        ``accel_mps2``. ``stop_probability`` / ``stop_s``: the older, brief stops at any node
        between two edges (junction or not), 2 s up to ``stop_s``.
    Heading and speed
        ``heading_noise_deg`` / ``speed_noise_mps`` 1-sigma noise; ``heading_noise_slow_deg``
        adds ``heading_noise_slow_deg * exp(-v / 1 m/s)`` to the heading's 1-sigma, so a slow
        or standing car's heading is nearly random (3 + 87 exp(-v) degrees: a GNSS course
        over ground degrades below walking speed).
    Outages
        ``outage_per_km`` outages per km of route (0: none) of a duration drawn uniformly from
        ``outage_range_s`` seconds without fixes (tunnels, garages); the older
        ``outage_rate`` is the chance per minute of an outage of ``outage_s``.
    Odometer
        The odometer reads ``1 + odometer_bias + U(-odometer_scale_error,
        +odometer_scale_error)`` times the distance driven (``odometer_bias`` 0.02: a meter
        2 % high; the random part is drawn per trip).
    Columns
        ``input_class`` which optional columns the trace keeps (:data:`INPUT_CLASSES`:
        ``positions``, ``accuracy``, ``heading_speed``, ``odometer`` = all); the truth is the
        same whatever it strips.
    """

    interval_s: float = 1.0
    noise_m: float = 5.0
    noise_correlation_s: float = 0.0
    noise_correlation_per_s: float = 0.0
    outlier_rate: float = 0.0
    outlier_m: float = 40.0
    outage_rate: float = 0.0
    outage_s: float = 30.0
    outage_per_km: float = 0.0
    outage_range_s: tuple[float, float] = (20.0, 60.0)
    canyon_per_km: float = 0.0
    canyon_s: tuple[float, float] = (10.0, 30.0)
    canyon_bias_m: float = 20.0
    heading_noise_deg: float = 5.0
    heading_noise_slow_deg: float = 0.0
    speed_noise_mps: float = 0.3
    odometer_scale_error: float = 0.005
    odometer_bias: float = 0.0
    route_length_m: float = 3000.0
    stop_probability: float = 0.15
    stop_s: float = 20.0
    junction_stop_share: float = 0.0
    junction_stop_s: tuple[float, float] = (5.0, 40.0)
    accel_mps2: float = 1.5
    decel_mps2: float = 2.5
    lateral_accel_mps2: float = 2.0
    route: str = "fastest"
    input_class: str = "odometer"

    def __post_init__(self) -> None:
        for name in ("interval_s", "route_length_m", "accel_mps2", "decel_mps2"):
            if not getattr(self, name) > 0:
                msg = f"{name} must be > 0 (got {getattr(self, name)!r})"
                raise ConfigError(msg)
        for name in ("outlier_rate", "stop_probability", "junction_stop_share"):
            if not 0 <= getattr(self, name) <= 1:
                msg = f"{name} must be within 0..1 (got {getattr(self, name)!r})"
                raise ConfigError(msg)
        for name in (
            "noise_m",
            "outage_rate",
            "noise_correlation_s",
            "outage_per_km",
            "canyon_per_km",
            "canyon_bias_m",
            "heading_noise_deg",
            "heading_noise_slow_deg",
            "speed_noise_mps",
            "odometer_scale_error",
        ):
            if not getattr(self, name) >= 0:
                msg = f"{name} must be >= 0 (got {getattr(self, name)!r})"
                raise ConfigError(msg)
        for name in ("outage_range_s", "canyon_s", "junction_stop_s"):
            lo, hi = getattr(self, name)
            if not 0 < lo <= hi:
                msg = f"{name} must be a range (low, high) with 0 < low <= high (got {(lo, hi)!r})"
                raise ConfigError(msg)
        if not 0 <= self.noise_correlation_per_s < 1:
            msg = (
                "noise_correlation_per_s must be within 0..1 (1 excluded: the error would never "
                f"change; got {self.noise_correlation_per_s!r})"
            )
            raise ConfigError(msg)
        if self.noise_correlation_per_s > 0 and self.noise_correlation_s > 0:
            msg = (
                "give noise_correlation_per_s or noise_correlation_s, not both (got "
                f"{self.noise_correlation_per_s!r} and {self.noise_correlation_s!r}); "
                "correlation per second rho = exp(-1 / tau)"
            )
            raise ConfigError(msg)
        if not self.odometer_bias > -1:
            msg = f"odometer_bias must be > -1 (got {self.odometer_bias!r}); 0.02 is 2 % high"
            raise ConfigError(msg)
        if self.route not in ("fastest", "random_walk"):
            msg = f"route must be 'fastest' or 'random_walk' (got {self.route!r})"
            raise ConfigError(msg)
        if self.input_class not in INPUT_CLASSES:
            msg = f"input_class must be one of {sorted(INPUT_CLASSES)} (got {self.input_class!r})"
            raise ConfigError(msg)

    @property
    def correlation_time_s(self) -> float:
        """Time constant tau of the position error's AR(1) process (0: white noise)."""
        if self.noise_correlation_per_s > 0:
            return -1.0 / math.log(self.noise_correlation_per_s)
        return self.noise_correlation_s

    def replace(self, **changes: Any) -> SimulationConfig:
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)

    @classmethod
    def noise_free(cls, **changes: Any) -> SimulationConfig:
        """
        Exact observations; ``changes`` set other fields (``interval_s`` ...).

        No position, heading or speed noise, no outliers or outages, an exact odometer, every
        column. The ``accuracy`` column then reads 1 m (the smallest it reports). Stops stay as
        configured: a stop is driving, not noise.

        Examples
        --------
        >>> cfg = SimulationConfig.noise_free(interval_s=15.0)
        >>> cfg.noise_m, cfg.heading_noise_deg, cfg.odometer_scale_error, cfg.interval_s
        (0.0, 0.0, 0.0, 15.0)
        """
        exact: dict[str, Any] = {
            "noise_m": 0.0,
            "outlier_rate": 0.0,
            "outage_rate": 0.0,
            "outage_per_km": 0.0,
            "canyon_per_km": 0.0,
            "heading_noise_deg": 0.0,
            "heading_noise_slow_deg": 0.0,
            "speed_noise_mps": 0.0,
            "odometer_scale_error": 0.0,
            "odometer_bias": 0.0,
        }
        return cls(**{**exact, **changes})

    @classmethod
    def realistic(cls, **changes: Any) -> SimulationConfig:
        """
        Raw-GNSS-like city observations; ``changes`` set other fields (``interval_s`` ...).

        AR(1) position error with correlation 0.95 per second and 6 m stationary std per
        axis; 2 % outliers of 40 m; urban canyons 0.5 per km of 10-30 s pulling the fixes
        20 m to one side; stops at a third of the junctions of 5-40 s (no other stops);
        heading noise 3 + 87 exp(-v) degrees, speed noise 0.3 m/s; outages 0.3 per km of
        20-60 s; the odometer reads exactly 2 % high.

        Examples
        --------
        >>> cfg = SimulationConfig.realistic(interval_s=15.0)
        >>> cfg.noise_correlation_per_s, cfg.odometer_bias, cfg.interval_s
        (0.95, 0.02, 15.0)
        """
        rough: dict[str, Any] = {
            "noise_m": 6.0,
            "noise_correlation_per_s": 0.95,
            "outlier_rate": 0.02,
            "canyon_per_km": 0.5,
            "canyon_s": (10.0, 30.0),
            "canyon_bias_m": 20.0,
            "stop_probability": 0.0,
            "junction_stop_share": 1.0 / 3.0,
            "junction_stop_s": (5.0, 40.0),
            "heading_noise_deg": 3.0,
            "heading_noise_slow_deg": 87.0,
            "speed_noise_mps": 0.3,
            "outage_per_km": 0.3,
            "outage_range_s": (20.0, 60.0),
            "odometer_bias": 0.02,
            "odometer_scale_error": 0.0,
        }
        return cls(**{**rough, **changes})
