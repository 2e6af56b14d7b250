"""Arrays of items inside a table's rows: written in the same compiled call, as json.dumps does."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mapmatch import _jsontext as jt

#: Values whose text is easy to get wrong: signs of zero, exponents, halves, not finite.
_AWKWARD = [0.0, -0.0, 1e-05, 5e-05, 1e-4, 2.675, 1.0005, 1e15, 1e16, -1e22, 0.1]
#: (Below 1e300: numpy's rounding of a value near the largest float overflows, and warns.)
_FLOATS = st.one_of(st.sampled_from([*_AWKWARD, np.nan, np.inf, -np.inf]), st.floats(-1e300, 1e300))
_INTS = st.integers(-(2**63), 2**63 - 1)
_NAMES = st.one_of(st.none(), st.sampled_from(["", 'a "quote"', "back\\slash", "Straße", "\x00"]))


def _dumped(objects: list[Any]) -> str:
    return json.dumps(objects, separators=(",", ":"), allow_nan=False)


@st.composite
def _segments(draw: st.DrawFn) -> tuple[Any, ...]:
    """Rows with arrays of zero to three items each, and every column such a table has."""
    sizes = draw(st.lists(st.integers(0, 3), max_size=4))
    bounds = np.concatenate(([0], np.cumsum(sizes, dtype=np.int64))).astype(np.int64)
    n = int(bounds[-1])

    def column(strategy: st.SearchStrategy[Any], size: int) -> list[Any]:
        return draw(st.lists(strategy, min_size=size, max_size=size))

    decimals = draw(st.sampled_from([0, 1, 3, 7]))
    rounding = draw(st.sampled_from(["none", "numpy", "python"]))
    inner = {
        "x": np.array(column(_FLOATS, n)),
        "u": np.array(column(_INTS, n), dtype=np.int64),
        "valid": np.array(column(st.booleans(), n), dtype=bool),
        "name": column(_NAMES, n),
        "lon": np.array(column(_FLOATS, n)),
    }
    outer = np.array(column(_FLOATS, len(sizes)))
    return bounds, inner, outer, decimals, rounding


def _table(case: tuple[Any, ...], schema: str | None) -> jt.Table:
    bounds, inner, outer, decimals, rounding = case
    n = int(bounds[-1])
    edges = jt.Table(
        n,
        [
            ("x", jt.Floats(inner["x"], decimals=decimals, rounding=rounding)),
            ("u", jt.Ints(inner["u"], inner["valid"])),
            ("name", jt.Strings(inner["name"])),
            ("ids", jt.Tuple((jt.Ints(inner["u"]),), inner["valid"])),
        ],
    )
    line = jt.Tuple(
        (jt.Floats(inner["lon"], rounding="numpy"), jt.Floats(inner["x"], rounding="numpy"))
    )
    rows = len(bounds) - 1
    properties = jt.Table(rows, [("kind", jt.Const("segment")), ("edges", jt.Items(edges, bounds))])
    return jt.Table(
        rows,
        [
            ("geometry", jt.Items(line, bounds, geometry="LineString")),
            ("properties", jt.Nested(properties)),
            ("t", jt.Floats(outer, decimals=3, rounding="python")),
        ],
        schema=None if schema is None else f"{schema}-{decimals}-{rounding}",
    )


@settings(max_examples=300, deadline=None)
@given(_segments())
def test_arrays_of_items_are_written_as_json_dumps_writes_them(case: tuple[Any, ...]) -> None:
    walked = _table(case, None)
    assert f"[{walked.text()}]" == _dumped(walked.objects())
    assert _table(case, "test-items").text() == walked.text()  # by the schema's plan
    cells = jt.Nested(walked).cells(walked.rows)
    assert cells == [_dumped(row) for row in walked.objects()]


def test_an_empty_array_and_a_lone_item_are_written_as_such() -> None:
    bounds = np.array([0, 0, 1, 1], dtype=np.int64)
    table = jt.Table(3, [("v", jt.Items(jt.Floats(np.array([-0.0])), bounds))])
    assert table.text() == '{"v":[]},{"v":[-0.0]},{"v":[]}'


@pytest.mark.parametrize(
    ("bounds", "size"),
    [([0, 2, 1], 2), ([1, 2], 2), ([0, 1], 2), ([0, 3], 2), ([0, 1, 2, 3], 3)],
    ids=["decreasing", "not-from-0", "short-of-the-part", "past-the-part", "one-too-many"],
)
def test_bounds_that_do_not_split_the_part_are_refused(bounds: list[int], size: int) -> None:
    items = jt.Items(jt.Floats(np.arange(size, dtype=np.float64)), np.array(bounds, dtype=np.int64))
    with pytest.raises(ValueError, match=r"bounds|length"):
        jt.Table(2, [("v", items)]).text()


def test_a_column_of_the_wrong_length_is_refused() -> None:
    with pytest.raises(ValueError, match="length"):
        jt.Table(3, [("x", jt.Floats(np.zeros(2)))]).text()


@settings(max_examples=100, deadline=None)
@given(st.lists(_segments(), max_size=3))
def test_a_chain_of_tables_is_their_rows_joined(cases: list[tuple[Any, ...]]) -> None:
    tables = [_table(case, None) for case in cases]
    expected = b",".join(t.ascii() for t in tables if t.rows)  # empty tables add no comma
    assert jt.chained_ascii(tables) == expected
    schema = "test-chain-" + "-".join(f"{case[3]}{case[4]}" for case in cases)
    assert jt.chained_ascii(tables, schema) == expected  # by the plan: the same
    assert jt.chained_ascii(tables, schema) == expected


@settings(max_examples=500, deadline=None)
@given(st.one_of(_FLOATS, st.floats(-1e16, 1e16)), st.sampled_from([0, 1, 2, 3, 4, 7]))
def test_one_number_is_rounded_as_the_arrays_are(value: float, digits: int) -> None:
    one = jt._py_round_one(value, digits)
    many = float(jt.py_round(np.array([value]), digits)[0])
    assert repr(one) == repr(many)
