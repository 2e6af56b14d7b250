"""Read the drivable ways and turn restrictions of an OSM extract (XML or PBF).

One reader for every format (libosmium through the ``osmium`` package): ``.osm``, ``.osm.bz2``,
``.osm.gz`` and ``.osm.pbf`` give the same ways, so the graph is the same whichever file a user
has. Ways clipped at the extract border (nodes missing from the file) are kept as the runs of
nodes that are present.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
import osmium

from roadnets.drivable import is_drivable
from roadnets.errors import InvalidNetworkSourceError

if TYPE_CHECKING:
    from pathlib import Path

__all__ = ["OsmExtract", "OsmWay", "TurnRestriction", "read_osm"]

_KEPT_TAGS = (
    "highway",
    "name",
    "ref",
    "oneway",
    "oneway:motor_vehicle",
    "junction",
    "maxspeed",
    "maxspeed:forward",
    "maxspeed:backward",
    "service",
    "access",
    "motor_vehicle",
    "motorcar",
)


@dataclass(frozen=True, slots=True)
class OsmWay:
    """One drivable OSM way (or the present run of a clipped one), in WGS84."""

    way_id: int
    node_ids: npt.NDArray[np.int64]
    lon: npt.NDArray[np.float64]
    lat: npt.NDArray[np.float64]
    tags: dict[str, str]


@dataclass(frozen=True, slots=True)
class TurnRestriction:
    """
    A car turn restriction: ``no_*`` bans the move, ``only_*`` bans every other one.

    The move runs from ``from_way`` over ``via_node`` onto ``to_way``, or, for a via-way
    restriction (``via_node`` is ``None``), from ``from_way`` along the whole of each way in
    ``via_ways`` in turn, then onto ``to_way``.
    """

    from_way: int
    via_node: int | None
    to_way: int
    only: bool
    via_ways: tuple[int, ...] = ()


@dataclass(frozen=True, slots=True)
class OsmExtract:
    """The drivable part of an OSM file."""

    ways: list[OsmWay]
    restrictions: list[TurnRestriction]
    clipped_ways: int
    #: ``type=restriction`` relations left out, by reason (not for cars, malformed...).
    skipped_restrictions: dict[str, int] = field(default_factory=dict)


def _osmium_file(path: Path) -> osmium.io.File:
    """Pick libosmium's format from the file's first bytes, not only its name."""
    with path.open("rb") as handle:
        head = handle.read(64)
    if head.startswith(b"BZh"):
        fmt = "osm.bz2"
    elif head.startswith(b"\x1f\x8b"):
        fmt = "osm.gz"
    elif b"OSMHeader" in head:
        fmt = "pbf"
    elif head.lstrip().startswith(b"<"):
        fmt = "osm"
    else:
        msg = "not OSM XML (.osm, .osm.bz2, .osm.gz) nor PBF (.osm.pbf) by its first bytes"
        raise InvalidNetworkSourceError(str(path), msg)
    return osmium.io.File(str(path), fmt)


def _runs_of_present_nodes(valid: npt.NDArray[np.bool_]) -> list[tuple[int, int]]:
    """Start/stop indices of the runs of at least two consecutive present nodes."""
    padded = np.concatenate(([False], valid, [False]))
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    starts, stops = edges[0::2], edges[1::2]
    return [(int(a), int(b)) for a, b in zip(starts, stops, strict=True) if b - a >= 2]


def read_osm(path: Path) -> OsmExtract:
    """
    Read the drivable ways and the turn restrictions of an OSM file.

    Parameters
    ----------
    path
        An OSM XML (optionally bz2/gzip compressed) or PBF file.

    Returns
    -------
    OsmExtract
        Drivable ways with their node coordinates and the tags the graph needs, the car
        turn restrictions (``type=restriction`` relations via a node or via ways), and the
        count of restriction relations left out by reason.

    Raises
    ------
    InvalidNetworkSourceError
        The file is not OSM data, or it is truncated or corrupt.
    """
    ways: list[OsmWay] = []
    restrictions: list[TurnRestriction] = []
    skipped: Counter[str] = Counter()
    clipped = 0
    try:
        processor = osmium.FileProcessor(_osmium_file(path)).with_locations()
        for obj in processor:
            if isinstance(obj, osmium.osm.Way):
                tags = obj.tags
                if "highway" not in tags:
                    continue
                kept = {key: tags[key] for key in _KEPT_TAGS if key in tags}
                if not is_drivable(kept):
                    continue
                nodes = obj.nodes
                ids = np.fromiter((nd.ref for nd in nodes), dtype=np.int64, count=len(nodes))
                valid = np.fromiter((nd.location.valid() for nd in nodes), bool, len(nodes))
                lon = np.array(
                    [nd.lon if ok else np.nan for nd, ok in zip(nodes, valid, strict=True)]
                )
                lat = np.array(
                    [nd.lat if ok else np.nan for nd, ok in zip(nodes, valid, strict=True)]
                )
                if valid.all():
                    if len(ids) >= 2:
                        ways.append(OsmWay(obj.id, ids, lon, lat, kept))
                    continue
                clipped += 1
                for start, stop in _runs_of_present_nodes(valid):
                    ways.append(
                        OsmWay(obj.id, ids[start:stop], lon[start:stop], lat[start:stop], kept)
                    )
            elif isinstance(obj, osmium.osm.Relation) and obj.tags.get("type") == "restriction":
                found, reason = _restrictions(obj)
                restrictions.extend(found)
                if reason:
                    skipped[reason] += 1
    except RuntimeError as exc:
        raise InvalidNetworkSourceError(str(path), str(exc)) from exc
    return OsmExtract(ways, restrictions, clipped, dict(skipped))


#: The ``restriction`` values that ban (``no_*``) or mandate (``only_*``) a move.
_TURN_KINDS = frozenset(
    {
        "no_right_turn",
        "no_left_turn",
        "no_u_turn",
        "no_straight_on",
        "no_entry",
        "no_exit",
        "only_right_turn",
        "only_left_turn",
        "only_straight_on",
        "only_u_turn",
    }
)

#: Vehicle classes an ``except`` tag may name that exempt a car from a restriction.
_CAR_CLASSES = frozenset({"motorcar", "motor_vehicle", "vehicle"})


def _restrictions(relation: osmium.osm.Relation) -> tuple[list[TurnRestriction], str]:
    """
    The car turn restrictions of a ``type=restriction`` relation, or why there are none.

    ``no_*`` with several ``from`` or ``to`` ways (``no_entry``, ``no_exit``) gives one ban per
    pair; ``only_*`` needs exactly one ``to``. The via is one node or a chain of ways.
    """
    tags = relation.tags
    kind = (
        tags.get("restriction:motorcar")
        or tags.get("restriction:motor_vehicle")
        or tags.get("restriction")
        or ""
    )
    if kind not in _TURN_KINDS:
        return [], "not a no_* / only_* turn restriction"
    exempt = {part.strip() for part in (tags.get("except") or "").split(";")}
    if exempt & _CAR_CLASSES:
        return [], "cars exempt (except=...)"
    from_ways: list[int] = []
    to_ways: list[int] = []
    via_nodes: list[int] = []
    via_ways: list[int] = []
    for member in relation.members:
        if member.role == "from" and member.type == "w":
            from_ways.append(member.ref)
        elif member.role == "to" and member.type == "w":
            to_ways.append(member.ref)
        elif member.role == "via" and member.type == "n":
            via_nodes.append(member.ref)
        elif member.role == "via" and member.type == "w":
            via_ways.append(member.ref)
    only = kind.startswith("only_")
    if not from_ways or not to_ways:
        return [], "no from or no to way"
    if only and len(to_ways) > 1:
        return [], "only_* with several to ways"
    if len(via_nodes) == 1 and not via_ways:
        via: tuple[int | None, tuple[int, ...]] = (via_nodes[0], ())
    elif via_ways and not via_nodes:
        via = (None, tuple(via_ways))
    else:
        return [], "via is neither one node nor ways"
    return [TurnRestriction(f, via[0], t, only, via[1]) for f in from_ways for t in to_ways], ""
