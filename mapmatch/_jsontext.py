r"""
JSON objects of many rows at once, from arrays: as text, or as Python objects.

(Over 400 lines on purpose: the compiled writer, the program it runs and the number formatting
must agree byte for byte with ``json.dumps`` and are checked against it together.)

:mod:`mapmatch.export` declares each kind of feature once, as a :class:`Table` of named
columns, and renders it as JSON text (:meth:`Table.text`) or as dicts
(:meth:`Table.objects`); both show the same values, so ``json.loads(table.text())`` equals
``table.objects()``.

The text of a whole table is written by one compiled call (:func:`_write_rows`), from a
small program made once per set of columns (literals, numbers, nested objects and arrays
inlined) and the columns' arrays, so no dict, no JSON encoder and no Python object is
touched per value. Numbers come out as ``json.dumps`` writes them (``repr``); values that
are not finite, and rows outside a column's ``valid`` mask, are ``null``.

Examples
--------
>>> points = Table(2, [("kind", Const("point")), ("n", Ints(np.array([7, -1]))),
...     ("at", Tuple((Floats(np.array([1.23456789, np.nan]), rounding="numpy"),),
...                  np.array([True, False]))),
...     ("name", Strings(["Main St", None]))])
>>> print(points.text().replace("},{", "},\n{"))
{"kind":"point","n":7,"at":[1.2345679],"name":"Main St"},
{"kind":"point","n":-1,"at":null,"name":null}
>>> json.loads("[" + points.text() + "]") == points.objects()
True
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from itertools import accumulate, pairwise
from typing import TYPE_CHECKING, Any, Literal, Protocol

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


@dataclass(slots=True)  # not frozen: a document makes some fifty, a frozen one costs 3x
class Const:
    """The same value (a string, number, bool or ``None``) in every row."""

    value: str | float | bool | None

    def cells(self, rows: int) -> list[str]:
        """The value's JSON text, once per row."""
        return [json.dumps(self.value)] * rows

    def objects(self, rows: int) -> list[Any]:
        """The value, once per row."""
        return [self.value] * rows


@dataclass(slots=True)  # not frozen: a document makes some fifty, a frozen one costs 3x
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
#: ``10.0**k``, for the kernels (``decimals`` up to 22, where every power is exact).
_POW10 = 10.0 ** np.arange(23)
_ROUNDING = {"none": 0, "numpy": 1, "python": 2}
#: What a row of the text is made of: the codes of :func:`_write_rows`' program.
_LIT, _FLOAT, _INT, _BOOL, _TEXT, _GROUP = 0, 1, 2, 3, 4, 5


@njit(cache=True, nogil=True)
def _put_null(out, at):  # type: ignore[no-untyped-def]  # pragma: no cover
    out[at] = 110  # n
    out[at + 1] = 117  # u
    out[at + 2] = 108  # l
    out[at + 3] = 108  # l
    return at + 4


#: The two ASCII digits of 0 to 99, for writing two digits per division.
_PAIRS = np.frombuffer("".join(f"{i:02d}" for i in range(100)).encode("ascii"), dtype=np.uint8)


@njit(cache=True, nogil=True)
def _width(k):  # type: ignore[no-untyped-def]  # pragma: no cover
    """How many decimal digits the unsigned ``k`` has (at least one)."""
    size = 1
    bound = np.uint64(10)
    while size < 20 and k >= bound:
        size += 1
        if size < 20:
            bound *= np.uint64(10)
    return size


