"""
One live fix at a time: validated on arrival, in time order, against the fix before it.

A whole trace is validated by :class:`~mapmatch.trace.Trace`, which sorts its rows and judges
them together. A live trip cannot wait for its last fix, and its fixes must be judged in well
under a millisecond each, so :func:`read_fix` applies the same rules to one mapping of scalars
(the fields and their aliases of :data:`~mapmatch.trace.FIELD_ALIASES`, case-insensitive;
unknown keys ignored), with what only a stream can check on top:

- ``time`` is required: the lag and the idle expiry are measured in trip time. Epoch seconds
  (a number, or a numeric string), ISO-8601 text (naive = UTC) or a :class:`datetime.datetime`.
  A number of 1e11 or more is refused: it looks like epoch milliseconds (a single fix cannot be
  told apart by the size of a whole column, as a trace's times are).
- A fix older than the one before it is refused (a trace would be sorted; a stream is not
  re-ordered once matched). One at the same time is kept (the step is judged by distance only,
  as in a trace). One equal to the fix before it in every field is the same fix sent twice: it
  is merged into it and counted.
- ``lat``/``lon`` are WGS84 degrees in range; ``heading`` is normalised to ``[0, 360)`` (a
  non-finite one is unknown); ``speed`` must be ``>= 0``, ``accuracy > 0`` (``hdop`` fills an
  unknown accuracy as ``hdop * UERE_M``); ``odometer`` must not decrease from the last known
  reading. A missing or null optional field is unknown.

Every refusal raises :class:`~mapmatch.errors.InvalidTraceError` naming the trip, the fix (its
0-based number in the trip), the field and the value, with a fix; the trip is left as it was.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Final, NoReturn

from mapmatch.errors import InvalidTraceError
from mapmatch.trace import FIELD_ALIASES, UERE_M
from mapmatch.trace.columns import column

__all__ = ["OPTIONAL_FIELDS", "LiveFix", "read_fix"]

#: The optional fields of a fix, in the order :class:`LiveFix` holds them.
OPTIONAL_FIELDS: Final = ("heading", "speed", "accuracy", "odometer")

_ALIAS_TO_FIELD: Final = {a: f for f, aliases in FIELD_ALIASES.items() for a in aliases}


def _range(name: str) -> tuple[float, float]:
    """``(low, high)`` of a trace column as :mod:`mapmatch.trace.columns` declares it."""
    col = column(name)
    return (
        -math.inf if col.ge is None else col.ge,
        math.inf if col.le is None else col.le,
    )


#: The bounds of the bounded fields, as the trace columns declare them.
_RANGES: Final = {name: _range(name) for name in ("lat", "lon", "speed")}
_MAX_EPOCH_S: Final = 1e11  # larger numbers are epoch ms or finer (see the module docstring)


@dataclass(frozen=True, slots=True)
class LiveFix:
    """
    One validated fix of a live trip; NaN marks an unknown optional value.

    ``time_s`` epoch seconds; ``lon``/``lat`` WGS84 degrees; ``heading_deg`` clockwise from
    north in ``[0, 360)``; ``speed_mps``; ``accuracy_m`` 1-sigma; ``odometer_m`` cumulative.
    """

    time_s: float
    lon: float
    lat: float
    heading_deg: float = math.nan
    speed_mps: float = math.nan
    accuracy_m: float = math.nan
    odometer_m: float = math.nan

    def values(self) -> tuple[float, float, float, float, float, float, float]:
        """The fields in order: time, lon, lat, heading, speed, accuracy, odometer."""
        return (
            self.time_s,
            self.lon,
            self.lat,
            self.heading_deg,
            self.speed_mps,
            self.accuracy_m,
            self.odometer_m,
        )

    def same_as(self, other: LiveFix) -> bool:
        """Whether ``other`` repeats this fix in every field (NaN equal to NaN)."""
        return all(
            a == b or (math.isnan(a) and math.isnan(b))
            for a, b in zip(self.values(), other.values(), strict=True)
        )

    def has(self, field: str) -> bool:
        """Whether the optional ``field`` (``heading``, ``speed``...) is known."""
        return not math.isnan(self.optional(field))

    def optional(self, field: str) -> float:
        """The value of an optional field by its name (NaN when unknown)."""
        return {
            "heading": self.heading_deg,
            "speed": self.speed_mps,
            "accuracy": self.accuracy_m,
            "odometer": self.odometer_m,
        }[field]


class _Refusal:
    """Builds the messages of one fix's refusals."""

    def __init__(self, trip_id: str, index: int) -> None:
        self.trip_id, self.index = trip_id, index

    def refuse(self, field: str | None, problem: str, fix: str) -> NoReturn:
        """Raise the refusal of ``field``: what is wrong, and how to fix it."""
        msg = f"trip {self.trip_id!r}: fix {self.index}: {problem}; {fix}"
        raise InvalidTraceError(msg, trace_id=self.trip_id, field=field, rows=[self.index])


