"""Fuzz every operation of the OpenAPI document (schemathesis): no input may produce a 5xx.

Bounded and derandomized: a fixed number of examples per operation, the same ones every run.
Responses must also match the documented status codes and schemas.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
    response_schema_conformance,
    status_code_conformance,
)

if TYPE_CHECKING:
    from schemathesis import Case

OPERATIONS = [
    ("/v1/match", "POST", 60),
    ("/v1/networks", "GET", 5),
    ("/healthz", "GET", 5),
    ("/readyz", "GET", 5),
    ("/metrics", "GET", 5),
]


@pytest.fixture(scope="module")
def api_schema(live) -> Any:
    return schemathesis.openapi.from_url(live.base_url + "/openapi.json")


def not_a_server_error(ctx: Any, response: Any, case: Case) -> None:
    assert response.status_code < 500, (
        f"{case.method} {case.path} answered {response.status_code}: {response.text[:500]}"
    )


@pytest.mark.parametrize(("path", "method", "examples"), OPERATIONS)
def test_no_input_produces_a_server_error(
    api_schema: Any, path: str, method: str, examples: int
) -> None:
    operation = api_schema[path][method]

    @given(case=operation.as_strategy())
    @settings(
        max_examples=examples,
        derandomize=True,
        deadline=None,
        suppress_health_check=list(HealthCheck),
        database=None,
    )
    def run(case: Case) -> None:
        case.call_and_validate(
            checks=[
                not_a_server_error,
                status_code_conformance,
                content_type_conformance,
                response_schema_conformance,
            ]
        )

    run()


# Random but well-formed traces inside the served network's bounding box reach the matcher
# itself (the schema-driven cases above almost never land on a road).
MONACO = (7.4049, 43.7245, 7.4395, 43.7519)

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
@settings(
    max_examples=60,
    derandomize=True,
    deadline=None,
    database=None,
    suppress_health_check=list(HealthCheck),
)
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