@njit(cache=True, nogil=True)
def _put_digits(out, end, k, width):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Write the last ``width`` decimal digits of the unsigned ``k`` (zero-padded) before ``end``.

    Returns ``k`` without them.
    """
    hundred = np.uint64(100)
    j = end
    while width >= 2:
        q = k // hundred
        r = (k - q * hundred) * np.uint64(2)
        out[j - 1] = _PAIRS[r + np.uint64(1)]
        out[j - 2] = _PAIRS[r]
        j -= 2
        width -= 2
        k = q
    if width:
        out[j - 1] = k % np.uint64(10) + np.uint64(48)
        k //= np.uint64(10)
    return k


@njit(cache=True, nogil=True)
def _put_int(out, at, k):  # type: ignore[no-untyped-def]  # pragma: no cover
    """The decimal digits of the int64 ``k`` at ``out[at:]``; returns the end."""
    if k < 0:
        out[at] = 45  # -
        at += 1
        u = np.uint64(-(k + 1)) + np.uint64(1)
    else:
        u = np.uint64(k)
    end = at + _width(u)
    _put_digits(out, end, u, end - at)
    return end


@njit(cache=True, nogil=True)
def _put_float(out, at, v, digits, rounding, pow10):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Write ``repr`` of the finite ``v`` (rounded first) at ``out[at:]``; return the end.

    -1 if ``repr`` itself must write it.
    ``rounding`` 1 is numpy's (``rint(v * 10**digits) / 10**digits``), 2 Python's
    ``round`` (:func:`py_round`: numpy's unless the product is within rounding error of a
    half, then -1). Then ``n = |v| * 10**digits`` rounded must give ``v`` back (then the
    decimal ``n / 10**digits`` with its trailing zeros dropped is the shortest text reading
    back as ``v``, which is what ``repr`` writes) and have at most 15 digits; ``repr`` also
    writes ``1e-05`` below 1e-4.
    """
    scale = pow10[digits]
    if rounding:
        y = v * scale
        if not np.isfinite(y):
            return -1
        if rounding == 2:
            ay = abs(y)
            if ay >= 2.0**52 or abs(abs(y - np.trunc(y)) - 0.5) <= 1e-9 + 8.0 * _EPS * ay:
                return -1
        whole = np.rint(y)
        v = whole / scale
        a = abs(v)
        n = np.rint(a * scale)
        back = n == abs(whole) or n / scale == a  # the first: the same division as v's
    else:
        a = abs(v)
        n = np.rint(a * scale)
        back = n / scale == a
    if n >= _MAX_EXACT or not back or (a != 0.0 and a < 1e-4):
        return -1
    if math.copysign(1.0, v) < 0:
        out[at] = 45  # -
        at += 1
    ten = np.uint64(10)
    k = np.uint64(n)
    if digits == 0:
        end = at + _width(k)
        _put_digits(out, end, k, end - at)
        out[end] = 46  # .
        out[end + 1] = 48  # 0
        return end + 2
    kept = digits  # decimals written: trailing zeros dropped, at least one
    while kept > 1 and k % ten == 0:
        k //= ten
        kept -= 1
    end = at + max(_width(k) - kept, 1) + 1 + kept  # the whole part, the point, the decimals
    whole = _put_digits(out, end, k, kept)
    out[end - kept - 1] = 46  # .
    _put_digits(out, end - kept - 1, whole, end - kept - 1 - at)
    return end


