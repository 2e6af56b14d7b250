"""Pickled networks (issue 16): small, re-opened from the cache, the same answers; a short repr."""

from __future__ import annotations

import dataclasses
import multiprocessing
import pickle
import shutil
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pytest

import roadnets
from roadnets.network import RoadNetwork

DATA = Path(__file__).resolve().parents[1] / "data"


def _points(net: roadnets.RoadNetwork, n: int = 300) -> tuple[np.ndarray, np.ndarray]:
    a = net.arrays
    rng = np.random.default_rng(11)
    return (
        rng.uniform(a.geom_x.min(), a.geom_x.max(), n),
        rng.uniform(a.geom_y.min(), a.geom_y.max(), n),
    )


def _same_answers(one: roadnets.RoadNetwork, other: roadnets.RoadNetwork) -> None:
    x, y = _points(one)
    n = one.arrays.n_edges
    src, dst = np.arange(n) % 60, (np.arange(n) * 7 + 3) % n
    for mine, theirs in (
        (one.nearby_edges(x, y, 50.0), other.nearby_edges(x, y, 50.0)),
        (one.edge_routes(src, dst, 3000.0), other.edge_routes(src, dst, 3000.0)),
    ):
        for f in dataclasses.fields(mine):
            value = getattr(mine, f.name)
            if isinstance(value, np.ndarray):
                assert np.array_equal(value, getattr(theirs, f.name)), f.name
    paths = one.shortest_paths(np.arange(20), 2000.0), other.shortest_paths(np.arange(20), 2000.0)
    assert np.array_equal(paths[0].keys, paths[1].keys)
    assert np.array_equal(paths[0].distance_m, paths[1].distance_m)
    mine_info, their_info = one.info(), other.info()
    assert mine_info == dataclasses.replace(
        their_info, load_s=mine_info.load_s, from_cache=mine_info.from_cache
    )
    assert one.way_names == other.way_names


@pytest.fixture
def cached(tmp_path: Path) -> roadnets.RoadNetwork:
    source = tmp_path / "oakland.osm.bz2"
    shutil.copyfile(DATA / "west-oakland_us.osm.bz2", source)
    return roadnets.load(source, cache_dir=tmp_path / "cache")


def test_a_cached_network_pickles_small_and_reopens_its_entry(
    default_net: roadnets.RoadNetwork,
) -> None:
    default_net.rtree  # noqa: B018 - an R-tree and a turn graph built: not in the pickle
    default_net.turns  # noqa: B018
    blob = pickle.dumps(default_net)
    assert len(blob) < 1000  # bytes: id, source, digest, cache entry path
    again = pickle.loads(blob)
    assert again is not default_net
    assert again.cache_entry == default_net.cache_entry
    assert again.from_cache
    assert "rtree" not in vars(again)  # rebuilt on first use, with its own lock
    assert again._rtree_lock is not default_net._rtree_lock
    assert isinstance(again.arrays.geom_x.base, np.memmap)  # mapped, not a copy
    _same_answers(default_net, again)
    assert repr(again) == repr(default_net)


def test_a_network_pickles_into_a_fresh_process(default_net: roadnets.RoadNetwork) -> None:
    # a process pool as joblib / dask use it, started the way notebooks on macOS / Windows are
    x, y = _points(default_net, 50)
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(1, mp_context=context) as pool:
        info = pool.submit(RoadNetwork.info, default_net).result(timeout=120)
        hits = pool.submit(RoadNetwork.nearby_edges, default_net, x, y, 50.0).result(timeout=60)
    assert dataclasses.replace(info, load_s=0.0, from_cache=True) == dataclasses.replace(
        default_net.info(), load_s=0.0, from_cache=True
    )
    mine = default_net.nearby_edges(x, y, 50.0)
    assert np.array_equal(hits.edge, mine.edge)
    assert np.array_equal(hits.offset_m, mine.offset_m)


def test_a_lost_cache_entry_is_compiled_again_from_the_source(
    cached: roadnets.RoadNetwork,
) -> None:
    blob = pickle.dumps(cached)
    assert cached.cache_entry is not None
    shutil.rmtree(cached.cache_entry)
    again = pickle.loads(blob)
    assert not again.from_cache  # compiled here
    assert Path(cached.cache_entry, "meta.json").exists()  # and cached again
    _same_answers(cached, again)


def test_a_pickle_whose_source_changed_or_vanished_is_a_clear_error(
    cached: roadnets.RoadNetwork, tmp_path: Path
) -> None:
    blob = pickle.dumps(cached)
    assert cached.cache_entry is not None
    shutil.rmtree(cached.cache_entry)
    source = Path(cached.source)
    source.write_bytes(source.read_bytes() + b"\n")
    with pytest.raises(roadnets.NetworkReopenError, match="changed since") as caught:
        pickle.loads(blob)
    assert isinstance(caught.value, roadnets.RoadNetworkError)
    assert "use_cache=False to pickle its arrays" in str(caught.value)
    source.unlink()
    with pytest.raises(roadnets.NetworkReopenError, match="not in this process's reach"):
        pickle.loads(blob)


def test_an_uncached_network_pickles_its_arrays(data_dir: Path) -> None:
    net = roadnets.load(data_dir / "west-oakland_us.osm.bz2", use_cache=False)
    assert net.cache_entry is None
    blob = pickle.dumps(net)
    size = sum(getattr(net.arrays, f.name).nbytes for f in dataclasses.fields(net.arrays))
    assert size < len(blob) < size + 20_000
    again = pickle.loads(blob)
    _same_answers(net, again)
    assert not again.arrays.edge_length_m.flags.writeable  # as every network's arrays


def test_a_graph_network_pickles_too(data_dir: Path) -> None:
    ox = pytest.importorskip("osmnx")
    G = ox.graph_from_xml(data_dir / "west-oakland_us.osm.bz2", retain_all=True)
    net = roadnets.from_graph(G, network_id="oak")
    again = pickle.loads(pickle.dumps(net))
    assert again.network_id == "oak"
    _same_answers(net, again)


def test_precomputed_tables_travel_with_the_pickle(cached: roadnets.RoadNetwork) -> None:
    cached.precompute_paths(500.0)
    cached.precompute_routes(300.0)
    again = pickle.loads(pickle.dumps(cached))
    assert again.precomputed is not None
    assert again.precomputed_routes is not None
    assert again.precomputed_bound_m == 500.0
    assert np.array_equal(again.precomputed.keys, cached.precomputed.keys)  # type: ignore[union-attr]
    _same_answers(cached, again)


def test_repr_is_one_short_line(default_net: roadnets.RoadNetwork) -> None:
    text = repr(default_net)
    assert text == str(default_net)
    assert len(text) < 250
    assert "\n" not in text
    assert "array(" not in text
    assert text.startswith("<RoadNetwork 'monaco_2020' from 'monaco_2020.osm.pbf': ")
    assert "857 nodes, 1,453 edges" in text
    assert "crs tmerc(7.422118, 43.738232)" in text
    lon0, lat0, lon1, lat1 = default_net.bbox
    assert f"bbox ({lon0:.5f}, {lat0:.5f}, {lon1:.5f}, {lat1:.5f})" in text
    assert text.endswith(", cached>")
