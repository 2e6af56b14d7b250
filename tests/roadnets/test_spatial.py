from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from roadnets.projection import Projector
from roadnets.spatial import PACKED_FANOUT, query_edges, query_packed, rtree_rank

if TYPE_CHECKING:
    import roadnets


def _brute_force(
    net: roadnets.RoadNetwork, x: float, y: float, radius: float
) -> dict[int, tuple[float, float]]:
    """Every directed edge within radius: (distance, offset), scanning every segment."""
    a = net.arrays
    out: dict[int, tuple[float, float]] = {}
    for e in range(a.n_edges):
        lo, hi = a.edge_geom_ptr[e], a.edge_geom_ptr[e + 1]
        gx, gy, cum = a.geom_x[lo:hi], a.geom_y[lo:hi], a.geom_cum_m[lo:hi]
        best = (np.inf, 0.0)
        for i in range(len(gx) - 1):
            dx, dy = gx[i + 1] - gx[i], gy[i + 1] - gy[i]
            seg2 = dx * dx + dy * dy
            t = 0.0 if seg2 == 0 else min(max(((x - gx[i]) * dx + (y - gy[i]) * dy) / seg2, 0), 1)
            d = float(np.hypot(x - gx[i] - t * dx, y - gy[i] - t * dy))
            if d < best[0]:
                best = (d, float(cum[i] + t * np.sqrt(seg2)))
        if best[0] <= radius:
            out[e] = best
    return out


def _query(
    net: roadnets.RoadNetwork, index: str, x: np.ndarray, y: np.ndarray, radius: float, **kw: int
) -> roadnets.EdgeHits:
    """The nearby-edge query through one of the two indexes."""
    r = np.full(len(x), radius)
    if index == "rtree":
        return query_edges(net.rtree, net.arrays, x, y, r, **kw)
    return query_packed(net.segment_tree, net.arrays, x, y, r, **kw)


@pytest.mark.parametrize("index", ["rtree", "packed"])
@settings(max_examples=60)
@given(
    fx=st.floats(min_value=0.0, max_value=1.0),
    fy=st.floats(min_value=0.0, max_value=1.0),
    radius=st.floats(min_value=1.0, max_value=120.0),
)
def test_rtree_query_agrees_with_a_brute_force_scan(
    oakland_net: roadnets.RoadNetwork, index: str, fx: float, fy: float, radius: float
) -> None:
    a = oakland_net.arrays
    x = a.geom_x.min() - 50 + fx * (np.ptp(a.geom_x) + 100)
    y = a.geom_y.min() - 50 + fy * (np.ptp(a.geom_y) + 100)
    hits = _query(oakland_net, index, np.array([x]), np.array([y]), radius)
    expected = _brute_force(oakland_net, x, y, radius)
    found: dict[int, tuple[float, float]] = {}
    for e, d, o in zip(hits.edge, hits.distance_m, hits.offset_m, strict=True):
        if int(e) not in found or d < found[int(e)][0]:
            found[int(e)] = (float(d), float(o))
    # a point exactly on the radius may fall either way by rounding
    assert set(found) ^ set(expected) <= {
        e for e, (d, _) in expected.items() if abs(d - radius) < 1e-6
    }
    for e in set(found) & set(expected):
        assert abs(found[e][0] - expected[e][0]) < 1e-6
    assert list(hits.distance_m) == sorted(hits.distance_m)


def test_a_hairpin_road_is_a_candidate_at_both_passes(default_net: roadnets.RoadNetwork) -> None:
    # edge 960 of the Monaco extract is a hairpin: it passes the same spot twice,
    # near offset 85 m and again near offset 223 m
    x, y = default_net.point_on_edge(np.array([960]), np.array([85.0]))
    hits = default_net.nearby_edges(x, y, 30.0)
    offsets = sorted(hits.offset_m[hits.edge == 960].tolist())
    assert len(offsets) == 2
    assert abs(offsets[0] - 85.0) < 1e-6
    assert offsets[1] > 85.0 + 20.0


