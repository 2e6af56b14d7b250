"""
JSON objects of many rows at once, from arrays: as text, or as Python objects.

:mod:`mapmatch.export` declares each kind of feature once, as a :class:`Table` of named
columns, and renders it as JSON text (:meth:`Table.text`) or as dicts
(:meth:`Table.objects`); both show the same values, so ``json.loads(table.text())`` equals
``table.objects()``.

The text is made column by column (the floats' digits by a compiled kernel, ``str`` of the
ints) and row by row with one ``%`` template for the whole object, so no dict, no JSON
encoder and no numpy scalar is touched per value. Numbers come out as ``json.dumps`` writes
them (``repr``); values that are not finite, and rows outside a column's ``valid`` mask,
are ``null``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from numba import njit

if TYPE_CHECKING:
    from collections.abc import Sequence

    from mapmatch.types import BoolArray, FloatArray, IntArray

__all__ = [
    "Bools",
    "Column",
    "Const",
    "Floats",
    "Ints",
    "Items",
    "Nested",
    "Strings",
    "Table",
    "Tuple",
    "Values",
    "py_round",
]

_NULL = "null"
_EPS = float(np.finfo(np.float64).eps)


def py_round(values: FloatArray, digits: int) -> FloatArray:
    """
    Python's ``round(value, digits)`` of every value, vectorised.

    ``numpy.round`` multiplies, rounds and divides, which differs from Python's correctly
    rounded result where the product lands within rounding error of a half; those few values
    are rounded by Python itself.

    Examples
    --------
    >>> x = np.array([2.675, 1.0005, 0.125, -0.0004])
    >>> py_round(x, 2).tolist() == [round(v, 2) for v in x.tolist()]
    True
    """
    x = np.asarray(values, dtype=np.float64)
    scale = 10.0**digits
    with np.errstate(invalid="ignore", over="ignore"):
        y = x * scale
        out = np.rint(y) / scale
        near_half = np.abs(np.abs(y - np.trunc(y)) - 0.5) <= 1e-9 + 8.0 * _EPS * np.abs(y)
        odd = np.isfinite(x) & (near_half | (np.abs(y) >= 2.0**52))
    if odd.any():
        out[odd] = [round(v, digits) for v in x[odd].tolist()]
    return out


def _nulls(cells: list[Any], missing: BoolArray | None, value: Any = _NULL) -> list[Any]:
    """``cells`` with ``value`` where ``missing``."""
    if missing is not None and missing.any():
        for i in np.flatnonzero(missing).tolist():
            cells[i] = value
    return cells


class Column(Protocol):
    """A column of a :class:`Table`: each row's value as JSON text and as a Python object."""

    def cells(self, rows: int) -> list[str]:
        """Every row's value as JSON text."""

    def objects(self, rows: int) -> list[Any]:
        """Every row's value as a Python object."""


@dataclass(frozen=True, slots=True)
class Const:
    """The same value (a string, number, bool or ``None``) in every row."""

    value: str | float | bool | None

    def cells(self, rows: int) -> list[str]:
        """The value's JSON text, once per row."""
        return [json.dumps(self.value)] * rows

    def objects(self, rows: int) -> list[Any]:
        """The value, once per row."""
        return [self.value] * rows


@dataclass(frozen=True, slots=True)
class Ints:
    """Whole numbers; ``null`` outside ``valid``."""

    values: IntArray
    valid: BoolArray | None = None

    def _missing(self) -> BoolArray | None:
        return None if self.valid is None else ~self.valid

    def cells(self, rows: int) -> list[str]:
        """The digits."""
        text = list(map(str, np.asarray(self.values, dtype=np.int64).tolist()))
        return _nulls(text, self._missing())

    def objects(self, rows: int) -> list[Any]:
        """Python ints, ``None`` outside ``valid``."""
        values: list[Any] = np.asarray(self.values, dtype=np.int64).tolist()
        return _nulls(values, self._missing(), None)


#: ``n`` below this has at most 15 significant digits: its decimal reads back unambiguously.
_MAX_EXACT = 1e15


