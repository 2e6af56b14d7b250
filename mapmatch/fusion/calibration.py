"""
Recursive least-squares odometer calibration over GNSS-measured stretches.

An independent check of the filter's odometer-scale state, after the calibration patent in
``shared/reference`` (odometer-calibration-recursive-least-squares): over each stretch of about
``stretch_m`` metres between two used GNSS fixes, the dead-reckoned displacement (raw odometer
distance along the fused heading) is regressed on the GNSS displacement,
``d_gnss = k * d_dr`` per axis, and ``k`` is fitted by recursive least squares. The odometer
scale (odometer reading / true distance) is ``1 / k``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import numpy.typing as npt

    FloatArray = npt.NDArray[np.float64]

__all__ = ["ScalarRLS", "rls_odometer_scale"]


@dataclass(slots=True)
class ScalarRLS:
    """
    Recursive least squares for one parameter ``k`` in ``y = k * phi + noise``.

    Examples
    --------
    >>> rls = ScalarRLS(k=1.0, p=1e6)
    >>> for phi in (10.0, 20.0, 30.0):
    ...     rls.update(phi, 0.98 * phi)
    >>> round(rls.k, 6)
    0.98
    """

    k: float = 1.0
    p: float = 1e6
    forgetting: float = 1.0
    n: int = field(default=0)

    def update(self, phi: float, y: float) -> None:
        """Fold in one observation ``y`` of ``k * phi``."""
        gain = self.p * phi / (self.forgetting + phi * self.p * phi)
        self.k += gain * (y - self.k * phi)
        self.p = (self.p - gain * phi * self.p) / self.forgetting
        self.n += 1


def rls_odometer_scale(
    time_s: FloatArray,
    odo_speed_mps: FloatArray,
    yaw_rad: FloatArray,
    fix_x_m: FloatArray,
    fix_y_m: FloatArray,
    fix_used: npt.NDArray[np.bool_],
    *,
    stretch_m: float,
    max_gap_s: float,
    forgetting: float = 1.0,
) -> FloatArray:
    """
    Odometer scale estimated by RLS over GNSS-measured stretches, per epoch (NaN before any).

    Parameters
    ----------
    time_s
        Epoch times, seconds.
    odo_speed_mps
        Raw odometer speed over the interval ending at each epoch.
    yaw_rad
        Fused heading per epoch, radians counter-clockwise from east.
    fix_x_m, fix_y_m
        GNSS fix in local metres (NaN without a fix).
    fix_used
        Fixes the filter accepted (quality gate and innovation test passed).
    stretch_m
        Minimum GNSS displacement of one stretch.
    max_gap_s
        A stretch restarts when used fixes are further apart in time than this.
    forgetting
        RLS forgetting factor.

    Returns
    -------
    numpy.ndarray
        Odometer reading / true distance, the latest estimate at each epoch.
    """
    n = time_s.shape[0]
    dt = np.zeros(n)
    dt[1:] = np.diff(time_s)
    yaw_mid = yaw_rad.copy()
    yaw_mid[1:] = yaw_rad[:-1] + 0.5 * np.angle(np.exp(1j * (yaw_rad[1:] - yaw_rad[:-1])))
    step = odo_speed_mps * dt
    cum_x = np.cumsum(step * np.cos(yaw_mid))
    cum_y = np.cumsum(step * np.sin(yaw_mid))
    out = np.full(n, np.nan)
    rls = ScalarRLS(k=1.0, p=1e6, forgetting=forgetting)
    used = np.flatnonzero(fix_used)
    start = -1
    last = -1
    for i in used.tolist():
        if start < 0 or time_s[i] - time_s[last] > max_gap_s:
            start = last = i
            continue
        last = i
        gx = fix_x_m[i] - fix_x_m[start]
        gy = fix_y_m[i] - fix_y_m[start]
        if math.hypot(gx, gy) < stretch_m:
            continue
        dx = cum_x[i] - cum_x[start]
        dy = cum_y[i] - cum_y[start]
        rls.update(float(dx), float(gx))
        rls.update(float(dy), float(gy))
        out[i] = 1.0 / rls.k
        start = i
    # carry the latest estimate forward
    valid = np.isfinite(out)
    idx = np.where(valid, np.arange(n), -1)
    np.maximum.accumulate(idx, out=idx)
    return np.where(idx >= 0, out[np.maximum(idx, 0)], np.nan)
