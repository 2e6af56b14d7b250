"""The trip-distance cross-check: fused distance against the matched road length."""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Literal

import numpy as np

from mapmatch.frozen import quick_init

if TYPE_CHECKING:
    from mapmatch.types import BoolArray, FloatArray

__all__ = [
    "END_OUTLIERS",
    "DistanceCheck",
    "check_distance",
    "chord_length_m",
    "measured_chord",
    "measured_span",
]

Verdict = Literal["pass", "over", "under", "incomplete"]
Source = Literal["odometer", "caller", "chord"]
Evidence = Literal["positions", "heading", "odometer"]

_log = logging.getLogger("mapmatch")


@quick_init
@dataclass(frozen=True, slots=True)
class DistanceCheck:
    """
    The fused trip distance held against the matched road distance.

    Attributes
    ----------
    matched_length_m
        Road distance along the matched path, metres.
    fused_length_m
        Trip distance the vehicle reported, metres.
    source
        Where the fused distance came from: the ``odometer`` column (last - first), a
        distance the ``caller`` gave, or the ``chord`` sum of the raw positions (which
        undercounts curves at low sampling rates).
    relative_error
        ``(fused - matched) / matched``; NaN when the matched length is 0.
    band
        The pass band ``(low, high)`` of relative errors.
    verdict
        ``pass`` inside the band, ``over``/``under`` outside it, ``incomplete`` when breaks
        or unmatched fixes leave part of the road distance unknown (an outlier left
        unmatched at an end does not: both distances then run between the first and last
        matched fix, :func:`measured_span`).
    evidence
        What the matched length rests on, the strongest of: ``positions`` only (the
        weakest: a route between fixes, chosen by distance), ``heading`` (the reported
        heading at speed told directions and U-turns apart), ``odometer`` (the travelled
        distance between fixes ruled out loops and detours). A verdict on a length that
        rests on positions alone deserves less trust.
    uturns
        U-turns on the matched path: each one is driven distance that only a U-turn
        explains, so a verdict that hangs on one is worth a look.
    """

    matched_length_m: float
    fused_length_m: float
    source: Source
    relative_error: float
    band: tuple[float, float]
    verdict: Verdict
    evidence: Evidence = "positions"
    uturns: int = 0

    def to_dict(self) -> dict[str, object]:
        """JSON-ready members (NaN becomes ``None``)."""
        out = {name: getattr(self, name) for name in _CHECK_FIELDS}  # asdict deep-copies
        out["band"] = list(self.band)
        if math.isnan(self.relative_error):
            out["relative_error"] = None
        return out


_CHECK_FIELDS = tuple(f.name for f in fields(DistanceCheck))


#: At most this many unmatched outliers at either end of a trace leave its length complete.
END_OUTLIERS = 2


def measured_span(
    matched: BoolArray, outlier: BoolArray, segments: int, odometer_m: FloatArray | None
) -> tuple[slice, bool, FloatArray | None]:
    """
    The fixes the distance check compares, whether the length covers them, their odometer.

    With one segment and every fix before the first matched one and after the last one an
    outlier (at most :data:`END_OUTLIERS` at each end: a displaced fix, not a stretch away
    from the roads), the check compares the span from the first to the last matched fix,
    odometer included, and the length is complete (unless there is no odometer: a caller's
    distance is the whole trip's). Otherwise the whole trace, and the length is complete only
    if one segment runs from the first fix to the last.

    Examples
    --------
    >>> matched = np.array([False, True, True, True])
    >>> odometer = np.array([0.0, 10.0, 20.0, 30.0])
    >>> measured_span(matched, np.array([True, False, False, False]), 1, odometer)
    (slice(1, 4, None), True, array([10., 20., 30.]))
    >>> measured_span(matched, np.zeros(4, dtype=bool), 1, None)
    (slice(None, None, None), False, None)
    """
    from mapmatch._measure import span_kernel  # compiled: imported when first asked for

    lo, hi, complete = span_kernel(
        np.ascontiguousarray(matched, np.bool_),
        np.ascontiguousarray(outlier, np.bool_),
        int(segments),
        odometer_m is not None,
    )
    return _span_of(lo, hi, len(matched), complete, odometer_m)


def _span_of(
    lo: int, hi: int, n: int, complete: bool, odometer_m: FloatArray | None
) -> tuple[slice, bool, FloatArray | None]:
    """:func:`measured_span`'s answer from the compiled span's bounds."""
    if lo == 0 and hi == n:
        return slice(None), bool(complete), odometer_m
    span = slice(int(lo), int(hi))
    return span, bool(complete), None if odometer_m is None else odometer_m[span]