def _float_or_none(value: int | float | str) -> float | None:
    try:
        return float(value)
    except ValueError:
        return None


def _iso_or_none(text: str) -> datetime | None:
    try:
        return datetime.fromisoformat(text)
    except ValueError:
        return None


def _number(value: object, field: str, why: _Refusal, *, required: bool) -> float:
    """A finite or NaN float from a JSON-like scalar; ``None`` and ``""`` are unknown (NaN)."""
    if value is None or (isinstance(value, str) and not value.strip()):
        if required:
            why.refuse(field, f"{field} is missing", f'give it, e.g. {{"{field}": ...}}')
        return math.nan
    if isinstance(value, bool) or not isinstance(value, int | float | str):
        why.refuse(
            field,
            f"{field} is a {type(value).__name__} ({value!r}), not a number",
            "send a number",
        )
    number = _float_or_none(value)
    if number is None:
        why.refuse(field, f"{field} is {value!r}, not a number", "send a number")
    if required and not math.isfinite(number):
        why.refuse(field, f"{field} is {value!r}, not a finite number", "send a number")
    return number


def _positive(value: object, field: str, unit: str, why: _Refusal) -> float:
    """An optional value that must be > 0 (NaN when unknown)."""
    number = _number(value, field, why, required=False)
    if math.isnan(number):
        return number
    if not 0 < number < math.inf:
        shown = f"{number:g} {unit}".strip()
        why.refuse(field, f"{field} is {shown}", "it must be > 0; leave it out if unknown")
    return number


def _time(value: object, why: _Refusal) -> float:
    """Epoch seconds of a fix's time (see the module docstring)."""
    if isinstance(value, datetime):
        stamp = value if value.tzinfo is not None else value.replace(tzinfo=UTC)
        return stamp.timestamp()
    if isinstance(value, str) and value.strip():
        text = value.strip()
        number = _float_or_none(text)
        if number is not None:
            return _time_number(number, why)
        parsed = _iso_or_none(text)
        if parsed is None:
            why.refuse(
                "time",
                f"time is {value!r}, which is neither epoch seconds nor ISO-8601",
                'send epoch seconds or ISO-8601 text such as "2024-05-01T10:00:00Z"',
            )
        return _time(parsed, why)
    return _time_number(_number(value, "time", why, required=True), why)


def _time_number(seconds: float, why: _Refusal) -> float:
    if not math.isfinite(seconds):
        why.refuse("time", f"time is {seconds!r}, not a time", "send epoch seconds")
    if abs(seconds) >= _MAX_EPOCH_S:
        why.refuse(
            "time",
            f"time is {seconds:.17g}, which looks like epoch milliseconds (or finer), not seconds",
            "send epoch seconds (divide by 1000) or ISO-8601 text",
        )
    return seconds


def _fields(fix: Mapping[str, object], why: _Refusal) -> dict[str, object]:
    """The fix's values by canonical field name; two keys for one field are refused."""
    out: dict[str, object] = {}
    seen: dict[str, str] = {}
    for key, value in fix.items():
        field = _ALIAS_TO_FIELD.get(str(key).strip().lower())
        if field is None:
            continue  # unknown keys are ignored, as a trace's unknown columns are
        if field in seen:
            why.refuse(
                field,
                f"{seen[field]!r} and {key!r} both give {field}",
                "send one of them",
            )
        seen[field] = str(key)
        out[field] = value
    return out


