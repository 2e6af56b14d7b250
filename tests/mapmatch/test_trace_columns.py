"""The column declaration is what Trace and the readers enforce (one declaration, issue 13)."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mapmatch.errors import InvalidTraceError
from mapmatch.trace import FIELD_ALIASES, Column, Trace, input_columns, read_traces
from mapmatch.trace import columns as columns_module
from mapmatch.trace.columns import COLUMNS, ID_COLUMNS, column, id_kind
from mapmatch.trace.readers import id_columns

POINTS = [
    {"time": 0.0, "lat": 43.7300, "lon": 7.4200},
    {"time": 5.0, "lat": 43.7305, "lon": 7.4206},
    {"time": 10.0, "lat": 43.7310, "lon": 7.4212},
]
NUMBERS = [c for c in input_columns() if c.kind == "number" and not c.required]


def test_field_aliases_are_derived_from_the_columns() -> None:
    assert {c.name: c.names for c in COLUMNS} == FIELD_ALIASES
    assert [c.name for c in input_columns(required_only=True)] == ["lat", "lon"]
    names = [n for c in COLUMNS for n in c.names]
    assert len(names) == len(set(names)), "an alias belongs to two columns"


@pytest.mark.parametrize("col", COLUMNS, ids=lambda c: c.name)
def test_every_alias_in_any_case_reaches_the_trace(col: Column) -> None:
    value = 2.0 if col.example is None or col.kind == "label" else col.example
    for name in col.names:
        for spelling in (name, name.upper(), name.title()):
            recs = []
            for p in POINTS:
                rec: dict[str, object] = {k: v for k, v in p.items() if k != col.name}
                rec[spelling] = p.get(col.name, value)
                recs.append(rec)
            tr = Trace.from_records(recs, trace_id=spelling)
            assert len(tr) == 3
            if col.name == "hdop":  # hdop has no attribute of its own: it fills the accuracy
                assert tr.accuracy_m is not None
                np.testing.assert_allclose(tr.accuracy_m, float(value) * 5.0)
            elif col.kind == "number" and not col.required:
                got = getattr(tr, str(col.attribute))
                assert got is not None, spelling
                np.testing.assert_allclose(got, float(value) % (col.wraps or math.inf))
            elif col.kind == "time":
                assert tr.time_s.tolist() == [0.0, 5.0, 10.0]


@pytest.mark.parametrize("col", [c for c in NUMBERS if c.bounded], ids=lambda c: c.name)
def test_the_declared_bounds_are_the_bounds_trace_enforces(col: Column) -> None:
    edge = col.gt if col.gt is not None else col.ge
    assert edge is not None
    inside = edge + 0.5 if col.gt is not None else edge
    outside = edge if col.gt is not None else math.nextafter(edge, -math.inf)
    ok = [{**p, col.name: inside} for p in POINTS]
    Trace.from_records(ok)
    bad = [{**p, col.name: outside if i == 1 else inside} for i, p in enumerate(POINTS)]
    with pytest.raises(InvalidTraceError) as err:
        Trace.from_records(bad)
    assert err.value.field == col.name
    assert err.value.rows == (1,)
    unit = f" {col.unit}" if col.unit else ""
    assert f"must be {col.rule()}{unit}" in str(err.value)


@pytest.mark.parametrize("name", ["lat", "lon"])
def test_coordinate_bounds_come_from_the_declaration(name: str) -> None:
    col = column(name)
    assert col.le is not None
    at_edge = [{**p, name: col.le if i == 2 else p[name]} for i, p in enumerate(POINTS)]
    Trace.from_records(at_edge)
    beyond = [
        {**p, name: math.nextafter(col.le, math.inf) if i == 2 else p[name]}
        for i, p in enumerate(POINTS)
    ]
    with pytest.raises(InvalidTraceError, match=rf"{name} is out of range") as err:
        Trace.from_records(beyond)
    assert err.value.field == name
    assert err.value.rows == (2,)


@pytest.mark.parametrize("col", [c for c in NUMBERS if c.wraps is None], ids=lambda c: c.name)
def test_infinite_values_are_refused_and_blank_is_unknown(col: Column) -> None:
    blank = [{**p, col.name: None if i == 0 else col.example} for i, p in enumerate(POINTS)]
    Trace.from_records(blank)
    inf = [{**p, col.name: math.inf if i == 0 else col.example} for i, p in enumerate(POINTS)]
    with pytest.raises(InvalidTraceError) as err:
        Trace.from_records(inf)
    assert err.value.field == col.name
    assert err.value.rows == (0,)


def test_heading_wraps_as_declared() -> None:
    col = column("heading")
    assert col.wraps == 360.0
    assert not col.bounded
    tr = Trace.from_records([{**p, "course": -90.0 + 400 * i} for i, p in enumerate(POINTS)])
    assert tr.heading_deg is not None
    np.testing.assert_allclose(tr.heading_deg, [270.0, 310.0, 350.0])


def test_a_missing_required_column_lists_its_declared_aliases() -> None:
    with pytest.raises(InvalidTraceError, match=r"'lon' \(or lng, longitude\)") as err:
        Trace.from_records([{"time": p["time"], "lat": p["lat"]} for p in POINTS])
    assert err.value.field == "lon"


def test_id_columns_come_from_the_declaration() -> None:
    assert ID_COLUMNS == ("trace_id", "trip_id", "track_id", "vehicle_id", "device_id", "id")
    assert id_kind("IMEI") == "device_id"
    assert id_kind("Vehicle") == "vehicle_id"
    assert id_columns(["imei", "time", "lat", "lon"]) == ["imei"]
    body = b'[{"imei": "a", "t": 0, "lat": 43.73, "lon": 7.42}, {"imei": "a", "t": 5,' + (
        b' "lat": 43.731, "lon": 7.421}, {"imei": "b", "t": 0, "lat": 43.73, "lon": 7.42},'
        b' {"imei": "b", "t": 9, "lat": 43.732, "lon": 7.422}]'
    )
    assert [t.trace_id for t in read_traces(body, format="json")] == ["a", "b"]


def test_describe_names_unit_bounds_and_aliases() -> None:
    text = column("accuracy").describe()
    assert "Unit m" in text
    assert "must be > 0" in text
    assert "`accuracy_m`" in text
    assert column("time").json_types == ("number", "string")
    assert all(c.json_types == ("number",) for c in COLUMNS if c.kind != "time")
    with pytest.raises(KeyError, match="no trace column"):
        column("elevation")


def test_the_columns_module_needs_neither_numpy_nor_pandas() -> None:
    # A web layer may build its point model from the declaration alone.
    path = Path(columns_module.__file__ or "")
    code = (
        "import runpy, sys\n"
        f"ns = runpy.run_path({str(path)!r})\n"
        "assert 'numpy' not in sys.modules and 'pandas' not in sys.modules\n"
        "print(len(ns['input_columns']()))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == str(len(COLUMNS))
