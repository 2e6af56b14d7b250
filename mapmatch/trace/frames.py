"""
Tables as trace input: which column gives which field, and what a reader knew of the rows.

A table's columns are matched to the fields of :mod:`mapmatch.trace.columns` by name
(aliases, any case); two columns for one field and a missing required column are errors
naming the columns found. A reader's :class:`~mapmatch.trace.readers.RawTrace` becomes the
field columns plus an :class:`~mapmatch.trace.report.Origin` (its line numbers, segments and
dropped records) for :func:`~mapmatch.trace.validation.validate`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

import numpy as np

from mapmatch.errors import InvalidTraceError
from mapmatch.trace.checks import SHOW, is_plain_number
from mapmatch.trace.columns import FIELD_ALIASES, canonical, id_kind, input_columns
from mapmatch.trace.readers import RawTrace, id_columns, read_raw_traces
from mapmatch.trace.report import Origin, in_source

if TYPE_CHECKING:
    from collections.abc import Hashable, Iterable, Mapping, Sequence

    import pandas as pd

    from mapmatch.types import IntArray

__all__ = ["frame_columns", "raw_origin", "record_columns", "resolve_columns", "single_raw"]

_REQUIRED = tuple(c.name for c in input_columns(required_only=True))
_IGNORED = ""  # a key that names no column


def resolve_columns(
    columns: Iterable[Hashable], *, trace_id: str, origin: Origin
) -> dict[str, Hashable]:
    """Canonical field -> the column naming it; two columns for one field is an error."""
    found: dict[str, list[Hashable]] = {}
    for col in columns:
        field = canonical(col)
        if field is not None:
            found.setdefault(field, []).append(col)
    for field, cols in found.items():
        if len(cols) > 1:
            both = " and ".join(repr(str(c)) for c in cols)
            msg = (
                f"trace {trace_id!r}{in_source(origin)}: columns {both} both give {field!r}; "
                "drop or rename all but one"
            )
            raise InvalidTraceError(msg, trace_id=trace_id, field=field)
    return {field: cols[0] for field, cols in found.items()}


def frame_columns(df: pd.DataFrame, *, trace_id: str, origin: Origin) -> dict[str, object]:
    """
    The field columns of a table (canonical name -> column), the reader's segments added.

    Raises
    ------
    InvalidTraceError
        A required column is missing, or two columns give one field.
    """
    names = resolve_columns(df.columns, trace_id=trace_id, origin=origin)
    missing = [f for f in _REQUIRED if f not in names]
    if missing:
        found = ", ".join(repr(str(c)) for c in df.columns) or "none"
        need = "; ".join(f"{f!r} (or {', '.join(FIELD_ALIASES[f][1:])})" for f in missing)
        msg = (
            f"trace {trace_id!r}{in_source(origin)}: missing required column(s) {need}; "
            f"found columns: {found}; rename the columns (names are case-insensitive)"
        )
        raise InvalidTraceError(msg, trace_id=trace_id, field=missing[0])
    columns: dict[str, object] = {f: df[col] for f, col in names.items()}
    if origin.segment is not None and "segment" not in columns:
        columns["segment"] = origin.segment
    return columns


def raw_origin(raw: RawTrace) -> Origin:
    """What a reader knew about its rows, for messages and the report."""
    numbers: IntArray | None = raw.numbers
    source: str | None = raw.source
    if raw.label == "table row":
        source = None
        if np.array_equal(raw.numbers, np.arange(len(raw.numbers))):
            numbers = None  # the whole table in order: "row 5" says it all
    return Origin(
        source=source,
        label=raw.label,
        numbers=numbers,
        segment=raw.segment,
        dropped=raw.dropped,
        notes=raw.notes,
    )


def single_raw(df: pd.DataFrame, *, trace_id: str | None, id_column: str | None) -> RawTrace:
    """
    The one trace of a table, named ``trace_id`` when given.

    Raises
    ------
    InvalidTraceError
        The id columns hold several traces.
    """
    raws = read_raw_traces(df, default_trace_id=trace_id or "trace", id_column=id_column)
    if len(raws) > 1:
        cols = " / ".join(id_columns([str(c) for c in df.columns], id_column=id_column))
        shown = ", ".join(repr(r.trace_id) for r in raws[:SHOW])
        more = f" and {len(raws) - SHOW} more" if len(raws) > SHOW else ""
        name = trace_id or raws[0].trace_id
        msg = (
            f"trace {name!r}: the {cols} column holds {len(raws)} ids ({shown}{more}); "
            f"use mapmatch.read_traces or split the table by {cols}"
        )
        raise InvalidTraceError(msg, trace_id=name, field="trace_id")
    raw = raws[0]
    return raw if trace_id is None else dataclasses.replace(raw, trace_id=trace_id)


def _key_fields(keys: Iterable[Hashable]) -> dict[Hashable, str] | None:
    """
    The field each key of the points names (``_IGNORED`` for none), in the keys' order.

    ``None`` where the table path must decide: an id key (rows of a fleet, grouped or refused
    there) or two keys for one field (it names both).
    """
    fields: dict[Hashable, str] = {}
    named: set[str] = set()
    for key in keys:
        field = canonical(key)
        if field is None:
            if id_kind(key) is not None:
                return None
            field = _IGNORED
        elif field in named:
            return None
        else:
            named.add(field)
        fields[key] = field
    return fields


def _by_column(
    records: Sequence[Mapping[str, object]], fields: dict[Hashable, str]
) -> dict[str, object] | None:
    """
    The columns of points that all have the keys of ``fields``, read one column at a time.

    Each key's values are typed together instead of one value at a time; ``None`` unless
    every value is a plain number (the point-by-point walk then decides).
    """
    columns: dict[str, object] = {}
    for key, field in fields.items():
        if field is _IGNORED:
            continue
        values = [r[key] for r in records]  # type: ignore[index]
        kinds = set(map(type, values))
        if kinds == {float}:
            columns[field] = np.array(values, dtype=np.float64)
        elif kinds <= {float, int} and all(map(is_plain_number, values)):
            columns[field] = np.array([float(v) for v in values], dtype=np.float64)  # type: ignore[arg-type]
        else:
            return None
    return columns


def _by_value(
    records: Sequence[Mapping[str, object]], fields: dict[Hashable, str]
) -> dict[str, object] | None:
    """The columns read one value at a time (text times allowed); ``None`` past any other."""
    n = len(records)
    named = (f for f in fields.values() if f is not _IGNORED)
    columns: dict[str, list[object]] = {f: [math.nan] * n for f in named}
    text_times = False
    for i, record in enumerate(records):
        for key, value in record.items():
            field = fields[key]
            if field is _IGNORED or value is None:
                continue
            if is_plain_number(value):
                columns[field][i] = float(value)  # type: ignore[arg-type]
            elif field == "time" and type(value) is str:
                columns[field][i] = value
                text_times = True
            else:
                return None
    return {
        field: values if field == "time" and text_times else np.array(values, dtype=np.float64)
        for field, values in columns.items()
    }


def record_columns(records: Sequence[Mapping[str, object]]) -> dict[str, object] | None:
    """
    The field columns of point objects, without a table where none is needed.

    That is when every value under a column's name is a Python ``float`` or ``int`` (not a
    bool), text under ``time``, or ``None`` (unknown; so is a missing key), no two keys give
    one field, no key is an id column and ``lat`` and ``lon`` are there. Then the columns
    are float64 arrays (a list for text times, read by :func:`~.times.parse_time`), and
    validation gives what the table path (:func:`frame_columns` of
    ``pandas.DataFrame.from_records``) gives. Otherwise ``None``: the caller takes the table
    path, which also words every error.

    Examples
    --------
    >>> cols = record_columns([{"t": 0, "lat": 43.73, "LNG": 7.42}, {"t": 5, "lat": 43.74}])
    >>> {k: v.tolist() for k, v in cols.items()}
    {'time': [0.0, 5.0], 'lat': [43.73, 43.74], 'lon': [7.42, nan]}
    >>> record_columns([{"trace_id": "a", "lat": 1.0, "lon": 2.0}] * 2) is None
    True
    """
    if len(records) < 2:
        return None
    first = records[0]
    same_keys = type(first) is dict and all(
        type(r) is dict and r.keys() == first.keys() for r in records
    )
    keys = first.keys() if same_keys else dict.fromkeys(k for r in records for k in r)
    fields = _key_fields(keys)
    if fields is None or any(f not in fields.values() for f in _REQUIRED):
        return None
    columns = _by_column(records, fields) if same_keys else None
    return columns if columns is not None else _by_value(records, fields)
