"""The objects ``match(trace, net)`` is called with: refused with a message saying what to pass."""

from __future__ import annotations

import os

import pandas as pd

from mapmatch.errors import InputTypeError
from mapmatch.trace.model import Trace

__all__ = ["check_match_inputs"]


def check_match_inputs(trace: object, net: object) -> None:
    """
    Refuse, with a message that says what to pass, a ``match()`` call on the wrong objects.

    Parameters
    ----------
    trace
        Must be a :class:`Trace`.
    net
        Must be a :class:`roadnets.RoadNetwork`.

    Raises
    ------
    InputTypeError
        (also a ``TypeError``) naming the argument, what it got and how to make the right one.

    Examples
    --------
    >>> check_match_inputs([(7.42, 43.73)], None)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    mapmatch.errors.InputTypeError: match(trace, net): trace must be a mapmatch.Trace, not a ...
    """
    from roadnets import RoadNetwork

    if isinstance(trace, RoadNetwork) and isinstance(net, Trace):
        msg = "match(trace, net): the arguments are swapped; call match(trace, net)"
        raise InputTypeError(msg)
    if not isinstance(trace, Trace):
        msg = f"match(trace, net): trace must be a mapmatch.Trace, not {_kind(trace)}; " + (
            _how_to_trace(trace)
        )
        raise InputTypeError(msg)
    if not isinstance(net, RoadNetwork):
        msg = (
            f"match(trace, net): net must be a roadnets.RoadNetwork, not {_kind(net)}; "
            + _how_to_network(net)
        )
        raise InputTypeError(msg)


def _kind(value: object) -> str:
    if value is None:
        return "None"
    cls = type(value)
    module = cls.__module__.split(".")[0]
    name = cls.__name__ if module in ("builtins", "") else f"{module} {cls.__name__}"
    return f"an {name}" if name[:1].lower() in "aeiou" else f"a {name}"


def _how_to_trace(value: object) -> str:
    if isinstance(value, pd.DataFrame):
        return "build one with mapmatch.Trace.from_dataframe(df) (or mapmatch.read_traces(df))"
    if isinstance(value, str | os.PathLike):
        return "read the file with mapmatch.Trace.from_file(path) (or mapmatch.read_traces(path))"
    if isinstance(value, list | tuple):
        return (
            "build one with mapmatch.Trace.from_records(points) (or Trace(lon=..., lat=..., "
            "time=...))"
        )
    return "build one with mapmatch.Trace(lon=..., lat=..., time=...) or Trace.from_file(path)"


def _how_to_network(value: object) -> str:
    module = type(value).__module__.split(".")[0]
    if module in ("networkx", "osmnx"):
        return (
            "convert the graph with roadnets.from_graph(G), or load an extract with "
            "roadnets.load(path)"
        )
    if isinstance(value, str | os.PathLike):
        return "load the extract first: net = roadnets.load(path)"
    return (
        "load one with roadnets.load(path) (roadnets.load() is the embedded default network) "
        "or convert an osmnx graph with roadnets.from_graph(G)"
    )
