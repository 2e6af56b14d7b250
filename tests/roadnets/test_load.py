from __future__ import annotations

import bz2
import logging
from pathlib import Path

import numpy as np
import osmium
import pytest

import roadnets
from roadnets.cache import FORMAT_VERSION

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data" / "osm"


def _way_nodes(path: Path, way_id: int) -> list[int]:
    for obj in osmium.FileProcessor(str(path), osmium.osm.WAY):
        if obj.id == way_id:
            return [n.ref for n in obj.nodes]
    msg = f"way {way_id} not in {path}"
    raise AssertionError(msg)


def _edges_of_way(net: roadnets.RoadNetwork, way_id: int) -> list[tuple[int, int]]:
    a = net.arrays
    index = np.flatnonzero(a.edge_way_id == way_id)
    return [(int(a.node_osm_id[a.edge_u[e]]), int(a.node_osm_id[a.edge_v[e]])) for e in index]


def test_embedded_default_network_loads(default_net: roadnets.RoadNetwork) -> None:
    info = default_net.info()
    assert info.network_id == "monaco_2020"
    # a transverse Mercator centred on the roads (roadnets.projection)
    assert info.crs.startswith("+proj=tmerc +lat_0=43.7382")
    assert "+lon_0=7.4221" in info.crs
    assert (info.nodes, info.edges) == (857, 1453)
    assert 60 < info.road_km < 70
    lon0, lat0, lon1, lat1 = info.bbox
    assert 7.40 < lon0 < lon1 < 7.45
    assert 43.72 < lat0 < lat1 < 43.76


def test_oneway_way_is_only_drivable_in_node_order(default_net: roadnets.RoadNetwork) -> None:
    # Boulevard Albert 1er (way 4226740): primary, oneway=yes, maxspeed=50
    nodes = _way_nodes(roadnets.default_network_path(), 4226740)
    edges = _edges_of_way(default_net, 4226740)
    assert edges
    for u, v in edges:
        assert nodes.index(u) < nodes.index(v)
    a = default_net.arrays
    index = np.flatnonzero(a.edge_way_id == 4226740)
    assert np.allclose(a.edge_speed_mps[index], 50 / 3.6)
    assert (a.edge_twin[index] == -1).all()
    assert a.edge_oneway[index].all()


def test_two_way_way_has_both_directions(default_net: roadnets.RoadNetwork) -> None:
    # Avenue Princesse Alice (way 4097656): primary, no oneway tag, maxspeed=30
    edges = _edges_of_way(default_net, 4097656)
    assert len(edges) % 2 == 0
    assert {(v, u) for u, v in edges} == set(edges)
    a = default_net.arrays
    index = np.flatnonzero(a.edge_way_id == 4097656)
    assert (a.edge_twin[index] >= 0).all()
    assert (a.edge_way_id[a.edge_twin[index]] == 4097656).all()
    assert np.allclose(a.edge_length_m[index], a.edge_length_m[a.edge_twin[index]])
    assert np.allclose(a.edge_speed_mps[index], 30 / 3.6)


def test_roundabout_is_one_way_and_untagged_speed_uses_class_default(
    default_net: roadnets.RoadNetwork,
) -> None:
    nodes = _way_nodes(roadnets.default_network_path(), 92627441)  # primary roundabout
    edges = _edges_of_way(default_net, 92627441)
    assert edges
    for u, v in edges:
        assert nodes.index(u) < nodes.index(v) or u == v
    a = default_net.arrays
    index = np.flatnonzero(a.edge_way_id == 92627441)
    assert (a.edge_twin[index] == -1).all()
    assert np.allclose(a.edge_speed_mps[index], 60 / 3.6)


def test_pedestrian_ways_are_not_in_the_graph(default_net: roadnets.RoadNetwork) -> None:
    assert not _edges_of_way(default_net, 4227155)  # Place du Palais, highway=pedestrian
    assert not _edges_of_way(default_net, 4230116)  # a footway


