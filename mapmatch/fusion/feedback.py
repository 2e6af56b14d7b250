"""Map-aided feedback: matched road positions fed back to the filter as pseudo-measurements."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from mapmatch.fusion.errors import RawLogError

if TYPE_CHECKING:
    import numpy.typing as npt

    FloatArray = npt.NDArray[np.float64]

__all__ = ["RoadFeedback"]

_SOURCE = "<road feedback>"


@dataclass(frozen=True, slots=True, eq=False)
class RoadFeedback:
    """
    Per-epoch road pseudo-measurements, built by a caller from a match result.

    Each entry says "at ``time_s`` the vehicle was on the road at ``(lon, lat)`` (WGS84), driving
    along ``road_heading_deg`` (clockwise from north, direction of travel)"; the position is
    uncertain by ``along_sigma_m`` along the road and ``cross_sigma_m`` across it (1 sigma).
    A matched point's cross-road error is small (lane width), its along-road error is what the
    matcher could not resolve (large on straight roads).

    Entries are applied at the sensor epoch whose time is nearest (within half an epoch);
    others are ignored. Use :meth:`from_arrays` to validate.
    """

    time_s: FloatArray
    lon: FloatArray
    lat: FloatArray
    road_heading_deg: FloatArray
    along_sigma_m: FloatArray
    cross_sigma_m: FloatArray

    def __len__(self) -> int:
        return int(self.time_s.shape[0])

    @classmethod
    def from_arrays(
        cls,
        time_s: npt.ArrayLike,
        lon: npt.ArrayLike,
        lat: npt.ArrayLike,
        road_heading_deg: npt.ArrayLike,
        along_sigma_m: npt.ArrayLike,
        cross_sigma_m: npt.ArrayLike,
    ) -> RoadFeedback:
        """
        Validate and broadcast the pseudo-measurements (sigmas may be scalars).

        Raises
        ------
        RawLogError
            Non-finite values or non-positive sigmas.

        Examples
        --------
        >>> fb = RoadFeedback.from_arrays([0.0, 1.0], [116.4, 116.4001], [39.9, 39.9],
        ...                              [90.0, 90.0], 10.0, 1.5)
        >>> len(fb), float(fb.cross_sigma_m[1])
        (2, 1.5)
        """
        arrays = np.broadcast_arrays(
            *(
                np.atleast_1d(np.asarray(a, dtype=np.float64))
                for a in (time_s, lon, lat, road_heading_deg, along_sigma_m, cross_sigma_m)
            )
        )
        names = ("time_s", "lon", "lat", "road_heading_deg", "along_sigma_m", "cross_sigma_m")
        for name, arr in zip(names, arrays, strict=True):
            bad = np.flatnonzero(~np.isfinite(arr))
            if bad.size:
                i = int(bad[0])
                raise RawLogError(
                    _SOURCE,
                    f"entry {i}: field {name!r} is not finite ({float(arr[i])!r})",
                    "drop unmatched points before building RoadFeedback",
                )
        for name, arr in zip(names[4:], arrays[4:], strict=True):
            bad = np.flatnonzero(arr <= 0.0)
            if bad.size:
                i = int(bad[0])
                raise RawLogError(
                    _SOURCE,
                    f"entry {i}: {name} must be > 0 (got {float(arr[i])!r})",
                    "give realistic 1-sigma errors in metres",
                )
        t, lon_a, lat_a, hd, al, cr = (a.copy() for a in arrays)
        return cls(t, lon_a, lat_a, hd, al, cr)
