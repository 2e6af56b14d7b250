"""Errors raised on purpose by the fusion front-end."""

from __future__ import annotations

from roadnets.errors import MapMatchError

__all__ = ["FusionConfigError", "NoGnssFixError", "RawLogError", "RawLogNotFoundError"]


class RawLogError(MapMatchError, ValueError):
    """A raw sensor log is malformed (missing column, bad value, time going backwards, ...)."""

    def __init__(self, source: str, problem: str, fix: str) -> None:
        self.source, self.problem, self.fix = source, problem, fix
        msg = f"raw log {source!r}: {problem}; {fix}"
        super().__init__(msg)


class NoGnssFixError(RawLogError):
    """The raw log has no usable GNSS fix, so the fused track cannot be placed on the earth."""

    def __init__(self, source: str, detail: str) -> None:
        super().__init__(
            source,
            f"no usable GNSS fix ({detail})",
            "fusion needs at least one fix with lat/lon, enough satellites and a low HDOP; "
            "check the lat/lon/hdop/sats columns or relax FusionConfig.min_sats/max_hdop",
        )


class FusionConfigError(MapMatchError, ValueError):
    """A :class:`~mapmatch.fusion.FusionConfig` field is out of range."""

    def __init__(self, field: str, rule: str, value: object) -> None:
        self.field, self.rule, self.value = field, rule, value
        msg = f"FusionConfig.{field} must be {rule} (got {value!r})"
        super().__init__(msg)


class RawLogNotFoundError(MapMatchError, FileNotFoundError):
    """The raw log file named by the caller does not exist."""

    def __init__(self, path: str) -> None:
        self.path = path
        msg = f"raw log {path!r} does not exist; check the path"
        super().__init__(msg)
