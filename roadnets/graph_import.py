"""
``roadnets.from_graph``: a networkx / osmnx graph to a :class:`~roadnets.RoadNetwork`.

The graph goes through the same path as an OSM file (:func:`roadnets.compile.compile_network`
with the drivable rules of :mod:`roadnets.drivable`): every edge of the graph becomes a "way"
of its own, from ``u`` through its ``geometry`` to ``v``, so the compiled network has the
graph's nodes and edges, projected as a loaded file is (:mod:`roadnets.projection`).

How a graph is read
-------------------
- **Nodes** need ``x`` and ``y`` in the graph's CRS (``G.graph["crs"]``, default WGS84; a
  projected graph from ``ox.project_graph`` is converted back). Integer node ids are kept as
  the OSM node ids of the output (``u``/``v``); other ids are numbered ``0 .. N-1`` in the
  graph's node order.
- **Direction**: every directed edge can be driven from ``u`` to ``v``, as osmnx builds them
  (its ``oneway`` and ``reversed`` attributes are already applied). An edge ``u -> v`` and an
  edge ``v -> u`` with the same geometry reversed and the same ``highway`` are the two
  directions of one two-way road (twins, so U-turns are understood). An undirected graph's
  edges are two-way.
- **Tags** (osmnx keeps them on the edges; lists from simplified edges are read as their
  first value, ``maxspeed`` lists as the highest): ``highway``, ``maxspeed``, ``name``,
  ``ref``, ``access``, ``service``, ``area``, ``motor_vehicle``, ``motorcar``. Edges the
  drivable rules refuse (footways, parking aisles, private roads ...) are left out, and so
  are edges without ``highway`` in a graph where other edges have one (railways and other
  non-road ways ``ox.graph_from_xml`` keeps). In a graph without any ``highway`` tag (a plain
  networkx graph) every edge is a ``highway=road`` at 40 km/h, unless it has ``maxspeed`` or
  osmnx's ``speed_kph``.
- An edge osmnx simplified from several ways (``osmid`` is a list) carries their tags merged,
  without saying which way an ``access`` or ``service`` value came from; such an edge is kept
  when its road class is drivable (its ``access``, ``service``, ``motor_vehicle`` and
  ``motorcar`` are not used), so a private stub merged into a public street does not remove
  the street.
- **Geometry**: ``geometry`` (a shapely LineString, from ``u`` to ``v``), else the straight
  line between the nodes. **Way id**: ``osmid`` (the first of a list), else ``-1 - i`` for the
  ``i``-th edge. Edge keys are renumbered ``0, 1 ...`` per node pair.
- A graph holds no turn restrictions (OSM relations are not in osmnx graphs).
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import fields
from typing import TYPE_CHECKING, Any

import networkx as nx
import numpy as np
from pyproj import CRS, Transformer

from roadnets.compile import choose_projector, compile_network
from roadnets.drivable import ROAD_CLASSES, is_drivable, parse_maxspeed_kph
from roadnets.errors import InvalidNetworkSourceError, NoDrivableRoadsError
from roadnets.network import RoadNetwork
from roadnets.osm_reader import OsmExtract, OsmWay

if TYPE_CHECKING:
    from collections.abc import Hashable, Mapping

    import numpy.typing as npt

    from roadnets.arrays import NetworkArrays

    FloatArray = npt.NDArray[np.float64]

__all__ = ["from_graph"]

#: Tags read from a graph's edges (the rest are ignored).
GRAPH_TAGS = (
    "highway",
    "maxspeed",
    "name",
    "ref",
    "access",
    "service",
    "area",
    "motor_vehicle",
    "motorcar",
)
_DEFAULT_HIGHWAY = "road"
_MERGED_UNKNOWN = ("access", "service", "motor_vehicle", "motorcar")
_ROUND_DEG = 7  # geometry compared at 1e-7 degrees (1 cm) to pair the two directions


def from_graph(
    G: object, *, network_id: str | None = None, source: str | None = None
) -> RoadNetwork:
    """
    Compile a networkx / osmnx graph into a routable, R-tree indexed road network.

    Parameters
    ----------
    G
        A ``networkx.MultiDiGraph`` (as osmnx returns from ``graph_from_xml``,
        ``graph_from_place`` ...), ``DiGraph``, or an undirected graph. See the module
        docstring for what is read from it.
    network_id
        Id of the network in results; default ``G.graph["name"]`` or ``"graph"``.
    source
        What to name as the network's source; default ``"<graph NAME>"``.

    Returns
    -------
    RoadNetwork
        Not cached on disk (``from_cache`` False); its ``source_sha256`` is a digest of the
        compiled arrays, so the same graph gives the same digest.

    Raises
    ------
    TypeError
        ``G`` is not a networkx graph.
    InvalidNetworkSourceError
        A node has no usable ``x``/``y``, or the graph's CRS is unknown.
    NoDrivableRoadsError
        No edge of the graph is a drivable road.

    Examples
    --------
    >>> import networkx as nx
    >>> G = nx.MultiDiGraph(crs="EPSG:4326")
    >>> G.add_node(1, x=7.4200, y=43.7300)
    >>> G.add_node(2, x=7.4210, y=43.7300)
    >>> _ = G.add_edge(1, 2, highway="residential")
    >>> _ = G.add_edge(2, 1, highway="residential")
    >>> net = from_graph(G, network_id="two")
    >>> net.arrays.n_edges, net.arrays.edge_twin.tolist(), net.info().oneway_share
    (2, [1, 0], 0.0)
    """
    started = time.perf_counter()
    if not isinstance(G, nx.Graph):
        msg = (
            f"from_graph needs a networkx graph (an osmnx MultiDiGraph ...), not "
            f"{type(G).__name__}; for an OSM file use roadnets.load(path)"
        )
        raise TypeError(msg)
    name = network_id or str(G.graph.get("name") or "graph")
    where = source or f"<graph {name}>"
    node_ids, lon_of, lat_of = _nodes(G, where)
    to_wgs84 = _to_wgs84(G, where)
    ways = _ways(G, node_ids, lon_of, lat_of, to_wgs84)
    if not ways:
        raise NoDrivableRoadsError(where)
    extract = OsmExtract(ways, [], 0)
    projector = choose_projector(extract, where)
    arrays = compile_network(extract, projector)
    return RoadNetwork(
        network_id=name,
        source=where,
        source_sha256=_digest(arrays),
        arrays=arrays,
        projector=projector,
        clipped_ways=0,
        from_cache=False,
        load_s=time.perf_counter() - started,
    )


def _to_wgs84(G: nx.Graph[Any], where: str) -> Transformer | None:
    """The transformer from the graph's CRS to WGS84, or ``None`` when it is WGS84 already."""
    given = G.graph.get("crs")
    if given is None:
        return None
    try:
        crs = CRS.from_user_input(given)
    except Exception as exc:  # pyproj raises its own CRSError (and TypeError for odd input)
        reason = f"its crs {given!r} is not a coordinate reference system pyproj knows ({exc})"
        raise InvalidNetworkSourceError(where, reason) from exc
    if crs.equals(CRS.from_epsg(4326)) or (crs.is_geographic and crs.to_epsg() == 4326):
        return None
    return Transformer.from_crs(crs, 4326, always_xy=True)


