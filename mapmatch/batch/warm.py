"""
Load the compiled kernels once in the local pool's fork server, before any worker is forked.

The first match of a fresh process loads (or compiles) the matcher's and the router's
kernels: about a second, more when several workers do it at once. The pool's fork server
imports this module (``set_forkserver_preload``): :func:`warm_up` matches a short trace on a
block of four streets built in memory and writes its GeoJSON, so every worker forked from
the server starts with the kernels loaded. A failed warm-up changes nothing (the workers
load them themselves).
"""

from __future__ import annotations

import itertools
import pickle

from mapmatch.warm_block import (
    BLOCK_FIXES,
    OPTIONAL_COLUMNS,
    block_network,
    timed_quietly,
)

__all__ = ["WARMUP_S", "warm_up"]


def warm_up() -> float:
    """Match a short trace on an in-memory block once; the seconds it took (0 on failure)."""
    return timed_quietly(_match_on_the_block)


def _match_on_the_block() -> None:
    from mapmatch.export import geojson_bytes
    from mapmatch.matcher import match
    from mapmatch.trace import Trace

    net = block_network()
    lon = [fix["lon"] for fix in BLOCK_FIXES]
    lat = [fix["lat"] for fix in BLOCK_FIXES]
    times = [fix["time"] for fix in BLOCK_FIXES]
    columns = {k: [fix[k] for fix in BLOCK_FIXES] for k in OPTIONAL_COLUMNS}
    trace = Trace(time=times, lon=lon, lat=lat, heading=columns["heading"])
    result = match(trace, net)
    geojson_bytes(result)  # the writer's number kernel too
    # a result sent back by a worker process carries its segments' attributes and lines, not
    # the network: its GeoJSON columns come from a kernel of their own
    geojson_bytes(pickle.loads(pickle.dumps(result)))
    # every set of optional columns, and no times: numba compiles a variant of some kernels
    # for each (the travel terms, per-fix accuracy, a file with no time column), the
    # assembly's taking a minute on a slow machine
    for given in itertools.product((False, True), repeat=len(columns)):
        chosen = {k: v for (k, v), on in zip(columns.items(), given, strict=True) if on}
        given_trace = Trace(
            time=times,
            lon=lon,
            lat=lat,
            heading=chosen.get("heading"),
            speed=chosen.get("speed"),
            accuracy=chosen.get("accuracy"),
            odometer=chosen.get("odometer"),
        )
        geojson_bytes(match(given_trace, net))
    geojson_bytes(match(Trace(lon=lon, lat=lat), net))


#: Seconds the warm-up took when this module was imported.
WARMUP_S = warm_up()