@njit(cache=True, nogil=True)
def _decimals_kernel(values, digits):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Each value's ``repr`` when it has at most ``digits`` decimals, comma-separated ASCII.

    ``n = |v| * 10**digits`` rounded must give ``v`` back (then the decimal ``n / 10**digits``
    with its trailing zeros dropped is the shortest text reading back as ``v``, which is what
    ``repr`` writes) and have at most 15 digits; ``repr`` also writes ``1e-05`` below 1e-4.
    Values that do not qualify are written as nothing and flagged for ``repr`` itself.
    """
    scale = 10.0**digits
    out = np.empty(len(values) * 24, dtype=np.uint8)
    slow = np.zeros(len(values), dtype=np.bool_)
    digit = np.empty(20, dtype=np.uint8)
    at = 0
    for i in range(len(values)):
        if i:
            out[at] = 44  # ,
            at += 1
        v = values[i]
        if not np.isfinite(v):
            slow[i] = True
            continue
        a = abs(v)
        n = np.rint(a * scale)
        if n >= _MAX_EXACT or n / scale != a or (a != 0.0 and a < 1e-4):
            slow[i] = True
            continue
        if math.copysign(1.0, v) < 0:
            out[at] = 45  # -
            at += 1
        k = int(n)
        count = 0
        while True:  # every digit of n, least significant first
            digit[count] = 48 + k % 10
            k //= 10
            count += 1
            if k == 0 and count > digits:
                break
        for j in range(count - 1, digits - 1, -1):  # the whole part
            out[at] = digit[j]
            at += 1
        out[at] = 46  # .
        at += 1
        if digits == 0:
            out[at] = 48  # 0
            at += 1
            continue
        last = digits - 1  # the fraction, trailing zeros dropped, at least one digit
        for j in range(digits - 1):
            if digit[j] != 48:
                last = j
                break
        for j in range(digits - 1, last - 1, -1):
            out[at] = digit[j]
            at += 1
    return out[:at], slow


@dataclass(frozen=True, slots=True)
class Floats:
    """
    Real numbers as ``repr`` writes them (round them first); ``null`` if not finite or valid.

    ``decimals`` is how many the values carry: those are written by a compiled kernel, any
    other by ``repr`` itself (the same text, slower).
    """

    values: FloatArray
    valid: BoolArray | None = None
    decimals: int = 7

    def _missing(self) -> BoolArray | None:
        missing = ~np.isfinite(self.values)
        if self.valid is not None:
            missing |= ~self.valid
        return missing if missing.any() else None

    def cells(self, rows: int) -> list[str]:
        """``repr`` of each number."""
        values = np.ascontiguousarray(self.values, dtype=np.float64)
        if len(values) == 0:
            return []
        text, slow = _decimals_kernel(values, self.decimals)
        cells = text.tobytes().decode("ascii").split(",")
        if slow.any():
            for i in np.flatnonzero(slow).tolist():
                cells[i] = repr(float(values[i]))
        return _nulls(cells, self._missing())

    def objects(self, rows: int) -> list[Any]:
        """Python floats, ``None`` where missing."""
        values: list[Any] = np.asarray(self.values, dtype=np.float64).tolist()
        return _nulls(values, self._missing(), None)


@dataclass(frozen=True, slots=True)
class Bools:
    """``true`` / ``false``."""

    values: BoolArray

    def cells(self, rows: int) -> list[str]:
        """``true`` or ``false``."""
        text: list[str] = np.where(self.values, "true", "false").tolist()
        return text

    def objects(self, rows: int) -> list[Any]:
        """Python bools."""
        flags: list[Any] = np.asarray(self.values, dtype=bool).tolist()
        return flags


@dataclass(frozen=True, slots=True)
class Strings:
    """Texts (escaped as ``json.dumps`` does, ASCII); ``null`` for ``None``."""

    values: Sequence[str | None]

    def cells(self, rows: int) -> list[str]:
        """The quoted strings."""
        return list(map(json.dumps, self.values))

    def objects(self, rows: int) -> list[Any]:
        """The strings."""
        return list(self.values)


@dataclass(frozen=True, slots=True)
class Tuple:
    """
    ``[a, b, ...]`` of some columns per row, e.g. a position ``[lon, lat]``.

    ``null`` outside ``valid``; with ``geometry``, each array is the ``coordinates`` of a
    GeoJSON geometry of that type (``{"type": "Point", "coordinates": [lon, lat]}``).
    """

    items: Sequence[Column]
    valid: BoolArray | None = None
    geometry: str | None = None

    def _missing(self) -> BoolArray | None:
        return None if self.valid is None else ~self.valid

    def cells(self, rows: int) -> list[str]:
        """The arrays' text."""
        inner = ",".join(["%s"] * len(self.items))
        if self.geometry is None:
            template = f"[{inner}]"
        else:
            template = f'{{"type":{json.dumps(self.geometry)},"coordinates":[{inner}]}}'
        columns = [c.cells(rows) for c in self.items]
        text = list(map(template.__mod__, zip(*columns, strict=True)))
        return _nulls(text, self._missing())

    def objects(self, rows: int) -> list[Any]:
        """Lists (or geometry dicts), ``None`` outside ``valid``."""
        arrays: list[Any] = list(
            map(list, zip(*(c.objects(rows) for c in self.items), strict=True))
        )
        if self.geometry is not None:
            arrays = [{"type": self.geometry, "coordinates": a} for a in arrays]
        return _nulls(arrays, self._missing(), None)