def _nodes(
    G: nx.Graph[Any], where: str
) -> tuple[dict[Hashable, int], dict[Hashable, float], dict[Hashable, float]]:
    """Integer id, x and y of every node (x/y still in the graph's CRS)."""
    integer = all(isinstance(n, int | np.integer) and not isinstance(n, bool) for n in G.nodes)
    ids: dict[Hashable, int] = {}
    xs: dict[Hashable, float] = {}
    ys: dict[Hashable, float] = {}
    for i, (node, data) in enumerate(G.nodes(data=True)):
        try:
            x, y = float(data["x"]), float(data["y"])
        except (KeyError, TypeError, ValueError):
            x = y = float("nan")
        if not (np.isfinite(x) and np.isfinite(y)):
            reason = (
                f"node {node!r} has no usable x/y ({data.get('x')!r}, {data.get('y')!r}); "
                "every node needs x (longitude) and y (latitude) in the graph's crs"
            )
            raise InvalidNetworkSourceError(where, reason)
        ids[node] = int(node) if integer else i
        xs[node], ys[node] = x, y
    return ids, xs, ys


def _first(value: object) -> object:
    if isinstance(value, list | tuple | set):
        items = sorted(value, key=str) if isinstance(value, set) else list(value)
        return items[0] if items else None
    return value


