"""The fused track: the filter's output, ready to be matched."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

if TYPE_CHECKING:
    import numpy.typing as npt

    FloatArray = npt.NDArray[np.float64]

__all__ = ["TRACE_COLUMNS", "FusedTrack"]

TRACE_COLUMNS = ("time", "lat", "lon", "heading", "speed", "accuracy", "odometer")


@dataclass(frozen=True, slots=True, eq=False)
class FusedTrack:
    """
    Fused positions and distance, one entry per sensor epoch from the first usable GNSS fix.

    Attributes
    ----------
    time_s
        Epoch seconds.
    lon, lat
        Fused WGS84 position, degrees.
    heading_deg
        Fused heading, degrees clockwise from north in [0, 360).
    speed_mps
        Fused speed (odometer corrected by the estimated scale), m/s.
    accuracy_m
        1-sigma horizontal error from the filter covariance (square root of the largest
        eigenvalue of the 2x2 position covariance), metres.
    odometer_m
        Fused cumulative distance from the first epoch, metres.
    odo_scale, odo_scale_sigma
        Estimated odometer scale (odometer reading / true distance) and its 1 sigma per epoch.
    gyro_bias_dps
        Estimated gyro bias per epoch, deg/s.
    gyro_scale
        Estimated gyro scale factor (true rate / bias-corrected reading) per epoch.
    odo_scale_rls
        Odometer scale from the independent recursive least-squares calibration over
        GNSS-measured stretches (NaN until the first stretch completes).
    gnss_status
        Per epoch: 0 no fix, 1 fix used, 2 fix failed the quality gate (sats/HDOP),
        3 fix failed the innovation (chi-square) test.
    road_feedback_used
        Per epoch: a road pseudo-measurement was applied.
    first_row
        Index in the raw log of the first fused epoch (earlier rows have no position yet).
    """

    time_s: FloatArray
    lon: FloatArray
    lat: FloatArray
    heading_deg: FloatArray
    speed_mps: FloatArray
    accuracy_m: FloatArray
    odometer_m: FloatArray
    odo_scale: FloatArray
    odo_scale_sigma: FloatArray
    gyro_bias_dps: FloatArray
    gyro_scale: FloatArray
    odo_scale_rls: FloatArray
    gnss_status: npt.NDArray[np.int8]
    road_feedback_used: npt.NDArray[np.bool_]
    first_row: int

    def __len__(self) -> int:
        return int(self.time_s.shape[0])

    @property
    def distance_m(self) -> float:
        """Fused trip distance (last odometer value), metres."""
        return float(self.odometer_m[-1]) if len(self) else 0.0

    def to_dataframe(self, *, interval_s: float | None = None) -> pd.DataFrame:
        """
        Return the fused trace in the matcher's input columns.

        Columns are exactly ``time, lat, lon, heading, speed, accuracy, odometer`` (epoch
        seconds, degrees, degrees clockwise from north, m/s, 1-sigma metres, cumulative metres).

        Parameters
        ----------
        interval_s
            Keep one epoch per ``interval_s`` seconds (the first epoch at or after each
            multiple, plus the last epoch); None keeps every epoch. The odometer column stays
            cumulative, so no distance is lost by thinning.
        """
        keep = np.arange(len(self))
        if interval_s is not None and interval_s > 0.0 and len(self):
            slot = np.floor((self.time_s - self.time_s[0]) / interval_s + 1e-9)
            first = np.ones(len(self), dtype=bool)
            first[1:] = slot[1:] != slot[:-1]
            first[-1] = True
            keep = np.flatnonzero(first)
        return pd.DataFrame(
            {
                "time": self.time_s[keep],
                "lat": self.lat[keep],
                "lon": self.lon[keep],
                "heading": self.heading_deg[keep],
                "speed": self.speed_mps[keep],
                "accuracy": self.accuracy_m[keep],
                "odometer": self.odometer_m[keep],
            },
            columns=list(TRACE_COLUMNS),
        )
