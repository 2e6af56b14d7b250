"""Candidate road positions for every fix of a trace, in one vectorised R-tree query."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from numba import njit

from mapmatch.frozen import quick_init
from mapmatch.readonly import kernel_array
from roadnets.spatial import PLACE_SEPARATION_M, packed_arrays
from roadnets.spatial_kernels import nearby_kernel

if TYPE_CHECKING:
    from mapmatch.config import MatchConfig
    from mapmatch.types import FloatArray, IntArray
    from roadnets import RoadNetwork

__all__ = [
    "EDGES_PER_PLACE",
    "Candidates",
    "edges_searched",
    "find_candidates",
    "radius_of_sigma",
    "search_radii",
    "sigma_radius_kernel",
    "sigmas_radius",
]

#: Directed edges searched per fix, per road place the trellis keeps (``max_candidates``): a
#: place of a two-way road is two directed edges, and the trellis keeps the places with the
#: best emission (distance and heading) among those found, so where a junction's many edges
#: fill the nearest ones, the road the heading agrees with a little farther out still gets in.
EDGES_PER_PLACE = 2


@quick_init
@dataclass(frozen=True, slots=True)
class Candidates:
    """
    Candidate positions of all fixes, ragged: fix ``t`` owns rows ``ptr[t]:ptr[t + 1]``.

    Rows of one fix are sorted nearest first. ``edge`` is a directed edge index, ``offset_m``
    the distance along it, ``x``/``y`` the projection (metres), ``distance_m`` the distance
    from the fix and ``bearing_deg`` the road's direction there (clockwise from north).
    """

    ptr: IntArray
    edge: IntArray
    offset_m: FloatArray
    distance_m: FloatArray
    x: FloatArray
    y: FloatArray
    bearing_deg: FloatArray

    @property
    def counts(self) -> IntArray:
        """Number of candidates of each fix."""
        return self.ptr[1:] - self.ptr[:-1]  # np.diff's checks cost more than this

    def __len__(self) -> int:
        return len(self.edge)

    def take(self, keep: npt.NDArray[np.bool_]) -> Candidates:
        """
        The candidates flagged in ``keep`` (one flag per row), fixes unchanged.

        Examples
        --------
        >>> c = Candidates(np.array([0, 2, 3]), *(np.arange(3.0),) * 6)
        >>> c.take(np.array([False, True, True])).ptr.tolist()
        [0, 1, 2]
        """
        point_of = np.repeat(np.arange(len(self.ptr) - 1), self.counts)
        counts = np.bincount(point_of[keep], minlength=len(self.ptr) - 1)
        return Candidates(
            ptr=np.concatenate(([0], np.cumsum(counts))).astype(np.int64),
            edge=self.edge[keep],
            offset_m=self.offset_m[keep],
            distance_m=self.distance_m[keep],
            x=self.x[keep],
            y=self.y[keep],
            bearing_deg=self.bearing_deg[keep],
        )

    def spread(self, fixes: IntArray, n: int) -> Candidates:
        """
        These candidates of ``fixes`` (indices into ``n`` fixes), the other fixes having none.

        Examples
        --------
        >>> c = Candidates(np.array([0, 2, 3]), *(np.arange(3.0),) * 6)
        >>> c.spread(np.array([1, 3]), 4).ptr.tolist()
        [0, 0, 2, 2, 3]
        """
        counts = np.zeros(n, dtype=np.int64)
        counts[fixes] = self.counts
        return Candidates(
            np.concatenate(([0], np.cumsum(counts))).astype(np.int64),
            self.edge,
            self.offset_m,
            self.distance_m,
            self.x,
            self.y,
            self.bearing_deg,
        )

    def subset(self, fixes: IntArray) -> Candidates:
        """
        The candidates of some fixes only, in the order given.

        Examples
        --------
        >>> c = Candidates(np.array([0, 2, 3, 5]), *(np.arange(5.0),) * 6)
        >>> c.subset(np.array([0, 2])).edge.tolist()
        [0.0, 1.0, 3.0, 4.0]
        """
        counts = self.counts[fixes]
        ptr = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
        rows = np.repeat(self.ptr[fixes] - ptr[:-1], counts) + np.arange(int(ptr[-1]))
        return Candidates(
            ptr=ptr,
            edge=self.edge[rows],
            offset_m=self.offset_m[rows],
            distance_m=self.distance_m[rows],
            x=self.x[rows],
            y=self.y[rows],
            bearing_deg=self.bearing_deg[rows],
        )


@njit(cache=True, nogil=True, inline="always")
def sigmas_radius(sigma, sigmas, floor_m, ceiling_m):  # type: ignore[no-untyped-def]  # pragma: no cover
    """A radius of ``sigmas`` position sigmas, at least ``floor_m`` and at most ``ceiling_m``."""
    return min(max(floor_m, sigmas * sigma), ceiling_m)


@njit(cache=True, nogil=True)
def sigma_radius_kernel(n, accuracy, sigma_m, radius_m, factor, max_radius):  # type: ignore[no-untyped-def]  # pragma: no cover
    """
    Each fix's sigma and search radius (``accuracy`` empty: none reported).

    A fix's sigma is its accuracy where that is larger than ``sigma_m`` (NaN: not known), and
    its radius ``factor`` sigmas, at least ``radius_m`` and at most ``max_radius``.
    """
    sigma = np.full(n, sigma_m)
    for i in range(len(accuracy)):
        sigma[i] = np.fmax(sigma_m, accuracy[i])
    radius = np.empty(n)
    for i in range(n):
        radius[i] = sigmas_radius(sigma[i], factor, radius_m, max_radius)
    return sigma, radius


def radius_of_sigma(sigma_m: float, config: MatchConfig) -> float:
    """
    The search radius of a fix whose position sigma is ``sigma_m`` (as :func:`search_radii`).

    Examples
    --------
    >>> from mapmatch.config import MatchConfig
    >>> [radius_of_sigma(s, MatchConfig()) for s in (5.0, 20.0, 80.0)]
    [50.0, 80.0, 200.0]
    """
    wide = config.radius_accuracy_factor * sigma_m
    return float(min(max(config.search_radius_m, wide), config.max_search_radius_m))


def search_radii(accuracy_m: FloatArray | None, n: int, config: MatchConfig) -> FloatArray:
    """
    Search radius of each fix: the configured one, widened where its sigma asks for more.

    ``radius_accuracy_factor`` times the fix's sigma (its accuracy where larger than
    ``sigma_m``), at least ``search_radius_m``, at most ``max_search_radius_m``.

    Examples
    --------
    >>> from mapmatch.config import MatchConfig
    >>> search_radii(np.array([3.0, 20.0, np.nan, 500.0]), 4, MatchConfig())
    array([ 50.,  80.,  50., 200.])
    >>> search_radii(np.array([3.0, 20.0, np.nan, 500.0]), 4, MatchConfig(sigma_m=20.0))
    array([ 80.,  80.,  80., 200.])
    """
    accuracy = np.empty(0) if accuracy_m is None else np.ascontiguousarray(accuracy_m, np.float64)
    _, radius = sigma_radius_kernel(
        n,
        accuracy,
        float(config.sigma_m),
        float(config.search_radius_m),
        float(config.radius_accuracy_factor),
        float(config.max_search_radius_m),
    )
    return np.asarray(radius, dtype=np.float64)


def edges_searched(config: MatchConfig) -> int:
    """
    How many nearest directed edges are searched per fix: :data:`EDGES_PER_PLACE` per place kept.

    Examples
    --------
    >>> from mapmatch.config import MatchConfig
    >>> edges_searched(MatchConfig(max_candidates=12))
    24
    """
    return EDGES_PER_PLACE * int(config.max_candidates)


def find_candidates(
    net: RoadNetwork, x: FloatArray, y: FloatArray, radius_m: FloatArray, config: MatchConfig
) -> Candidates:
    """
    The :data:`EDGES_PER_PLACE` x ``max_candidates`` nearest directed edges of each fix.

    Within each fix's radius; the trellis keeps the ``max_candidates`` places of them with the
    best emission. What :meth:`~roadnets.RoadNetwork.nearby_edges` finds, straight from the
    packed R-tree's compiled query (one call for every fix, rows already grouped by fix).

    Parameters
    ----------
    net
        The road network.
    x, y
        Fix positions, metres in the network CRS.
    radius_m
        Search radius of each fix, metres.
    config
        Matcher parameters (``max_candidates``).
    """
    args = (
        *packed_arrays(net.segment_tree, net.arrays),
        kernel_array(x),  # read-only, whichever caller's (one variant)
        kernel_array(y),
        kernel_array(radius_m),
        edges_searched(config),
        PLACE_SEPARATION_M,
    )
    ptr, edge, dist, offset, qx, qy, bearing = nearby_kernel(*args)
    return Candidates(ptr, edge, offset, dist, qx, qy, bearing)
