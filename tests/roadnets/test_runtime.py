"""Lean loaded networks, frozen heaps, warm kernels and lazy imports (issue 15)."""

from __future__ import annotations

import gc
import importlib.util
import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

import roadnets
from roadnets.names import edge_records, encode_names
from roadnets.route_store import THREAD_NAME

ROOT = Path(__file__).resolve().parents[2]


def _grid_city(path: Path, size: int) -> Path:
    """The grid city of ``benchmarks/bench_match.py`` (size x size junctions 100 m apart)."""
    spec = importlib.util.spec_from_file_location(
        "benchmarks_bench_match", ROOT / "benchmarks" / "bench_match.py"
    )
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    written: Path = module.grid_city(path, size)
    return written


def _tracked() -> int:
    for thread in threading.enumerate():  # other tests' networks building their route tables
        if thread.name == THREAD_NAME:
            thread.join()
    gc.collect()
    return len(gc.get_objects())


def _use(net: roadnets.RoadNetwork) -> None:
    """What a matcher does with a network: R-tree, turn graph, routes, names, summary."""
    a = net.arrays
    net.nearby_edges(a.node_x[:200], a.node_y[:200], 50.0)
    net.edge_routes(np.arange(100), np.arange(100, 200), 1500.0)
    net.shortest_paths(np.arange(50), 800.0)
    net.way_names.names_of(a.edge_way_id[:100])
    net.info()
    repr(net)


def test_a_200k_edge_network_adds_only_a_few_dozen_tracked_objects(tmp_path: Path) -> None:
    # a full collection walks every tracked object: a loaded network must not add a graph of
    # Python objects (the pause itself is measured in benchmarks/bench_network.py)
    source = _grid_city(tmp_path / "grid.osm", 230)
    roadnets.warm_kernels()
    _use(roadnets.load(cache_dir=tmp_path / "warm"))  # first-use caches of the libraries
    for expect_cached in (False, True):
        # the count is the whole process's: a thread another test left winding down adds to
        # it, so a count over the limit is taken once more (a network's own objects come back)
        added: list[tuple[int, int]] = []
        for attempt in range(2):
            before = _tracked()
            folder = "cache" if expect_cached or not attempt else "cache-again"
            net = roadnets.load(source, cache_dir=tmp_path / folder)
            assert net.from_cache is expect_cached
            assert net.arrays.n_edges > 200_000
            loaded = _tracked()
            _use(net)
            used = _tracked()
            added.append((loaded - before, used - before))
            assert "graph" not in vars(net)  # the networkx view: built only when read
            assert not gc.is_tracked(net.arrays.edge_u)
            del net
            if added[-1][0] < 200 and added[-1][1] < 400:
                break
        least_loaded, least_used = min(a for a, _ in added), min(u for _, u in added)
        assert least_loaded < 200, f"loading added {added} (loaded, used) tracked objects"
        assert least_used < 400, f"loading and using added {added} (loaded, used) tracked objects"


def test_way_names_are_arrays_read_like_a_dict(oakland_net: roadnets.RoadNetwork) -> None:
    names = oakland_net.way_names
    assert isinstance(names, roadnets.WayNames)
    assert {"8th Street", "Campbell Street"} <= set(names.values())
    a = oakland_net.arrays
    way = int(a.name_way_id[0])
    assert names[way] == names.get(way, "") == names.names_of(np.array([way]))[0]
    assert names.get(-5, "") == ""
    edges_names = names.names_of(a.edge_way_id)
    assert edges_names == [names.get(int(w), "") for w in a.edge_way_id]
    # a relabel (as a test does with monkeypatch.setitem) stays in this process's overlay
    names[way] = "<b>x</b>"
    assert names[way] == "<b>x</b>" == names.names_of(np.array([way]))[0]
    del names[way]
    assert way not in names
    with pytest.raises(KeyError):
        del names[way]
    vars(oakland_net).pop("way_names")  # the next read is fresh again
    assert oakland_net.way_names[way] != "<b>x</b>"


def test_many_way_names_are_read_at_once_whatever_their_text() -> None:
    # more than a few names are gathered and decoded in one piece; multi-byte text, empty
    # names, unknown ways and (never in OSM, but the arrays allow it) a NUL inside a name
    # all come back as one by one
    table = {1: "Calle Álvaro Obregón", 2: "", 3: "東京通り", 4: "A\x00B", 9: "Rue Grimaldi"}
    names = roadnets.WayNames(*encode_names(table))
    ways = np.array([3, 1, 7, 1, 2, 9, 3, 3, 1, 9, 2, 7, 1, 3, 9, 9, 1, 2, 3, 1])
    assert names.names_of(ways) == [table.get(int(w), "") for w in ways]
    with_nul = np.concatenate([ways, [4, 4, 9]])
    assert names.names_of(with_nul) == [table.get(int(w), "") for w in with_nul]


def test_every_array_is_read_only_compiled_or_cached(data_dir: Path, cache_dir: Path) -> None:
    # so that numba compiles each kernel once, not once per writable / read-only variant
    source = data_dir / "west-oakland_us.osm.bz2"
    for net in (roadnets.load(source, use_cache=False), roadnets.load(source, cache_dir=cache_dir)):
        for name in net.arrays.__slots__:
            assert not getattr(net.arrays, name).flags.writeable, name


def test_freeze_after_load_leaves_later_collections_nothing_old_to_walk(
    default_net: roadnets.RoadNetwork,
) -> None:
    try:
        frozen = roadnets.freeze_after_load()
        assert frozen > 10_000
        # objects freed since (frames, temporaries) leave the permanent generation
        assert 0.99 * frozen <= gc.get_freeze_count() <= frozen
        assert len(gc.get_objects()) < 1000  # what a full collection still walks
        assert default_net.nearby_edges(np.zeros(1), np.zeros(1), 50.0) is not None
    finally:
        gc.unfreeze()


