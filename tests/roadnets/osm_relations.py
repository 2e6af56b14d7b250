"""Hand-made OSM XML with turn restriction relations, for tests that load through roadnets.load.

Ways are given as in ``tests.mapmatch.toy.write_osm`` (way id, [(x, y) metres], tags), in the
same local frame (metres east/north of ``toy.LON0, toy.LAT0``), so a matcher test can drive the
same network with ``toy.drive``. Restrictions name their ways by id and their via as a point
``(x, y)`` (a node) or a list of way ids.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from tests.mapmatch import toy

if TYPE_CHECKING:
    from collections.abc import Sequence
    from pathlib import Path

Point = tuple[float, float]


@dataclass(frozen=True)
class Restriction:
    """``type=restriction`` with one from way, a via node (a point) or via ways, one to way."""

    kind: str  # no_left_turn, only_straight_on, no_u_turn, ...
    from_way: int
    via: Point | list[int]
    to_way: int
    tags: tuple[tuple[str, str], ...] = ()


def write_osm(
    path: Path,
    ways: list[tuple[int, list[Point], dict[str, str]]],
    restrictions: Sequence[Restriction] = (),
) -> dict[Point, int]:
    """Write ways (``toy.write_osm``) and restriction relations; return each point's node id."""
    toy.write_osm(path, ways)
    node_ids: dict[Point, int] = {}
    for _, points, _ in ways:  # toy numbers the points from 1 in order of first appearance
        for point in points:
            node_ids.setdefault(point, len(node_ids) + 1)
    relation_xml = []
    for i, r in enumerate(restrictions):
        members = [f'<member type="way" ref="{r.from_way}" role="from"/>']
        if isinstance(r.via, tuple):
            members.append(f'<member type="node" ref="{node_ids[r.via]}" role="via"/>')
        else:
            members += [f'<member type="way" ref="{w}" role="via"/>' for w in r.via]
        members.append(f'<member type="way" ref="{r.to_way}" role="to"/>')
        tags = {"type": "restriction", "restriction": r.kind, **dict(r.tags)}
        tag_xml = "".join(f'<tag k="{k}" v="{v}"/>' for k, v in tags.items())
        relation_xml.append(f'<relation id="{i + 1}">{"".join(members)}{tag_xml}</relation>')
    text = path.read_text(encoding="utf-8")
    path.write_text(text.replace("</osm>", "".join(relation_xml) + "</osm>"), encoding="utf-8")
    return node_ids