def test_projection_lies_on_the_edge_and_bearing_follows_it(
    default_net: roadnets.RoadNetwork,
) -> None:
    a = default_net.arrays
    rng = np.random.default_rng(7)
    x = rng.uniform(a.geom_x.min(), a.geom_x.max(), 500)
    y = rng.uniform(a.geom_y.min(), a.geom_y.max(), 500)
    hits = default_net.nearby_edges(x, y, 60.0, max_per_point=6)
    px, py = default_net.point_on_edge(hits.edge, hits.offset_m)
    assert np.allclose(px, hits.x, atol=1e-6)
    assert np.allclose(py, hits.y, atol=1e-6)
    assert np.allclose(np.hypot(x[hits.point] - hits.x, y[hits.point] - hits.y), hits.distance_m)
    assert np.bincount(hits.point, minlength=500).max() <= 6
    # the bearing points from the projection towards the edge's next vertex
    ahead_x, ahead_y = default_net.point_on_edge(hits.edge, hits.offset_m + 0.5)
    moved = np.hypot(ahead_x - hits.x, ahead_y - hits.y) > 0.2
    bearing = np.degrees(np.arctan2(ahead_x - hits.x, ahead_y - hits.y)) % 360
    diff = np.abs((bearing - hits.bearing_deg + 180) % 360 - 180)
    assert np.median(diff[moved]) < 1.0


def test_both_directions_of_a_two_way_road_are_candidates(
    default_net: roadnets.RoadNetwork,
) -> None:
    a = default_net.arrays
    e = int(np.flatnonzero(a.edge_twin >= 0)[0])
    mx, my = default_net.point_on_edge(np.array([e]), np.array([a.edge_length_m[e] / 2]))
    hits = default_net.nearby_edges(mx, my, 5.0)
    found = set(hits.edge.tolist())
    assert {e, int(a.edge_twin[e])} <= found
    twin_row = int(np.flatnonzero(hits.edge == a.edge_twin[e])[0])
    row = int(np.flatnonzero(hits.edge == e)[0])
    assert hits.offset_m[row] + hits.offset_m[twin_row] == pytest.approx(a.edge_length_m[e])
    assert abs(((hits.bearing_deg[row] - hits.bearing_deg[twin_row]) % 360) - 180) < 1e-6


def test_path_polyline_joins_edge_stretches(default_net: roadnets.RoadNetwork) -> None:
    a = default_net.arrays
    e1 = int(np.flatnonzero(np.diff(a.edge_geom_ptr) > 3)[0])
    nxt = a.out_edge[a.out_ptr[a.edge_v[e1]] : a.out_ptr[a.edge_v[e1] + 1]]
    e2 = int(nxt[nxt != a.edge_twin[e1]][0])
    start, end = 1.0, float(a.edge_length_m[e2]) / 2
    x, y = default_net.path_polyline(
        np.array([e1, e2]), np.array([start, 0.0]), np.array([a.edge_length_m[e1], end])
    )
    ex, ey = [], []
    for e, lo, hi in ((e1, start, float(a.edge_length_m[e1])), (e2, 0.0, end)):
        px, py = default_net.edge_polyline(e, lo, hi)
        ex.append(px if not ex else px[1:])
        ey.append(py if not ey else py[1:])
    assert np.allclose(x, np.concatenate(ex))
    assert np.allclose(y, np.concatenate(ey))
    length = float(np.hypot(np.diff(x), np.diff(y)).sum())
    assert length == pytest.approx(a.edge_length_m[e1] - start + end)


def test_path_lonlat_is_the_unprojected_polyline(default_net: roadnets.RoadNetwork) -> None:
    # one compiled call gives the numbers of path_polyline then unproject, bit for bit: the
    # vertices read from the network's own degrees, whole edges' ends among them, the points
    # between vertices and a backwards stretch's unprojected; a network in a CRS the
    # compiled projection does not cover still gets them through pyproj
    a = default_net.arrays
    rng = np.random.default_rng(5)
    edge = rng.integers(0, a.n_edges, 12)
    start = rng.random(12) * a.edge_length_m[edge]
    end = start + rng.random(12) * (a.edge_length_m[edge] - start)
    whole = rng.integers(0, a.n_edges, 6)
    edge = np.concatenate((edge, whole, edge[:1]))
    start = np.concatenate((start, np.zeros(6), end[:1]))
    end = np.concatenate((end, a.edge_length_m[whole], start[:1] - 5.0))
    elsewhere = dataclasses.replace(default_net, projector=Projector("EPSG:32632"))
    for net in (default_net, elsewhere):
        want = net.unproject(*net.path_polyline(edge, start, end))
        got = net.path_lonlat(edge, start, end)
        assert got[0].tobytes() == want[0].tobytes()
        assert got[1].tobytes() == want[1].tobytes()
    assert default_net.projector.compiled is not None
    assert elsewhere.projector.compiled is None