def chord_length_m(x: FloatArray, y: FloatArray) -> float:
    """
    Sum of straight-line distances between consecutive positions, metres.

    Examples
    --------
    >>> chord_length_m(np.array([0.0, 3.0, 3.0]), np.array([0.0, 4.0, 8.0]))
    9.0
    """
    from mapmatch._measure import chord_kernel  # compiled: imported when first asked for

    x = np.ascontiguousarray(x, np.float64)
    return float(chord_kernel(x, np.ascontiguousarray(y, np.float64), 0, len(x)))


def measured_chord(
    matched: BoolArray,
    outlier: BoolArray,
    segments: int,
    odometer_m: FloatArray | None,
    x: FloatArray,
    y: FloatArray,
) -> tuple[bool, FloatArray | None, float]:
    """
    :func:`measured_span` and the :func:`chord_length_m` of the positions over that span.

    Returns
    -------
    tuple
        Whether the matched length covers the span, the odometer over it, and the chord
        length over it in metres (one compiled call for a match's distance check).
    """
    from mapmatch._measure import measure_kernel  # compiled: imported when first asked for

    span = measure_kernel(
        np.ascontiguousarray(matched, np.bool_),
        np.ascontiguousarray(outlier, np.bool_),
        int(segments),
        odometer_m is not None,
        np.ascontiguousarray(x, np.float64),
        np.ascontiguousarray(y, np.float64),
    )
    return chord_of_span(span, len(matched), odometer_m)


def chord_of_span(
    span: tuple[int, int, bool, float], n: int, odometer_m: FloatArray | None
) -> tuple[bool, FloatArray | None, float]:
    """
    :func:`measured_chord`'s answer from the compiled measure's ``(lo, hi, complete, chord)``.

    ``n`` is the number of fixes. The assembly's call measures the span too
    (:class:`~mapmatch.hmm.assemble.Assembled`'s ``span``).
    """
    lo, hi, complete, chord = span
    _, whole, odometer = _span_of(lo, hi, n, complete, odometer_m)
    return whole, odometer, float(chord)


def check_distance(
    *,
    trace_id: str,
    matched_length_m: float,
    complete: bool,
    band: tuple[float, float],
    odometer_m: FloatArray | None,
    fused_distance_m: float | None,
    chord_m: float,
    evidence: Evidence = "positions",
    uturns: int = 0,
    log: bool = True,
) -> DistanceCheck:
    """
    Compare the fused trip distance with the matched length and give a verdict.

    The fused distance is, in order of preference, the odometer's last minus first known
    value, the caller's ``fused_distance_m``, or the chord sum. A verdict other than
    ``pass`` on a reported distance (odometer or caller) is also logged as a warning, so a
    suspect meter never goes unseen; ``log=False`` leaves that to the caller (a live trip's
    running check, recomputed as it settles). A chord sum is no meter (it cuts every curve
    between fixes, so a sparse trace is always ``under``): its verdict is returned, not logged.

    Examples
    --------
    >>> c = check_distance(trace_id="t", matched_length_m=1000.0, complete=True,
    ...                    band=(-0.04, 0.01), odometer_m=np.array([0.0, 1020.0]),
    ...                    fused_distance_m=None, chord_m=990.0)
    >>> c.source, round(c.relative_error, 3), c.verdict
    ('odometer', 0.02, 'over')
    """
    source: Source
    known = odometer_m[np.isfinite(odometer_m)] if odometer_m is not None else np.empty(0)
    if len(known) >= 2:
        fused, source = float(known[-1] - known[0]), "odometer"
    elif fused_distance_m is not None:
        fused, source = float(fused_distance_m), "caller"
    else:
        fused, source = chord_m, "chord"
    relative = (fused - matched_length_m) / matched_length_m if matched_length_m > 0 else math.nan
    verdict: Verdict
    if not complete or math.isnan(relative):
        verdict = "incomplete"
    elif relative > band[1]:
        verdict = "over"
    elif relative < band[0]:
        verdict = "under"
    else:
        verdict = "pass"
    if verdict != "pass" and log and source != "chord":
        _log.warning(
            "trace %r: fused distance %.1f m (%s) vs matched %.1f m: relative error %s, %s",
            trace_id,
            fused,
            source,
            matched_length_m,
            "n/a" if math.isnan(relative) else f"{relative:+.2%}",
            verdict,
        )
    return DistanceCheck(matched_length_m, fused, source, relative, band, verdict, evidence, uturns)