def test_geometry_and_lengths_are_consistent(default_net: roadnets.RoadNetwork) -> None:
    a = default_net.arrays
    start = a.edge_geom_ptr[:-1]
    end = a.edge_geom_ptr[1:] - 1
    assert np.allclose(a.geom_x[start], a.node_x[a.edge_u])
    assert np.allclose(a.geom_y[end], a.node_y[a.edge_v])
    assert np.allclose(a.geom_cum_m[end], a.edge_length_m)
    assert (a.edge_length_m > 0).all()
    # CSR adjacency lists exactly the edges leaving each node
    for node in range(0, a.n_nodes, 37):
        leaving = set(a.out_edge[a.out_ptr[node] : a.out_ptr[node + 1]].tolist())
        assert leaving == set(np.flatnonzero(a.edge_u == node).tolist())


def test_turn_restrictions_are_compiled(default_net: roadnets.RoadNetwork) -> None:
    a = default_net.arrays
    assert len(a.banned_in) > 0
    # a banned move goes from an edge into the node where the other starts
    assert (a.edge_v[a.banned_in] == a.edge_u[a.banned_out]).all()


def test_networkx_view_follows_osmnx_conventions(oakland_net: roadnets.RoadNetwork) -> None:
    G = oakland_net.graph
    a = oakland_net.arrays
    assert G.number_of_nodes() == a.n_nodes
    assert G.number_of_edges() == a.n_edges
    u, v, key = oakland_net.edge_osm_ids(np.arange(a.n_edges))
    data = G.edges[int(u[0]), int(v[0]), int(key[0])]
    assert data["osmid"] == int(a.edge_way_id[0])
    assert data["length"] == pytest.approx(float(a.edge_length_m[0]))
    assert G.graph["crs"] == oakland_net.crs


def test_xml_and_pbf_of_the_same_data_give_the_same_graph(tmp_path: Path, data_dir: Path) -> None:
    xml = tmp_path / "oakland.osm"
    xml.write_bytes(bz2.decompress((data_dir / "west-oakland_us.osm.bz2").read_bytes()))
    pbf = tmp_path / "oakland.osm.pbf"
    with osmium.SimpleWriter(str(pbf)) as writer:
        for obj in osmium.FileProcessor(str(xml)):
            writer.add(obj)
    from_xml = roadnets.load(xml, use_cache=False).arrays
    from_pbf = roadnets.load(pbf, use_cache=False).arrays
    from_bz2 = roadnets.load(data_dir / "west-oakland_us.osm.bz2", use_cache=False).arrays
    for other in (from_pbf, from_bz2):
        assert np.array_equal(from_xml.node_osm_id, other.node_osm_id)
        assert np.array_equal(from_xml.edge_u, other.edge_u)
        assert np.array_equal(from_xml.edge_v, other.edge_v)
        assert np.allclose(from_xml.edge_length_m, other.edge_length_m)


def test_clipped_ways_keep_their_present_nodes(melbourne_net: roadnets.RoadNetwork) -> None:
    info = melbourne_net.info()
    assert info.clipped_ways == 64
    assert info.edges > 900


@pytest.mark.skipif(not SHARED.exists(), reason="the development data set is not beside the repo")
@pytest.mark.parametrize(
    "name", sorted(p.name for p in SHARED.glob("*.osm*")) if SHARED.exists() else []
)
def test_every_shared_extract_loads(name: str, cache_dir: Path) -> None:
    net = roadnets.load(SHARED / name, cache_dir=cache_dir)
    assert net.arrays.n_edges > 10


# --- bad input -------------------------------------------------------------------------------


def test_missing_file_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(roadnets.NetworkSourceNotFoundError, match="does not exist"):
        roadnets.load(tmp_path / "nowhere.osm.pbf")


def test_a_folder_is_not_a_network(tmp_path: Path) -> None:
    with pytest.raises(roadnets.InvalidNetworkSourceError, match="folder"):
        roadnets.load(tmp_path)


def test_a_file_that_is_not_osm_is_rejected(tmp_path: Path) -> None:
    bogus = tmp_path / "notes.osm.pbf"
    bogus.write_text("these are not the roads you are looking for\n")
    with pytest.raises(roadnets.InvalidNetworkSourceError, match="not OSM"):
        roadnets.load(bogus, use_cache=False)


