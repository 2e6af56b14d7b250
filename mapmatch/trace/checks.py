"""
The row rules of a trace: numbers, coordinates, the declared bounds, lengths, the odometer.

A :class:`Checker` converts one trace's columns to float64 and builds the messages that
point at the offending rows (``row 5 (line 7) = -2.5``), with the field and a suggested fix;
the bounds come from :mod:`mapmatch.trace.columns`. The rules that concern the order of the
rows (sorting, merging, the plausibility of times) are in :mod:`mapmatch.trace.ordering`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Final, cast

import numpy as np
import numpy.typing as npt
import pandas as pd

from mapmatch.errors import InvalidTraceError
from mapmatch.trace.columns import Column, column
from mapmatch.trace.report import Origin, in_source

if TYPE_CHECKING:
    from collections.abc import Iterable, Mapping

    from mapmatch.types import BoolArray, FloatArray, IntArray

__all__ = [
    "SHOW",
    "Checker",
    "as_series",
    "check_lengths",
    "check_odometer",
    "checked_column",
    "is_plain_number",
    "plain_numbers",
    "within",
]

SHOW: Final = 5
"""Offending rows quoted in a message."""

_INT64: Final = (-(2**63), 2**63)
_LAT: Final = column("lat")
_LON: Final = column("lon")


class Checker:
    """Builds the row-pointing messages of one trace's validation."""

    def __init__(self, trace_id: str, origin: Origin) -> None:
        self.tid = trace_id
        self.origin = origin

    def where(self, row: int) -> str:
        """``row 5``, or ``row 5 (line 7)`` when the source numbers its rows."""
        nums = self.origin.numbers
        if nums is None:
            return f"row {row}"
        return f"row {row} ({self.origin.label} {int(nums[row])})"

    def rows_phrase(self, rows: IntArray) -> str:
        """``rows 3, 5 (line 7) and 2 more (4 in all)``: the first :data:`SHOW` rows named."""
        shown = ", ".join(self.where(int(r)).removeprefix("row ") for r in rows[:SHOW])
        more = f" and {rows.size - SHOW} more ({rows.size} in all)" if rows.size > SHOW else ""
        return f"row{'s' if rows.size > 1 else ''} {shown}{more}"

    def fail(
        self,
        field: str,
        problem: str,
        rows: IntArray,
        raw: pd.Series[Any] | npt.NDArray[Any],
        fix: str,
    ) -> InvalidTraceError:
        """The error for ``rows`` of ``field``: the problem, the values in ``raw``, a fix."""
        shown = ", ".join(f"{self.where(int(r))} = {_fmt(raw[int(r)])}" for r in rows[:SHOW])
        more = f" and {rows.size - SHOW} more" if rows.size > SHOW else ""
        msg = (
            f"trace {self.tid!r}{in_source(self.origin)}: {field} {problem} in {rows.size} row(s): "
            f"{shown}{more}; {fix}"
        )
        return InvalidTraceError(msg, trace_id=self.tid, field=field, rows=rows.tolist())

    def numeric(self, values: object, field: str) -> FloatArray:
        """
        Float64 values; blanks become NaN, text that is not a number is an error.

        A numpy array of numbers is taken as it is (no pandas, no copy when it is float64:
        validation never writes into it); anything else goes through a pandas Series.
        """
        arr = plain_numbers(values)
        if arr is not None:
            if arr.dtype.kind == "b":
                bad = np.arange(arr.size, dtype=np.int64)
                raise self.fail(field, "is boolean, not a number", bad, arr, "give numbers")
            return arr.astype(np.float64, copy=False)
        s = as_series(values)
        if pd.api.types.is_bool_dtype(s.dtype):
            bad = np.arange(len(s), dtype=np.int64)
            raise self.fail(field, "is boolean, not a number", bad, s, "give numbers")
        if pd.api.types.is_numeric_dtype(s.dtype):
            return np.asarray(s.to_numpy(dtype=np.float64, na_value=np.nan), dtype=np.float64)
        text = s.astype("string").str.strip()
        blank = s.isna().to_numpy() | (text == "").fillna(True).to_numpy()
        num = pd.to_numeric(s.where(~blank, None), errors="coerce")
        out = np.asarray(num.to_numpy(dtype=np.float64, na_value=np.nan), dtype=np.float64)
        bad = np.flatnonzero(np.isnan(out) & ~blank)
        if bad.size:
            raise self.fail(
                field, "is not a number", bad, s, "give decimal numbers (or leave blank)"
            )
        return out

    def rule(self, values: FloatArray, field: str, broken: BoolArray, rule: str) -> None:
        """Raise naming the ``broken`` rows of ``field`` and the ``rule`` they break."""
        if not broken.any():
            return
        bad = np.flatnonzero(broken)
        if bad.size:
            raise self.fail(
                field,
                f"breaks the rule: {rule}",
                bad,
                values,
                "fix the values or leave them blank (NaN = unknown)",
            )

    def coordinates(self, lon: FloatArray, lat: FloatArray) -> None:
        """Every row has a finite position within the declared bounds (swapped lon/lat told)."""
        if within(lat, _LAT).all() and within(lon, _LON).all():  # NaN and inf keep no bound
            return
        for field, values in (("lat", lat), ("lon", lon)):
            bad = np.flatnonzero(~np.isfinite(values))
            if bad.size:
                raise self.fail(
                    field,
                    "is missing or not finite",
                    bad,
                    values,
                    f"every row needs a {field} in degrees; fix or drop those rows",
                )
        outside = ~within(lat, _LAT)
        if np.all(outside) and np.all(within(lon, _LAT)):
            bad = np.flatnonzero(outside)
            raise self.fail(
                field="lat",
                problem=f"is out of range [{_LAT.ge:g}, {_LAT.le:g}]",
                rows=bad,
                raw=lat,
                fix="every lat looks like a longitude: swapped lon/lat? swap the two columns",
            )
        for values, col in ((lat, _LAT), (lon, _LON)):
            bad = np.flatnonzero(~within(values, col))
            if bad.size:
                raise self.fail(
                    col.name,
                    f"is out of range [{col.ge:g}, {col.le:g}]",
                    bad,
                    values,
                    "give WGS84 degrees (not metres or projected coordinates); swapped lon/lat?",
                )