def test_issue_5_concurrent_queries_from_many_threads_agree(
    default_net: roadnets.RoadNetwork,
) -> None:
    # libspatialindex crashes when one index is probed from several threads at once
    from concurrent.futures import ThreadPoolExecutor

    a = default_net.arrays
    rng = np.random.default_rng(5)
    x = rng.uniform(a.geom_x.min(), a.geom_x.max(), 2000)
    y = rng.uniform(a.geom_y.min(), a.geom_y.max(), 2000)
    expected = default_net.nearby_edges(x, y, 50.0)
    with ThreadPoolExecutor(8) as pool:
        results = list(pool.map(lambda _: default_net.nearby_edges(x, y, 50.0), range(32)))
    for hits in results:
        assert np.array_equal(hits.edge, expected.edge)
        assert np.array_equal(hits.offset_m, expected.offset_m)


_FIELDS = ("point", "edge", "distance_m", "offset_m", "x", "y", "bearing_deg")


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(min_value=0, max_value=2**32 - 1),
    spread=st.floats(min_value=0.0, max_value=60.0),
    radius=st.sampled_from([3.0, 20.0, 50.0, 80.0, 200.0]),
    top=st.sampled_from([None, 1, 3, 16]),
)
def test_packed_tree_gives_the_rtree_query_row_for_row(
    melbourne_net: roadnets.RoadNetwork,
    default_net: roadnets.RoadNetwork,
    seed: int,
    spread: float,
    radius: float,
    top: int | None,
) -> None:
    # points at and around the roads' vertices, where two segments of a road tie, and some
    # anywhere in the box; both indexes must keep the same rows, bit for bit
    kw = {} if top is None else {"max_per_point": top}
    rng = np.random.default_rng(seed)
    for net in (melbourne_net, default_net):
        a = net.arrays
        v = rng.integers(0, len(a.geom_x), 300)
        x = a.geom_x[v] + rng.normal(0.0, spread + 1e-9, 300) * (rng.random(300) < 0.7)
        y = a.geom_y[v] + rng.normal(0.0, spread + 1e-9, 300) * (rng.random(300) < 0.7)
        x[:20] = rng.uniform(a.geom_x.min() - 300, a.geom_x.max() + 300, 20)
        want = _query(net, "rtree", x, y, radius, **kw)
        got = _query(net, "packed", x, y, radius, **kw)
        for name in _FIELDS:
            assert np.array_equal(getattr(want, name), getattr(got, name)), name


def test_packed_tree_query_finding_hundreds_of_segments_matches_the_rtree(
    default_net: roadnets.RoadNetwork,
) -> None:
    # a radius that takes in more segments than the compiled probe's first buffer holds:
    # the probe counts past it and runs again into a larger one, losing none
    a = default_net.arrays
    x, y = np.array([np.median(a.geom_x)]), np.array([np.median(a.geom_y)])
    want = _query(default_net, "rtree", x, y, 600.0)
    got = _query(default_net, "packed", x, y, 600.0)
    assert len(set(want.edge.tolist())) > 600
    for name in _FIELDS:
        assert np.array_equal(getattr(want, name), getattr(got, name)), name


def test_rtree_lists_every_query_in_one_global_order(melbourne_net: roadnets.RoadNetwork) -> None:
    # what the packed tree's tie order rests on: libspatialindex walks its tree depth first,
    # so the hits of any box come in the order of a query that covers every box
    tree = melbourne_net.rtree
    a = melbourne_net.arrays
    rank = rtree_rank(tree, len(a.seg_start))
    assert sorted(rank.tolist()) == list(range(len(a.seg_start)))
    rng = np.random.default_rng(11)
    cx = rng.uniform(a.geom_x.min(), a.geom_x.max(), 200)
    cy = rng.uniform(a.geom_y.min(), a.geom_y.max(), 200)
    half = rng.uniform(5.0, 400.0, 200)
    ids, counts = tree.intersection_v(
        np.column_stack((cx - half, cy - half)), np.column_stack((cx + half, cy + half))
    )
    start = 0
    for count in counts.tolist():
        found = rank[np.asarray(ids[start : start + count], dtype=np.int64)]
        assert np.all(np.diff(found) > 0)
        start += count


