"""Fuzz every operation of the OpenAPI document (schemathesis): no input may produce a 5xx.

Bounded and derandomized: a fixed number of examples per operation, the same ones every run.
Responses must also match the documented status codes and schemas.
"""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.api.fuzzing import BOUNDED, MONACO, fuzz_operation

OPERATIONS = [
    ("/v1/match", "POST", 60),
    ("/v1/networks", "GET", 5),
    ("/healthz", "GET", 5),
    ("/readyz", "GET", 5),
    ("/metrics", "GET", 5),
]


@pytest.mark.parametrize(("path", "method", "examples"), OPERATIONS)
def test_no_input_produces_a_server_error(
    api_schema: Any, path: str, method: str, examples: int
) -> None:
    fuzz_operation(api_schema, path, method, examples)


# Random but well-formed traces inside the served network's bounding box reach the matcher
# itself (the schema-driven cases above almost never land on a road).

coords = st.tuples(
    st.floats(MONACO[0], MONACO[2], allow_nan=False),
    st.floats(MONACO[1], MONACO[3], allow_nan=False),
)
optional = st.none() | st.floats(0.0, 100.0, allow_nan=False)
point = st.fixed_dictionaries(
    {"time": st.integers(0, 300).map(lambda t: 1_700_000_000 + t), "coords": coords},
    optional={
        "heading": st.floats(-720, 720, allow_nan=False),
        "speed": optional,
        "accuracy": st.floats(0.5, 300),
        "odometer": optional,
    },
)
options = st.fixed_dictionaries(
    {},
    optional={
        "sigma_m": st.floats(0.5, 500),
        "search_radius_m": st.floats(1, 200),
        "max_candidates": st.integers(1, 64),
        "beta_m": st.floats(0.1, 1000),
        "uturn_penalty": st.floats(0, 1000),
        "use_travel": st.booleans(),
        "thinning_sigmas": st.floats(0, 100),
        "outlier_sigmas": st.floats(0, 100),
        "distance_band": st.tuples(st.floats(-0.99, 0), st.floats(0, 9.9)).map(list),
    },
)


@given(points=st.lists(point, min_size=2, max_size=40), opts=options)
@settings(BOUNDED, max_examples=60)
def test_random_traces_on_the_map_never_crash_the_matcher(client, points, opts) -> None:
    body_points = []
    for p in points:
        q = dict(p)
        q["lon"], q["lat"] = q.pop("coords")
        body_points.append(q)
    answer = client.post("/v1/match", json={"points": body_points, "options": opts})
    assert answer.status_code in (200, 422), answer.text
    if answer.status_code == 422:
        assert answer.json()["error"]["code"] in {
            "invalid_trace",
            "no_road_nearby",
            "invalid_options",
        }
