"""What the OpenAPI fuzzing tests share: bounded settings, the checks, one operation's run."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from hypothesis import HealthCheck, given, settings
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
    response_schema_conformance,
    status_code_conformance,
)

if TYPE_CHECKING:
    from schemathesis import Case

#: The served embedded network's bounding box (lon0, lat0, lon1, lat1): random traces in it
#: land on roads and reach the matcher itself.
MONACO = (7.4049, 43.7245, 7.4395, 43.7519)

#: Derandomized and bounded: the same examples every run, no deadline, no example database.
BOUNDED = settings(
    derandomize=True, deadline=None, database=None, suppress_health_check=list(HealthCheck)
)


def not_a_server_error(ctx: Any, response: Any, case: Case) -> None:
    assert response.status_code < 500, (
        f"{case.method} {case.path} answered {response.status_code}: {response.text[:500]}"
    )


CHECKS = (
    not_a_server_error,
    status_code_conformance,
    content_type_conformance,
    response_schema_conformance,
)


def fuzz_operation(api_schema: Any, path: str, method: str, examples: int) -> None:
    """Call one documented operation with ``examples`` schema-made cases; check each answer."""
    operation = api_schema[path][method]

    @given(case=operation.as_strategy())
    @settings(BOUNDED, max_examples=examples)
    def run(case: Case) -> None:
        case.call_and_validate(checks=list(CHECKS))

    run()
