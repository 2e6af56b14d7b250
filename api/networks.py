"""
The road networks one service process matches on, loaded once at startup.

Each network is read from the compiled cache, whose arrays are memory-mapped: N worker
processes share one copy of them through the page cache. What every process still builds for
itself is small next to the arrays: the R-tree over the edge segments and numba's compiled
kernels, both warmed up here so the first request does not pay for them. Each network's
candidate density is sampled for the cost model (:mod:`api.costs`), and once everything is
loaded the objects are frozen out of the garbage collector's reach (``gc.freeze``), so full
collections do not walk them during matches.
"""

from __future__ import annotations

import logging
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

import mapmatch
import roadnets
from api.costs import CandidateDensity
from api.errors import NotReadyError, UnknownNetworkError
from mapmatch.online.warm import warm_up_live
from roadnets.errors import MapMatchError, RoadNetworkError

if TYPE_CHECKING:
    from collections.abc import Sequence

    from roadnets import NetworkInfo, RoadNetwork

__all__ = ["NetworkRegistry"]

_log = logging.getLogger("api.networks")


class NetworkRegistry:
    """
    Networks by id, filled by :meth:`load_all` (in a thread at startup), read by requests.

    Parameters
    ----------
    sources
        OSM extracts; empty = the embedded default network.
    cache_dir
        Folder of compiled networks; ``None`` = roadnets' default.
    route_table_mb
        Budget of each network's route table for sparse traces, read or built at load
        (:meth:`roadnets.RoadNetwork.sparse_route_table`); 0: none.
    """

    def __init__(
        self, sources: Sequence[str], cache_dir: str | None, route_table_mb: float = 0.0
    ) -> None:
        self._sources: tuple[str | None, ...] = tuple(sources) or (None,)
        self._cache_dir = cache_dir
        self._route_table_mb = route_table_mb
        self._nets: dict[str, RoadNetwork] = {}
        self._infos: dict[str, NetworkInfo] = {}
        self._density: dict[str, CandidateDensity] = {}
        self._default: str | None = None
        self._ready = threading.Event()
        self._failure: str | None = None

    @property
    def ready(self) -> bool:
        """Whether every network is loaded."""
        return self._ready.is_set()

    @property
    def failure(self) -> str | None:
        """Why loading failed, if it did."""
        return self._failure

    def load_all(self) -> None:
        """
        Load every network (from the cache when it has them) and warm each one up.

        A failure is kept (see :attr:`failure`) and logged, not raised: the process stays up,
        ``/healthz`` answers, ``/readyz`` and matches answer 503 with the reason. A warm-up
        match that fails is only logged. Before the networks, the matcher's kernels for every
        kind of input (:mod:`mapmatch.batch.warm`, a live trip: :mod:`mapmatch.online.warm`),
        from numba's cache once ``mapmatch network build`` has compiled them.
        """
        started = time.perf_counter()
        from mapmatch.batch import warm  # noqa: F401 - its import matches on the block

        if not warm_up_live():
            _log.warning("the live matcher's warm-up failed; the first live trip compiles it")
        try:
            for source in self._sources:
                net = self._load(source)
                if net.network_id in self._nets:
                    msg = (
                        f"two networks have the id {net.network_id!r} ({source}); "
                        "rename one of the files"
                    )
                    raise RoadNetworkError(msg)
                net.route_table_budget_mb = self._route_table_mb
                net.sparse_route_table()  # now, not in the background while serving
                _log.info("network %s: route table %s", net.network_id, net.route_table_note)
                _warm_up(net)
                self._nets[net.network_id] = net
                self._infos[net.network_id] = net.info()
                self._density[net.network_id] = CandidateDensity.of(net)
                self._default = self._default or net.network_id
        except Exception as exc:
            self._failure = f"loading the road networks failed: {exc}"
            _log.error("%s", self._failure, exc_info=not isinstance(exc, MapMatchError))
            return
        # What is loaded now lives as long as the process: keep the collector from walking it
        # again and again (full collections of it paused matches for 70-150 ms).
        roadnets.freeze_after_load()
        self._ready.set()
        _log.info(
            "networks ready in %.2f s: %s", time.perf_counter() - started, ", ".join(self._nets)
        )

    def _load(self, source: str | None) -> RoadNetwork:
        net = roadnets.load(source, cache_dir=self._cache_dir)
        if not net.from_cache:
            # A fresh compile lives in this process's memory; the cached copy is memory-mapped
            # and shared with the other workers, so serve that one.
            cached = roadnets.load(source, cache_dir=self._cache_dir)
            if cached.from_cache:
                net = cached
        return net

    def get(self, network_id: str | None) -> RoadNetwork:
        """
        The network named ``network_id``, or the default one for ``None``.

        Raises
        ------
        NotReadyError
            Still loading.
        RoadNetworkError
            Loading failed.
        UnknownNetworkError
            No network has that id.
        """
        self._check_ready()
        name = network_id if network_id is not None else self._default
        net = self._nets.get(name) if name is not None else None
        if net is None:
            msg = (
                f"unknown network {network_id!r}; this service serves "
                f"{', '.join(map(repr, self._nets))} (see GET /v1/networks)"
            )
            raise UnknownNetworkError(msg, field="network")
        return net

    def density(self, network_id: str) -> CandidateDensity:
        """How many candidates points on network ``network_id`` find (see :mod:`api.costs`)."""
        self._check_ready()
        return self._density[network_id]

    def describe(self) -> list[dict[str, object]]:
        """One summary per network, default first (the ``GET /v1/networks`` items)."""
        self._check_ready()
        out: list[dict[str, object]] = []
        for network_id, info in self._infos.items():
            out.append(
                {
                    "id": network_id,
                    "source": Path(info.source).name,
                    "crs": info.crs,
                    "bbox": [round(v, 7) for v in info.bbox],
                    "nodes": info.nodes,
                    "edges": info.edges,
                    "road_km": round(info.road_km, 3),
                    "route_table": self._nets[network_id].route_table_note,
                    "default": network_id == self._default,
                }
            )
        return out

    def ids(self) -> list[str]:
        """Ids of the loaded networks."""
        return list(self._nets)

    def _check_ready(self) -> None:
        if self._failure is not None:
            raise RoadNetworkError(self._failure)
        if not self._ready.is_set():
            msg = "the service is still loading its road networks; retry in a moment"
            raise NotReadyError(msg)


def _warm_up(net: RoadNetwork) -> None:
    """Build the R-tree and compile the kernels with a three-point match along one edge."""
    a = net.arrays
    start, stop = int(a.edge_geom_ptr[0]), int(a.edge_geom_ptr[1])
    x = np.asarray(a.geom_x[start:stop], dtype=np.float64)
    y = np.asarray(a.geom_y[start:stop], dtype=np.float64)
    xs = np.array([x[0], (x[0] + x[-1]) / 2, x[-1]])
    ys = np.array([y[0], (y[0] + y[-1]) / 2, y[-1]])
    lon, lat = net.unproject(xs, ys)
    trace = mapmatch.Trace(time=[0.0, 1.0, 2.0], lon=lon, lat=lat, trace_id="warm-up")
    try:
        mapmatch.match(trace, net)
    except MapMatchError as exc:  # the network still serves; only the first request is slower
        _log.warning("warm-up match on %s failed: %s", net.network_id, exc)
    except Exception:  # a bug of the matcher; requests will answer internal_error for it
        _log.exception("warm-up match on %s crashed", net.network_id)
