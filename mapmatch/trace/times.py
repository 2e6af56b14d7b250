"""
Times of a trace: epoch seconds from numbers (s, ms, us, ns by size), text or datetimes.

The rules are those of :mod:`mapmatch.trace` ("Time"): numeric times are epoch
seconds, milliseconds, microseconds or nanoseconds told apart by size (a column mixing sizes
is refused), float32/float16 times too coarse to tell fixes apart are refused, ISO-8601 text
is read at microsecond resolution (no zone = UTC), and all-blank times mean a trace without
times.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING, Any, Final, cast

import numpy as np
import numpy.typing as npt
import pandas as pd

from mapmatch.errors import InvalidTraceError
from mapmatch.trace.checks import Checker, as_series, plain_numbers
from mapmatch.trace.report import in_source

if TYPE_CHECKING:
    from mapmatch.types import BoolArray, FloatArray

__all__ = ["epoch_seconds", "parse_time", "per_second", "unit_note"]

_UNIT_BOUNDS: Final = (1e11, 1e14, 1e17, 1e20)

_UNITS: Final = (("s", 1.0), ("ms", 1e3), ("us", 1e6), ("ns", 1e9))  # unit, per second

_UNIT_NAMES: Final = {
    "s": "seconds",
    "ms": "milliseconds",
    "us": "microseconds",
    "ns": "nanoseconds",
}

_FLOAT_TIME_RESOLUTION_S: Final = 0.01

_TIME: Final = "time"
_TIME_FIX: Final = (
    "give ISO-8601 text (2024-05-01T08:00:00Z; no zone = UTC) or epoch seconds in every row, "
    "or leave the time column out to match by distance only"
)


def parse_time(values: object, n: int, chk: Checker) -> tuple[FloatArray, str]:
    """
    Epoch seconds and how they were read (``TraceReport.time_unit``); NaN without times.

    Numbers are epoch seconds, ms, us or ns by size; text is ISO-8601 or numbers;
    ``datetime64`` and Timestamps are converted (naive = UTC).
    """
    if values is None:
        return np.full(n, np.nan), "none"
    arr = plain_numbers(values)
    if arr is not None:  # a numpy array of numbers: no pandas
        if arr.dtype.kind == "b":
            raise chk.fail(_TIME, "is missing or not a time", np.arange(n), arr, _TIME_FIX)
        out = arr.astype(np.float64, copy=False)
        blank = np.isnan(out)
        out, unit = epoch_seconds(out, chk)
        _check_float_precision(arr.dtype, out, unit, chk)
        return _finished(out, blank, unit, arr, chk)
    if type(values) is np.ndarray and values.dtype.kind == "M":
        out = _datetime64_to_epoch_s(values)
        return _finished(out, np.isnan(out), "datetime", values, chk)
    iso = _plain_iso(values)
    if iso is not None:
        return iso, "iso"
    return _parse_with_pandas(values, n, chk)


# UTC ISO-8601 as clients write it, which numpy reads exactly as pandas does: a date and a
# time to the second, at most microseconds, "Z" or nothing (UTC) after.
_ISO_UTC = r"[1-9][0-9]{3}-[0-9]{2}-[0-9]{2}[T ][0-9]{2}:[0-9]{2}:[0-9]{2}(?:\.[0-9]{1,6})?Z?"
_ISO_UTC_LINES: Final = re.compile(rf"(?:{_ISO_UTC}\n)*{_ISO_UTC}", re.ASCII)


def _plain_iso(values: object) -> FloatArray | None:
    """
    Epoch seconds of a list (or text array) of plain UTC ISO-8601 times, read without pandas.

    ``None`` for anything else (numbers as text, other zones, blanks, a date that does not
    exist ...): :func:`_parse_with_pandas` reads those and words the errors.

    Examples
    --------
    >>> _plain_iso(["2024-05-01T08:00:00Z", "2024-05-01 08:00:01.5"])
    array([1.7145504e+09, 1.7145504e+09])
    >>> _plain_iso(["2024-05-01T08:00:00+02:00"]) is None, _plain_iso(["1714550400"]) is None
    (True, True)
    """
    if type(values) is np.ndarray and values.dtype.kind in "UO":
        values = values.tolist()
    if type(values) is not list and type(values) is not tuple:
        return None
    items = cast("list[object]", values)
    if not items or not all(type(v) is str for v in items):
        return None
    text = "\n".join(cast("list[str]", items))
    if _ISO_UTC_LINES.fullmatch(text) is None:
        return None
    try:
        stamps = np.array(text.replace("Z", "").split("\n"), dtype="datetime64[us]")
    except ValueError:  # February 30, hour 24, a leap second ...
        return None
    return np.asarray(stamps.astype(np.int64) / 1e6, dtype=np.float64)


def _finished(
    out: FloatArray,
    blank: BoolArray,
    unit: str,
    raw: pd.Series[Any] | npt.NDArray[Any],
    chk: Checker,
) -> tuple[FloatArray, str]:
    """The times, or ``"none"`` when all are blank; a blank or non-finite one is an error."""
    if blank.all():
        return np.full(out.size, np.nan), "none"
    bad = np.flatnonzero(~np.isfinite(out))
    if bad.size:
        raise chk.fail(_TIME, "is missing or not a time", bad, raw, _TIME_FIX)
    return out, unit


def _datetime64_to_epoch_s(values: npt.NDArray[np.datetime64]) -> FloatArray:
    """
    Naive ``datetime64`` (UTC) to epoch seconds; NaT becomes NaN.

    Examples
    --------
    >>> _datetime64_to_epoch_s(np.array(["2024-05-01T08:00:00.5", "NaT"], dtype="M8[ms]"))
    array([1.7145504e+09,           nan])
    """
    out = np.asarray((values - np.datetime64(0, "s")) / np.timedelta64(1, "s"), dtype=np.float64)
    out[np.isnat(values)] = np.nan
    return out


def _parse_with_pandas(values: object, n: int, chk: Checker) -> tuple[FloatArray, str]:
    """:func:`parse_time` of anything but a numpy array: lists, Series, text, Timestamps."""
    s = as_series(values)
    raw: pd.Series[Any] | npt.NDArray[Any] = s
    if pd.api.types.is_bool_dtype(s.dtype):
        rows = np.arange(n, dtype=np.int64)
        raise chk.fail(_TIME, "is missing or not a time", rows, s, _TIME_FIX)
    if pd.api.types.is_datetime64_any_dtype(s.dtype):
        dti = pd.DatetimeIndex(s)
        naive_utc = dti if dti.tz is None else dti.tz_convert("UTC").tz_localize(None)
        out = _datetime64_to_epoch_s(naive_utc.to_numpy())  # in its own unit: no overflow
        blank = np.isnan(out)
        unit = "datetime"
    elif pd.api.types.is_numeric_dtype(s.dtype):
        out = np.asarray(s.to_numpy(dtype=np.float64, na_value=np.nan), dtype=np.float64)
        blank = np.isnan(out)
        out, unit = epoch_seconds(out, chk)
        _check_float_precision(s.dtype, out, unit, chk)
    else:
        text = s.where(s.isna(), s.astype("string").str.strip())
        blank = s.isna().to_numpy() | (text == "").fillna(True).to_numpy()
        num = np.asarray(
            pd.to_numeric(text, errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan),
            dtype=np.float64,
        )
        iso = np.isnan(num) & ~blank
        out, unit = epoch_seconds(num, chk)
        if iso.any():
            out = out.copy()
            out[iso] = _iso_to_epoch_s(s[iso])
            unit = "iso" if np.isnan(num).all() else "mixed"
    return _finished(out, blank, unit, raw, chk)


def per_second(unit: str) -> float:
    """How many of ``unit`` make a second (``"ms"``: 1000); 1 for anything else."""
    return dict(_UNITS).get(unit, 1.0)


def epoch_seconds(values: FloatArray, chk: Checker) -> tuple[FloatArray, str]:
    """
    Numeric times in seconds, their unit told by size; a column mixing sizes is refused.

    Examples
    --------
    >>> from mapmatch.trace.report import Origin
    >>> chk = Checker("t", Origin())
    >>> seconds, unit = epoch_seconds(np.array([1714550400123.0, 1714550401123.0]), chk)
    >>> seconds.tolist(), unit
    ([1714550400.123, 1714550401.123], 'ms')
    >>> epoch_seconds(np.array([0.0, 1.5]), chk)
    (array([0. , 1.5]), 's')
    """
    finite = np.isfinite(values)
    if finite.all() and np.abs(values).max(initial=0.0) < _UNIT_BOUNDS[0]:
        return values, "s"  # the usual case, decided without sorting into bands
    band = np.searchsorted(np.asarray(_UNIT_BOUNDS), np.abs(values), side="right")
    band[~finite] = -1
    present = np.unique(band[finite]).tolist()
    if not present:
        return values, "s"
    if present[-1] >= len(_UNITS):
        bad = np.flatnonzero(band >= len(_UNITS))
        raise chk.fail(
            _TIME,
            "is too large for epoch seconds, milliseconds, microseconds or nanoseconds",
            bad,
            values,
            "give epoch seconds or ISO-8601 text",
        )
    if len(present) > 1:
        counts = {b: int((band == b).sum()) for b in present}
        main = max(present, key=lambda b: counts[b])
        bad = np.flatnonzero(finite & (band != main))
        odd = ", ".join(_UNIT_NAMES[_UNITS[b][0]] for b in present if b != main)
        raise chk.fail(
            _TIME,
            f"mixes units: these rows look like epoch {odd} while the others are epoch "
            f"{_UNIT_NAMES[_UNITS[main][0]]}",
            bad,
            values,
            "give every time in one unit (epoch seconds, or ISO-8601 text)",
        )
    unit, per_s = _UNITS[present[0]]
    out = values if per_s == 1.0 else values / per_s
    return np.asarray(out, dtype=np.float64), unit


def _check_float_precision(dtype: object, time_s: FloatArray, unit: str, chk: Checker) -> None:
    """Refuse float32/float16 times (``dtype`` of the input) too coarse to tell fixes apart."""
    if isinstance(dtype, np.dtype) and (dtype.kind != "f" or dtype.itemsize >= 8):
        return
    kind = str(dtype).lower()
    if kind not in ("float32", "float16"):
        return
    finite = time_s[np.isfinite(time_s)]
    if not finite.size:
        return
    raw_max = float(np.max(np.abs(finite))) * per_second(unit)
    ftype = np.float32 if kind == "float32" else np.float16
    step_s = float(np.spacing(ftype(raw_max))) / per_second(unit)
    if step_s <= _FLOAT_TIME_RESOLUTION_S:
        return
    bits = 24 if kind == "float32" else 11
    msg = (
        f"trace {chk.tid!r}{in_source(chk.origin)}: time is stored as {kind}, which keeps "
        f"{bits} bits: "
        f"near {raw_max:.6g} its values can only be {step_s:g} s apart, so fixes seconds apart "
        "would collapse into repeated times; store times as float64 or int64 epoch seconds, "
        "or as ISO-8601 text"
    )
    raise InvalidTraceError(msg, trace_id=chk.tid, field="time")


def _iso_to_epoch_s(text: pd.Series[Any]) -> FloatArray:
    """
    ISO-8601 text to epoch seconds (NaN for text that is no time).

    Works at microsecond resolution, so times outside pandas' nanosecond range (1677-2262)
    neither overflow nor crash.
    """
    try:
        dt = pd.to_datetime(text, utc=True, format="ISO8601", errors="coerce")
        stamps = dt.dt.tz_localize(None).to_numpy(dtype="datetime64[us]")
    except (pd.errors.OutOfBoundsDatetime, OverflowError, ValueError):
        stamps = np.array([_one_iso(value) for value in text], dtype="datetime64[us]")
    out = stamps.astype(np.int64) / 1e6
    out[np.isnat(stamps)] = np.nan
    return np.asarray(out, dtype=np.float64)


def _one_iso(value: object) -> str:
    """One ISO-8601 time as naive UTC text numpy can read, or ``"NaT"``."""
    try:
        stamp = pd.Timestamp(str(value))
    except (ValueError, OverflowError, pd.errors.OutOfBoundsDatetime):
        return "NaT"
    if stamp.tzinfo is not None:
        stamp = stamp.tz_convert("UTC").tz_localize(None)
    return str(stamp.isoformat())


def unit_note(time_s: FloatArray, unit: str) -> str | None:
    """The report's sentence on times converted from ms, us or ns, else None."""
    if unit not in _UNIT_NAMES or unit == "s":
        return None
    first = float(time_s[np.flatnonzero(np.isfinite(time_s))[0]]) * per_second(unit)
    shown = f"{first:.0f}" if abs(first - round(first)) < 0.5 else f"{first:.17g}"
    return f"times are epoch {_UNIT_NAMES[unit]} (e.g. {shown}) and were converted to seconds"
