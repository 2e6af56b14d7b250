"""roadnets.from_graph: osmnx / networkx graphs through the same compile path as OSM files."""

from __future__ import annotations

from typing import TYPE_CHECKING

import networkx as nx
import numpy as np
import pytest

import roadnets
from roadnets.errors import InvalidNetworkSourceError, NoDrivableRoadsError

if TYPE_CHECKING:
    from pathlib import Path

ox = pytest.importorskip("osmnx")


@pytest.fixture(scope="module")
def oakland_graph(data_dir: Path) -> nx.MultiDiGraph:
    return ox.graph_from_xml(data_dir / "west-oakland_us.osm.bz2", retain_all=True)


@pytest.fixture(scope="module")
def oakland_from_graph(oakland_graph: nx.MultiDiGraph) -> roadnets.RoadNetwork:
    return roadnets.from_graph(oakland_graph, network_id="oakland-graph")


def _drivable_edges(G: nx.MultiDiGraph) -> list[tuple[int, int, dict]]:
    keep = {"secondary", "unclassified", "residential", "service"}
    out = []
    for u, v, d in G.edges(data=True):
        hw = d.get("highway")
        classes = set(hw) if isinstance(hw, list) else {hw}
        if classes & keep and d.get("service") not in ("driveway", "parking_aisle"):
            out.append((u, v, d))
    return out


def test_every_drivable_edge_of_the_osmnx_graph_is_one_directed_edge(
    oakland_graph: nx.MultiDiGraph, oakland_from_graph: roadnets.RoadNetwork
) -> None:
    a = oakland_from_graph.arrays
    expected = _drivable_edges(oakland_graph)
    assert a.n_edges == len(expected)
    u, v, _ = oakland_from_graph.edge_osm_ids(np.arange(a.n_edges))
    assert sorted(zip(u.tolist(), v.tolist(), strict=True)) == sorted(
        (x, y) for x, y, _ in expected
    )
    # lengths along the geometry agree with osmnx's own edge lengths
    by_pair = {(x, y): d["length"] for x, y, d in expected}
    for e in range(a.n_edges):
        assert a.edge_length_m[e] == pytest.approx(by_pair[(int(u[e]), int(v[e]))], rel=0.005)


def test_two_way_roads_are_twins_and_one_way_roads_are_not(
    oakland_graph: nx.MultiDiGraph, oakland_from_graph: roadnets.RoadNetwork
) -> None:
    a = oakland_from_graph.arrays
    u, v, _ = oakland_from_graph.edge_osm_ids(np.arange(a.n_edges))
    oneway = {(x, y): bool(d["oneway"]) for x, y, d in _drivable_edges(oakland_graph)}
    for e in range(a.n_edges):
        assert bool(a.edge_oneway[e]) == oneway[(int(u[e]), int(v[e]))]
        if a.edge_twin[e] >= 0:
            t = a.edge_twin[e]
            assert (int(u[t]), int(v[t])) == (int(v[e]), int(u[e]))
            assert a.edge_twin[t] == e
    assert (a.edge_twin >= 0).sum() == sum(not o for o in oneway.values())


def test_the_graph_gives_the_roads_of_the_file(
    data_dir: Path, oakland_from_graph: roadnets.RoadNetwork, cache_dir: Path
) -> None:
    ref = roadnets.load(data_dir / "west-oakland_us.osm.bz2", cache_dir=cache_dir)
    mine, theirs = oakland_from_graph.info(), ref.info()
    for crs in (mine.crs, theirs.crs):  # centred on the roads each holds (the same blocks)
        assert crs.startswith("+proj=tmerc +lat_0=37.81")
        assert "+lon_0=-122.29" in crs
    for cls in ("secondary", "residential", "service"):
        assert mine.road_km_by_class[cls] == pytest.approx(theirs.road_km_by_class[cls], abs=0.01)
    names = set(oakland_from_graph.way_names.values())
    assert {"8th Street", "9th Street", "Campbell Street", "7th Street", "Wood Street"} <= names
    assert oakland_from_graph.source == "<graph oakland-graph>"
    assert not oakland_from_graph.from_cache
    assert oakland_from_graph.info().turn_restrictions == 0


