from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from roadnets.projection import Projector, utm_epsg


@given(
    lon=st.floats(min_value=-179.9, max_value=179.9),
    lat=st.floats(min_value=-79.9, max_value=83.9),
    d_lon=st.floats(min_value=-2.5, max_value=2.5),
    d_lat=st.floats(min_value=-1.0, max_value=1.0),
)
def test_project_then_unproject_returns_the_point_within_1_mm(
    lon: float, lat: float, d_lon: float, d_lat: float
) -> None:
    projector = Projector(utm_epsg(lon, lat))
    p_lon = np.array([np.clip(lon + d_lon, -180, 180)])
    p_lat = np.array([np.clip(lat + d_lat, -80, 84)])
    x, y = projector.forward(p_lon, p_lat)
    back_lon, back_lat = projector.inverse(x, y)
    x2, y2 = projector.forward(back_lon, back_lat)
    assert float(np.hypot(x2 - x, y2 - y)[0]) < 1e-3
    metres_per_deg = 111_320.0
    assert abs(back_lat[0] - p_lat[0]) * metres_per_deg < 1e-3
    assert abs(back_lon[0] - p_lon[0]) * metres_per_deg * np.cos(np.radians(p_lat[0])) < 1e-3


def test_projected_distance_matches_the_geodesic_one() -> None:
    from pyproj import Geod

    projector = Projector(utm_epsg(7.42, 43.73))
    lon, lat = np.array([7.41, 7.44]), np.array([43.72, 43.75])
    x, y = projector.forward(lon, lat)
    planar = float(np.hypot(*np.diff(np.column_stack((x, y)), axis=0)[0]))
    _, _, geodesic = Geod(ellps="WGS84").inv(lon[0], lat[0], lon[1], lat[1])
    assert abs(planar - geodesic) / geodesic < 5e-4  # UTM scale error near Monaco