def read_fix(
    fix: object,
    *,
    trip_id: str,
    index: int,
    previous: LiveFix | None,
    last_odometer_m: float = math.nan,
) -> tuple[LiveFix, bool]:
    """
    Validate one fix of a live trip against the fix before it.

    Parameters
    ----------
    fix
        A mapping of the input fields (``time``, ``lat``, ``lon``, optional ``heading``,
        ``speed``, ``accuracy`` or ``hdop``, ``odometer``; aliases and any case).
    trip_id
        The trip's name, for messages.
    index
        The fix's 0-based number in the trip, for messages.
    previous
        The trip's last accepted fix, if any.
    last_odometer_m
        The trip's last known odometer reading (NaN: none yet).

    Returns
    -------
    tuple[LiveFix, bool]
        The fix, and whether it repeats ``previous`` exactly (to be merged, not added).

    Raises
    ------
    InvalidTraceError
        The fix breaks a rule; the message names the field and the value.

    Examples
    --------
    >>> fix, repeat = read_fix({"t": 1.7e9, "Lat": 43.73, "lng": 7.42, "heading": -90},
    ...                        trip_id="cab-7", index=0, previous=None)
    >>> fix.heading_deg, repeat
    (270.0, False)
    >>> try:
    ...     read_fix({"time": 1.7e9, "lat": 95, "lon": 7.4}, trip_id="c", index=3, previous=None)
    ... except ValueError as error:
    ...     print(error)
    trip 'c': fix 3: lat is 95, out of range [-90, 90]; give WGS84 degrees (swapped lon/lat?)
    """
    why = _Refusal(trip_id, index)
    if not isinstance(fix, Mapping):
        why.refuse(
            None,
            f"a fix is a {type(fix).__name__}, not an object",
            'send {"time": ..., "lat": ..., "lon": ...}',
        )
    given = _fields(fix, why)
    if "time" not in given:
        why.refuse(
            "time",
            "time is missing",
            "every live fix needs its time (epoch seconds or ISO-8601)",
        )
    time_s = _time(given["time"], why)
    lat = _number(given.get("lat"), "lat", why, required=True)
    lon = _number(given.get("lon"), "lon", why, required=True)
    for name, value, hint in (
        ("lat", lat, "give WGS84 degrees (swapped lon/lat?)"),
        ("lon", lon, "give WGS84 degrees"),
    ):
        low, high = _RANGES[name]
        if not low <= value <= high:
            why.refuse(name, f"{name} is {value:g}, out of range [{low:g}, {high:g}]", hint)
    heading = _number(given.get("heading"), "heading", why, required=False)
    heading = heading % 360.0 if math.isfinite(heading) else math.nan
    speed = _number(given.get("speed"), "speed", why, required=False)
    if speed < _RANGES["speed"][0] or speed == math.inf:
        why.refuse("speed", f"speed is {speed:g} m/s", "it must be >= 0; leave it out if unknown")
    accuracy = _positive(given.get("accuracy"), "accuracy", "m", why)
    hdop = _positive(given.get("hdop"), "hdop", "", why)
    if math.isnan(accuracy) and not math.isnan(hdop):
        accuracy = hdop * UERE_M
    odometer = _number(given.get("odometer"), "odometer", why, required=False)
    if not math.isfinite(odometer):
        odometer = math.nan
    if odometer < last_odometer_m:
        why.refuse(
            "odometer",
            f"odometer {odometer:g} m is less than the trip's last reading {last_odometer_m:g} m",
            "an odometer never decreases; leave it out if unknown",
        )
    out = LiveFix(time_s, lon, lat, heading, speed, accuracy, odometer)
    if previous is not None:
        if time_s < previous.time_s:
            why.refuse(
                "time",
                f"time {time_s:.17g} is {previous.time_s - time_s:g} s before the fix before it",
                "send a trip's fixes in time order (an older fix cannot be matched any more)",
            )
        if out.same_as(previous):
            return previous, True
    return out, False