def test_the_digest_is_stable_for_one_graph(oakland_graph: nx.MultiDiGraph) -> None:
    first = roadnets.from_graph(oakland_graph)
    again = roadnets.from_graph(oakland_graph.copy())
    assert first.source_sha256 == again.source_sha256
    assert first.network_id == "graph"  # graph_from_xml names no graph


def test_a_projected_graph_gives_the_same_network(oakland_graph: nx.MultiDiGraph) -> None:
    projected = ox.project_graph(oakland_graph)
    node = next(iter(projected.nodes.values()))
    assert node["x"] > 500_000  # metres east in UTM 10N, not degrees
    net = roadnets.from_graph(projected)
    ref = roadnets.from_graph(oakland_graph)

    def by_id(n: roadnets.RoadNetwork) -> tuple[np.ndarray, np.ndarray]:
        a = n.arrays
        u, v, _ = n.edge_osm_ids(np.arange(a.n_edges))
        order = np.lexsort((a.edge_length_m, v, u))
        nodes = np.argsort(a.node_osm_id)
        return np.column_stack((a.node_x, a.node_y))[nodes], a.edge_length_m[order]

    (nodes, lengths), (ref_nodes, ref_lengths) = by_id(net), by_id(ref)
    np.testing.assert_allclose(nodes, ref_nodes, atol=1e-3)
    np.testing.assert_allclose(lengths, ref_lengths, atol=1e-3)


def _toy(**edge: object) -> nx.MultiDiGraph:
    G = nx.MultiDiGraph(crs="EPSG:4326", name="toy")
    G.add_node(1, x=7.4200, y=43.7300)
    G.add_node(2, x=7.4210, y=43.7300)
    G.add_node(3, x=7.4210, y=43.7310)
    G.add_edge(1, 2, **edge)
    G.add_edge(2, 1, **edge)
    G.add_edge(2, 3, **edge)
    return G


def test_a_graph_without_tags_uses_the_documented_defaults() -> None:
    net = roadnets.from_graph(_toy())
    a = net.arrays
    assert net.network_id == "toy"
    assert a.n_edges == 3
    assert {roadnets.ROAD_CLASSES[c] for c in a.edge_class} == {"road"}
    np.testing.assert_allclose(a.edge_speed_mps, 40 / 3.6)
    assert a.edge_oneway.tolist() == [False, False, True]
    assert a.edge_way_id.tolist() == [-1, -1, -3]  # -1 - (edge position), twins share a way
    # 0.001 deg of longitude at 43.73 N: 111195 m * cos(43.73 deg) / 1000 = 80.4 m
    assert a.edge_length_m[0] == pytest.approx(80.4, abs=0.2)


def test_speed_kph_from_osmnx_fills_a_missing_maxspeed() -> None:
    net = roadnets.from_graph(_toy(highway="primary", speed_kph=72.0))
    np.testing.assert_allclose(net.arrays.edge_speed_mps, 20.0)


def test_non_drivable_edges_are_left_out_and_none_left_is_an_error() -> None:
    G = _toy(highway="footway")
    G.add_edge(1, 3, highway="residential")
    net = roadnets.from_graph(G)
    assert net.arrays.n_edges == 1
    with pytest.raises(NoDrivableRoadsError, match="'<graph toy>' has no drivable roads"):
        roadnets.from_graph(_toy(highway="footway"))


def test_bad_graphs_are_refused_with_a_reason() -> None:
    with pytest.raises(TypeError, match=r"from_graph needs a networkx graph .* not dict"):
        roadnets.from_graph({"nodes": []})
    G = _toy()
    del G.nodes[3]["x"]
    with pytest.raises(InvalidNetworkSourceError, match="node 3 has no usable x/y"):
        roadnets.from_graph(G)