@njit(cache=True, nogil=True)
def _write_rows(  # type: ignore[no-untyped-def]  # pragma: no cover
    rows, sep, ops, lit, lit_at, floats, ints, masks, text, text_at, pow10
):
    """
    Every row's text, by the program ``ops`` (one ``(code, a, b, c)`` per step), ASCII.

    ``_LIT``: the literal ``lit[lit_at[a]:lit_at[a + 1]]``; ``_FLOAT``: ``floats[a]``,
    ``null`` if not finite or not ``masks[b]`` (``b >= 0``), ``c`` is ``decimals * 4 +
    rounding``; ``_INT`` / ``_BOOL``: ``ints[a]`` as digits (``null`` outside ``masks[b]``)
    / ``true`` or ``false``; ``_TEXT``: the row's bytes of ``text`` between ``text_at[a]``;
    ``_GROUP``: ``null`` instead of the next ``b`` steps outside ``masks[a]``. Rows are
    separated by the byte ``sep`` (none if negative).

    Returns the text, where each row starts (and the end), and ``(position, step, row)``
    of each number left for ``repr`` (written as nothing).
    """
    n_ops = ops.shape[0]
    per_row = 1
    n_floats = 0
    for k in range(n_ops):
        code = ops[k, 0]
        if code == 0:
            per_row += lit_at[ops[k, 1] + 1] - lit_at[ops[k, 1]]
        elif code == 1:
            per_row += 28
            n_floats += 1
        elif code == 2:
            per_row += 21
        else:
            per_row += 5
    out = np.empty(rows * per_row + len(text), dtype=np.uint8)
    row_at = np.empty(rows + 1, dtype=np.int64)
    slow = np.empty((rows * n_floats, 3), dtype=np.int64)
    at = 0
    n_slow = 0
    for r in range(rows):
        if r and sep >= 0:
            out[at] = sep
            at += 1
        row_at[r] = at
        k = 0
        while k < n_ops:
            code = ops[k, 0]
            a = ops[k, 1]
            b = ops[k, 2]
            if code == 0:
                for j in range(lit_at[a], lit_at[a + 1]):
                    out[at] = lit[j]
                    at += 1
            elif code == 1:
                v = floats[a, r]
                if (b >= 0 and not masks[b, r]) or not np.isfinite(v):
                    at = _put_null(out, at)
                else:
                    end = _put_float(out, at, v, ops[k, 3] >> 2, ops[k, 3] & 3, pow10)
                    if end < 0:
                        slow[n_slow, 0] = at
                        slow[n_slow, 1] = k
                        slow[n_slow, 2] = r
                        n_slow += 1
                    else:
                        at = end
            elif code == 2:
                if b >= 0 and not masks[b, r]:
                    at = _put_null(out, at)
                else:
                    at = _put_int(out, at, ints[a, r])
            elif code == 3:
                if ints[a, r]:
                    out[at] = 116  # t
                    out[at + 1] = 114  # r
                    out[at + 2] = 117  # u
                    out[at + 3] = 101  # e
                    at += 4
                else:
                    out[at] = 102  # f
                    out[at + 1] = 97  # a
                    out[at + 2] = 108  # l
                    out[at + 3] = 115  # s
                    out[at + 4] = 101  # e
                    at += 5
            elif code == 4:
                for j in range(text_at[a, r], text_at[a, r + 1]):
                    out[at] = text[j]
                    at += 1
            elif not masks[a, r]:  # a group outside its mask
                at = _put_null(out, at)
                k += b
            k += 1
    row_at[rows] = at
    return out[:at], row_at, slow[:n_slow]


