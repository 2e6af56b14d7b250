"""Fuzz the OSRM and Valhalla operations of the OpenAPI document: no input may produce a 5xx.

As ``test_openapi_fuzz`` does for ``/v1/match``: a fixed number of derandomized examples per
operation, answers checked against the documented statuses, content types and schemas (the
peers' shapes: :mod:`api.osrm_schemas`, :mod:`api.valhalla_schemas`). Random coordinates and
shapes on the Monaco map then reach the matcher itself.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.api.fuzzing import BOUNDED, MONACO, fuzz_operation

if TYPE_CHECKING:
    import httpx

OPERATIONS = [
    ("/match/{version}/{profile}/{coordinates}", "GET", 40),
    ("/match/{version}/{profile}/{coordinates}", "POST", 20),
    ("/match/{version}/{profile}", "POST", 20),
    ("/trace_attributes", "POST", 40),
    ("/trace_attributes", "GET", 20),
]


@pytest.mark.parametrize(("path", "method", "examples"), OPERATIONS)
def test_no_input_produces_a_server_error(
    api_schema: Any, path: str, method: str, examples: int
) -> None:
    fuzz_operation(api_schema, path, method, examples)


position = st.tuples(
    st.floats(MONACO[0], MONACO[2], allow_nan=False),
    st.floats(MONACO[1], MONACO[3], allow_nan=False),
)
trace = st.lists(st.tuples(position, st.integers(0, 30)), min_size=2, max_size=30)


@given(points=trace, tidy=st.booleans(), gaps=st.sampled_from(["split", "ignore"]))
@settings(BOUNDED, max_examples=40)
def test_random_traces_on_the_map_never_crash_the_osrm_route(
    client: httpx.Client, points: list[tuple[tuple[float, float], int]], tidy: bool, gaps: str
) -> None:
    coords = ";".join(f"{lon:.6f},{lat:.6f}" for (lon, lat), _ in points)
    times, t = [], 1_700_000_000
    for _, step in points:
        t += step
        times.append(str(t))
    params = {
        "timestamps": ";".join(times),
        "tidy": str(tidy).lower(),
        "gaps": gaps,
        "annotations": "true",
        "overview": "full",
    }
    answer = client.get(f"/match/v1/driving/{coords}", params=params)
    assert answer.status_code in (200, 400), answer.text
    if answer.status_code == 400:
        assert answer.json()["code"] in {"NoMatch", "NoSegment"}, answer.text


@given(points=trace, timed=st.booleans(), use=st.booleans())
@settings(BOUNDED, max_examples=40)
def test_random_traces_on_the_map_never_crash_the_valhalla_route(
    client: httpx.Client, points: list[tuple[tuple[float, float], int]], timed: bool, use: bool
) -> None:
    shape, t = [], 0
    for (lon, lat), step in points:
        t += step
        shape.append({"lat": lat, "lon": lon, **({"time": t} if timed else {})})
    body = {"shape": shape, "costing": "auto", "use_timestamps": use and timed}
    answer = client.post("/trace_attributes", json=body)
    assert answer.status_code in (200, 400), answer.text
    if answer.status_code == 400:
        assert answer.json()["error_code"] in {171, 444}, answer.text
