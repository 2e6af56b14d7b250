"""The optional trace columns a simulated trip carries, and the input classes that keep some."""

from __future__ import annotations

from typing import TYPE_CHECKING

from mapmatch.errors import ConfigError
from mapmatch.trace import Trace

if TYPE_CHECKING:
    from collections.abc import Iterable

__all__ = ["INPUT_CLASSES", "TRUE_COLUMNS", "strip_to_class", "with_columns"]

#: The trace columns each input class keeps besides time and position; each class adds to the
#: one before it: plain GPS, + the receiver's accuracy, + heading and speed, + the odometer.
INPUT_CLASSES: dict[str, tuple[str, ...]] = {
    "positions": (),
    "accuracy": ("accuracy",),
    "heading_speed": ("accuracy", "heading", "speed"),
    "odometer": ("accuracy", "heading", "speed", "odometer"),
}
#: The optional trace columns a simulated trip carries.
TRUE_COLUMNS = ("heading", "speed", "accuracy", "odometer")


def with_columns(trace: Trace, columns: Iterable[str]) -> Trace:
    """
    A copy of ``trace`` that keeps only the named optional columns.

    ``columns`` names any of ``heading``, ``speed``, ``accuracy``, ``odometer``; the rest are
    dropped (a column the trace does not have stays absent). Time, position and id are kept.

    Raises
    ------
    ConfigError
        An unknown column name.
    """
    keep = set(columns)
    unknown = sorted(keep - set(TRUE_COLUMNS))
    if unknown:
        msg = f"unknown column(s) {unknown}; a trace's optional columns are {list(TRUE_COLUMNS)}"
        raise ConfigError(msg)
    return Trace(
        time=trace.time_s,
        lon=trace.lon,
        lat=trace.lat,
        heading=trace.heading_deg if "heading" in keep else None,
        speed=trace.speed_mps if "speed" in keep else None,
        accuracy=trace.accuracy_m if "accuracy" in keep else None,
        odometer=trace.odometer_m if "odometer" in keep else None,
        trace_id=trace.trace_id,
    )


def strip_to_class(trace: Trace, input_class: str) -> Trace:
    """
    ``trace`` with the columns of one input class of :data:`INPUT_CLASSES` only.

    Raises
    ------
    ConfigError
        An unknown input class.

    Examples
    --------
    >>> tr = Trace(time=[0, 1], lon=[7.42, 7.43], lat=[43.73] * 2, speed=[5, 6], odometer=[0, 6])
    >>> plain = strip_to_class(tr, "positions")
    >>> plain.speed_mps is None, plain.odometer_m is None
    (True, True)
    """
    if input_class not in INPUT_CLASSES:
        msg = f"input class must be one of {sorted(INPUT_CLASSES)} (got {input_class!r})"
        raise ConfigError(msg)
    return with_columns(trace, INPUT_CLASSES[input_class])
