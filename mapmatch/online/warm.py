"""
Compile the live matcher's kernels ahead: a short trip fed fix by fix, once per process.

A live trip runs the model's stages on the open tail of the trip as fixes arrive
(:class:`~mapmatch.online.OnlineMatcher`), with kernels and argument types of its own (the
tail's running totals, the settled part's measures). ``mapmatch network build`` and the
service's start-up call :func:`warm_up_live` after the whole-trace warm-up (on the block of
:mod:`mapmatch.warm_block`), so that the first fix of the first live trip does not wait for the
compiler.
"""

from __future__ import annotations

import itertools
from typing import TYPE_CHECKING

from mapmatch.warm_block import (
    BLOCK_FIXES,
    OPTIONAL_COLUMNS,
    block_network,
    timed_quietly,
)

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence

    from roadnets import RoadNetwork

__all__ = ["warm_up_live"]


#: Fixes fed for each step of the drive given: a live trip groups its newest fixes only
#: once a few have arrived since the last observation closed.
_STEPS = 4


def _densified(fixes: Sequence[Mapping[str, float]], steps: int) -> list[dict[str, float]]:
    """
    ``steps`` fixes for each step between two given ones, their columns interpolated.

    Examples
    --------
    >>> [f["time"] for f in _densified([{"time": 0.0}, {"time": 4.0}], 4)]
    [0.0, 1.0, 2.0, 3.0, 4.0]
    """
    out: list[dict[str, float]] = []
    for a, b in itertools.pairwise(fixes):
        for k in range(steps):
            out.append({name: a[name] + (b[name] - a[name]) * k / steps for name in a})
    return [*out, dict(fixes[-1])] if fixes else out


def warm_up_live(
    net: RoadNetwork | None = None, fixes: Sequence[Mapping[str, float]] = BLOCK_FIXES
) -> float:
    """
    Feed ``fixes`` to two live trips on ``net``, with their places only and with every column.

    Parameters
    ----------
    net
        The network the trips run on, by default the warm-ups' block
        (:func:`~mapmatch.warm_block.block_network`; the kernels are per install).
    fixes
        A short drive, each fix with ``time``, ``lon`` and ``lat`` and the optional columns
        it has (``heading``, ``speed``, ``accuracy``, ``odometer``), the same in each fix;
        fed with fixes interpolated between them.

    Returns
    -------
    float
        The seconds it took, 0 when a trip failed (the first live trip then compiles).
    """
    drive = _densified(fixes, _STEPS)

    def run() -> None:
        from mapmatch.export import geojson_bytes
        from mapmatch.online.matcher import OnlineMatcher

        on = block_network() if net is None else net
        for optional in ((), OPTIONAL_COLUMNS):
            live = OnlineMatcher(on, lag=10.0, trip_id="warm-up")
            for fix in drive:
                live.push(
                    {k: v for k, v in fix.items() if k not in OPTIONAL_COLUMNS or k in optional}
                )
            geojson_bytes(live.close())

    return timed_quietly(run)