@dataclass(frozen=True, slots=True)
class Nested:
    """A JSON object per row, made by a table of the same rows."""

    table: Table

    def cells(self, rows: int) -> list[str]:
        """Each row's object as text."""
        return self.table.rows_text()

    def objects(self, rows: int) -> list[Any]:
        """One dict per row."""
        return self.table.objects()


class Part(Protocol):
    """What :class:`Items` holds per row: a :class:`Table` or :class:`Values`."""

    def text(self) -> str:
        """The items' JSON text joined by commas."""

    def objects(self) -> list[Any]:
        """The items as Python objects."""


@dataclass(frozen=True, slots=True)
class Values:
    """The rows of one column as the items of a JSON array (``v0,v1,...``)."""

    column: Column
    rows: int

    def text(self) -> str:
        """The values' text joined by commas."""
        return ",".join(self.column.cells(self.rows))

    def objects(self) -> list[Any]:
        """The values as Python objects."""
        return self.column.objects(self.rows)


@dataclass(frozen=True, slots=True)
class Items:
    """
    Per row, a JSON array of a part of its own (a :class:`Table` or :class:`Values`).

    With ``geometry``, each array is the ``coordinates`` of a GeoJSON geometry of that type.
    For tables of few rows (segments) whose rows hold many items each (vertices, edges).
    """

    parts: Sequence[Part]
    geometry: str | None = None

    def cells(self, rows: int) -> list[str]:
        """Each row's array as text."""
        if self.geometry is None:
            return [f"[{part.text()}]" for part in self.parts]
        head = f'{{"type":{json.dumps(self.geometry)},"coordinates":['
        return [f"{head}{part.text()}]}}" for part in self.parts]

    def objects(self, rows: int) -> list[Any]:
        """Each row's list (or geometry dict)."""
        lists = [part.objects() for part in self.parts]
        if self.geometry is None:
            return lists
        return [{"type": self.geometry, "coordinates": items} for items in lists]


@dataclass(frozen=True, slots=True)
class Table:
    """
    Rows of JSON objects with the same members: ``{name: value, ...}`` per row.

    Parameters
    ----------
    rows
        Number of rows.
    columns
        ``(name, column)`` in member order.
    """

    rows: int
    columns: Sequence[tuple[str, Column]]

    def _template(self) -> tuple[str, list[Column]]:
        """
        One row's ``%`` template and the columns that fill it, in order.

        Constant members are written into the template and nested objects inlined, so a
        row is one ``%`` operation however deep it is.
        """
        parts: list[str] = []
        columns: list[Column] = []
        for name, column in self.columns:
            key = json.dumps(name).replace("%", "%%")
            if isinstance(column, Const):
                parts.append(f"{key}:{column.cells(1)[0].replace('%', '%%')}")
            elif isinstance(column, Nested) and column.table.rows == self.rows:
                inner, more = column.table._template()
                parts.append(f"{key}:{inner}")
                columns += more
            else:
                parts.append(f"{key}:%s")
                columns.append(column)
        return "{" + ",".join(parts) + "}", columns

    def rows_text(self) -> list[str]:
        """Each row's object as JSON text."""
        template, columns = self._template()
        cells = [column.cells(self.rows) for column in columns]
        if not cells:
            return [template.replace("%%", "%")] * self.rows
        return list(map(template.__mod__, zip(*cells, strict=True)))

    def text(self) -> str:
        """The rows' objects as JSON text joined by commas (no brackets around them)."""
        return ",".join(self.rows_text())

    def objects(self) -> list[Any]:
        """The rows' objects as dicts."""
        names = [name for name, _ in self.columns]
        values = [column.objects(self.rows) for _, column in self.columns]
        return [dict(zip(names, row, strict=True)) for row in zip(*values, strict=True)]