def test_a_truncated_pbf_is_rejected(tmp_path: Path) -> None:
    whole = roadnets.default_network_path().read_bytes()
    cut = tmp_path / "cut.osm.pbf"
    cut.write_bytes(whole[: len(whole) // 3])
    with pytest.raises(roadnets.InvalidNetworkSourceError, match="PBF error"):
        roadnets.load(cut, use_cache=False)


def test_broken_xml_is_rejected(tmp_path: Path) -> None:
    broken = tmp_path / "broken.osm"
    broken.write_text('<?xml version="1.0"?><osm version="0.6"><node id="1" lat="1" lon=')
    with pytest.raises(roadnets.InvalidNetworkSourceError):
        roadnets.load(broken, use_cache=False)


def test_an_extract_without_drivable_roads_is_rejected(tmp_path: Path) -> None:
    paths_only = tmp_path / "park.osm"
    paths_only.write_text(
        '<?xml version="1.0"?><osm version="0.6">'
        '<node id="1" lat="43.73" lon="7.42"/><node id="2" lat="43.731" lon="7.421"/>'
        '<way id="10"><nd ref="1"/><nd ref="2"/><tag k="highway" v="footway"/></way></osm>'
    )
    with pytest.raises(roadnets.NoDrivableRoadsError, match="no drivable roads"):
        roadnets.load(paths_only, use_cache=False)


def test_an_unusable_cache_folder_is_a_clear_error(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with pytest.raises(roadnets.CacheError, match="cannot be used"):
        roadnets.load(cache_dir=blocker / "cache")


# --- cache -----------------------------------------------------------------------------------


def test_second_load_reads_the_cache(tmp_path: Path) -> None:
    first = roadnets.load(cache_dir=tmp_path)
    second = roadnets.load(cache_dir=tmp_path)
    assert not first.from_cache
    assert second.from_cache
    assert isinstance(second.arrays.edge_length_m.base, np.memmap)
    assert not second.arrays.edge_length_m.flags.writeable
    assert np.array_equal(first.arrays.edge_u, second.arrays.edge_u)
    entries = list(tmp_path.glob(f"*-v{FORMAT_VERSION}"))
    assert len(entries) == 1


def test_a_corrupt_cache_entry_is_rebuilt(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    roadnets.load(cache_dir=tmp_path)
    (entry,) = tmp_path.glob(f"*-v{FORMAT_VERSION}")
    target = entry / "arrays.bin"
    raw = bytearray(target.read_bytes())
    raw[-8:] = b"\xff" * 8
    target.write_bytes(bytes(raw))
    with caplog.at_level(logging.WARNING, logger="roadnets"):
        again = roadnets.load(cache_dir=tmp_path)
    assert not again.from_cache
    assert "corrupt" in caplog.text
    assert roadnets.load(cache_dir=tmp_path).from_cache


def test_a_truncated_cache_file_is_rebuilt(tmp_path: Path) -> None:
    roadnets.load(cache_dir=tmp_path)
    (entry,) = tmp_path.glob(f"*-v{FORMAT_VERSION}")
    target = entry / "arrays.bin"
    target.write_bytes(target.read_bytes()[:1000])
    assert not roadnets.load(cache_dir=tmp_path).from_cache


def test_a_missing_cache_file_is_rebuilt(tmp_path: Path) -> None:
    roadnets.load(cache_dir=tmp_path)
    (entry,) = tmp_path.glob(f"*-v{FORMAT_VERSION}")
    (entry / "arrays.bin").unlink()
    assert not roadnets.load(cache_dir=tmp_path).from_cache


def test_a_changed_source_misses_the_cache(tmp_path: Path, data_dir: Path) -> None:
    copy = tmp_path / "oakland.osm.bz2"
    copy.write_bytes((data_dir / "west-oakland_us.osm.bz2").read_bytes())
    cache = tmp_path / "cache"
    assert not roadnets.load(copy, cache_dir=cache).from_cache
    assert roadnets.load(copy, cache_dir=cache).from_cache
    other = tmp_path / "other.osm.bz2"
    other.write_bytes((data_dir / "aguascalientes_mx.osm.bz2").read_bytes())
    copy.write_bytes(other.read_bytes())
    net = roadnets.load(copy, cache_dir=cache)
    assert not net.from_cache
    assert net.arrays.n_edges > 1000
