"""Read the drivable ways and turn restrictions of an OSM extract (XML or PBF).

One reader for every format (libosmium through the ``osmium`` package): ``.osm``, ``.osm.bz2``,
``.osm.gz`` and ``.osm.pbf`` give the same ways, so the graph is the same whichever file a user
has. Ways clipped at the extract border (nodes missing from the file) are kept as the runs of
nodes that are present.
"""

from __future__ import annotations

from dataclasses import dataclass
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
    """A ``type=restriction`` relation with a via node: ``no_*`` bans, ``only_*`` mandates."""

    from_way: int
    via_node: int
    to_way: int
    only: bool


@dataclass(frozen=True, slots=True)
class OsmExtract:
    """The drivable part of an OSM file."""

    ways: list[OsmWay]
    restrictions: list[TurnRestriction]
    clipped_ways: int


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
        Drivable ways with their node coordinates and the tags the graph needs, and the
        restrictions (``type=restriction`` relations whose via member is a node).

    Raises
    ------
    InvalidNetworkSourceError
        The file is not OSM data, or it is truncated or corrupt.
    """
    ways: list[OsmWay] = []
    restrictions: list[TurnRestriction] = []
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
            elif isinstance(obj, osmium.osm.Relation):
                restriction = _restriction(obj)
                if restriction is not None:
                    restrictions.append(restriction)
    except RuntimeError as exc:
        raise InvalidNetworkSourceError(str(path), str(exc)) from exc
    return OsmExtract(ways, restrictions, clipped)


def _restriction(relation: osmium.osm.Relation) -> TurnRestriction | None:
    """A car turn restriction with one from way, one via node and one to way, else ``None``."""
    tags = relation.tags
    if tags.get("type") != "restriction":
        return None
    kind = (
        tags.get("restriction:motorcar")
        or tags.get("restriction:motor_vehicle")
        or tags.get("restriction")
        or ""
    )
    if not kind.startswith(("no_", "only_")):
        return None
    from_way = via = to_way = None
    for member in relation.members:
        if member.role == "from" and member.type == "w":
            from_way = member.ref
        elif member.role == "via" and member.type == "n":
            via = member.ref
        elif member.role == "to" and member.type == "w":
            to_way = member.ref
    if from_way is None or via is None or to_way is None:
        return None
    return TurnRestriction(from_way, via, to_way, kind.startswith("only_"))
