"""The network's planar projection and its geodesic lengths (issue 14 item 9)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from pyproj import Geod, Proj

import roadnets
from roadnets.projection import (
    MAX_SCALE_ERROR,
    Projector,
    central_longitude,
    geodesic_steps,
    tm_scale_error,
)

DATA = Path(__file__).resolve().parents[1] / "data"
SHARED = Path(__file__).resolve().parents[3] / "shared" / "data" / "osm"
GEOD = Geod(ellps="WGS84")


def _write_osm(path: Path, ways: list[list[tuple[float, float]]]) -> Path:
    """OSM XML of residential two-way roads, each a list of (lon, lat) vertices."""
    nodes: dict[tuple[float, float], int] = {}
    way_xml = []
    for w, points in enumerate(ways, start=1):
        refs = [nodes.setdefault(p, len(nodes) + 1) for p in points]
        nds = "".join(f'<nd ref="{r}"/>' for r in refs)
        way_xml.append(f'<way id="{w}">{nds}<tag k="highway" v="residential"/></way>')
    node_xml = [
        f'<node id="{i}" lat="{lat:.9f}" lon="{lon:.9f}"/>' for (lon, lat), i in nodes.items()
    ]
    text = '<?xml version="1.0"?><osm version="0.6">' + "".join(node_xml + way_xml) + "</osm>"
    path.write_text(text, encoding="utf-8")
    return path


def _road_east(lon: float, lat: float, length_m: float) -> list[tuple[float, float]]:
    """
    A straight road of about ``length_m`` heading east from (lon, lat), 3 vertices.

    Vertices are rounded to 1e-7 degrees, as OSM stores them; :func:`_length` gives the exact
    geodesic length of the rounded road.
    """
    lon1, lat1, _ = GEOD.fwd(lon, lat, 90.0, length_m / 2)
    lon2, lat2, _ = GEOD.fwd(lon1, lat1, 90.0, length_m / 2)
    return [
        (round(float(a), 7), round(float(b), 7))
        for a, b in ((lon, lat), (lon1, lat1), (lon2, lat2))
    ]


def _length(points: list[tuple[float, float]]) -> float:
    lon, lat = np.array(points).T
    return float(GEOD.line_length(lon, lat))


def _planar_lengths(net: roadnets.RoadNetwork) -> np.ndarray:
    a = net.arrays
    step = np.hypot(np.diff(a.geom_x), np.diff(a.geom_y))
    step[a.edge_geom_ptr[1:-1] - 1] = 0.0
    cum = np.concatenate(([0.0], np.cumsum(step)))
    return np.asarray(cum[a.edge_geom_ptr[1:] - 1] - cum[a.edge_geom_ptr[:-1]])


# --- the projection itself -------------------------------------------------------------------


@given(
    lon=st.floats(min_value=-179.9, max_value=179.9),
    lat=st.floats(min_value=-84.0, max_value=84.0),
    d_lon=st.floats(min_value=-2.5, max_value=2.5),
    d_lat=st.floats(min_value=-1.0, max_value=1.0),
)
def test_project_then_unproject_returns_the_point_within_1_mm(
    lon: float, lat: float, d_lon: float, d_lat: float
) -> None:
    projector = Projector.local(lon, lat)
    p_lon = np.array([(lon + d_lon + 180.0) % 360.0 - 180.0])
    p_lat = np.array([np.clip(lat + d_lat, -85, 85)])
    x, y = projector.forward(p_lon, p_lat)
    back_lon, back_lat = projector.inverse(x, y)
    x2, y2 = projector.forward(back_lon, back_lat)
    assert float(np.hypot(x2 - x, y2 - y)[0]) < 1e-3
    metres_per_deg = 111_320.0
    assert abs(back_lat[0] - p_lat[0]) * metres_per_deg < 1e-3
    d = (back_lon[0] - p_lon[0] + 180.0) % 360.0 - 180.0
    assert abs(d) * metres_per_deg * np.cos(np.radians(p_lat[0])) < 1e-3


@given(
    lon=st.floats(min_value=-179.9, max_value=179.9),
    lat=st.floats(min_value=-84.0, max_value=84.0),
    east_m=st.floats(min_value=-300e3, max_value=300e3),
    north_m=st.floats(min_value=-300e3, max_value=300e3),
)
def test_the_compiled_projection_is_projs_to_a_few_nanometres(
    lon: float, lat: float, east_m: float, north_m: float
) -> None:
    # Projector.local projects with roadnets.tmerc; PROJ's own pipeline for the same CRS is the
    # reference, up to 300 km from the centre (a network reaches at most about 285 km)
    projector = Projector.local(lon, lat)
    proj = Proj(projector.crs)
    p_lon, p_lat = proj(east_m, north_m, inverse=True)
    if not (np.isfinite(p_lon) and np.isfinite(p_lat)) or abs(p_lat) > 89.0:
        return
    x, y = projector.forward(np.array([p_lon]), np.array([p_lat]))
    ref_x, ref_y = proj(p_lon, p_lat)
    assert abs(x[0] - ref_x) < 1e-8
    assert abs(y[0] - ref_y) < 1e-8
    back_lon, back_lat = projector.inverse(np.array([ref_x]), np.array([ref_y]))
    assert abs((back_lon[0] - p_lon + 180.0) % 360.0 - 180.0) < 1e-12
    assert abs(back_lat[0] - p_lat) < 1e-12


def test_the_local_projection_is_true_to_scale_at_its_centre() -> None:
    projector = Projector.local(7.42, 43.73)
    lon, lat = np.array([7.41, 7.43]), np.array([43.72, 43.74])
    x, y = projector.forward(lon, lat)
    planar = float(np.hypot(x[1] - x[0], y[1] - y[0]))
    _, _, geodesic = GEOD.inv(lon[0], lat[0], lon[1], lat[1])
    assert abs(planar - geodesic) / geodesic < 1e-6  # UTM zone 32 errs by 3.5e-4 here


@pytest.mark.parametrize(("lat", "d_lon"), [(0.0, 2.0), (45.0, 3.5), (-60.0, 5.0), (70.0, 1.0)])
def test_the_scale_error_estimate_matches_proj(lat: float, d_lon: float) -> None:
    projector = Projector.local(10.0, lat)
    factors = Proj(projector.crs).get_factors(10.0 + d_lon, lat)
    exact = float(factors.meridional_scale) - 1.0
    estimate = tm_scale_error(np.array([10.0 + d_lon]), np.array([lat]), 10.0)
    assert estimate == pytest.approx(exact, rel=0.01)


def test_the_centre_of_longitudes_across_the_antimeridian() -> None:
    assert central_longitude(np.array([179.5, -179.7, 179.9])) == pytest.approx(
        (179.9, 179.5, 180.3)
    )
    assert central_longitude(np.array([-10.0, 10.0])) == (0.0, -10.0, 10.0)


def test_geodesic_steps_are_karneys_distances() -> None:
    lon, lat = np.array([7.41, 7.43, 7.43]), np.array([43.72, 43.74, 43.74])
    steps = geodesic_steps(lon, lat)
    assert steps[0] == pytest.approx(GEOD.inv(7.41, 43.72, 7.43, 43.74)[2], abs=1e-9)
    assert steps[1] == 0.0
    assert len(geodesic_steps(lon[:1], lat[:1])) == 0


# --- networks ----------------------------------------------------------------------------------


def test_a_network_58_degrees_wide_is_refused_naming_its_extent(tmp_path: Path) -> None:
    # the case: two 1,000 m roads 58 degrees of longitude apart
    source = _write_osm(
        tmp_path / "two-roads.osm",
        [_road_east(-20.0, 37.4, 1000.0), _road_east(38.0, 37.4, 1000.0)],
    )
    with pytest.raises(roadnets.NetworkTooWideError) as caught:
        roadnets.load(source, use_cache=False)
    message = str(caught.value)
    assert "two-roads.osm" in message
    assert "-20.0000..38.0" in message  # the longitudes it spans
    assert "37.4000..37.4" in message
    assert "5,1" in message or "5,2" in message  # about 5,1xx km east-west
    assert "split the extract" in message
    assert "570 km" in message  # what would fit
    assert isinstance(caught.value, roadnets.RoadNetworkError)
    assert isinstance(caught.value, ValueError)
    assert caught.value.scale_error > MAX_SCALE_ERROR


def test_a_network_4_degrees_wide_keeps_every_length_true(tmp_path: Path) -> None:
    # 290 km east-west at 50 N: one UTM zone (the former choice) put the west road 175 km
    # from its meridian, where it read 1,000 m as 1,000.36 m
    roads = [
        _road_east(7.0, 50.0, 1000.0),
        _road_east(9.0, 50.2, 1000.0),
        _road_east(11.0, 50.0, 1000.0),
    ]
    net = roadnets.load(_write_osm(tmp_path / "wide.osm", roads), use_cache=False)
    a = net.arrays
    assert a.n_edges == 6
    expected = np.repeat([_length(r) for r in roads], 2)
    assert np.allclose(expected, 1000.0, atol=0.01)
    assert np.allclose(a.edge_length_m, expected, rtol=0, atol=1e-6)  # geodesic, exact
    planar = _planar_lengths(net)
    assert np.all(np.abs(planar / a.edge_length_m - 1.0) < 3e-4)  # 145 km off the meridian
    assert net.crs.startswith("+proj=tmerc +lat_0=50.100000 +lon_0=9.006")
    # a fix on the middle vertex of the west road: 500 m (geodesic) along it, both directions
    mid_lon, mid_lat = roads[0][1]
    x, y = net.project(np.array([mid_lon]), np.array([mid_lat]))
    hits = net.nearby_edges(x, y, 5.0)
    assert len(hits) == 2
    assert np.allclose(hits.offset_m, _length(roads[0][:2]), atol=1e-6)
    assert np.allclose(hits.offset_m, 500.0, atol=0.01)
    assert np.allclose(hits.distance_m, 0.0, atol=1e-3)
    # and a point placed 250 m along each edge is where the ellipsoid says
    for edge in hits.edge:
        px, py = net.point_on_edge(np.array([edge]), np.array([250.0]))
        lon, lat = net.unproject(px, py)
        u = int(a.edge_u[edge])
        lon0, lat0 = net.unproject(a.node_x[u : u + 1], a.node_y[u : u + 1])
        _, _, along = GEOD.inv(lon0[0], lat0[0], lon[0], lat[0])
        assert along == pytest.approx(250.0, abs=0.01)


def test_a_network_across_the_antimeridian_is_centred_on_it(tmp_path: Path) -> None:
    road = [(179.995, -17.8), (-179.995, -17.8), (-179.99, -17.79)]  # Fiji, across 180
    net = roadnets.load(_write_osm(tmp_path / "fiji.osm", [road]), use_cache=False)
    a = net.arrays
    expected = (
        GEOD.inv(179.995, -17.8, -179.995, -17.8)[2] + GEOD.inv(-179.995, -17.8, -179.99, -17.79)[2]
    )
    assert a.edge_length_m[0] == pytest.approx(expected, abs=1e-6)
    assert _planar_lengths(net)[0] == pytest.approx(expected, rel=1e-6)
    assert "+lon_0=-179.997500" in net.crs  # halfway between 179.995 and 180.01


def _bundled() -> list[Path]:
    files = [roadnets.default_network_path(), *sorted(DATA.glob("*.osm*"))]
    if SHARED.exists():
        files += sorted(SHARED.glob("*.osm*"))
    return files


@pytest.mark.parametrize("path", _bundled(), ids=lambda p: f"{p.parent.name}/{p.name}")
def test_geodesic_and_planar_lengths_agree_on_every_extract(path: Path, cache_dir: Path) -> None:
    net = roadnets.load(path, cache_dir=cache_dir)
    a = net.arrays
    planar = _planar_lengths(net)
    assert np.all(np.abs(planar - a.edge_length_m) <= 1e-3 * a.edge_length_m + 1e-6)
    # and each segment's geodesic length is Karney's, vertex to vertex
    lon, lat = net.unproject(a.geom_x, a.geom_y)
    steps = geodesic_steps(lon, lat)
    inside = np.ones(len(steps), dtype=bool)
    inside[a.edge_geom_ptr[1:-1] - 1] = False
    assert np.allclose(np.diff(a.geom_cum_m)[inside], steps[inside], rtol=0, atol=1e-6)


def test_offsets_of_nearby_edges_place_the_projection_back(
    default_net: roadnets.RoadNetwork,
) -> None:
    a = default_net.arrays
    rng = np.random.default_rng(3)
    x = rng.uniform(a.geom_x.min(), a.geom_x.max(), 400)
    y = rng.uniform(a.geom_y.min(), a.geom_y.max(), 400)
    hits = default_net.nearby_edges(x, y, 60.0)
    assert len(hits) > 400
    px, py = default_net.point_on_edge(hits.edge, hits.offset_m)
    assert np.allclose(px, hits.x, atol=1e-6)
    assert np.allclose(py, hits.y, atol=1e-6)
    assert np.all(hits.offset_m <= a.edge_length_m[hits.edge])


@pytest.mark.parametrize(("lon_0", "lat_0"), [(7.42, 43.73), (-122.29, 37.81), (179.99, -17.8)])
def test_the_fast_pipeline_is_the_crs_it_names(lon_0: float, lat_0: float) -> None:
    # the projector transforms through an explicit PROJ pipeline; geopandas, FMM and users
    # read net.crs: both must give the same metres
    from pyproj import Transformer

    projector = Projector.local(lon_0, lat_0)
    lon = lon_0 + np.array([-0.8, 0.0, 0.3, 1.2])
    lat = lat_0 + np.array([0.5, 0.0, -0.7, 0.2])
    x, y = projector.forward(lon, lat)
    ex, ey = Transformer.from_crs("EPSG:4326", projector.crs, always_xy=True).transform(lon, lat)
    assert np.allclose(x, ex, rtol=0, atol=1e-6)
    assert np.allclose(y, ey, rtol=0, atol=1e-6)
    back_lon, back_lat = projector.inverse(x, y)
    assert np.allclose((back_lon - lon + 180) % 360 - 180, 0, atol=1e-9)
    assert np.allclose(back_lat, lat, atol=1e-9)
