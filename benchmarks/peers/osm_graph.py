"""Offline drivable osmnx graph from a local OSM extract, shared by peers and interim traces.

osmnx only reads OSM XML (plain or .bz2), and ``graph_from_xml`` refuses extracts whose ways are
clipped at the border ("Some edges missing nodes"). This module reads any extract that pyosmium
reads (``.osm.pbf``, ``.osm``, ``.osm.bz2``, ``.osm.gz``), keeps the drivable ways, trims each way
to its longest run of nodes present in the file, writes a plain XML file into a cache folder and
loads it with ``osmnx.graph_from_xml``. It runs in the project venv and in the ``.peers/py311``
venv (both have osmnx and osmium); it imports nothing of the project.

The drivable filter follows the project's design (motorway .. residential, unclassified,
living_street, service and ``*_link``; no private/no access, no ``area=yes``), so that the peers
built on osmnx see the same roads as our matcher and Valhalla.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import TYPE_CHECKING
from xml.sax.saxutils import quoteattr

if TYPE_CHECKING:
    import networkx as nx

DRIVABLE_HIGHWAYS = frozenset(
    {
        "motorway",
        "trunk",
        "primary",
        "secondary",
        "tertiary",
        "unclassified",
        "residential",
        "living_street",
        "service",
        "road",
        "motorway_link",
        "trunk_link",
        "primary_link",
        "secondary_link",
        "tertiary_link",
    }
)
_NO_ACCESS = frozenset({"no", "private"})
_YES_ACCESS = frozenset({"yes", "designated", "permissive", "destination"})

CACHE_DIR = Path(__file__).resolve().parents[2] / ".peers" / "cache"


def is_drivable(tags: dict[str, str]) -> bool:
    """Return whether a way with these OSM tags is a drivable road."""
    if tags.get("highway") not in DRIVABLE_HIGHWAYS or tags.get("area") == "yes":
        return False
    car = tags.get("motorcar", tags.get("motor_vehicle"))
    if car == "no":
        return False
    return not (tags.get("access") in _NO_ACCESS and car not in _YES_ACCESS)


def _longest_present_run(refs: list[int], present: set[int] | dict[int, object]) -> list[int]:
    best: list[int] = []
    run: list[int] = []
    for ref in refs:
        if ref in present:
            run.append(ref)
            if len(run) > len(best):
                best = run
        else:
            run = []
    return list(best)


def drive_xml(extract: str | os.PathLike[str], cache_dir: Path = CACHE_DIR) -> Path:
    """Write (once) the drivable, border-trimmed part of an extract as plain OSM XML.

    Parameters
    ----------
    extract
        Any OSM file pyosmium reads.
    cache_dir
        Folder for the XML; the name carries a hash of the extract's path, size and mtime.

    Returns
    -------
    Path
        The XML file, ready for ``osmnx.graph_from_xml``.
    """
    import osmium

    src = Path(extract).resolve()
    st = src.stat()
    key = hashlib.sha1(f"{src}:{st.st_size}:{st.st_mtime_ns}:v1".encode()).hexdigest()[:12]
    stem = src.name.split(".")[0]
    out = cache_dir / f"{stem}-{key}.drive.osm"
    if out.exists():
        return out
    nodes: dict[int, tuple[float, float]] = {}
    ways: list[tuple[int, list[int], dict[str, str]]] = []
    for obj in osmium.FileProcessor(str(src), osmium.osm.NODE | osmium.osm.WAY):
        if obj.is_node():
            if obj.location.valid():
                nodes[obj.id] = (obj.location.lon, obj.location.lat)
        elif obj.is_way():
            tags = {t.k: t.v for t in obj.tags}
            if is_drivable(tags):
                ways.append((obj.id, [n.ref for n in obj.nodes], tags))
    cache_dir.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(f".tmp{os.getpid()}")
    used: set[int] = set()
    kept: list[tuple[int, list[int], dict[str, str]]] = []
    for way_id, refs, tags in ways:
        run = _longest_present_run(refs, nodes)
        if len(run) >= 2:
            kept.append((way_id, run, tags))
            used.update(run)
    with tmp.open("w", encoding="utf-8") as f:
        f.write("<?xml version='1.0' encoding='UTF-8'?>\n<osm version=\"0.6\">\n")
        for node_id in sorted(used):
            lon, lat = nodes[node_id]
            f.write(f'<node id="{node_id}" lat="{lat:.7f}" lon="{lon:.7f}"/>\n')
        for way_id, run, tags in kept:
            f.write(f'<way id="{way_id}">\n')
            f.writelines(f'<nd ref="{ref}"/>\n' for ref in run)
            f.writelines(f"<tag k={quoteattr(k)} v={quoteattr(v)}/>\n" for k, v in tags.items())
            f.write("</way>\n")
        f.write("</osm>\n")
    tmp.replace(out)
    return out


def load_drive_graph(
    extract: str | os.PathLike[str], *, simplify: bool = True, cache_dir: Path = CACHE_DIR
) -> nx.MultiDiGraph:
    """Load the drivable road graph of a local extract with osmnx, fully offline.

    Parameters
    ----------
    extract
        Any OSM file pyosmium reads.
    simplify
        Merge chains of degree-2 nodes into single edges with a ``geometry`` (osmnx default).
    cache_dir
        Where the intermediate XML is kept.

    Returns
    -------
    networkx.MultiDiGraph
        osmnx graph in EPSG:4326, largest weakly connected component, one-way rules applied.
    """
    import osmnx as ox

    ox.settings.log_console = False
    ox.settings.use_cache = False
    return ox.graph_from_xml(drive_xml(extract, cache_dir), simplify=simplify, retain_all=False)