class _Writer:
    """
    A program for :func:`_write_rows` and the arrays it reads, made by walking the columns.

    Literals next to each other are merged; a column this module does not know is written
    from its :meth:`Column.cells`.
    """

    __slots__ = ("_mask_at", "_pending", "floats", "ints", "masks", "ops", "rows", "texts")

    def __init__(self, rows: int) -> None:
        self.rows = rows
        self.ops: list[tuple[int, Any, int, int]] = []
        self.floats: list[FloatArray] = []
        self.ints: list[Any] = []
        self.masks: list[BoolArray] = []
        self.texts: list[list[str]] = []
        self._mask_at: dict[int, int] = {}
        self._pending: list[str] = []

    def lit(self, text: str) -> None:
        """Write ``text`` in every row."""
        self._pending.append(text)

    def _flush(self) -> None:
        if self._pending:
            self.ops.append((_LIT, "".join(self._pending), 0, 0))
            self._pending = []

    def _step(self, code: int, a: int, b: int = -1, c: int = 0) -> None:
        if self._pending:
            self._flush()
        self.ops.append((code, a, b, c))

    def _mask(self, valid: BoolArray | None) -> int:
        if valid is None:
            return -1
        at = self._mask_at.get(id(valid))
        if at is None:
            at = self._mask_at[id(valid)] = len(self.masks)
            self.masks.append(valid)
        return at

    def column(self, column: Column) -> None:
        """Write each row's value of ``column``."""
        write = _WRITES.get(type(column))  # one lookup instead of a chain of isinstance
        if write is None or not write(self, column):
            self._step(_TEXT, len(self.texts))
            self.texts.append(column.cells(self.rows))

    def _floats(self, column: Floats) -> bool:
        if not 0 <= column.decimals < len(_POW10):
            msg = f"decimals={column.decimals}: use 0 to {len(_POW10) - 1}"
            raise ValueError(msg)
        code = column.decimals * 4 + _ROUNDING[column.rounding]
        self._step(_FLOAT, len(self.floats), self._mask(column.valid), code)
        self.floats.append(column.values)
        return True

    def _ints(self, column: Ints) -> bool:
        self._step(_INT, len(self.ints), self._mask(column.valid))
        self.ints.append(column.values)
        return True

    def _bools(self, column: Bools) -> bool:
        self._step(_BOOL, len(self.ints))
        self.ints.append(column.values)
        return True

    def _const(self, column: Const) -> bool:
        value = column.value
        self._pending.append(_QUOTES[value] if isinstance(value, str) else json.dumps(value))
        return True

    def _tuple(self, column: Tuple) -> bool:
        column.write(self)
        return True

    def _nested(self, column: Nested) -> bool:
        if column.table.rows != self.rows:
            return False  # written from its cells
        column.table.write(self)
        return True

    def group(self, valid: BoolArray | None) -> int:
        """Open a part written as ``null`` outside ``valid``; close it with :meth:`close`."""
        if valid is None:
            return -1
        self._step(_GROUP, self._mask(valid))
        return len(self.ops) - 1

    def close(self, group: int) -> None:
        """Close the part :meth:`group` opened."""
        if group >= 0:
            self._flush()
            self.ops[group] = (_GROUP, self.ops[group][1], len(self.ops) - group - 1, 0)

    def run(self, sep: int) -> tuple[bytes, IntArray, list[tuple[int, int, str]]]:
        """
        Write the rows.

        Returns the rows' text (separated by the byte ``sep``, none if negative), where each
        row starts, and the ``(position, row, text)`` of each number ``repr`` writes instead.
        """
        self._flush()
        program = _program(tuple(self.ops))
        return _render(program, self.rows, self.floats, self.ints, self.masks, self.texts, sep)


def _render(
    program: tuple[IntArray, Any, IntArray],
    rows: int,
    floats: list[FloatArray],
    ints: list[Any],
    masks: list[BoolArray],
    texts: list[list[str]],
    sep: int,
) -> tuple[bytes, IntArray, list[tuple[int, int, str]]]:
    """:meth:`_Writer.run` of a program and the arrays it reads."""
    ops, lit, lit_at = program
    float_rows = _stacked(floats, rows, np.float64)
    text, text_at = _text(texts, rows)
    out, row_at, slow = _write_rows(
        rows, sep, ops, lit, lit_at, float_rows,
        _stacked(ints, rows, np.int64), _stacked(masks, rows, np.bool_), text, text_at, _POW10,
    )  # fmt: skip
    fixes = (
        [(at, r, _repr(ops, float_rows, k, r)) for at, k, r in slow.tolist()] if len(slow) else []
    )
    return out.tobytes(), row_at, fixes


def _repr(ops: IntArray, floats: FloatArray, step: int, row: int) -> str:
    """What ``repr`` writes for the number of ``step`` in ``row`` (rounded first)."""
    a, c = int(ops[step, 1]), int(ops[step, 3])
    digits, rounding = divmod(c, 4)
    value = floats[a, row : row + 1]
    if rounding == _ROUNDING["python"]:
        value = py_round(value, digits)
    elif rounding == _ROUNDING["numpy"]:
        value = np.round(value, digits)
    number = float(value[0])
    return repr(number) if math.isfinite(number) else _NULL


