"""The JSON point model is the trace reader's column declaration, and HTTP refuses what it does."""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest

from api.schemas import PointIn
from mapmatch.trace.columns import input_columns

if TYPE_CHECKING:
    import httpx

BOUNDED = [c for c in input_columns() if c.bounded]


def test_the_point_model_is_generated_from_the_columns(client: httpx.Client) -> None:
    spec = client.get("/openapi.json").json()
    documented = spec["components"]["schemas"]["PointIn"]
    assert list(documented["properties"]) == [c.name for c in input_columns()]
    assert set(documented.get("required", [])) == {c.name for c in input_columns() if c.required}
    for col in input_columns():
        prop = documented["properties"][col.name]
        number = next((s for s in prop.get("anyOf", [prop]) if s.get("type") == "number"), prop)
        for key, word in (("gt", "exclusiveMinimum"), ("ge", "minimum"), ("le", "maximum")):
            assert number.get(word) == getattr(col, key), (col.name, word)
        assert prop["description"] == col.describe()
        for alias in col.names:  # every alias the reader takes, the model takes
            point = {"lat": 43.7, "lon": 7.4, alias: col.example if col.example else 1.0}
            assert getattr(PointIn.model_validate(point), col.name) is not None, alias


@pytest.mark.parametrize("col", BOUNDED, ids=[c.name for c in BOUNDED])
def test_http_refuses_what_the_reader_refuses(client: httpx.Client, trip, bodies, col) -> None:
    bad = col.le + 1 if col.le is not None else (col.ge - 1 if col.ge is not None else col.gt)
    points = bodies.points(trip.trace)
    points[1][col.name] = bad
    answer = client.post("/v1/match", json={"points": points})
    assert answer.status_code == 422, answer.text
    error = answer.json()["error"]
    assert error["code"] == "invalid_trace"
    assert error["field"] == f"points[1].{col.name}"
    assert error["rows"] == [1]
