"""
``key=value`` overrides of :class:`MatchConfig` or :class:`SimulationConfig` fields.

The matrix's ``--config`` and ``--sim`` options: every field is open (unlike a request's
:data:`mapmatch.OVERRIDABLE` subset), typed as the field's default is.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

from mapmatch.config import MatchConfig
from mapmatch.errors import ConfigError

if TYPE_CHECKING:
    from collections.abc import Iterable, Mapping

__all__ = ["match_config", "parse_overrides"]


def _parse_value(name: str, text: str, default: object) -> object:
    """``text`` read as the type of ``default`` (the field's default value)."""
    if isinstance(default, bool):
        if text.lower() not in ("true", "false", "1", "0", "yes", "no"):
            msg = f"{name} takes true or false (got {text!r})"
            raise ConfigError(msg)
        return text.lower() in ("true", "1", "yes")
    try:
        if isinstance(default, int):
            return int(text)
        if isinstance(default, float):
            return float(text)
        if isinstance(default, tuple):
            return tuple(float(x) for x in text.split(","))
    except ValueError:
        kind = "comma-separated numbers" if isinstance(default, tuple) else type(default).__name__
        msg = f"{name} takes {kind} (got {text!r})"
        raise ConfigError(msg) from None
    return text


def parse_overrides(pairs: Iterable[str], defaults: Any) -> dict[str, object]:
    """
    ``["key=value", ...]`` as typed field values of the dataclass instance ``defaults``.

    Values are read as the field's default is typed: ``true``/``false``, integers, floats,
    comma-separated numbers for pairs (``distance_band=-0.04,0.01``), else text.

    Raises
    ------
    ConfigError
        A pair without ``=`` or an unknown field (the message lists the known ones).

    Examples
    --------
    >>> parse_overrides(["uturn_penalty=20", "use_travel=false"], MatchConfig())
    {'uturn_penalty': 20.0, 'use_travel': False}
    """
    fields = {f.name for f in dataclasses.fields(defaults)}
    out: dict[str, object] = {}
    for pair in pairs:
        name, sep, text = pair.partition("=")
        name = name.strip()
        if not sep:
            msg = f"override {pair!r} must be key=value"
            raise ConfigError(msg)
        if name not in fields:
            msg = f"unknown field {name!r} of {type(defaults).__name__}; known: {sorted(fields)}"
            raise ConfigError(msg)
        out[name] = _parse_value(name, text.strip(), getattr(defaults, name))
    return out


def match_config(overrides: Mapping[str, object]) -> MatchConfig:
    """
    The default :class:`MatchConfig` with any of its fields changed (validated).

    Unlike :meth:`MatchConfig.replace` (the fields a request may set) every field is open:
    this is for trying parameters.
    """
    return dataclasses.replace(MatchConfig(), **overrides)  # type: ignore[arg-type]