def _text(texts: list[list[str]], rows: int) -> tuple[Any, IntArray]:
    """The cells of the text columns as one ASCII buffer, and where each one starts."""
    text_at = np.zeros((len(texts), rows + 1), dtype=np.int64)
    if not texts:
        return np.zeros(0, dtype=np.uint8), text_at
    joined = []
    base = 0
    for i, cells in enumerate(texts):
        if len(cells) != rows:
            msg = f"a column has {len(cells)} cells for {rows} rows"
            raise ValueError(msg)
        ends = list(accumulate(map(len, cells), initial=base))
        text_at[i] = ends
        joined.append("".join(cells))
        base = ends[-1]
    data = bytearray("".join(joined).encode("ascii"))
    return np.frombuffer(data, dtype=np.uint8), text_at


class _Planner(_Writer):
    """
    A :class:`_Writer` that also notes where each array of its program came from.

    Each is found again in a table of the same schema by its path (the index of a column
    among its table's, a tuple's items or a nested table's columns, from the top table
    down) and what of it is read: ``values``, ``valid`` or ``cells``.
    """

    __slots__ = ("_next", "_path", "consts", "sources")

    def __init__(self, rows: int) -> None:
        super().__init__(rows)
        self._path: list[int] = []  # the column being written, from the top table
        self._next = [0]  # the index of the next column at each level
        self.sources: dict[str, list[tuple[int, ...]]] = {
            "floats": [], "ints": [], "masks": [], "texts": []
        }  # fmt: skip
        self.consts: list[tuple[tuple[int, ...], Any]] = []

    def column(self, column: Column) -> None:
        """Write the column, and note the path of every array it added."""
        index = self._next[-1]
        self._next[-1] += 1
        self._path.append(index)
        self._next.append(0)
        counts = len(self.floats), len(self.ints), len(self.texts)
        super().column(column)
        path = tuple(self._path)
        if self._next[-1] == 0:  # a leaf: what was added is its own
            for kind, before in zip(("floats", "ints", "texts"), counts, strict=True):
                added = len(getattr(self, kind)) - before
                self.sources[kind] += [path] * added
            if isinstance(column, Const):
                self.consts.append((path, column.value))
        self._next.pop()
        self._path.pop()

    def _mask(self, valid: BoolArray | None) -> int:
        count = len(self.masks)
        at = super()._mask(valid)
        if len(self.masks) > count:
            self.sources["masks"].append(tuple(self._path))
        return at


@dataclass(frozen=True, slots=True)
class _Plan:
    """A schema's program, and the paths of its arrays in a table (:class:`_Planner`)."""

    program: tuple[IntArray, Any, IntArray]
    floats: tuple[tuple[int, ...], ...]
    ints: tuple[tuple[int, ...], ...]
    masks: tuple[tuple[int, ...], ...]
    texts: tuple[tuple[int, ...], ...]
    consts: tuple[tuple[tuple[int, ...], Any], ...]

    def gather(self, table: Table) -> tuple[list[Any], list[Any], list[Any], list[list[str]]]:
        """The lists :func:`_render` reads, taken from ``table`` along the paths."""
        rows = table.rows
        return (
            [_find(table, p).values for p in self.floats],
            [_find(table, p).values for p in self.ints],
            [_find(table, p).valid for p in self.masks],
            [_find(table, p).cells(rows) for p in self.texts],
        )


#: The plan of each schema (:attr:`Table.schema`), made on its first table.
_PLANS: dict[str, _Plan] = {}


