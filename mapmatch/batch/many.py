"""
``mapmatch.match_many``: many traces matched at once, on local cores or a Dask cluster.

The Python counterpart of ``mapmatch match``: the same executors
(:mod:`mapmatch.batch.executors`), the network sent to each worker once (a cached
:class:`~roadnets.RoadNetwork` pickles as its cache entry and is memory-mapped again there),
the traces cut into chunks, the results back in input order.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from math import ceil
from typing import TYPE_CHECKING, Any, Literal, overload

from mapmatch.batch.executors import available_cores, make_executor
from mapmatch.matcher import match
from mapmatch.trace import check_match_inputs

if TYPE_CHECKING:
    from collections.abc import Iterable

    from mapmatch.config import MatchConfig
    from mapmatch.result import MatchResult
    from mapmatch.trace import Trace
    from roadnets import RoadNetwork

__all__ = ["match_many"]

_MAX_CHUNK = 32
_CHUNKS_PER_SLOT = 4
_FROZEN: list[bool] = []


@dataclass(frozen=True, slots=True)
class _Chunk:
    """Some traces to match, with their positions in the caller's list."""

    first: int
    traces: tuple[Trace, ...]
    config: MatchConfig | None


def _match_chunk(chunk: _Chunk, net: RoadNetwork) -> list[MatchResult | Exception]:
    """Match the traces of a chunk (in a worker); an error is returned in the trace's place."""
    out: list[MatchResult | Exception] = []
    for trace in chunk.traces:
        try:
            out.append(match(trace, net, chunk.config))
        except Exception as exc:
            out.append(exc)
    if not _FROZEN:  # the network is loaded and its R-tree built: spare the GC from them
        import roadnets

        roadnets.freeze_after_load()
        _FROZEN.append(True)
    return out


@overload
def match_many(
    traces: Iterable[Trace],
    net: RoadNetwork,
    config: MatchConfig | None = ...,
    *,
    workers: int | None = ...,
    client: Any = ...,
    progress: bool = ...,
    return_exceptions: Literal[False] = ...,
    chunk_traces: int | None = ...,
) -> list[MatchResult]: ...


@overload
def match_many(
    traces: Iterable[Trace],
    net: RoadNetwork,
    config: MatchConfig | None = ...,
    *,
    workers: int | None = ...,
    client: Any = ...,
    progress: bool = ...,
    return_exceptions: Literal[True],
    chunk_traces: int | None = ...,
) -> list[MatchResult | Exception]: ...


def match_many(
    traces: Iterable[Trace],
    net: RoadNetwork,
    config: MatchConfig | None = None,
    *,
    workers: int | None = None,
    client: Any = None,
    progress: bool = True,
    return_exceptions: bool = False,
    chunk_traces: int | None = None,
) -> list[MatchResult] | list[MatchResult | Exception]:
    """
    Match many traces on one network, in parallel; results in the order of ``traces``.

    Parameters
    ----------
    traces
        The traces (:class:`~mapmatch.Trace`), e.g. from :func:`mapmatch.read_traces`.
    net
        The road network, from :func:`roadnets.load`; sent to each worker once.
    config
        Matcher parameters, the same for every trace; the defaults otherwise.
    workers
        Local worker processes (default: one per core, at most one per trace; 1 matches in
        this process). Ignored with ``client``.
    client
        A ``dask.distributed.Client``: match on its cluster instead (the network is
        scattered to every worker once; the workers must reach its cache entry or source).
    progress
        Draw a progress bar (traces done, on standard error).
    return_exceptions
        Put a trace's error in its place in the list instead of raising it (as
        ``asyncio.gather`` does), so one bad trace does not lose the others.
    chunk_traces
        Traces per task (default: about four tasks per worker, at most 32).

    Returns
    -------
    list of MatchResult
        One per trace; with ``return_exceptions``, the error where a trace failed.

    Raises
    ------
    MapMatchError
        The first trace that failed (``NoCandidatesError`` ...), unless
        ``return_exceptions``.
    InputTypeError
        An item of ``traces`` is not a Trace, or ``net`` not a RoadNetwork.
    SchedulerError
        ``client`` has no workers.

    Examples
    --------
    >>> results = mapmatch.match_many(mapmatch.read_traces("fleet.csv"), net)  # doctest: +SKIP
    >>> from distributed import Client                                          # doctest: +SKIP
    >>> results = mapmatch.match_many(traces, net, client=Client(cluster))      # doctest: +SKIP
    """
    items = list(traces)
    for trace in items:
        check_match_inputs(trace, net)
    results: list[MatchResult | Exception | None] = [None] * len(items)
    if not items:
        return []
    count = workers if workers is not None else available_cores()
    executor = make_executor(
        min(count, len(items)),
        None,
        client=client,
        preload=["mapmatch.batch.many", "mapmatch.batch.warm"],
        shared=net,
    )
    bar = _bar(len(items), progress)
    try:
        size = chunk_traces or _chunk_size(len(items), executor.slots)
        chunks = [
            _Chunk(first=start, traces=tuple(items[start : start + size]), config=config)
            for start in range(0, len(items), size)
        ]
        for chunk, outcome in executor.run(_match_chunk, chunks):
            if isinstance(outcome, BaseException):  # the task itself failed (a lost worker)
                if not isinstance(outcome, Exception):
                    raise outcome
                done: list[MatchResult | Exception] = [outcome] * len(chunk.traces)
            else:
                done = outcome
            for k, item in enumerate(done):
                if isinstance(item, Exception) and not return_exceptions:
                    raise item
                results[chunk.first + k] = item
            if bar is not None:
                bar.update(len(chunk.traces))
    finally:
        if bar is not None:
            bar.close()
        executor.close()
    assert all(r is not None for r in results)  # every chunk came back
    return results  # type: ignore[return-value]


def _chunk_size(traces: int, slots: int) -> int:
    if slots <= 1:
        return 1
    return max(1, min(_MAX_CHUNK, ceil(traces / (slots * _CHUNKS_PER_SLOT))))


def _bar(total: int, show: bool) -> Any:
    if not show:
        return None
    from tqdm import tqdm

    return tqdm(total=total, unit="trace", desc="matching", file=sys.stderr, dynamic_ncols=True)
