"""Tests of the peer benchmark's FMM edge file writer (``benchmarks/peers/fmm_network.py``).

The writer needs only the project venv; the last tests also run FMM itself and are skipped when
it has not been built (``bash benchmarks/peers/setup.sh`` builds it into ``.bench/fmm``).
"""

from __future__ import annotations

import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
import pyproj
import pytest

import roadnets
from tests.benchmarks.scripts import load_script

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"
FMM_BUILD = ROOT / ".bench" / "fmm" / "src" / "build"

fmm_network = load_script("peers/fmm_network.py")


@pytest.fixture(scope="module")
def net() -> roadnets.RoadNetwork:
    return roadnets.load(DATA / "aguascalientes_mx.osm.bz2")


#: Our lengths are geodesic, FMM's planar in the network's centred projection: they agree to
#: its scale error (under 1e-6 on these extracts, at most 0.1 % anywhere; roadnets.projection).
PLANAR_RTOL = 1e-6


def _lengths(fe: object) -> np.ndarray:
    x, y, ptr = fe.x, fe.y, fe.ptr  # type: ignore[attr-defined]
    seg = np.hypot(np.diff(x), np.diff(y))
    cum = np.concatenate(([0.0], np.cumsum(seg)))
    # segments that cross from one edge to the next are not part of either
    return np.asarray(cum[ptr[1:] - 1] - cum[ptr[:-1]])


def test_segments_cover_every_edge_with_its_own_length(net: roadnets.RoadNetwork) -> None:
    fe = fmm_network.fmm_edges(net, "segments")
    a = net.arrays
    assert len(fe) == len(a.geom_x) - a.n_edges  # one FMM edge per geometry segment
    assert np.all(np.diff(fe.ptr) == 2)
    per_edge = np.bincount(fe.our_edge, weights=_lengths(fe), minlength=a.n_edges)
    np.testing.assert_allclose(per_edge, a.edge_length_m, rtol=PLANAR_RTOL, atol=1e-6)
    assert np.all(_lengths(fe) > 0)
    assert list(fe.id) == list(range(1, len(fe) + 1))


def test_every_node_id_has_one_position_and_graph_nodes_keep_theirs(
    net: roadnets.RoadNetwork,
) -> None:
    fe = fmm_network.fmm_edges(net, "segments")
    where: dict[int, set[tuple[float, float]]] = defaultdict(set)
    starts, ends = fe.ptr[:-1], fe.ptr[1:] - 1
    for s, t, i, j in zip(fe.source, fe.target, starts, ends, strict=True):
        where[int(s)].add((round(float(fe.x[i]), 6), round(float(fe.y[i]), 6)))
        where[int(t)].add((round(float(fe.x[j]), 6), round(float(fe.y[j]), 6)))
    assert all(len(p) == 1 for p in where.values())
    a = net.arrays
    for node in {n for n in where if n < a.n_nodes}:
        (x, y) = next(iter(where[node]))
        assert (x, y) == (round(float(a.node_x[node]), 6), round(float(a.node_y[node]), 6))


def test_twins_run_the_same_nodes_backwards(net: roadnets.RoadNetwork) -> None:
    fe = fmm_network.fmm_edges(net, "segments")
    a = net.arrays
    by_edge: dict[int, list[tuple[int, int]]] = defaultdict(list)
    for e, s, t in zip(fe.our_edge, fe.source, fe.target, strict=True):
        by_edge[int(e)].append((int(s), int(t)))
    pairs = [(e, int(a.edge_twin[e])) for e in range(a.n_edges) if a.edge_twin[e] > e]
    assert pairs, "the extract has two-way roads"
    for e, twin in pairs:
        assert by_edge[twin] == [(t, s) for s, t in reversed(by_edge[e])]
    # an interior node belongs to one road: one edge, or one edge and its twin
    owners: dict[int, set[int]] = defaultdict(set)
    for e, s, t in zip(fe.our_edge, fe.source, fe.target, strict=True):
        for node in (int(s), int(t)):
            if node >= a.n_nodes:
                owners[node].add(
                    min(int(e), int(a.edge_twin[e])) if a.edge_twin[e] >= 0 else int(e)
                )
    assert owners
    assert all(len(o) == 1 for o in owners.values())


def test_edges_layout_is_one_fmm_edge_per_edge(net: roadnets.RoadNetwork) -> None:
    fe = fmm_network.fmm_edges(net, "edges")
    a = net.arrays
    assert len(fe) == a.n_edges
    assert list(fe.our_edge) == list(range(a.n_edges))
    np.testing.assert_array_equal(fe.source, a.edge_u)
    np.testing.assert_array_equal(fe.target, a.edge_v)
    np.testing.assert_allclose(_lengths(fe), a.edge_length_m, rtol=PLANAR_RTOL, atol=1e-6)