def _find(table: Table, path: tuple[int, ...]) -> Any:
    """The column at ``path`` (indices of a table's columns, tuple's items, nested columns)."""
    node: Any = table
    for index in path:
        if isinstance(node, Tuple):
            node = node.items[index]
        else:
            node = (node.table if isinstance(node, Nested) else node).columns[index][1]
    return node


def _planned(table: Table, schema: str, sep: int) -> tuple[bytes, IntArray, list[Any]]:
    """:meth:`_Writer.run` of ``table`` by its schema's plan (made on the first table)."""
    plan = _PLANS.get(schema)
    if plan is None or any(_find(table, p).value != v for p, v in plan.consts):
        writer = _Planner(table.rows)
        table.write(writer)
        writer._flush()
        src = writer.sources
        plan = _Plan(
            _program(tuple(writer.ops)),
            tuple(src["floats"]), tuple(src["ints"]), tuple(src["masks"]), tuple(src["texts"]),
            tuple(writer.consts),
        )  # fmt: skip
        if len(_PLANS) >= 64:  # schemas are few; never grow without bound
            _PLANS.clear()
        _PLANS[schema] = plan
        arrays = writer.floats, writer.ints, writer.masks, writer.texts
    else:
        arrays = plan.gather(table)
    return _render(plan.program, table.rows, *arrays, sep)


def _stacked(columns: list[Any], rows: int, dtype: type) -> Any:
    """The columns' values as the rows of one 2-D array (``len(columns)`` x ``rows``)."""
    if not columns:
        return np.empty((0, rows), dtype=dtype)
    stacked: Any = np.array(columns, dtype=dtype)
    if stacked.shape != (len(columns), rows):
        msg = f"columns of {stacked.shape[1:]} values for {rows} rows"
        raise ValueError(msg)
    return stacked


_PROGRAMS: dict[tuple[tuple[int, Any, int, int], ...], tuple[IntArray, Any, IntArray]] = {}


def _program(steps: tuple[tuple[int, Any, int, int], ...]) -> tuple[IntArray, Any, IntArray]:
    """``steps`` as the arrays :func:`_write_rows` reads, made once per program."""
    program = _PROGRAMS.get(steps)
    if program is None:
        literals = [s[1] for s in steps if s[0] == _LIT]
        ops = np.array(
            [(code, a, b, c) for code, a, b, c in _numbered(steps)], dtype=np.int64
        ).reshape(-1, 4)
        lit = np.frombuffer(bytearray("".join(literals).encode("ascii")), dtype=np.uint8)
        lit_at = np.concatenate(([0], np.cumsum([len(t) for t in literals]))).astype(np.int64)
        if len(_PROGRAMS) >= 256:  # the tables' shapes are few; never grow without bound
            _PROGRAMS.clear()
        program = _PROGRAMS[steps] = (ops, lit, lit_at)
    return program


def _numbered(steps: Sequence[tuple[int, Any, int, int]]) -> list[tuple[int, int, int, int]]:
    """The steps with each literal replaced by its number."""
    out = []
    n = 0
    for code, a, b, c in steps:
        if code == _LIT:
            out.append((code, n, b, c))
            n += 1
        else:
            out.append((code, a, b, c))
    return out


def _joined(column: Column, rows: int) -> str:
    """The rows' values of ``column`` as JSON text joined by commas."""
    writer = _Writer(rows)
    writer.column(column)
    text, _, fixes = writer.run(ord(","))
    return _spliced(text, fixes, 0).decode("ascii")


def _each(write: Any, rows: int) -> list[str]:
    """Each row's JSON text of what ``write`` writes into a :class:`_Writer`."""
    writer = _Writer(rows)
    write(writer)
    text, starts, fixes = writer.run(-1)
    row_at = starts.tolist()
    by_row: dict[int, list[tuple[int, int, str]]] = {}
    for fix in fixes:
        by_row.setdefault(fix[1], []).append(fix)
    cells = [text[a:b] for a, b in pairwise(row_at)]
    for r, row_fixes in by_row.items():
        cells[r] = _spliced(cells[r], row_fixes, row_at[r])
    return [cell.decode("ascii") for cell in cells]