def checked_column(chk: Checker, col: Column, values: object) -> FloatArray:
    """
    An optional number column as float64, its declared rules applied (:mod:`.columns`).

    A wrapping column (heading) is taken modulo its period, a non-finite value being
    unknown (NaN); any other value must keep its bounds and be finite (NaN = unknown).
    """
    out = chk.numeric(values, col.name)
    if col.wraps is not None:
        finite = np.isfinite(out)
        out = np.where(finite, np.mod(np.where(finite, out, 0.0), col.wraps), np.nan)
        out[out >= col.wraps] = 0.0  # np.mod(-1e-15, 360) rounds to 360.0
        return out
    if col.bounded:
        kept = within(out, col) | np.isnan(out)
        if not kept.all():
            unit = f" {col.unit}" if col.unit else ""
            chk.rule(out, col.name, ~kept, f"must be {col.rule()}{unit}")
    chk.rule(out, col.name, np.isinf(out), "must be finite (NaN = unknown)")
    return out


def within(values: FloatArray, col: Column) -> BoolArray:
    """Whether each value keeps the column's bounds (NaN keeps none)."""
    ok: BoolArray | None = None
    for bound, keeps in ((col.gt, np.greater), (col.ge, np.greater_equal), (col.le, np.less_equal)):
        if bound is not None:
            kept = keeps(values, bound)
            ok = kept if ok is None else ok & kept
    return np.ones(values.shape, dtype=bool) if ok is None else ok


