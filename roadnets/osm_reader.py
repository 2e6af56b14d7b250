"""Read the drivable ways and turn restrictions of an OSM extract (XML or PBF).

One reader for every format (libosmium through the ``osmium`` package): ``.osm``, ``.osm.bz2``,
``.osm.gz`` and ``.osm.pbf`` give the same ways, so the graph is the same whichever file a user
has. Ways clipped at the extract border (nodes missing from the file) are kept as the runs of
nodes that are present.

Corrupt coordinates
-------------------
A node whose ``lat``/``lon`` is not a coordinate makes the whole file an
:class:`~roadnets.errors.InvalidNetworkSourceError` naming the node, the attribute, its text and
its line: libosmium itself stops at ``nan``, ``inf``, ``""`` or ``1e3`` (we only turn its
``InvalidLocationError`` into the project's error and find the node), and a node of a road out
of range (``lat="91.5"``, in XML or PBF) is refused rather than taken for a node missing from a
clipped extract. libosmium reads some overflowing exponents (``1e99``, ``1e999``) as 0 without
a word; every node of a road exactly on the equator or the prime meridian in an XML file is
therefore checked against its text. Skipping such a node instead (with a counted warning) would
cut its road in two or join it to the wrong place: a file with one corrupt coordinate may have
more, and is better fixed or exported again than half read. (osmnx has no check: its XML reader
keeps ``nan`` and ``inf`` as node positions.)
"""

from __future__ import annotations

import bz2
import gzip
import math
import re
from collections import Counter
from dataclasses import dataclass, field
from typing import IO, TYPE_CHECKING

import numpy as np
import numpy.typing as npt
import osmium

from roadnets.drivable import is_drivable
from roadnets.errors import InvalidNetworkSourceError

if TYPE_CHECKING:
    from collections.abc import Iterator
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


def _format_of(path: Path) -> str:
    """Name libosmium's format for a file from its first bytes, not only its name."""
    with path.open("rb") as handle:
        head = handle.read(64)
    if head.startswith(b"BZh"):
        return "osm.bz2"
    if head.startswith(b"\x1f\x8b"):
        return "osm.gz"
    if b"OSMHeader" in head:
        return "pbf"
    if head.lstrip().startswith(b"<"):
        return "osm"
    msg = "not OSM XML (.osm, .osm.bz2, .osm.gz) nor PBF (.osm.pbf) by its first bytes"
    raise InvalidNetworkSourceError(str(path), msg)


#: libosmium's location of a node missing from the file (``osmium::Location`` undefined).
_UNDEFINED = 2147483647
#: libosmium's fixed-point coordinates: degrees times this.
_PRECISION = 10_000_000
#: What libosmium's XML parser reads as a coordinate (no sign but "-", no blanks, no "e+").
_COORDINATE = re.compile(r"^-?(\d+\.?\d*|\.\d+)([eE]-?\d+)?$")
_NODE_TAG = re.compile(rb"<node\b[^>]*>")
_ATTRIBUTE = re.compile(rb"""\b(id|lat|lon)\s*=\s*(?:"([^"]*)"|'([^']*)')""")


def _coordinate_problem(attribute: str, text: str) -> str | None:
    """Why an XML ``lat``/``lon`` text is not a coordinate, or ``None`` if it is one."""
    limit = 90.0 if attribute == "lat" else 180.0
    if not _COORDINATE.match(text):
        return "not a decimal number"
    value = float(text)
    if not math.isfinite(value) or abs(value) > limit:
        return f"outside -{limit:g}..{limit:g} degrees"
    return None


def _xml_lines(path: Path, fmt: str) -> IO[bytes]:
    if fmt == "osm.bz2":
        return bz2.open(path, "rb")
    if fmt == "osm.gz":
        return gzip.open(path, "rb")  # type: ignore[return-value]  # a GzipFile is an IO[bytes]
    return path.open("rb")


