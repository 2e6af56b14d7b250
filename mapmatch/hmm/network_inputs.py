"""
The network's arrays the matcher's kernels read, handed over as one object.

A compiled call pays for each array it is given (numba types and unboxes every one, about
0.1 us each); the network's arrays are the same for every trace, and the solve and assembly
kernels read some ninety of them. Held in one structure (a numba ``StructRef``, built once per
network, route table and thread), they cross into compiled code as one argument: 0.6 us
instead of 8-9 us a match.
"""

from __future__ import annotations

import threading
import weakref
from typing import TYPE_CHECKING, Any

from numba import njit
from numba.core import types
from numba.experimental import structref

from mapmatch.hmm.geometry import network_geometry
from mapmatch.hmm.loops import loop_network
from mapmatch.hmm.transition import route_inputs

if TYPE_CHECKING:
    from roadnets import RoadNetwork

__all__ = ["NetworkInputs", "network_inputs"]


@structref.register
class NetworkInputsType(types.StructRef):
    """The numba type of :class:`NetworkInputs`."""

    def preprocess_fields(self, fields: Any) -> tuple[tuple[str, Any], ...]:
        return tuple((name, types.unliteral(typ)) for name, typ in fields)  # type: ignore[no-untyped-call]


class NetworkInputs(structref.StructRefProxy):
    """
    What the solve and assembly kernels read of a network, as one compiled-code object.

    Fields (read in compiled code): ``routing`` (:func:`~mapmatch.hmm.transition.route_inputs`),
    ``edge_speed`` and ``edge_class`` (per edge), ``walk_net`` (the edge arrays and geometry
    :func:`~mapmatch.hmm.pathwalk.walk_pieces` reads), ``loop_net``
    (:func:`~mapmatch.hmm.loops.loop_network`), ``geom``
    (:func:`~mapmatch.hmm.geometry.network_geometry`) and ``ids`` (the OSM node ids and the
    edges' ends and keys).
    """


_FIELDS = ("routing", "edge_speed", "edge_class", "walk_net", "loop_net", "geom", "ids")
structref.define_proxy(NetworkInputs, NetworkInputsType, list(_FIELDS))  # type: ignore[no-untyped-call]

_local = threading.local()


@njit(cache=True)
def _made(*fields):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """A :class:`NetworkInputs` of ``fields`` (:data:`_FIELDS`), by a constructor kept on disk."""
    return NetworkInputs(*fields)  # type: ignore[no-untyped-call]


def network_inputs(net: RoadNetwork) -> NetworkInputs:
    """
    The :class:`NetworkInputs` of ``net`` for the calling thread, made once.

    Made again when the thread matches on another network, or the network's route table
    arrived (:func:`~mapmatch.hmm.transition.route_inputs` reads it).
    """
    table = net.precomputed_routes
    last = getattr(_local, "last", None)  # this thread's last network, as it was then
    if last is not None and last[0]() is net and last[1] is table:
        held: NetworkInputs = last[2]
        return held
    routing = route_inputs(net)
    a, geom = net.arrays, network_geometry(net)
    fields = {
        "routing": routing,
        "edge_speed": a.edge_speed_mps,
        "edge_class": a.edge_class,
        "walk_net": (a.edge_length_m, a.edge_speed_mps, a.edge_u, a.edge_v, a.edge_twin,
                     a.out_ptr, net.turns.state_edge, geom),
        "loop_net": loop_network(net),
        "geom": geom,
        "ids": (a.node_osm_id, a.edge_u, a.edge_v, a.edge_key),
    }  # fmt: skip
    made: NetworkInputs = _made(*(fields[name] for name in _FIELDS))
    _local.last = (weakref.ref(net), table, made)
    return made
