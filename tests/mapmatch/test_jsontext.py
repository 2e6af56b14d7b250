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


def _table(case: tuple[Any, ...], name: jt.Column | None = None) -> jt.Table:
    """The case's table; its names ``name`` where given (else its strings)."""
    bounds, inner, outer, decimals, rounding = case
    n = int(bounds[-1])
    edges = jt.Table(
        n,
        [
            ("x", jt.Floats(inner["x"], decimals=decimals, rounding=rounding)),
            ("u", jt.Ints(inner["u"], inner["valid"])),
            ("name", jt.Strings(inner["name"]) if name is None else name),
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
    )


def _packed(case: tuple[Any, ...]) -> jt.Packed:
    """The case's columns packed as one compiled call gives them, its names as UTF-8."""
    bounds, inner, outer, _, _ = case
    encoded = [(name or "").encode("utf-8") for name in inner["name"]]
    stop = np.cumsum([len(e) for e in encoded], dtype=np.int64)
    floats = {"x": inner["x"], "lon": inner["lon"], "outer": outer}
    ints = {
        "u": inner["u"],
        "valid": inner["valid"],
        "bounds": bounds,
        "start": stop - [len(e) for e in encoded],
        "stop": stop,
        "rows": np.array([0, len(bounds) - 1]),
    }

    def packed(columns: dict[str, Any], dtype: type) -> tuple[Any, Any]:
        at = np.cumsum([0, *map(len, columns.values())], dtype=np.int64)
        values = [np.asarray(c, dtype=dtype) for c in columns.values()]
        return np.concatenate([np.zeros(0, dtype=dtype), *values]), at

    text = np.frombuffer(bytearray(b"".join(encoded)), dtype=np.uint8)
    return jt.Packed(
        *packed(floats, np.float64), *packed(ints, np.int64), text, tuple(floats), tuple(ints),
        frozenset({"valid"}),
    )  # fmt: skip


def _declared(case: tuple[Any, ...]) -> Any:
    """A declaration of the case's table over packed columns, as :func:`sourced_pieces` takes."""
    _, _, _, decimals, rounding = case

    def declare(c: dict[str, Any], text: Any) -> list[tuple[jt.Table, Any]]:
        inner = {"x": c["x"], "u": c["u"], "valid": c["valid"], "lon": c["lon"], "name": None}
        names = jt.Utf8(text, c["start"], c["stop"])
        return [(_table((c["bounds"], inner, c["outer"], decimals, rounding), names), c["rows"])]

    return declare


@settings(max_examples=300, deadline=None)
@given(_segments())
def test_arrays_of_items_are_written_as_json_dumps_writes_them(case: tuple[Any, ...]) -> None:
    walked = _table(case)
    assert f"[{walked.text()}]" == _dumped(walked.objects())
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
    tables = [_table(case) for case in cases]
    expected = b",".join(t.ascii() for t in tables if t.rows)  # empty tables add no comma
    assert jt.chained_ascii(tables) == expected


@settings(max_examples=200, deadline=None)
@given(st.lists(_segments(), min_size=1, max_size=3))
def test_a_sourced_table_is_the_table_walked(cases: list[tuple[Any, ...]]) -> None:
    for case in cases:  # the first of a schema makes its program, the others run it
        schema = f"test-sourced-{case[3]}-{case[4]}"  # the program holds the decimals
        packed = _packed(case)
        tables = _declared(case)(packed.columns(), packed.text)
        walked = b",".join(t.ascii() for t, _ in tables if t.rows)
        assert b"".join(jt.sourced_pieces(packed, _declared(case), schema)) == walked
        assert json.loads(b"[" + walked + b"]") == [o for t, _ in tables for o in t.objects()]


#: Every character a string may hold but lone surrogates (UTF-8 cannot carry them).
_TEXTS = st.text(st.characters(exclude_categories=("Cs",)), max_size=12)


@settings(max_examples=300, deadline=None)
@given(st.lists(_TEXTS, max_size=6))
def test_utf8_texts_are_escaped_as_json_dumps_escapes_them(texts: list[str]) -> None:
    texts += ['a "quote"', "back\\slash", "tab\tnew\nline\x00\x1f\x7f", "Straße", "\U0001f697"]
    encoded = [t.encode("utf-8") for t in texts]
    stop = np.cumsum([len(e) for e in encoded], dtype=np.int64)
    start = stop - [len(e) for e in encoded]
    rows = np.array([0, len(texts)])
    packed = jt.Packed(
        np.zeros(0), np.zeros(1, dtype=np.int64), np.concatenate((start, stop, rows)),
        np.array([0, len(texts), 2 * len(texts), 2 * len(texts) + 2]),
        np.frombuffer(bytearray(b"".join(encoded)), dtype=np.uint8), (), ("start", "stop", "rows"),
        frozenset(),
    )  # fmt: skip

    def declare(c: dict[str, Any], text: Any) -> list[tuple[jt.Table, Any]]:
        name = jt.Utf8(text, c["start"], c["stop"], empty_null=False)
        return [(jt.Table(len(c["start"]), [("name", name)]), c["rows"])]

    written = b"".join(jt.sourced_pieces(packed, declare, "test-utf8"))
    assert written.decode("ascii") == ",".join(_dumped({"name": t}) for t in texts)


def test_a_choice_is_one_of_its_texts() -> None:
    codes = np.array([2, 0, 1, 2])
    table = jt.Table(4, [("road", jt.Choice(codes, ("primary", 'say "hi"', "Straße")))])
    assert table.text() == _dumped(table.objects())[1:-1]
    assert table.objects()[1] == {"road": "primary"}
    with pytest.raises(ValueError, match="choice"):
        jt.Table(1, [("road", jt.Choice(np.array([3]), ("a", "b", "c")))]).text()


def test_a_sourced_table_reads_only_its_packed_columns() -> None:
    case = (np.array([0, 1]), {"x": np.ones(1), "u": np.ones(1, dtype=np.int64),
            "valid": np.ones(1, dtype=bool), "name": ["a"], "lon": np.ones(1)},
            np.ones(1), 3, "none")  # fmt: skip
    packed = _packed(case)

    def derived(c: dict[str, Any], text: Any) -> list[tuple[jt.Table, Any]]:
        return [(jt.Table(1, [("x", jt.Floats(c["x"] * 2))]), c["rows"])]

    with pytest.raises(ValueError, match="not one of its packed columns"):
        jt.sourced_pieces(packed, derived, "test-derived")

    def cells(c: dict[str, Any], text: Any) -> list[tuple[jt.Table, Any]]:
        return [(jt.Table(1, [("name", jt.Strings(["a"]))]), c["rows"])]

    with pytest.raises(ValueError, match="Choice or Utf8"):
        jt.sourced_pieces(packed, cells, "test-cells")
    outside = packed._replace(ints=packed.ints.copy())
    outside.ints[outside.ints_at[4]] = 99  # the name's stop past the text
    with pytest.raises(ValueError, match="outside the text"):
        jt.sourced_pieces(outside, _declared(case), "test-outside")


@settings(max_examples=500, deadline=None)
@given(st.one_of(_FLOATS, st.floats(-1e16, 1e16)), st.sampled_from([0, 1, 2, 3, 4, 7]))
def test_one_number_is_rounded_as_the_arrays_are(value: float, digits: int) -> None:
    one = jt._py_round_one(value, digits)
    many = float(jt.py_round(np.array([value]), digits)[0])
    assert repr(one) == repr(many)