def _node_elements(path: Path, fmt: str) -> Iterator[tuple[int, dict[str, str]]]:
    """``(line number, {id, lat, lon})`` of every ``<node>`` of an OSM XML file, in order."""
    with _xml_lines(path, fmt) as handle:
        pending, first_line = b"", 0
        for number, line in enumerate(handle, start=1):
            if pending:
                line, number = pending + line, first_line
            start = line.rfind(b"<node")
            if start >= 0 and line.find(b">", start) < 0:  # the element goes on
                pending, first_line = line, number
                continue
            pending = b""
            for tag in _NODE_TAG.finditer(line):
                found = {
                    m.group(1).decode(): (m.group(2) or m.group(3) or b"").decode(errors="replace")
                    for m in _ATTRIBUTE.finditer(tag.group(0))
                }
                yield number, found


def _bad_coordinate(path: Path, fmt: str, node_ids: set[int] | None = None) -> str | None:
    """
    Describe the first node whose ``lat``/``lon`` text is not a coordinate.

    Only the nodes of ``node_ids`` are read when given (and the scan stops once all were
    seen), else every node of the file. ``None`` when every text is a coordinate.
    """
    left = set(node_ids) if node_ids is not None else None
    for number, node in _node_elements(path, fmt):
        try:
            node_id = int(node.get("id", ""))
        except ValueError:
            continue
        if left is not None:
            if node_id not in left:
                continue
            left.discard(node_id)
        for attribute in ("lat", "lon"):
            text = node.get(attribute, "")
            problem = _coordinate_problem(attribute, text)
            if problem:
                return f'node {node_id} (line {number}) has {attribute}="{text}": {problem}'
        if left is not None and not left:
            break
    return None


def _corrupt(path: Path, detail: str) -> InvalidNetworkSourceError:
    reason = f"{detail}; fix the node or export the extract again"
    return InvalidNetworkSourceError(str(path), reason)


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
    fmt = _format_of(path)
    on_zero: set[int] = set()  # nodes of roads at exactly 0 degrees, to check in the text
    try:
        processor = osmium.FileProcessor(osmium.io.File(str(path), fmt)).with_locations()
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
                xy: npt.NDArray[np.int64] = np.fromiter(
                    ((loc.x, loc.y) for loc in (nd.location for nd in nodes)),
                    dtype=np.dtype((np.int64, 2)),
                    count=len(nodes),
                )
                x, y = xy[:, 0], xy[:, 1]
                valid = (x != _UNDEFINED) & (y != _UNDEFINED)
                outside = valid & ((np.abs(x) > 180 * _PRECISION) | (np.abs(y) > 90 * _PRECISION))
                if outside.any():
                    i = int(np.argmax(outside))
                    detail = (
                        f"node {ids[i]} of way {obj.id} is at lat {y[i] / _PRECISION:g}, "
                        f"lon {x[i] / _PRECISION:g}: outside -90..90 / -180..180 degrees"
                    )
                    raise _corrupt(path, detail)
                if fmt != "pbf":
                    on_zero.update(ids[valid & ((x == 0) | (y == 0))].tolist())
                lon = np.where(valid, x / _PRECISION, np.nan)
                lat = np.where(valid, y / _PRECISION, np.nan)
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
                found, why = _restrictions(obj)
                restrictions.extend(found)
                if why:
                    skipped[why] += 1
    except osmium.InvalidLocationError as exc:  # libosmium's XML parser, on a lat/lon text
        where = _bad_coordinate(path, fmt) if fmt != "pbf" else None
        raise _corrupt(path, where or f"a node's coordinate is unreadable ({exc})") from exc
    except RuntimeError as exc:
        raise InvalidNetworkSourceError(str(path), str(exc)) from exc
    if on_zero:
        read_as_zero = _bad_coordinate(path, fmt, on_zero)
        if read_as_zero:
            raise _corrupt(path, f"{read_as_zero} (libosmium read it as 0)")
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