def _spliced(text: bytes, fixes: list[tuple[int, int, str]], start: int) -> bytes:
    """``text`` (which starts at ``start``) with each fix's text inserted at its position."""
    if not fixes:
        return text
    parts: list[bytes] = []
    done = 0
    for at, _, fix in fixes:
        parts += (text[done : at - start], fix.encode("ascii"))
        done = at - start
    parts.append(text[done:])
    return b"".join(parts)


@dataclass(slots=True)  # not frozen: a document makes some fifty, a frozen one costs 3x
class Floats:
    """
    Real numbers as ``repr`` writes them; ``null`` if not finite or not valid.

    ``rounding`` rounds them to ``decimals`` first: ``"numpy"`` as ``numpy.round`` does,
    ``"python"`` as Python's ``round`` (:func:`py_round`); ``"none"`` writes them as they
    are, which is fastest when they carry at most ``decimals`` decimals (written by a
    compiled kernel; any other value by ``repr`` itself, the same text, slower).
    """

    values: FloatArray
    valid: BoolArray | None = None
    decimals: int = 7
    rounding: Literal["none", "numpy", "python"] = "none"

    def _rounded(self) -> FloatArray:
        values = np.asarray(self.values, dtype=np.float64)
        if self.rounding == "python":
            return py_round(values, self.decimals)
        if self.rounding == "numpy":
            return np.asarray(np.round(values, self.decimals), dtype=np.float64)
        return values

    def cells(self, rows: int) -> list[str]:
        """``repr`` of each number (rounded)."""
        return _each(lambda w: w.column(self), rows)

    def objects(self, rows: int) -> list[Any]:
        """Python floats (rounded), ``None`` where missing."""
        values = self._rounded()
        missing = ~np.isfinite(values)
        if self.valid is not None:
            missing |= ~self.valid
        return _nulls(values.tolist(), missing, None)


@dataclass(slots=True)  # not frozen: a document makes some fifty, a frozen one costs 3x
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


def _quoted(value: str | None) -> str:
    """``json.dumps(value)``; plain printable ASCII without quotes or backslashes directly."""
    if (
        value is not None
        and value.isascii()
        and value.isprintable()
        and '"' not in value
        and "\\" not in value
    ):
        return f'"{value}"'
    return json.dumps(value)


class _Quotes(dict[str | None, str]):
    """:func:`_quoted` of the strings seen (names and classes repeat), made once each."""

    def __missing__(self, value: str | None) -> str:
        if len(self) >= 65536:
            self.clear()
        text = self[value] = _quoted(value)
        return text


_QUOTES = _Quotes()


@dataclass(slots=True)  # not frozen: a document makes some fifty, a frozen one costs 3x
class Strings:
    """Texts (escaped as ``json.dumps`` does, ASCII); ``null`` for ``None``."""

    values: Sequence[str | None]

    def cells(self, rows: int) -> list[str]:
        """The quoted strings."""
        return list(map(_QUOTES.__getitem__, self.values))

    def objects(self, rows: int) -> list[Any]:
        """The strings."""
        return list(self.values)


