"""
Errors raised by the matching side of the project.

The root :class:`MapMatchError` lives in :mod:`roadnets.errors` (every package may import
:mod:`roadnets`) and is re-exported here together with :class:`RoadNetworkError`. Every leaf
also subclasses the matching built-in exception, so callers that catch ``ValueError`` keep
working.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from roadnets.errors import MapMatchError, RoadNetworkError

if TYPE_CHECKING:
    from collections.abc import Iterable

__all__ = [
    "ConfigError",
    "DeadlineExceededError",
    "InputTypeError",
    "InvalidTraceError",
    "MapMatchError",
    "NoCandidatesError",
    "RoadNetworkError",
    "TraceFileError",
]


class InvalidTraceError(MapMatchError, ValueError):
    """
    A trace's content breaks a rule (missing column, coordinate out of range, bad time ...).

    The message names the trace id, the offending rows (0-based input row and, for files, the
    1-based line or record), the field and value, and suggests a fix. The same facts are kept
    as attributes for programs.

    Parameters
    ----------
    msg
        The complete human-readable message.
    trace_id
        Id of the offending trace, if known.
    field
        Canonical name of the offending field (``"lat"``, ``"time"`` ...), if one is at fault.
    rows
        0-based input row indices at fault (all of them, not only those in the message).
    """

    def __init__(
        self,
        msg: str,
        *,
        trace_id: str | None = None,
        field: str | None = None,
        rows: Iterable[int] = (),
    ) -> None:
        self.trace_id = trace_id
        self.field = field
        self.rows: tuple[int, ...] = tuple(int(r) for r in rows)
        super().__init__(msg)


class TraceFileError(MapMatchError, ValueError):
    """
    A trace file or request body cannot be read: unreadable, unsupported or malformed.

    Parameters
    ----------
    msg
        The complete human-readable message; it names the file (or ``<bytes>``), the format and
        the problem.
    path
        The file, or ``None`` for an in-memory body.
    format
        The trace format that was tried (``"csv"``, ``"gpx"`` ...), if known.
    """

    def __init__(self, msg: str, *, path: str | None = None, format: str | None = None) -> None:
        self.path = path
        self.format = format
        super().__init__(msg)


class InputTypeError(MapMatchError, TypeError):
    """
    A function was given the wrong kind of object (a graph where a network belongs ...).

    The message names the argument, what it got and how to make what it needs.
    """


class ConfigError(MapMatchError, ValueError):
    """
    A matcher parameter breaks its rule; the message names the field, the rule and value.

    Attributes
    ----------
    field
        The offending parameter's name, when one is to blame.
    """

    def __init__(self, message: str, *, field: str | None = None) -> None:
        super().__init__(message)
        self.field = field


class DeadlineExceededError(MapMatchError, TimeoutError):
    """
    A match ran past the ``deadline`` it was given (checked between its stages).

    Parameters
    ----------
    trace_id
        Id of the trace.
    stage
        The stage that had just finished when the deadline was found passed.
    """

    def __init__(self, trace_id: str, stage: str) -> None:
        self.trace_id, self.stage = trace_id, stage
        super().__init__(f"trace {trace_id!r}: past its deadline after the {stage} stage")

    def __reduce__(self) -> tuple[type[DeadlineExceededError], tuple[str, str]]:
        return type(self), (self.trace_id, self.stage)


class NoCandidatesError(MapMatchError, ValueError):
    """
    No fix of a trace has a road within the search radius.

    Parameters
    ----------
    trace_id
        Id of the trace.
    radius_m
        The search radius that was used, in metres.
    """

    def __init__(self, trace_id: str, radius_m: float) -> None:
        self.trace_id, self.radius_m = trace_id, radius_m
        msg = f"trace {trace_id!r}: no road within {radius_m:g} m of any fix; swapped lon/lat?"
        super().__init__(msg)

    def __reduce__(self) -> tuple[type[NoCandidatesError], tuple[str, float]]:
        # Keeps the error picklable (worker processes send it back to the parent).
        return type(self), (self.trace_id, self.radius_m)
