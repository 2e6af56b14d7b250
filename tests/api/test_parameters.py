"""Every overridable matcher parameter: one declaration, the same rules in Python, CLI and HTTP."""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest

import mapmatch
from api.schemas import MatchOptions
from mapmatch.cli import build_parser
from mapmatch.config import config_from_flags

if TYPE_CHECKING:
    import httpx

OVERRIDABLE = sorted(mapmatch.OVERRIDABLE)


def _inside_and_outside(meta: mapmatch.Param, default: object) -> tuple[object, object, str]:
    """A value the rule takes, one it refuses, and the refused one as command-line text."""
    if meta.kind == "bool":
        return (not default), "maybe", "maybe"
    if meta.kind == "band":
        return (-0.05, 0.02), (0.01, -0.04), "0.01,-0.04"
    if meta.le is not None:
        bad = meta.le + 1
    elif meta.ge is not None:
        bad = meta.ge - 1
    else:
        assert meta.gt is not None
        bad = meta.gt
    bad = int(bad) if meta.kind == "int" else float(bad)
    return default, bad, str(bad)


def test_every_overridable_parameter_is_declared_with_its_rules() -> None:
    names = [name for name, _meta, _default in mapmatch.parameters(overridable_only=True)]
    assert sorted(names) == OVERRIDABLE
    assert set(MatchOptions.model_fields) == set(OVERRIDABLE)
    for name, meta, default in mapmatch.parameters():
        assert meta.doc, name
        assert getattr(mapmatch.MatchConfig(), name) == default
        if meta.kind in ("float", "int"):
            assert meta.le is not None, f"{name} has no upper bound"


@pytest.mark.parametrize("name", OVERRIDABLE)
def test_python_cli_and_openapi_take_the_same_values(name: str) -> None:
    meta, default = {n: (m, d) for n, m, d in mapmatch.parameters()}[name]
    good, bad, bad_text = _inside_and_outside(meta, default)
    # Python
    assert getattr(mapmatch.MatchConfig().replace({name: good}), name) == good
    with pytest.raises(mapmatch.ConfigError) as python_error:
        mapmatch.MatchConfig().replace({name: bad})
    assert python_error.value.field == name
    # the CLI flag named after the field
    flag = "--" + name.replace("_", "-")
    args = build_parser().parse_args(["match", "x.csv", "--out", "o", flag, bad_text])
    with pytest.raises(mapmatch.ConfigError) as cli_error:
        config_from_flags(vars(args))
    assert cli_error.value.field == name
    help_text = build_parser()._subparsers._group_actions[0].choices["match"].format_help()  # type: ignore[union-attr]
    assert flag in help_text
    # the HTTP options model and its OpenAPI schema, generated from the same declaration
    schema = MatchOptions.model_json_schema()["properties"][name]
    number = next((s for s in schema.get("anyOf", [schema]) if s.get("type") != "null"), schema)
    for key, word in (("gt", "exclusiveMinimum"), ("ge", "minimum"), ("le", "maximum")):
        if getattr(meta, key) is not None:
            assert number[word] == getattr(meta, key), (name, word)
    assert meta.doc in schema["description"]


@pytest.mark.parametrize("name", OVERRIDABLE)
def test_http_refuses_what_python_refuses(client: httpx.Client, trip, bodies, name: str) -> None:
    meta, default = {n: (m, d) for n, m, d in mapmatch.parameters()}[name]
    _good, bad, _text = _inside_and_outside(meta, default)
    body = {"points": bodies.points(trip.trace), "options": {name: bad}}
    answer = client.post("/v1/match", json=body)
    assert answer.status_code == 422, answer.text
    error = answer.json()["error"]
    assert error["code"] in ("invalid_options", "invalid_body")
    assert name in error.get("field", "") + error["message"]