def test_unknown_layout_is_refused(net: roadnets.RoadNetwork) -> None:
    with pytest.raises(ValueError, match="unknown FMM edge layout 'simplified'"):
        fmm_network.fmm_edges(net, "simplified")


@pytest.mark.parametrize(
    ("cum", "kept"),
    [
        ([0.0, 3.0, 7.0], [0, 1, 2]),
        ([0.0, 0.0, 5.0, 5.0, 10.0], [0, 2, 4]),
        ([0.0, 5.0, 5.0], [0, 2]),  # the end replaces its interior duplicate
        ([0.0, 0.0], [0]),  # zero length: nothing to write
    ],
)
def test_duplicate_vertices_merge(cum: list[float], kept: list[int]) -> None:
    assert fmm_network._kept_vertices(np.asarray(cum)).tolist() == kept


def test_edge_file_reads_back_with_gdal(net: roadnets.RoadNetwork, tmp_path: Path) -> None:
    pyogrio = pytest.importorskip("pyogrio")
    shp = tmp_path / "edges.shp"
    info = fmm_network.write_edge_file(net, shp)
    assert info.edges == len(net.arrays.geom_x) - net.arrays.n_edges
    assert {p.suffix for p in tmp_path.iterdir()} >= {".shp", ".shx", ".dbf", ".prj"}
    meta = pyogrio.read_info(shp)
    assert meta["geometry_type"] == "LineString"
    assert meta["features"] == info.edges
    assert pyproj.CRS(meta["crs"]) == pyproj.CRS(net.crs)
    df = pyogrio.read_dataframe(shp)
    fe = fmm_network.fmm_edges(net)
    np.testing.assert_array_equal(df["id"].to_numpy(), fe.id)
    np.testing.assert_array_equal(df["source"].to_numpy(), fe.source)
    np.testing.assert_array_equal(df["target"].to_numpy(), fe.target)
    np.testing.assert_array_equal(df["our_edge"].to_numpy(), fe.our_edge)
    np.testing.assert_allclose(df.geometry.length.to_numpy(), _lengths(fe), rtol=1e-9)


def _fmm() -> object:
    if not (FMM_BUILD / "python" / "_fmm.so").exists() or not (FMM_BUILD / "ubodt_gen").exists():
        pytest.skip("FMM is not built here (bash benchmarks/peers/setup.sh builds it)")
    sys.path.insert(0, str(FMM_BUILD / "python"))
    try:
        import fmm  # type: ignore[import-not-found]
    finally:
        sys.path.remove(str(FMM_BUILD / "python"))
    return fmm


def test_fmm_reads_the_file_and_matches_a_road_onto_it(
    net: roadnets.RoadNetwork, tmp_path: Path
) -> None:
    fmm = _fmm()
    shp = tmp_path / "edges.shp"
    info = fmm_network.write_edge_file(net, shp)
    network = fmm.Network(str(shp), "id", "source", "target")  # type: ignore[attr-defined]
    assert network.get_edge_count() == info.edges
    assert network.get_node_count() == info.nodes
    ubodt_path = tmp_path / "ubodt.bin"
    fmm_network.build_ubodt(shp, ubodt_path, 1000.0)
    graph = fmm.NetworkGraph(network)  # type: ignore[attr-defined]
    ubodt = fmm.UBODT.read_ubodt_binary(str(ubodt_path))  # type: ignore[attr-defined]
    model = fmm.FastMapMatch(network, graph, ubodt)  # type: ignore[attr-defined]
    # the longest one-way-or-not edge, sampled along its own geometry every 10 m
    a = net.arrays
    e = int(np.argmax(a.edge_length_m))
    offsets = np.arange(1.0, float(a.edge_length_m[e]) - 1.0, 10.0)
    x, y = net.point_on_edge(np.full(len(offsets), e), offsets)
    wkt = "LINESTRING(" + ",".join(f"{px:.3f} {py:.3f}" for px, py in zip(x, y, strict=True)) + ")"
    result = model.match_wkt(wkt, fmm.FastMapMatchConfig(8, 50.0, 5.0, 0.5))  # type: ignore[attr-defined]
    fe = fmm_network.fmm_edges(net)
    our = dict(zip(fe.id.tolist(), fe.our_edge.tolist(), strict=True))
    assert len(result.cpath) > 0
    assert {our[int(i)] for i in result.cpath} == {e}
