"""The error table, the settings, the OpenAPI document and the module examples of api/."""

from __future__ import annotations

import doctest
import importlib
from typing import TYPE_CHECKING, Any

import pytest

import roadnets
from api.errors import (
    ERROR_TABLE,
    BodyTooLargeError,
    OptionError,
    UnknownNetworkError,
    error_answer,
    rule_for,
)
from api.settings import Settings
from mapmatch import OVERRIDABLE, ConfigError, InvalidTraceError, NoCandidatesError, TraceFileError

if TYPE_CHECKING:
    import httpx


def test_error_codes_are_unique_and_4xx_or_5xx() -> None:
    codes = [rule.code for rule in ERROR_TABLE]
    assert len(codes) == len(set(codes))
    assert all(400 <= rule.status < 600 for rule in ERROR_TABLE)


@pytest.mark.parametrize(
    ("error", "status", "code"),
    [
        (InvalidTraceError("bad lat", field="lat", rows=[3]), 422, "invalid_trace"),
        (TraceFileError("not CSV"), 422, "invalid_body"),
        (ConfigError("sigma_m must be > 0"), 422, "invalid_options"),
        (OptionError("sigma_m must be > 0", field="options.sigma_m"), 422, "invalid_options"),
        (NoCandidatesError("t", 50.0), 422, "no_road_nearby"),
        (UnknownNetworkError("atlantis"), 404, "unknown_network"),
        (roadnets.CacheError("/nope", "read-only"), 503, "network_unavailable"),
        (roadnets.NetworkSourceNotFoundError("x.osm"), 503, "network_unavailable"),
        (BodyTooLargeError("big"), 413, "body_too_large"),
        (KeyError("a bug"), 500, "internal_error"),
    ],
)
def test_each_error_class_has_its_answer(error: Exception, status: int, code: str) -> None:
    assert (rule_for(error).status, rule_for(error).code) == (status, code)
    answer = error_answer(error)
    assert answer.status == status
    assert answer.code == code


def test_a_bug_answer_does_not_leak_its_message() -> None:
    answer = error_answer(KeyError("secret internals"))
    assert b"secret" not in answer.body


def test_settings_come_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MAPMATCH_NETWORKS", '["a.osm.pbf", "b.osm.pbf"]')
    monkeypatch.setenv("MAPMATCH_TOKEN", "  ")
    monkeypatch.setenv("MAPMATCH_MAX_POINTS", "500")
    settings = Settings()
    assert settings.networks == ("a.osm.pbf", "b.osm.pbf")
    assert settings.token is None  # blank = no auth
    assert settings.max_points == 500
    monkeypatch.setenv("MAPMATCH_MAX_POINTS", "1")
    with pytest.raises(ValueError, match="max_points"):
        Settings()


def test_settings_never_repeat_a_match_config_field() -> None:
    from mapmatch import MatchConfig

    assert not set(Settings.model_fields) & set(MatchConfig.__dataclass_fields__)


@pytest.mark.parametrize(
    "module",
    [
        "api.errors",
        "api.logs",
        "api.service",
        "api.settings",
        "api.schemas",
        "api.deps",
        "api.intake",
        "api.costs",
    ],
)
def test_module_examples_hold(module: str) -> None:
    failures, tried = doctest.testmod(importlib.import_module(module))
    assert failures == 0
    if module != "api.schemas":
        assert tried > 0


def _undocumented(spec: dict[str, Any]) -> list[str]:
    missing = []
    for name, model in spec["components"]["schemas"].items():
        for prop, sub in model.get("properties", {}).items():
            if (
                "description" not in sub
                and "$ref" not in sub
                and name
                not in {
                    "LineStringGeometry",
                    "PointGeometry",
                    "SegmentProperties",
                    "PointProperties",
                    "SegmentFeature",
                    "PointFeature",
                    "MatchResponse",
                }
            ):
                missing.append(f"{name}.{prop}")
    for path, ops in spec["paths"].items():
        for method, op in ops.items():
            missing += [
                f"{method.upper()} {path} ?{p['name']}"
                for p in op.get("parameters", [])
                if not p.get("description")
            ]
    return missing


def test_openapi_documents_every_field_and_the_option_bounds(client: httpx.Client) -> None:
    spec = client.get("/openapi.json").json()
    assert _undocumented(spec) == []
    options = spec["components"]["schemas"]["MatchOptions"]["properties"]
    assert set(options) == OVERRIDABLE
    sigma = options["sigma_m"]["anyOf"][0]
    assert sigma["exclusiveMinimum"] == 0
    assert options["search_radius_m"]["anyOf"][0]["maximum"] == 200
    body = spec["paths"]["/v1/match"]["post"]["requestBody"]["content"]
    assert set(body) == {
        "application/json",
        "application/geo+json",
        "application/gpx+xml",
        "text/csv",
    }
    query = {p["name"] for p in spec["paths"]["/v1/match"]["post"]["parameters"]}
    assert query == OVERRIDABLE | {"network", "trace_id", "fused_distance_m", "crs", "polyline"}
    assert client.get("/docs").status_code == 200