def _tags(data: Mapping[str, Any], *, tagged: bool) -> dict[str, str] | None:
    """The edge's OSM tags as the drivable rules read them, or None if not a road."""
    tags: dict[str, str] = {}
    for key in GRAPH_TAGS:
        value = data.get(key)
        if value is None:
            continue
        if key == "highway" and isinstance(value, list | tuple):
            known = [v for v in value if v in ROAD_CLASSES]
            value = min(known, key=ROAD_CLASSES.index) if known else _first(value)
        elif key == "maxspeed" and isinstance(value, list | tuple):
            value = ";".join(str(v) for v in value)
        else:
            value = _first(value)
        if value is not None and str(value).strip():
            tags[key] = str(value)
    if "highway" not in tags:
        if tagged:
            return None
        tags["highway"] = _DEFAULT_HIGHWAY
    if isinstance(data.get("osmid"), list | tuple) and len(data["osmid"]) > 1:
        for key in _MERGED_UNKNOWN:
            tags.pop(key, None)
    speed = data.get("speed_kph")
    if "maxspeed" not in tags and speed is not None and parse_maxspeed_kph(str(speed)):
        tags["maxspeed"] = str(speed)
    return tags


def _line(
    data: Mapping[str, Any],
    ends: tuple[tuple[float, float], tuple[float, float]],
    to_wgs84: Transformer | None,
) -> tuple[FloatArray, FloatArray]:
    """The edge's lon/lat vertices from u to v, its ends exactly at the nodes (WGS84)."""
    (ux, uy), (vx, vy) = ends
    geom = data.get("geometry")
    coords = None
    if geom is not None and hasattr(geom, "coords"):
        coords = np.asarray(geom.coords, dtype=np.float64)[:, :2]
    if coords is None or len(coords) < 2:
        coords = np.array([[ux, uy], [vx, vy]], dtype=np.float64)
    elif np.hypot(*(coords[0] - (vx, vy))) < np.hypot(*(coords[0] - (ux, uy))):
        coords = coords[::-1]  # stored from v to u
    coords = coords.copy()
    coords[0], coords[-1] = (ux, uy), (vx, vy)
    x, y = coords[:, 0], coords[:, 1]
    if to_wgs84 is not None:
        x, y = to_wgs84.transform(x, y)
    return np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)


def _ways(
    G: nx.Graph[Any],
    node_ids: dict[Hashable, int],
    xs: dict[Hashable, float],
    ys: dict[Hashable, float],
    to_wgs84: Transformer | None,
) -> list[OsmWay]:
    """One way per drivable edge; a pair of opposite edges with one geometry is one way."""
    ways: list[OsmWay] = []
    pending: dict[tuple[object, ...], int] = {}  # reversed shape -> way waiting for its twin
    synthetic = -1  # ids of inner vertices: negative, so never shared with a node
    tagged = any("highway" in data for _, _, data in G.edges(data=True))
    for i, (u, v, data) in enumerate(G.edges(data=True)):
        tags = _tags(data, tagged=tagged)
        if tags is None or not is_drivable(tags):
            continue
        lon, lat = _line(data, ((xs[u], ys[u]), (xs[v], ys[v])), to_wgs84)
        if u == v and len(lon) == 2:
            continue  # a self-loop without geometry has no length
        highway = tags["highway"]
        twin = pending.pop(_shape(node_ids[u], node_ids[v], highway, lon, lat), None)
        if twin is not None:
            w = ways[twin]
            ways[twin] = OsmWay(w.way_id, w.node_ids, w.lon, w.lat, dict(w.tags, oneway="no"))
            continue
        osmid = _first(data.get("osmid"))
        try:
            way_id = int(osmid)  # type: ignore[call-overload]
        except (TypeError, ValueError):
            way_id = -1 - i
        inner = np.arange(synthetic, synthetic - (len(lon) - 2), -1, dtype=np.int64)
        synthetic -= len(lon) - 2
        ids = np.concatenate(([node_ids[u]], inner, [node_ids[v]])).astype(np.int64)
        two_way = not G.is_directed()
        tags["oneway"] = "no" if two_way else "yes"
        ways.append(OsmWay(way_id, ids, lon, lat, tags))
        if not two_way:
            back = _shape(node_ids[v], node_ids[u], highway, lon[::-1], lat[::-1])
            pending[back] = len(ways) - 1
    return ways


def _shape(u: int, v: int, highway: str, lon: FloatArray, lat: FloatArray) -> tuple[object, ...]:
    """What two opposite edges of one road share: ends, class and vertices (to 1 cm)."""
    rounded = np.round(np.concatenate((lon, lat)), _ROUND_DEG).tolist()
    return (u, v, highway, *rounded)


def _digest(arrays: NetworkArrays) -> str:
    """SHA-256 of the compiled arrays: the same graph always gives the same digest."""
    h = hashlib.sha256(b"roadnets.from_graph\n")
    for f in fields(arrays):
        value = getattr(arrays, f.name)
        if isinstance(value, np.ndarray):
            h.update(f.name.encode())
            h.update(np.ascontiguousarray(value).tobytes())
    return h.hexdigest()
