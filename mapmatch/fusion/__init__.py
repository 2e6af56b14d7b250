"""
Fusion front-end: raw GNSS + odometer + gyro logs in, fused positions and distance out.

>>> from mapmatch.fusion import RawLog, fuse                  # doctest: +SKIP
>>> track = fuse(RawLog.from_file("raw.csv", crs="gcj02"))    # doctest: +SKIP
>>> track.to_dataframe(interval_s=1.0).to_csv("trace.csv")    # doctest: +SKIP

Modules: :mod:`~mapmatch.fusion.rawlog` (input layout and validation),
:mod:`~mapmatch.fusion.config` (parameters and their sources), :mod:`~mapmatch.fusion.ekf`
(the filter), :mod:`~mapmatch.fusion.calibration` (RLS odometer check),
:mod:`~mapmatch.fusion.feedback` (map-aided pseudo-measurements), :mod:`~mapmatch.fusion.fuse`,
:mod:`~mapmatch.fusion.track` (output), :mod:`~mapmatch.fusion.trajectory` and
:mod:`~mapmatch.fusion.simulate` (ground truth and the raw-log simulator),
:mod:`~mapmatch.fusion.geo` (local tangent plane), :mod:`~mapmatch.fusion.road` (road
bearings, feedback from a match result) and :mod:`~mapmatch.fusion.pipeline` (raw logs from
real-road drives, the fuse -> match -> feedback -> fuse -> match loop).
"""

from __future__ import annotations

from mapmatch.fusion.config import FusionConfig
from mapmatch.fusion.errors import (
    FusionConfigError,
    NoGnssFixError,
    RawLogError,
    RawLogNotFoundError,
)
from mapmatch.fusion.feedback import RoadFeedback
from mapmatch.fusion.fuse import fuse
from mapmatch.fusion.geo import LocalTangentPlane
from mapmatch.fusion.pipeline import (
    RAW_COLUMNS,
    FusedMatch,
    fuse_and_match,
    raw_log_dataframe,
    simulate_trip_raw_log,
    true_trajectory_of,
    write_raw_logs,
)
from mapmatch.fusion.rawlog import RawLog
from mapmatch.fusion.road import road_bearing_deg, road_feedback_from_match
from mapmatch.fusion.simulate import RawLogSimConfig, SimTruth, simulate_raw_log
from mapmatch.fusion.track import TRACE_COLUMNS, FusedTrack
from mapmatch.fusion.trajectory import (
    Leg,
    TrueTrajectory,
    build_trajectory,
    stop,
    straight,
    turn,
)

__all__ = [
    "RAW_COLUMNS",
    "TRACE_COLUMNS",
    "FusedMatch",
    "FusedTrack",
    "FusionConfig",
    "FusionConfigError",
    "Leg",
    "LocalTangentPlane",
    "NoGnssFixError",
    "RawLog",
    "RawLogError",
    "RawLogNotFoundError",
    "RawLogSimConfig",
    "RoadFeedback",
    "SimTruth",
    "TrueTrajectory",
    "build_trajectory",
    "fuse",
    "fuse_and_match",
    "raw_log_dataframe",
    "road_bearing_deg",
    "road_feedback_from_match",
    "simulate_raw_log",
    "simulate_trip_raw_log",
    "stop",
    "straight",
    "true_trajectory_of",
    "turn",
    "write_raw_logs",
]
