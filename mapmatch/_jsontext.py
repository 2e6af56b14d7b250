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
inlined, the arrays of items of each row too: :class:`Items`) and the columns' arrays, so
no dict, no JSON encoder and no Python object is touched per value; several tables' rows
one after another are one call as well (:func:`chained_ascii`). Tables declared over the
columns of one compiled call (:class:`Packed`: a document's features) are walked once;
later calls run that walk's program on the packed arrays themselves, no table made
(:func:`sourced_pieces`). Numbers come out as ``json.dumps`` writes them (``repr``); values
that are not finite, and rows outside a column's ``valid`` mask, are ``null``; texts as it
writes them too.

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
from typing import TYPE_CHECKING, Any, Literal, NamedTuple, Protocol

import numpy as np
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from mapmatch.readonly import read_only

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from mapmatch.types import BoolArray, ByteArray, FloatArray, IntArray

__all__ = [
    "Bools",
    "Choice",
    "Column",
    "Const",
    "Floats",
    "Ints",
    "Items",
    "Nested",
    "Packed",
    "Strings",
    "Table",
    "Tuple",
    "Utf8",
    "chained_ascii",
    "chained_pieces",
    "py_round",
    "sourced_pieces",
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
_LIT, _FLOAT, _INT, _BOOL, _TEXT, _GROUP, _EACH, _NEXT, _CHOICE, _UTF8 = range(10)


@njit(cache=True, nogil=True, inline="always")
def _put_null(out, at):  # type: ignore[no-untyped-def]  # pragma: no cover
    out[at] = 110  # n
    out[at + 1] = 117  # u
    out[at + 2] = 108  # l
    out[at + 3] = 108  # l
    return at + 4


@intrinsic
def _memcpy(typingctx, out, at, source, start, size):  # type: ignore[no-untyped-def]  # pragma: no cover
    """``out[at:at + size] = source[start:start + size]`` as one ``memcpy`` (C-contiguous bytes)."""
    if not all(isinstance(a, types.Array) and a.layout == "C" for a in (out, source)):
        return None
    sig = types.void(out, at, source, start, size)

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        out_v, at_v, source_v, start_v, size_v = args
        into = context.make_array(signature.args[0])(context, builder, out_v)
        part = context.make_array(signature.args[2])(context, builder, source_v)
        into_at = builder.gep(into.data, [at_v])
        part_at = builder.gep(part.data, [start_v])
        cgutils.raw_memcpy(builder, into_at, part_at, size_v, 1)  # type: ignore[no-untyped-call]
        return context.get_dummy_value()

    return sig, codegen


@njit(cache=True, nogil=True, inline="always")
def _put_bytes(out, at, source, start, end):  # type: ignore[no-untyped-def]  # pragma: no cover
    """Copy ``source[start:end]`` to ``out[at:]``; return the end."""
    size = end - start
    _memcpy(out, at, source, start, size)  # type: ignore[call-arg]  # the typing context is numba's
    return at + size


#: The two ASCII digits of 0 to 99, for writing two digits per division.
_PAIRS = np.frombuffer("".join(f"{i:02d}" for i in range(100)).encode("ascii"), dtype=np.uint8)


@njit(cache=True, nogil=True, inline="always")
def _width(k):  # type: ignore[no-untyped-def]  # pragma: no cover
    """How many decimal digits the unsigned ``k`` has (at least one)."""
    size = 1
    bound = np.uint64(10)
    while size < 20 and k >= bound:
        size += 1
        if size < 20:
            bound *= np.uint64(10)
    return size


@njit(cache=True, nogil=True, inline="always")
def _put_digits(out, end, k, width):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Write the last ``width`` decimal digits of the unsigned ``k`` (zero-padded) before ``end``.

    Returns ``k`` without them.
    """
    hundred = np.uint64(100)
    j = end
    # the odd digit first, so that ``out`` is last used in the loop on every path (a last use
    # in a branch makes numba count references on ``out`` at each inlined call, a few ns each)
    if width & 1:
        out[j - 1] = k % np.uint64(10) + np.uint64(48)
        k //= np.uint64(10)
        j -= 1
        width -= 1
    while width >= 2:
        q = k // hundred
        r = (k - q * hundred) * np.uint64(2)
        out[j - 1] = _PAIRS[r + np.uint64(1)]
        out[j - 2] = _PAIRS[r]
        j -= 2
        width -= 2
        k = q
    return k


@njit(cache=True, nogil=True, inline="always")
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


@njit(cache=True, nogil=True, inline="always")
def _float_decimal(v, digits, rounding, pow10):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    The decimal ``repr`` writes for the finite ``v`` (rounded first): ``(n, decimals, minus)``.

    The text is ``n`` with a point before its last ``decimals`` digits (trailing zeros
    dropped, at least one decimal: a whole number is ``10 n`` with one), ``-`` first when
    ``minus``; ``decimals`` is -1 where ``repr`` itself must write it.
    ``rounding`` 1 is numpy's (``rint(v * 10**digits) / 10**digits``), 2 Python's
    ``round`` (:func:`py_round`: numpy's unless the product is within rounding error of a
    half, then -1). Then ``n = |v| * 10**digits`` rounded must give ``v`` back (then the
    decimal ``n / 10**digits`` with its trailing zeros dropped is the shortest text reading
    back as ``v``, which is what ``repr`` writes) and have at most 15 digits; ``repr`` also
    writes ``1e-05`` below 1e-4.
    """
    none = (np.uint64(0), -1, False)
    scale = pow10[digits]
    if rounding:
        y = v * scale
        if not np.isfinite(y):
            return none
        if rounding == 2:
            ay = abs(y)
            if ay >= 2.0**52 or abs(abs(y - np.trunc(y)) - 0.5) <= 1e-9 + 8.0 * _EPS * ay:
                return none
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
        return none
    minus = math.copysign(1.0, v) < 0
    ten = np.uint64(10)
    k = np.uint64(n)
    if digits == 0:  # "n.0" (below 10**15: ten times it fits)
        return k * ten, 1, minus
    kept = digits  # decimals written: trailing zeros dropped, at least one
    while kept > 1 and k % ten == 0:
        k //= ten
        kept -= 1
    return k, kept, minus


@njit(cache=True, nogil=True, inline="always")
def _put_decimal(out, at, k, kept, minus):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Write :func:`_float_decimal`'s decimal at ``out[at:]``; return the end.

    Kept apart from :func:`_float_decimal` (which may leave the number to ``repr``) so that
    ``out`` is last used at one place on every path (see :func:`_put_digits`).
    """
    if minus:
        out[at] = 45  # -
        at += 1
    end = at + max(_width(k) - kept, 1) + 1 + kept  # the whole part, the point, the decimals
    whole = _put_digits(out, end, k, kept)
    out[end - kept - 1] = 46  # .
    _put_digits(out, end - kept - 1, whole, end - kept - 1 - at)
    return end


#: At most this many bytes of JSON text per byte of UTF-8 (a control character: ``\\u001f``).
_ESCAPED_PER_BYTE = 6
#: The hexadecimal digits ``json.dumps`` escapes with (lower case).
_HEX = np.frombuffer(b"0123456789abcdef", dtype=np.uint8)
#: The two-character escapes ``json.dumps`` uses, by character (0 where it uses ``\\u``).
_SHORT_ESCAPES = np.zeros(128, dtype=np.uint8)
for _char, _escape in zip('"\\\n\r\t\b\f', '"\\nrtbf', strict=True):
    _SHORT_ESCAPES[ord(_char)] = ord(_escape)


@njit(cache=True, nogil=True, inline="always")
def _put_u_escape(out, at, unit):  # type: ignore[no-untyped-def]  # pragma: no cover
    r"""``\uXXXX`` of the UTF-16 code unit ``unit`` at ``out[at:]``; returns the end."""
    out[at] = 92  # backslash
    out[at + 1] = 117  # u
    for j in range(4):
        out[at + 5 - j] = _HEX[(unit >> (4 * j)) & 15]
    return at + 6


@njit(cache=True, nogil=True)
def _put_escaped(out, at, text, start, stop):  # type: ignore[no-untyped-def]  # pragma: no cover
    r"""
    The UTF-8 ``text[start:stop]`` as ``json.dumps`` writes a string (ASCII, quoted); the end.

    Printable ASCII but ``"`` and ``\`` as it is, those two and ``\n``, ``\r``, ``\t``,
    ``\b``, ``\f`` with a backslash, every other character as ``\uXXXX`` (a surrogate pair
    beyond U+FFFF). A sequence cut off by ``stop`` is written as U+FFFD.
    """
    out[at] = 34  # "
    at += 1
    i = start
    while i < stop:
        lead = np.int64(text[i])
        if lead < 0x80:
            size, point = 1, lead
        elif lead < 0xE0:
            size, point = 2, lead & 0x1F
        elif lead < 0xF0:
            size, point = 3, lead & 0x0F
        else:
            size, point = 4, lead & 0x07
        if i + size > stop:
            size, point = stop - i, np.int64(0xFFFD)
        else:
            for j in range(i + 1, i + size):
                point = (point << 6) | (np.int64(text[j]) & 0x3F)
        i += size
        if 0x20 <= point < 0x7F and point != 34 and point != 92:
            out[at] = point
            at += 1
        elif point < 0x80 and _SHORT_ESCAPES[point]:
            out[at] = 92  # backslash
            out[at + 1] = _SHORT_ESCAPES[point]
            at += 2
        elif point < 0x10000:
            at = _put_u_escape(out, at, point)
        else:
            point -= 0x10000
            at = _put_u_escape(out, at, 0xD800 | (point >> 10))
            at = _put_u_escape(out, at, 0xDC00 | (point & 0x3FF))
    out[at] = 34  # "
    return at + 1


@njit(cache=True, nogil=True)
def _output_size(rows, sep, ops, lit_at, floats_at, ints, ints_at, text, text_at, text_col):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Bytes enough for the text of :func:`_write_rows`, after checking every column's length.

    Each step runs at most once per row of its level (the top table's rows, or the rows of
    the part an ``_EACH`` runs over: its bounds rise from 0 to that part's length, so every
    row of the part is written at most once), which bounds what it writes.
    """
    size = rows + 1
    extent = rows
    outer = np.empty(ops.shape[0] + 1, dtype=np.int64)
    depth = 0
    for k in range(ops.shape[0]):
        code = ops[k, 0]
        a = ops[k, 1]
        b = ops[k, 2]
        if code == 0:
            size += (lit_at[a + 1] - lit_at[a]) * extent
            continue
        if code == 6:
            at = ints_at[a]
            if ints_at[a + 1] - at != extent + 1 or ints[at] != 0:
                msg = "an array's bounds need one entry more than its table's rows, from 0"
                raise ValueError(msg)
            for j in range(at, at + extent):
                if ints[j + 1] < ints[j]:
                    msg = "an array's bounds must not decrease"
                    raise ValueError(msg)
            outer[depth] = extent
            depth += 1
            extent = ints[at + extent]
            size += extent + outer[depth - 1]  # the commas between the items, and before
            continue
        if code == 7:
            depth -= 1
            extent = outer[depth]
            continue
        if code == 1:
            length = floats_at[a + 1] - floats_at[a]
            size += 28 * extent
        elif code == 4:
            length = text_col[a + 1] - text_col[a]
            size += text_at[text_col[a + 1]] - text_at[text_col[a]]
        elif code == 8:
            length = ints_at[a + 1] - ints_at[a]
            widest = 0
            for j in range(b, b + ops[k, 3]):
                widest = max(widest, lit_at[j + 1] - lit_at[j])
            for j in range(ints_at[a], ints_at[a + 1]):
                if ints[j] < 0 or ints[j] >= ops[k, 3]:
                    msg = "a choice's number is not one of its choices"
                    raise ValueError(msg)
            size += widest * extent
        elif code == 9:
            length = ints_at[a + 1] - ints_at[a]
            if ints_at[b + 1] - ints_at[b] != length:
                msg = "a text column's starts and stops differ in length"
                raise ValueError(msg)
            for j in range(length):
                lo = ints[ints_at[a] + j]
                hi = ints[ints_at[b] + j]
                if lo < 0 or hi < lo or hi > len(text):
                    msg = "a text's bytes are outside the text"
                    raise ValueError(msg)
                size += _ESCAPED_PER_BYTE * (hi - lo) + 4  # the quotes, or null
        else:  # ints, bools, a group's mask
            length = ints_at[a + 1] - ints_at[a]
            size += (21 if code == 2 else 5) * extent
        mask = b if code == 1 or code == 2 else -1
        if length != extent or (mask >= 0 and ints_at[mask + 1] - ints_at[mask] != extent):
            msg = "a column's length is not its table's rows"
            raise ValueError(msg)
    return size


@njit(cache=True, nogil=True)
def _write_rows(  # type: ignore[no-untyped-def]  # pragma: no cover
    rows, sep, ops, lit, lit_at, floats, floats_at, ints, ints_at, text, text_at, text_col, pow10
):
    """
    Every row's text, by the program ``ops`` (one ``(code, a, b, c)`` per step), ASCII.

    Each column is a run of one of the flat arrays: column ``a`` of ``floats`` is
    ``floats[floats_at[a]:floats_at[a + 1]]``, one value per row of its level, the same for
    ``ints`` (whole numbers, bools, masks and bounds); text column ``a`` has its rows' bytes
    ``text[text_at[i]:text_at[i + 1]]``, ``i`` from ``text_col[a]``.

    ``_LIT``: the literal ``lit[lit_at[a]:lit_at[a + 1]]``; ``_FLOAT``: float column ``a``,
    ``null`` if not finite or not set in mask ``b`` (``b >= 0``), ``c`` is ``decimals * 4 +
    rounding``; ``_INT`` / ``_BOOL``: int column ``a`` as digits (``null`` outside mask
    ``b``) / ``true`` or ``false``; ``_TEXT``: the row's bytes of text column ``a``;
    ``_GROUP``: ``null`` instead of the next ``b`` steps outside mask ``a``; ``_EACH``: the
    next ``b`` steps (up to and with their ``_NEXT``) once for each row of a part from
    ``bounds[row]`` to ``bounds[row + 1]`` (int column ``a``), separated by commas (with
    ``c`` 1, one before the first too if the row has text already). Rows are separated by
    the byte ``sep`` (none if negative).

    Returns the text, where each row starts (and the end), and ``(position, step, row,
    top row)`` of each number left for ``repr`` (written as nothing; ``row`` of its level).
    """
    n_ops = ops.shape[0]
    size = _output_size(rows, sep, ops, lit_at, floats_at, ints, ints_at, text, text_at, text_col)
    n_floats = 0
    for k in range(n_ops):
        if ops[k, 0] == 1:
            n_floats += floats_at[ops[k, 1] + 1] - floats_at[ops[k, 1]]
    out = np.empty(size, dtype=np.uint8)
    row_at = np.empty(rows + 1, dtype=np.int64)
    slow = np.empty((n_floats, 4), dtype=np.int64)
    saved = np.empty((n_ops + 1, 3), dtype=np.int64)  # an _EACH's row, end and first step
    depth = 0
    at = 0
    n_slow = 0
    for r in range(rows):
        if r and sep >= 0:
            out[at] = sep
            at += 1
        row_at[r] = at
        row = r
        k = 0
        while k < n_ops:
            code = ops[k, 0]
            a = ops[k, 1]
            b = ops[k, 2]
            if code == 0:
                at = _put_bytes(out, at, lit, lit_at[a], lit_at[a + 1])
            elif code == 1:
                v = floats[floats_at[a] + row]
                if (b >= 0 and not ints[ints_at[b] + row]) or not np.isfinite(v):
                    at = _put_null(out, at)
                else:
                    n, kept, minus = _float_decimal(v, ops[k, 3] >> 2, ops[k, 3] & 3, pow10)
                    if kept < 0:
                        slow[n_slow, 0] = at
                        slow[n_slow, 1] = k
                        slow[n_slow, 2] = row
                        slow[n_slow, 3] = r
                        n_slow += 1
                    else:
                        at = _put_decimal(out, at, n, kept, minus)
            elif code == 2:
                if b >= 0 and not ints[ints_at[b] + row]:
                    at = _put_null(out, at)
                else:
                    at = _put_int(out, at, ints[ints_at[a] + row])
            elif code == 3:
                if ints[ints_at[a] + row]:
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
                i = text_col[a] + row
                at = _put_bytes(out, at, text, text_at[i], text_at[i + 1])
            elif code == 8:
                j = b + ints[ints_at[a] + row]
                at = _put_bytes(out, at, lit, lit_at[j], lit_at[j + 1])
            elif code == 9:
                lo = ints[ints_at[a] + row]
                hi = ints[ints_at[b] + row]
                if lo == hi and ops[k, 3]:
                    at = _put_null(out, at)
                else:
                    at = _put_escaped(out, at, text, lo, hi)
            elif code == 5:
                if not ints[ints_at[a] + row]:  # a group outside its mask
                    at = _put_null(out, at)
                    k += b
            elif code == 6:
                lo = ints[ints_at[a] + row]
                hi = ints[ints_at[a] + row + 1]
                if lo < hi and ops[k, 3] and at > row_at[r]:  # joined to what came before
                    out[at] = 44  # ,
                    at += 1
                if lo < hi:
                    saved[depth, 0] = row
                    saved[depth, 1] = hi
                    saved[depth, 2] = k + 1
                    depth += 1
                    row = lo
                else:
                    k += b  # an empty array
            elif row + 1 < saved[depth - 1, 1]:  # _NEXT, and more items to write
                row += 1
                out[at] = 44  # ,
                at += 1
                k = saved[depth - 1, 2]
                continue
            else:  # _NEXT after the last item
                depth -= 1
                row = saved[depth, 0]
            k += 1
    row_at[rows] = at
    return out[:at], row_at, slow[:n_slow]


class _Writer:
    """
    A program for :func:`_write_rows` and the arrays it reads, made by walking the columns.

    Literals next to each other are merged; a column this module does not know is written
    from its :meth:`Column.cells`. ``rows`` is the rows of the level being written: the
    top table's, or inside an :class:`Items` those of its part.
    """

    __slots__ = ("_mask_at", "_pending", "floats", "ints", "ops", "rows", "text", "texts")

    def __init__(self, rows: int) -> None:
        self.rows = rows
        self.text: Any = None  # the UTF-8 text :class:`Utf8` columns are written from, if any
        self.ops: list[tuple[int, Any, int, int]] = []
        self.floats: list[FloatArray] = []
        self.ints: list[Any] = []  # whole numbers, bools, masks and bounds
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

    def _add_floats(self, values: FloatArray) -> int:
        self.floats.append(values)
        return len(self.floats) - 1

    def _add_ints(self, values: Any, member: str) -> int:
        """Add an int column read from the ``member`` (values, valid, bounds) of a column."""
        self.ints.append(values)
        return len(self.ints) - 1

    def _add_text(self, column: Column) -> int:
        self.texts.append(column.cells(self.rows))
        return len(self.texts) - 1

    def _mask(self, valid: BoolArray | None) -> int:
        if valid is None:
            return -1
        at = self._mask_at.get(id(valid))
        if at is None:
            at = self._mask_at[id(valid)] = self._add_ints(valid, "valid")
        return at

    def column(self, column: Column) -> None:
        """Write each row's value of ``column``."""
        write = _WRITES.get(type(column))  # one lookup instead of a chain of isinstance
        if write is None or not write(self, column):
            self._step(_TEXT, self._add_text(column))

    def _floats(self, column: Floats) -> bool:
        if not 0 <= column.decimals < len(_POW10):
            msg = f"decimals={column.decimals}: use 0 to {len(_POW10) - 1}"
            raise ValueError(msg)
        code = column.decimals * 4 + _ROUNDING[column.rounding]
        mask = self._mask(column.valid)
        self._step(_FLOAT, self._add_floats(column.values), mask, code)
        return True

    def _ints(self, column: Ints) -> bool:
        mask = self._mask(column.valid)
        self._step(_INT, self._add_ints(column.values, "values"), mask)
        return True

    def _bools(self, column: Bools) -> bool:
        self._step(_BOOL, self._add_ints(column.values, "values"))
        return True

    def _const(self, column: Const) -> bool:
        value = column.value
        self._pending.append(_QUOTES[value] if isinstance(value, str) else json.dumps(value))
        return True

    def _tuple(self, column: Tuple) -> bool:
        column.write(self)
        return True

    def _choice(self, column: Choice) -> bool:
        self._step(_CHOICE, self._add_ints(column.codes, "codes"), column.choices)  # type: ignore[arg-type]  # numbered in _program
        return True

    def _utf8(self, column: Utf8) -> bool:
        if self.text is None or column.text is not self.text:
            return False  # written from its cells
        start = self._add_ints(column.start, "start")
        self._step(_UTF8, start, self._add_ints(column.stop, "stop"), int(column.empty_null))
        return True

    def _nested(self, column: Nested) -> bool:
        if column.table.rows != self.rows:
            return False  # written from its cells
        column.table.write(self)
        return True

    def _items(self, column: Items) -> bool:
        column.write(self)
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

    def each(
        self, bounds: IntArray, rows: int, member: str = "bounds", *, join: bool = False
    ) -> tuple[int, int]:
        """
        Open the items of an array: rows ``bounds[row]:bounds[row + 1]`` of a part of ``rows``.

        What is written until :meth:`next` is written once per item, commas between them
        (and with ``join`` one before the first if the row has text already). ``member``
        names where the bounds are found.
        """
        self._step(_EACH, self._add_ints(bounds, member), -1, int(join))
        outer, self.rows = self.rows, rows
        return len(self.ops) - 1, outer

    def next(self, opened: tuple[int, int]) -> None:
        """Close the items :meth:`each` opened."""
        step, self.rows = opened
        self._step(_NEXT, 0)
        code, a, _, c = self.ops[step]
        self.ops[step] = (code, a, len(self.ops) - step - 1, c)

    def run(self, sep: int) -> tuple[memoryview, IntArray, list[tuple[int, int, str]]]:
        """
        Write the rows.

        Returns the rows' text (separated by the byte ``sep``, none if negative; a view of the
        written buffer, not copied), where each row starts, and the ``(position, row, text)``
        of each number ``repr`` writes instead.
        """
        self._flush()
        program = _program(tuple(self.ops))
        return _render(program, self.rows, self.floats, self.ints, self.texts, sep)


def _render(
    program: tuple[IntArray, Any, IntArray],
    rows: int,
    floats: list[FloatArray],
    ints: list[Any],
    texts: list[list[str]],
    sep: int,
) -> tuple[memoryview, IntArray, list[tuple[int, int, str]]]:
    """:meth:`_Writer.run` of a program and the arrays it reads."""
    ops, lit, lit_at = program
    flat_floats, floats_at = _flat(floats, np.float64)
    flat_ints, ints_at = _flat(ints, np.int64)
    text, text_at, text_col = _text(texts)
    out, row_at, slow = _write_rows(
        rows, sep, ops, lit, lit_at, flat_floats, floats_at, flat_ints, ints_at,
        text, text_at, text_col, _POW10,
    )  # fmt: skip
    fixes = (
        [(at, top, _repr(ops, flat_floats, floats_at, k, r)) for at, k, r, top in slow.tolist()]
        if len(slow)
        else []
    )
    return memoryview(out), row_at, fixes


def _flat(columns: list[Any], dtype: type) -> tuple[Any, IntArray]:
    """The columns end to end as one array of ``dtype``, and where each one starts (and ends)."""
    at = np.fromiter(accumulate(map(len, columns), initial=0), np.int64, len(columns) + 1)
    if not columns:
        return np.zeros(0, dtype=dtype), at
    return np.concatenate(columns, dtype=dtype, casting="unsafe"), at


def _repr(ops: IntArray, floats: FloatArray, floats_at: IntArray, step: int, row: int) -> str:
    """What ``repr`` writes for the number of ``step`` in ``row`` (rounded first)."""
    a, c = int(ops[step, 1]), int(ops[step, 3])
    digits, rounding = divmod(c, 4)
    at = int(floats_at[a]) + row
    if rounding == _ROUNDING["python"]:
        number = _py_round_one(float(floats[at]), digits)
    elif rounding == _ROUNDING["numpy"]:
        number = float(np.round(floats[at : at + 1], digits)[0])
    else:
        number = float(floats[at])
    return repr(number) if math.isfinite(number) else _NULL


def _py_round_one(x: float, digits: int) -> float:
    """
    :func:`py_round` of one number: float arithmetic, not a dozen calls on a one-item array.

    Examples
    --------
    >>> values = [2.675, -0.0004, 1700000200.9154978, -2.5e-3, 1e300, float("nan")]
    >>> rounded = [_py_round_one(v, 3) for v in values]
    >>> [repr(v) for v in rounded] == [repr(v) for v in py_round(np.array(values), 3).tolist()]
    True
    """
    scale = 10.0**digits
    y = x * scale
    if not math.isfinite(x):
        return x
    ay = abs(y)
    if ay >= 2.0**52 or abs(abs(y - math.trunc(y)) - 0.5) <= 1e-9 + 8.0 * _EPS * ay:
        return round(x, digits)
    return math.copysign(round(y) / scale, y)  # numpy's rint(y) / scale, the sign of zero kept


def _text(texts: list[list[str]]) -> tuple[Any, IntArray, IntArray]:
    """
    The cells of the text columns as one ASCII buffer, and where each cell starts.

    Also where each column's cells start among them; each with the end appended.
    """
    cells = [cell for column in texts for cell in column]
    text_at = np.fromiter(accumulate(map(len, cells), initial=0), np.int64, len(cells) + 1)
    text_col = np.fromiter(accumulate(map(len, texts), initial=0), np.int64, len(texts) + 1)
    data = "".join(cells).encode("ascii")
    return np.frombuffer(data, dtype=np.uint8), text_at, text_col  # read-only (frombuffer of bytes)


class Packed(NamedTuple):
    """
    Named columns made by one compiled call: what :func:`sourced_pieces` writes from.

    Float column ``i`` is ``floats[floats_at[i]:floats_at[i + 1]]``, named ``float_names[i]``;
    whole-number columns (bools as 0 / 1) likewise, those in ``bool_names`` read as bools;
    ``text`` holds the UTF-8 bytes :class:`Utf8` columns point into.
    """

    floats: FloatArray
    floats_at: IntArray
    ints: IntArray
    ints_at: IntArray
    text: ByteArray
    float_names: tuple[str, ...]
    int_names: tuple[str, ...]
    bool_names: frozenset[str]

    def columns(self) -> dict[str, Any]:
        """Every column by name: views of the arrays (a copy as bools for the bool columns)."""
        out: dict[str, Any] = {}
        for i, name in enumerate(self.float_names):
            out[name] = self.floats[self.floats_at[i] : self.floats_at[i + 1]]
        for i, name in enumerate(self.int_names):
            values = self.ints[self.ints_at[i] : self.ints_at[i + 1]]
            out[name] = values.astype(bool) if name in self.bool_names else values
        return out


class _SourcePlanner(_Writer):
    """
    A :class:`_Writer` whose program reads a :class:`Packed`'s arrays as they are.

    Each step names the packed column its values come from (not a column of its own), so
    the program runs on any later :class:`Packed` of the same names without a table made or
    an array copied. Every array the tables write must be one of the packed columns (a view
    :meth:`Packed.columns` gave), and every text a :class:`Choice` or a :class:`Utf8` of
    the packed text.
    """

    __slots__ = ("_float_of", "_int_of")

    def __init__(self, rows: int, packed: Packed, columns: dict[str, Any]) -> None:
        super().__init__(rows)
        self.text = packed.text
        self._float_of = {id(columns[n]): i for i, n in enumerate(packed.float_names)}
        self._int_of = {id(columns[n]): i for i, n in enumerate(packed.int_names)}

    def _add_floats(self, values: FloatArray) -> int:
        at = self._float_of.get(id(values))
        if at is None:
            msg = "a float column of a sourced table is not one of its packed columns"
            raise ValueError(msg)
        return at

    def _add_ints(self, values: Any, member: str) -> int:
        at = self._int_of.get(id(values))
        if at is None:
            msg = f"the {member} of a sourced table's column are not one of its packed columns"
            raise ValueError(msg)
        return at

    def _add_text(self, column: Column) -> int:
        msg = f"a sourced table cannot write {type(column).__name__} from cells: use Choice or Utf8"
        raise ValueError(msg)


#: The program of each sourced schema (:func:`sourced_pieces`), made on its first call.
_SOURCED: dict[str, tuple[IntArray, Any, IntArray]] = {}
_NO_INTS = np.zeros(1, dtype=np.int64)


def sourced_pieces(
    packed: Packed,
    declare: Callable[[dict[str, Any], ByteArray], Sequence[tuple[Table, IntArray]]],
    schema: str,
) -> list[bytes | memoryview]:
    """
    :func:`chained_pieces` of the tables ``declare`` makes of ``packed``'s columns.

    ``declare`` takes the columns by name (:meth:`Packed.columns`) and the packed text, and
    returns each table with its ``[0, rows]`` bounds, a packed column too. It runs once per
    ``schema``, on the first call: its walk becomes a program that reads the packed arrays
    themselves, so later calls make no table and copy no array; the text is one compiled
    call. A sourced schema's tables must have the same members, kinds and constants
    whatever the columns hold (their program is not checked again).

    Raises
    ------
    ValueError
        If a table writes an array that is not one of the packed columns (on the first
        call), or the columns' lengths do not fit the tables.
    """
    program = _SOURCED.get(schema)
    if program is None:
        columns = packed.columns()
        tables = declare(columns, packed.text)
        writer = _SourcePlanner(1, packed, columns)
        _Chain([t for t, _ in tables], [b for _, b in tables]).write(writer)
        writer._flush()
        program = _program(tuple(writer.ops))
        if len(_SOURCED) >= 64:  # schemas are few; never grow without bound
            _SOURCED.clear()
        _SOURCED[schema] = program
    ops, lit, lit_at = program
    out, _, slow = _write_rows(
        1, -1, ops, lit, lit_at, packed.floats, packed.floats_at, packed.ints, packed.ints_at,
        read_only(packed.text), _NO_INTS, _NO_INTS, _POW10,
    )  # fmt: skip
    text = memoryview(out)
    if not len(slow):
        return [text]
    fixes = [
        (at, top, _repr(ops, packed.floats, packed.floats_at, k, r))
        for at, k, r, top in slow.tolist()
    ]
    return _pieces(text, fixes)


_PROGRAMS: dict[tuple[tuple[int, Any, int, int], ...], tuple[IntArray, Any, IntArray]] = {}


def _program(steps: tuple[tuple[int, Any, int, int], ...]) -> tuple[IntArray, Any, IntArray]:
    """``steps`` as the arrays :func:`_write_rows` reads, made once per program."""
    program = _PROGRAMS.get(steps)
    if program is None:
        literals, numbered = _numbered(steps)
        ops = np.array(numbered, dtype=np.int64).reshape(-1, 4)
        lit = np.frombuffer(bytearray("".join(literals).encode("ascii")), dtype=np.uint8)
        lit_at = np.concatenate(([0], np.cumsum([len(t) for t in literals]))).astype(np.int64)
        if len(_PROGRAMS) >= 256:  # the tables' shapes are few; never grow without bound
            _PROGRAMS.clear()
        program = _PROGRAMS[steps] = (ops, lit, lit_at)
    return program


def _numbered(
    steps: Sequence[tuple[int, Any, int, int]],
) -> tuple[list[str], list[tuple[int, int, int, int]]]:
    """
    The program's literals, and its steps with each literal replaced by its number.

    A ``_CHOICE`` step's choices (quoted) are literals too: its ``b`` becomes the number of
    the first, its ``c`` how many.
    """
    literals: list[str] = []
    out = []
    for code, a, b, c in steps:
        if code == _LIT:
            out.append((code, len(literals), b, c))
            literals.append(a)
        elif code == _CHOICE:
            out.append((code, a, len(literals), len(b)))  # type: ignore[arg-type]  # the choices
            literals.extend(_QUOTES[choice] for choice in b)  # type: ignore[attr-defined]
        else:
            out.append((code, a, b, c))
    return literals, out


def _each(write: Any, rows: int) -> list[str]:
    """Each row's JSON text of what ``write`` writes into a :class:`_Writer`."""
    writer = _Writer(rows)
    write(writer)
    text, starts, fixes = writer.run(-1)
    row_at = starts.tolist()
    by_row: dict[int, list[tuple[int, int, str]]] = {}
    for fix in fixes:
        by_row.setdefault(fix[1], []).append(fix)
    cells: list[bytes | memoryview] = [text[a:b] for a, b in pairwise(row_at)]
    for r, row_fixes in by_row.items():
        cells[r] = b"".join(_pieces(text[row_at[r] : row_at[r + 1]], row_fixes, row_at[r]))
    return [str(cell, "ascii") for cell in cells]


def _pieces(
    text: memoryview, fixes: list[tuple[int, int, str]], start: int = 0
) -> list[bytes | memoryview]:
    """
    ``text`` (which starts at ``start``) with each fix's text inserted at its position.

    As the pieces to join (views of ``text``, not copied): joined with what surrounds them,
    the written buffer is copied once.
    """
    parts: list[bytes | memoryview] = []
    done = 0
    for at, _, fix in fixes:
        parts += (text[done : at - start], fix.encode("ascii"))
        done = at - start
    parts.append(text[done:])
    return parts


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
class Choice:
    """
    One of a few texts per row, by number: ``choices[codes[row]]`` (a road's class).

    Written from the program's literals (each choice quoted once), so no text per row.
    """

    codes: IntArray
    choices: tuple[str, ...]

    def cells(self, rows: int) -> list[str]:
        """The quoted choices."""
        return [_QUOTES[self.choices[c]] for c in np.asarray(self.codes).tolist()]

    def objects(self, rows: int) -> list[Any]:
        """The choices."""
        return [self.choices[c] for c in np.asarray(self.codes).tolist()]


@dataclass(slots=True)  # not frozen: a document makes some fifty, a frozen one costs 3x
class Utf8:
    """
    Texts held as UTF-8 bytes: row ``r``'s is ``text[start[r]:stop[r]]``; ``null`` if empty.

    With ``empty_null`` False an empty text is ``""``. Written by the compiled writer
    itself (escaped as ``json.dumps`` does) when the table is written from its sources
    (:func:`sourced_pieces`, whose text ``text`` is); otherwise from its cells.
    """

    text: ByteArray
    start: IntArray
    stop: IntArray
    empty_null: bool = True

    def _texts(self) -> list[str]:
        # each text's own bytes: the text may be a whole network's names, not to be copied
        text = np.ascontiguousarray(self.text, dtype=np.uint8).data
        bounds = zip(np.asarray(self.start).tolist(), np.asarray(self.stop).tolist(), strict=True)
        return [str(text[a:b], "utf-8") for a, b in bounds]

    def cells(self, rows: int) -> list[str]:
        """The quoted texts."""
        return [_QUOTES[value] for value in self.objects(rows)]

    def objects(self, rows: int) -> list[Any]:
        """The texts (``None`` for an empty one with ``empty_null``)."""
        texts: list[Any] = self._texts()
        return [t or None for t in texts] if self.empty_null else texts


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


@dataclass(slots=True)  # not frozen: a document makes some fifty, a frozen one costs 3x
class Items:
    """
    Per row, a JSON array of some rows of ``part``: rows ``bounds[row]`` to ``bounds[row + 1]``.

    ``part`` is a :class:`Table` (its rows' objects are the items) or a column (its rows'
    values); ``bounds`` rise from 0 to the part's rows, one more than the rows of the table
    holding the column, so every row of the part is an item of one row (the edges of each
    segment, the vertices of each segment's line). With ``geometry``, each array is the
    ``coordinates`` of a GeoJSON geometry of that type. Written inside the same compiled
    call as the table holding it.
    """

    part: Table | Column
    bounds: IntArray
    geometry: str | None = None

    @property
    def part_rows(self) -> int:
        """The rows of the part."""
        return int(self.bounds[-1]) if len(self.bounds) else 0

    def write(self, writer: _Writer) -> None:
        """Write each row's array."""
        if self.geometry is None:
            writer.lit("[")
        else:
            writer.lit(f'{{"type":{json.dumps(self.geometry)},"coordinates":[')
        opened = writer.each(self.bounds, self.part_rows)
        if isinstance(self.part, Table):
            self.part.write(writer)
        else:
            writer.column(self.part)
        writer.next(opened)
        writer.lit("]" if self.geometry is None else "]}")

    def cells(self, rows: int) -> list[str]:
        """Each row's array as text."""
        return _each(lambda w: w.column(self), rows)

    def objects(self, rows: int) -> list[Any]:
        """Each row's list (or geometry dict)."""
        part = self.part
        items = part.objects() if isinstance(part, Table) else part.objects(self.part_rows)
        lists = [items[a:b] for a, b in pairwise(np.asarray(self.bounds).tolist())]
        if self.geometry is None:
            return lists
        return [{"type": self.geometry, "coordinates": items} for items in lists]


@dataclass(slots=True)  # not frozen: a document makes some fifty, a frozen one costs 3x
class Table:
    """
    Rows of JSON objects with the same members: ``{name: value, ...}`` per row.

    The text is written by one compiled call for the whole table (nested objects, arrays
    and arrays of items inlined), from a program made once per set of columns.

    Parameters
    ----------
    rows
        Number of rows.
    columns
        ``(name, column)`` in member order.
    """

    rows: int
    columns: Sequence[tuple[str, Column]]

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
        writer = _Writer(self.rows)
        self.write(writer)
        text, _, fixes = writer.run(ord(","))
        return b"".join(_pieces(text, fixes))

    def text(self) -> str:
        """:meth:`ascii` as a string."""
        return self.ascii().decode("ascii")

    def objects(self) -> list[Any]:
        """The rows' objects as dicts."""
        names = [name for name, _ in self.columns]
        values = [column.objects(self.rows) for _, column in self.columns]
        return [dict(zip(names, row, strict=True)) for row in zip(*values, strict=True)]


class _Chain:
    """Several tables' rows one after another, as the one row of a program."""

    __slots__ = ("bounds", "tables")

    rows = 1

    def __init__(self, tables: Sequence[Table], bounds: Sequence[IntArray] | None = None) -> None:
        self.tables = tables
        self.bounds = (
            [np.array([0, t.rows], dtype=np.int64) for t in tables] if bounds is None else bounds
        )

    def write(self, writer: _Writer) -> None:
        """Write each table's rows, commas between all of them."""
        for i, table in enumerate(self.tables):
            opened = writer.each(self.bounds[i], table.rows, f"bounds[{i}]", join=True)
            table.write(writer)
            writer.next(opened)


def chained_ascii(tables: Sequence[Table]) -> bytes:
    """
    The rows' objects of several tables one after another, joined by commas, ASCII.

    ``b",".join(t.ascii() for t in tables if t.rows)``, written by one compiled call:
    :func:`chained_pieces` joined.

    Examples
    --------
    >>> segments = Table(0, [("kind", Const("segment"))])
    >>> points = Table(2, [("kind", Const("point")), ("n", Ints(np.array([7, 8])))])
    >>> chained_ascii([segments, points, points])
    b'{"kind":"point","n":7},{"kind":"point","n":8},{"kind":"point","n":7},{"kind":"point","n":8}'
    """
    return b"".join(chained_pieces(tables))


def chained_pieces(tables: Sequence[Table]) -> list[bytes | memoryview]:
    """
    :func:`chained_ascii` as the pieces to join, views of the written buffer (not copied).

    ``b"".join((before, *pieces, after))`` copies the text once, whatever surrounds it.

    Parameters
    ----------
    tables
        The tables, in order.

    Examples
    --------
    >>> points = Table(2, [("kind", Const("point")), ("n", Ints(np.array([7, 8])))])
    >>> b"".join((b"[", *chained_pieces([points]), b"]"))
    b'[{"kind":"point","n":7},{"kind":"point","n":8}]'
    """
    writer = _Writer(1)
    _Chain(tables).write(writer)
    text, _, fixes = writer.run(-1)
    return _pieces(text, fixes)


#: How :meth:`_Writer.column` writes each kind of column this module knows (in the program;
#: any other column, or a writer returning False, is written from its cells).
_WRITES: dict[type, Any] = {
    Floats: _Writer._floats,
    Ints: _Writer._ints,
    Bools: _Writer._bools,
    Const: _Writer._const,
    Tuple: _Writer._tuple,
    Choice: _Writer._choice,
    Utf8: _Writer._utf8,
    Nested: _Writer._nested,
    Items: _Writer._items,
}