@dataclass(slots=True)  # not frozen: a document makes some fifty, a frozen one costs 3x
class Tuple:
    """
    ``[a, b, ...]`` of some columns per row, e.g. a position ``[lon, lat]``.

    ``null`` outside ``valid``; with ``geometry``, each array is the ``coordinates`` of a
    GeoJSON geometry of that type (``{"type": "Point", "coordinates": [lon, lat]}``).
    """

    items: Sequence[Column]
    valid: BoolArray | None = None
    geometry: str | None = None

    def write(self, writer: _Writer) -> None:
        """Write each row's array."""
        group = writer.group(self.valid)
        if self.geometry is None:
            writer.lit("[")
        else:
            writer.lit(f'{{"type":{json.dumps(self.geometry)},"coordinates":[')
        for i, item in enumerate(self.items):
            if i:
                writer.lit(",")
            writer.column(item)
        writer.lit("]" if self.geometry is None else "]}")
        writer.close(group)

    def cells(self, rows: int) -> list[str]:
        """The arrays' text."""
        return _each(self.write, rows)

    def objects(self, rows: int) -> list[Any]:
        """Lists (or geometry dicts), ``None`` outside ``valid``."""
        arrays: list[Any] = list(
            map(list, zip(*(c.objects(rows) for c in self.items), strict=True))
        )
        if self.geometry is not None:
            arrays = [{"type": self.geometry, "coordinates": a} for a in arrays]
        return _nulls(arrays, None if self.valid is None else ~self.valid, None)


@dataclass(slots=True)  # not frozen: a document makes some fifty, a frozen one costs 3x
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


@dataclass(slots=True)  # not frozen: a document makes some fifty, a frozen one costs 3x
class Values:
    """The rows of one column as the items of a JSON array (``v0,v1,...``)."""

    column: Column
    rows: int

    def text(self) -> str:
        """The values' text joined by commas."""
        return _joined(self.column, self.rows)

    def objects(self) -> list[Any]:
        """The values as Python objects."""
        return self.column.objects(self.rows)


@dataclass(slots=True)  # not frozen: a document makes some fifty, a frozen one costs 3x
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


@dataclass(slots=True)  # not frozen: a document makes some fifty, a frozen one costs 3x
class Table:
    """
    Rows of JSON objects with the same members: ``{name: value, ...}`` per row.

    The text is written by one compiled call for the whole table (nested objects and
    arrays of the same rows inlined), from a program made once per set of columns.

    Parameters
    ----------
    rows
        Number of rows.
    columns
        ``(name, column)`` in member order.
    schema
        A name for tables made by the same code every time: the same members and column
        kinds, masks shared by the same columns, the same decimals and geometry types (a
        :class:`Const` may change: its value is checked). Its first table's walk over the
        columns is kept (the program, and where each array sits), and later ones are
        written from it without walking them again.
    """

    rows: int
    columns: Sequence[tuple[str, Column]]
    schema: str | None = None

    def write(self, writer: _Writer) -> None:
        """Write each row's object."""
        for i, (name, column) in enumerate(self.columns):
            writer.lit(("{" if i == 0 else ",") + _QUOTES[name] + ":")
            writer.column(column)
        writer.lit("}" if self.columns else "{}")

    def rows_text(self) -> list[str]:
        """Each row's object as JSON text."""
        return _each(self.write, self.rows)

    def ascii(self) -> bytes:
        """The rows' objects as JSON text joined by commas (no brackets around them)."""
        if self.rows == 0:
            return b""
        if self.schema is not None:
            text, _, fixes = _planned(self, self.schema, ord(","))
        else:
            writer = _Writer(self.rows)
            self.write(writer)
            text, _, fixes = writer.run(ord(","))
        return _spliced(text, fixes, 0)

    def text(self) -> str:
        """:meth:`ascii` as a string."""
        return self.ascii().decode("ascii")

    def objects(self) -> list[Any]:
        """The rows' objects as dicts."""
        names = [name for name, _ in self.columns]
        values = [column.objects(self.rows) for _, column in self.columns]
        return [dict(zip(names, row, strict=True)) for row in zip(*values, strict=True)]


#: How :meth:`_Writer.column` writes each kind of column this module knows (in the program;
#: any other column, or a writer returning False, is written from its cells).
_WRITES: dict[type, Any] = {
    Floats: _Writer._floats,
    Ints: _Writer._ints,
    Bools: _Writer._bools,
    Const: _Writer._const,
    Tuple: _Writer._tuple,
    Nested: _Writer._nested,
}