def test_packed_tree_nodes_cover_their_children(oakland_net: roadnets.RoadNetwork) -> None:
    tree = oakland_net.segment_tree
    n_seg = len(oakland_net.arrays.seg_start)
    assert sorted(tree.item_seg.tolist()) == list(range(n_seg))
    leaves = np.arange(tree.n_inner, len(tree.box))
    covered = np.zeros(n_seg, dtype=int)
    for node in range(len(tree.box)):
        lo, hi = int(tree.child_lo[node]), int(tree.child_hi[node])
        assert 0 < hi - lo <= PACKED_FANOUT
        inner = tree.item_box[lo:hi] if node in leaves else tree.box[lo:hi]
        assert np.all(inner[:, :2] >= tree.box[node, :2])
        assert np.all(inner[:, 2:] <= tree.box[node, 2:])
        if node >= tree.n_inner:
            covered[tree.item_seg[lo:hi]] += 1
        else:
            assert np.all(np.arange(lo, hi) > node)  # children come after their parent
    assert np.all(covered == 1)  # every segment in exactly one leaf


def test_points_on_edges_are_the_vectorised_interpolation(
    melbourne_net: roadnets.RoadNetwork,
) -> None:
    # the compiled places against the same interpolation in numpy: bit for bit, offsets
    # before, on and past every vertex and end clipped to the edge, NaN staying NaN
    a = melbourne_net.arrays
    rng = np.random.default_rng(7)
    edge = rng.integers(0, a.n_edges, 2000)
    length = a.edge_length_m[edge]
    offset = rng.uniform(-0.2, 1.2, 2000) * length
    offset[:50] = 0.0
    offset[50:100] = length[50:100]
    offset[100:110] = np.nan
    x, y = melbourne_net.point_on_edge(edge, offset)
    clipped = np.clip(offset, 0.0, length)
    i = melbourne_net.segment_at(edge, clipped)
    seg = a.geom_cum_m[i + 1] - a.geom_cum_m[i]
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.clip(np.where(seg > 0, (clipped - a.geom_cum_m[i]) / seg, 0.0), 0.0, 1.0)
    assert np.array_equal(x, a.geom_x[i] + t * (a.geom_x[i + 1] - a.geom_x[i]), equal_nan=True)
    assert np.array_equal(y, a.geom_y[i] + t * (a.geom_y[i + 1] - a.geom_y[i]), equal_nan=True)
    assert np.isnan(x[100:110]).all()
    with pytest.raises(IndexError, match="out of range"):
        melbourne_net.point_on_edge(np.array([a.n_edges]), np.array([0.0]))


def test_the_compiled_bearing_is_pythons_modulo_to_the_bit() -> None:
    from roadnets.spatial_kernels import bearings_kernel

    rng = np.random.default_rng(5)
    tiny = [0.0, -0.0, 5e-324, -5e-324, 1e-300, -1e-300, 1.0, -1.0, 1e300, -1e300]
    pairs = [(a, b) for a in tiny for b in tiny]
    dx = np.concatenate((rng.normal(size=4000) * 100, [a for a, _ in pairs] * 2))
    dy = np.concatenate((rng.normal(size=4000) * 100, [b for _, b in pairs] * 2))
    reverse = np.concatenate(
        (rng.random(4000) < 0.5, np.zeros(len(pairs), bool), np.ones(len(pairs), bool))
    )
    forward = [math.degrees(math.atan2(a, b)) % 360.0 for a, b in zip(dx, dy, strict=True)]
    want = np.array(
        [(f + 180.0) % 360.0 if r else f for f, r in zip(forward, reverse, strict=True)]
    )
    got = bearings_kernel(dx, dy, reverse)
    assert np.array_equal(got.view(np.int64), want.view(np.int64))  # -0.0 is not 0.0 here