_CHILD = """
import json, sys
import numpy as np
import roadnets
from roadnets.runtime import _dispatchers

warm = roadnets.warm_kernels()
signatures = [len(d.signatures) for d in _dispatchers()]
for net in (roadnets.load(sys.argv[1], cache_dir=sys.argv[2]),
            roadnets.load(sys.argv[1], use_cache=False)):
    a = net.arrays
    edges = np.arange(a.n_edges)
    net.shortest_paths(a.edge_u[:5], 500.0)
    found = net.edge_routes(edges[:20], edges[-20:], 1000.0)
    found.table.lookup(edges[:3], edges[:3])
    net.route_table(edges[:4], 300.0).lookup(edges[:4], edges[4:8])
    net.precompute_routes(200.0)
    net.edge_routes(edges[:20], edges[-20:], 150.0)
    net.edge_routes(edges[:5], edges[5:10], 100.0, edge_cost=a.edge_length_m / a.edge_speed_mps)
print(json.dumps({
    "compiled": warm.compiled, "loaded": warm.loaded, "before": signatures,
    "after": [len(d.signatures) for d in _dispatchers()],
    "modules": sorted(m for m in ("networkx", "shapely", "osmnx") if m in sys.modules),
}))
"""


def test_warm_kernels_compiles_every_signature_a_network_uses(
    data_dir: Path, tmp_path: Path
) -> None:
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, str(data_dir / "west-oakland_us.osm.bz2"), str(tmp_path)],
        capture_output=True,
        text=True,
        check=True,
        cwd=ROOT,
        timeout=300,
    )
    report = json.loads(out.stdout.strip().splitlines()[-1])
    assert report["compiled"] + report["loaded"] >= 5
    assert all(n >= 1 for n in report["before"])
    assert report["after"] == report["before"]  # nothing compiled after the warm-up
    assert report["modules"] == []  # routing needs neither networkx nor shapely


def test_import_and_cached_load_skip_the_heavy_modules(cache_dir: Path) -> None:
    roadnets.load(cache_dir=cache_dir)  # cached for the child
    code = (
        "import sys, roadnets\n"
        "heavy = ('numba', 'networkx', 'shapely', 'osmnx', 'osmium', 'pyproj', 'rtree', 'pandas')\n"
        "at_import = [m for m in heavy if m in sys.modules]\n"
        f"net = roadnets.load(cache_dir={str(cache_dir)!r})\n"
        "assert net.from_cache\n"
        "at_load = [m for m in heavy if m in sys.modules]\n"
        "net.nearby_edges(*net.project([7.42], [43.73]), 50.0)\n"
        "at_query = [m for m in heavy if m in sys.modules]\n"
        "print(at_import, at_load, at_query)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env
    )
    # the query runs the packed R-tree's compiled probe (its tie order comes from rtree's) and
    # the compiled projection (roadnets.tmerc: no pyproj)
    assert out.stdout.strip() == "[] [] ['numba', 'rtree']"


def test_network_build_on_a_cached_network_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from mapmatch.cli import main

    args = ["network", "build", "--cache-dir", str(tmp_path)]
    assert main(args) == 0
    first = capsys.readouterr().out
    assert "(parsed, compiled, indexed)" in first
    assert "kernels      " in first
    assert "matcher      kernels ready in " in first  # the matcher's kernels warmed too
    assert "route table  built and stored in the cache entry: " in first
    assert main(args) == 0
    again = capsys.readouterr().out
    assert "route table  read from the cache entry: " in again
    build = next(line for line in again.splitlines() if line.startswith("build"))
    assert build.startswith("build        already cached in ")
    assert "parsed" not in again
    assert main([*args, "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["from_cache"] is True
    assert payload["build_s"] is None
    assert payload["kernels"]["compiled"] == 0  # compiled once, by the first build
    assert payload["cache_entry"].startswith(str(tmp_path))
    assert payload["route_table"]["bytes"] > 0
    with pytest.raises(SystemExit):
        main([*args, "--route-table-mb", "-1"])
    assert "--route-table-mb: must be a number of MB >= 0 (got '-1')" in capsys.readouterr().err


def test_edge_records_are_the_arrays_gathered_one_by_one(oakland_net: roadnets.RoadNetwork) -> None:
    # one compiled pass gives what a dozen numpy gathers and the names' own gather give
    a = oakland_net.arrays
    names = oakland_net.way_names
    edge = np.array([5, 0, a.n_edges - 1, 5, 17])
    u, v, key, way, length, speed, road_class, name = edge_records(a, names, edge)
    assert u.tolist() == a.node_osm_id[a.edge_u[edge]].tolist()
    assert v.tolist() == a.node_osm_id[a.edge_v[edge]].tolist()
    assert key.tolist() == a.edge_key[edge].tolist()
    assert way.tolist() == a.edge_way_id[edge].tolist()
    assert length.tobytes() == a.edge_length_m[edge].astype(np.float64).tobytes()
    kph = np.asarray(a.edge_speed_mps[edge], dtype=np.float64) * 3.6
    assert speed.tobytes() == kph.tobytes()
    assert road_class.tolist() == a.edge_class[edge].tolist()
    assert name == names.names_of(a.edge_way_id[edge])
    assert edge_records(a, names, np.zeros(0, dtype=np.int64))[-1] == []
    way = int(a.edge_way_id[5])
    names[way] = "<b>x</b>"  # an edited mapping is read through its edits
    try:
        assert edge_records(a, names, edge)[-1][0] == "<b>x</b>"
    finally:
        del names[way]
    with pytest.raises(IndexError):
        edge_records(a, names, np.array([a.n_edges]))