def plain_numbers(values: object) -> npt.NDArray[Any] | None:
    """
    ``values`` as a numpy array when no pandas is needed to read them, else None.

    That is a 1-D numpy array of numbers or booleans (as it is), a pandas Series of numpy
    numbers (a table's number column as read; a copy of its values, so the trace never
    shares the caller's frame), or a list or tuple of Python floats and ints (int64 range;
    not bools), as float64: what pandas would make of them. Anything else (blanks, text,
    nullable or boolean Series ...) is for :func:`as_series`.

    Examples
    --------
    >>> plain_numbers([0, 1.5]), plain_numbers([0, None]), plain_numbers([True, 1])
    (array([0. , 1.5]), None, None)
    >>> plain_numbers(pd.Series([3, 4], index=[7, 8])), plain_numbers(pd.Series([1.0, None]))
    (array([3, 4]), array([ 1., nan]))
    """
    kind = type(values)
    if kind is np.ndarray:
        arr = cast("npt.NDArray[Any]", values)
        return arr if arr.ndim == 1 and arr.dtype.kind in "biuf" else None
    if kind is pd.Series:  # 0.2 ms less a column than the Series checks of as_series
        series = cast("pd.Series[Any]", values)
        dtype = series.dtype
        if isinstance(dtype, np.dtype) and dtype.kind in "iuf":
            return series.to_numpy(copy=True)
    if kind is list or kind is tuple:
        items = cast("list[object]", values)
        if all(map(is_plain_number, items)):
            return np.array(items, dtype=np.float64)
    return None


def is_plain_number(value: object) -> bool:
    """Whether ``value`` is a Python float, or an int in the int64 range (not a bool)."""
    kind = type(value)
    return kind is float or (kind is int and _INT64[0] <= value < _INT64[1])  # type: ignore[operator]


def _fmt(value: object) -> str:
    if isinstance(value, np.generic):
        value = value.item()
    if value is None or value is pd.NA or value is pd.NaT:
        return "missing"
    if isinstance(value, float | np.floating):
        if np.isnan(value):
            return "missing"
        return f"{float(value):g}"
    return repr(value)


def check_lengths(given: Mapping[str, object], tid: str) -> int:
    """The number of points: every given column 1-D with one value per point, 2 or more."""
    lengths: dict[str, int] = {}
    for field, values in given.items():
        ndim = values.ndim if isinstance(values, np.ndarray) else np.ndim(values)  # type: ignore[arg-type]
        if isinstance(values, str | bytes) or ndim != 1:
            msg = (
                f"trace {tid!r}: {field!r} must be a 1-D sequence with one value per point "
                f"(got {type(values).__name__})"
            )
            raise InvalidTraceError(msg, trace_id=tid, field=field)
        lengths[field] = len(values)  # type: ignore[arg-type]
    ref = "time" if "time" in lengths else "lat"
    n = lengths[ref]
    for field, size in lengths.items():
        if size != n:
            msg = (
                f"trace {tid!r}: {field!r} has {size} values but {ref!r} has {n}; "
                "give every field one value per point"
            )
            raise InvalidTraceError(msg, trace_id=tid, field=field)
    if n < 2:
        msg = f"trace {tid!r}: {n} point(s); a trace needs at least 2 points"
        raise InvalidTraceError(msg, trace_id=tid, field="lat")
    return n


def check_odometer(odometer: FloatArray, kept: IntArray, chk: Checker, origin: Origin) -> None:
    """The known odometer values never decrease along the ``kept`` rows (in time order)."""
    odo = odometer[kept]
    known = np.flatnonzero(~np.isnan(odo))
    back = np.flatnonzero(np.diff(odo[known]) < 0)
    if not back.size:
        return
    later, earlier = kept[known[back + 1]], kept[known[back]]
    shown = ", ".join(
        f"{chk.where(int(b))} = {odometer[b]:g} after {chk.where(int(a))} = {odometer[a]:g}"
        for a, b in zip(earlier[:SHOW], later[:SHOW], strict=True)
    )
    more = f" and {later.size - SHOW} more" if later.size > SHOW else ""
    msg = (
        f"trace {chk.tid!r}{in_source(origin)}: odometer decreases in time at {later.size} "
        f"row(s): {shown}{more}; the odometer must be cumulative distance in metres "
        "(fix or blank those values, NaN = unknown)"
    )
    raise InvalidTraceError(msg, trace_id=chk.tid, field="odometer", rows=later.tolist())


def as_series(values: object) -> pd.Series[Any]:
    """The values as a pandas Series with a fresh 0-based index."""
    if isinstance(values, pd.Series):
        return values.reset_index(drop=True)
    if isinstance(values, pd.Index):
        return values.to_series().reset_index(drop=True)
    if isinstance(values, np.ndarray):
        return pd.Series(values)
    return pd.Series(list(cast("Iterable[Any]", values)))
