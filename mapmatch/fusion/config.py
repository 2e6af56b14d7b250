"""Every noise, gating and calibration parameter of the fusion filter, with its source."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from mapmatch.fusion.errors import FusionConfigError

__all__ = ["FusionConfig"]

# Chi-square 99.9 % quantiles: 2 degrees of freedom (position, velocity) and 3 (road feedback).
_CHI2_2DOF_999 = 13.816
_CHI2_3DOF_999 = 16.266


@dataclass(frozen=True, slots=True, kw_only=True)
class FusionConfig:
    """
    Parameters of the GNSS/odometer/gyro extended Kalman filter.

    Defaults suit a passenger car with a MEMS yaw gyro, a wheel-speed odometer and a 1 Hz
    consumer GNSS receiver. Sources: [BDS] bds-ins-vehicle-navigation-hmm-map-matching,
    [DR] dead-reckoning-gps-dr-vehicle-positioning, [PHONE] smartphone-gps-ins-loose-coupling,
    [RLS] odometer-calibration-recursive-least-squares, [TAXI]
    gnss-ins-ridehailing-distance-metering (all in ``shared/reference``); "ours" marks a value
    chosen here and checked by the simulator tests.

    Examples
    --------
    >>> FusionConfig(max_hdop=3.0).max_hdop
    3.0
    >>> FusionConfig(gnss_uere_m=-1.0)
    Traceback (most recent call last):
    ...
    mapmatch.fusion.errors.FusionConfigError: FusionConfig.gnss_uere_m must be > 0 (got -1.0)
    """

    # --- GNSS quality gating -------------------------------------------------------------
    min_sats: int = 5
    """Fixes with fewer satellites are not used. [DR] sec. 4.1: below 4 no fix is possible and
    multipath spoils fixes with few satellites; we require one redundant satellite (ours)."""
    max_hdop: float = 4.0
    """Fixes with a larger HDOP are not used. [DR] 4.1 names HDOP as the criterion without a
    number; 4 is the usual "fair geometry" bound (ours)."""
    gnss_uere_m: float = 3.0
    """1-sigma horizontal error per axis at HDOP 1, metres; sigma = uere * hdop (hdop 1 when
    unknown). [BDS] 7.3: dynamic errors 0.6/2.8 m (lon/lat); [BDS] table 1: <= 10 m at 95 %."""
    chi2_gate_position: float = _CHI2_2DOF_999
    """Innovation test for GNSS positions (chi-square, 2 dof, 99.9 %); rejects multipath jumps."""
    max_consecutive_rejects: int = 5
    """After this many consecutive rejected fixes the filter assumes it has drifted, inflates
    its position covariance and accepts the fix (ours)."""
    gnss_speed_sigma_mps: float = 0.2
    """1-sigma receiver speed error. [BDS] table 1: speed accuracy <= 0.2 m/s."""
    gnss_course_sigma_floor_deg: float = 1.0
    """Floor of the course error; above it the error is speed_sigma / speed (ours)."""
    min_course_speed_mps: float = 5.0
    """Receiver course is used only above this speed. [DR] 4.2: heading from GNSS only at
    sufficient speed (the paper gives no number; ours)."""
    chi2_gate_velocity: float = _CHI2_2DOF_999
    """Innovation test for GNSS speed and course (chi-square, 2 dof, 99.9 %)."""

    # --- motion model and sensor noise ---------------------------------------------------
    gyro_arw_deg_per_sqrt_s: float = 0.02
    """Gyro angle random walk (white rate noise density), deg/sqrt(s); 0.063 deg/s per
    sample at 10 Hz. [PHONE] tunes ARW per device (table 1); MEMS automotive grade (ours)."""
    gyro_bias_sigma_dps: float = 0.5
    """Initial 1-sigma gyro bias; MEMS turn-on bias is tenths of deg/s ([DR] 3.1: the static
    value drifts with temperature and must be re-estimated)."""
    gyro_bias_walk_dps_per_sqrt_s: float = 0.002
    """Random walk of the gyro bias (temperature drift, [DR] 4.3), deg/s/sqrt(s) (ours)."""
    estimate_gyro_scale: bool = True
    """Estimate the gyro scale factor K_G ([DR] 3.2) as a state."""
    gyro_scale_sigma: float = 0.02
    """Initial 1-sigma relative gyro scale error ([DR] 5: left/right 90-degree turns differ)."""
    odo_speed_sigma_mps: float = 0.05
    """1-sigma odometer speed noise per sample (plus pulse quantisation for count logs)."""
    initial_odo_scale: float = 1.0
    """Prior odometer scale (odometer reading / true distance); pass a previous trip's
    estimate to start calibrated."""
    odo_scale_sigma: float = 0.05
    """Initial 1-sigma of the odometer scale: tyre wear and pressure change K_0 by a few
    per cent ([DR] 3.2)."""
    odo_scale_walk_per_sqrt_s: float = 1e-5
    """Random walk of the odometer scale (tyre warm-up, [DR] 3.2) per sqrt(s) (ours)."""
    accel_sigma_mps2: float = 1.5
    """Speed random walk, m/s^2 / sqrt(Hz): urban car accelerations (ours)."""
    position_walk_m_per_sqrt_s: float = 0.1
    """Position process noise for what the non-holonomic 2-D model leaves out (side slip,
    lane changes), m/sqrt(s). [PHONE]: the non-holonomic constraint cut 30 s outage drift from
    73 m to 50 m; our odometer-aided model has it built in (ours)."""
    zupt_speed_mps: float = 0.01
    """The vehicle is stopped when the odometer speed stays at or below this ..."""
    zupt_window_s: float = 0.5
    """... for this long; then speed is held at zero, heading is not integrated and the gyro
    reading updates its bias (zero-velocity / zero-angular-rate update, [PHONE], [BDS] 5)."""
    zupt_sigma_mps: float = 0.01
    """1-sigma of the zero-velocity pseudo-measurement."""
    heading_init_baseline_m: float = 30.0
    """Without a usable receiver course the initial heading is found by aligning the
    dead-reckoned path with the GNSS displacement over this distance ([DR] 4.2) (ours)."""

    # --- map-aided feedback --------------------------------------------------------------
    road_heading_sigma_deg: float = 5.0
    """1-sigma of the road-heading pseudo-measurement (vehicle vs road direction, [DR] 4.2)."""
    road_feedback_min_gnss_gap_s: float = 2.0
    """Road feedback is applied only when no GNSS fix was used for this long, so a match made
    from GNSS positions is not counted twice (ours)."""
    chi2_gate_road: float = _CHI2_3DOF_999
    """Innovation test for the road pseudo-measurement (chi-square, 3 dof, 99.9 %)."""

    # --- recursive least-squares odometer calibration (independent check) ----------------
    rls_stretch_m: float = 100.0
    """GNSS-measured stretch length per RLS observation ([RLS]: error "over a set distance")."""
    rls_forgetting: float = 1.0
    """RLS forgetting factor (1 = no forgetting; < 1 tracks a slowly changing scale)."""
    rls_max_gap_s: float = 5.0
    """A stretch is restarted when consecutive used fixes are further apart than this."""

    def __post_init__(self) -> None:
        positive = (
            "max_hdop",
            "gnss_uere_m",
            "chi2_gate_position",
            "gnss_speed_sigma_mps",
            "gnss_course_sigma_floor_deg",
            "chi2_gate_velocity",
            "gyro_arw_deg_per_sqrt_s",
            "odo_speed_sigma_mps",
            "initial_odo_scale",
            "accel_sigma_mps2",
            "zupt_sigma_mps",
            "heading_init_baseline_m",
            "road_heading_sigma_deg",
            "chi2_gate_road",
            "rls_stretch_m",
            "rls_max_gap_s",
        )
        non_negative = (
            "gyro_bias_sigma_dps",
            "gyro_bias_walk_dps_per_sqrt_s",
            "gyro_scale_sigma",
            "odo_scale_sigma",
            "odo_scale_walk_per_sqrt_s",
            "position_walk_m_per_sqrt_s",
            "zupt_speed_mps",
            "zupt_window_s",
            "min_course_speed_mps",
            "road_feedback_min_gnss_gap_s",
        )
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, float) and not math.isfinite(value):
                raise FusionConfigError(f.name, "finite", value)
        for name in positive:
            if not getattr(self, name) > 0.0:
                raise FusionConfigError(name, "> 0", getattr(self, name))
        for name in non_negative:
            if not getattr(self, name) >= 0.0:
                raise FusionConfigError(name, ">= 0", getattr(self, name))
        int_rules = (
            ("min_sats", self.min_sats >= 0, ">= 0"),
            ("max_consecutive_rejects", self.max_consecutive_rejects >= 1, ">= 1"),
            ("rls_forgetting", 0.9 <= self.rls_forgetting <= 1.0, "in [0.9, 1]"),
        )
        for name, ok, rule in int_rules:
            if not ok:
                raise FusionConfigError(name, rule, getattr(self, name))
