"""
Issue 12 end to end: the messy trace files of the wild, matched on a real extract.

The traces in ``tests/data/traces`` lie along named streets of ``west-oakland_us.osm.bz2``
(8th Street is OSM way 6358365, 9th Street 6338259, Campbell Street 6340506), so which
streets a match must drive is known, and on these straight streets the matched length must
be the trace's own (chord) length within 2 %.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
import pytest

import mapmatch
import roadnets
from mapmatch.errors import InputTypeError

if TYPE_CHECKING:
    from pathlib import Path

EIGHTH, NINTH, CAMPBELL = 6358365, 6338259, 6340506


@pytest.fixture(scope="module")
def traces(data_dir: Path) -> Path:
    return data_dir / "traces"


def _chord_m(trace: mapmatch.Trace) -> float:
    """The trace's own length: great-circle distance between consecutive fixes."""
    total = 0.0
    for i in range(1, len(trace)):
        phi1, phi2 = math.radians(trace.lat[i - 1]), math.radians(trace.lat[i])
        dphi = phi2 - phi1
        dlam = math.radians(trace.lon[i] - trace.lon[i - 1])
        h = math.sin(dphi / 2) ** 2 + math.cos(phi1) * math.cos(phi2) * math.sin(dlam / 2) ** 2
        total += 2 * 6_371_008.8 * math.asin(math.sqrt(h))
    return total


def _assert_drove(result: mapmatch.MatchResult, ways: list[int], length_m: float) -> None:
    assert result.way_ids() == ways
    assert result.breaks == []
    assert result.matched_length_m == pytest.approx(length_m, rel=0.02)


def test_gpx_without_times_matches_8th_street(
    traces: Path, oakland_net: roadnets.RoadNetwork
) -> None:
    trace = mapmatch.Trace.from_file(traces / "no_time.gpx")
    result = mapmatch.match(trace, oakland_net)
    _assert_drove(result, [EIGHTH], _chord_m(trace))
    assert result.stats.time_source == "absent"
    assert bool(result.points.matched.all())
    doc = result.to_geojson()
    times = [f["properties"]["time"] for f in doc["features"] if f["properties"]["kind"] == "point"]
    assert times == [None] * 21
    assert doc["stats"]["time_source"] == "absent"


def test_a_burst_stamped_with_one_second_matches_9th_street(
    traces: Path, oakland_net: roadnets.RoadNetwork
) -> None:
    trace = mapmatch.Trace.from_file(traces / "burst_one_second.gpx")
    result = mapmatch.match(trace, oakland_net)
    _assert_drove(result, [NINTH], _chord_m(trace))
    assert result.stats.points == 29
    assert result.stats.shared_time_rows == 28
    assert result.stats.time_source == "implausible"
    assert any(w.startswith("the times cannot be right") for w in result.stats.warnings)


def test_repeated_times_in_a_timed_trace_match_8th_street(
    traces: Path, oakland_net: roadnets.RoadNetwork
) -> None:
    # the fleet file's bus with a logger clock that stamps every fifth fix with the second
    # before (08:00:00, 01, 01, 03, 04, 05, 06, 06, 08 ...): positions kept, dt = 0 steps
    frame = pd.read_csv(traces / "fleet_interleaved.csv")
    bus = frame[frame["vehicle_id"] == "bus-12"].reset_index(drop=True)
    seconds = (pd.to_datetime(bus["timestamp"]) - pd.Timestamp(0, tz="UTC")) // pd.Timedelta("1s")
    bus["timestamp"] = seconds - (np.arange(len(bus)) % 5 == 2)
    trace = mapmatch.Trace.from_dataframe(bus)
    assert len(trace) == 60
    assert trace.report.shared_time_rows == 12
    assert trace.has_time  # 12 of 59 moving steps without time is not "most"
    result = mapmatch.match(trace, oakland_net)
    _assert_drove(result, [EIGHTH], _chord_m(trace))
    assert result.stats.points == 60
    assert result.stats.shared_time_rows == 12


def test_two_identical_points_match_with_length_zero(
    traces: Path, oakland_net: roadnets.RoadNetwork
) -> None:
    trace = mapmatch.Trace.from_file(traces / "two_identical.gpx")
    result = mapmatch.match(trace, oakland_net)
    assert result.matched_length_m == 0.0
    assert result.way_ids() == [EIGHTH]
    assert result.breaks == []


def test_fleet_vehicles_interleaved_in_time_match_their_own_streets(
    traces: Path, oakland_net: roadnets.RoadNetwork
) -> None:
    bus, van = mapmatch.read_traces(traces / "fleet_interleaved.csv")
    _assert_drove(mapmatch.match(bus, oakland_net), [EIGHTH], _chord_m(bus))
    _assert_drove(mapmatch.match(van, oakland_net), [CAMPBELL], _chord_m(van))


def test_microsecond_epochs_match_like_seconds(
    traces: Path, oakland_net: roadnets.RoadNetwork
) -> None:
    trace = mapmatch.Trace.from_file(traces / "microseconds.csv")
    assert np.diff(trace.time_s).tolist() == [2.0] * 19
    result = mapmatch.match(trace, oakland_net)
    _assert_drove(result, [EIGHTH], _chord_m(trace))
    assert result.stats.time_source == "ok"


def test_nmea_log_matches_campbell_street(traces: Path, oakland_net: roadnets.RoadNetwork) -> None:
    trace = mapmatch.Trace.from_file(traces / "box.nmea")
    result = mapmatch.match(trace, oakland_net)
    _assert_drove(result, [CAMPBELL], _chord_m(trace))
    assert result.stats.dropped_rows == 3


def test_gpx_segments_are_breaks_of_the_match(
    traces: Path, oakland_net: roadnets.RoadNetwork
) -> None:
    gap, _ = mapmatch.read_traces(traces / "two_segments.gpx")
    result = mapmatch.match(gap, oakland_net)
    assert result.breaks == [10]
    assert result.way_ids() == [EIGHTH]


def test_a_geodataframe_in_a_projected_crs_matches_like_the_csv(
    traces: Path, oakland_net: roadnets.RoadNetwork
) -> None:
    gpd = pytest.importorskip("geopandas")
    frame = pd.read_csv(traces / "fleet_interleaved.csv")
    gdf = gpd.GeoDataFrame(
        frame.drop(columns=["latitude", "longitude"]),
        geometry=gpd.points_from_xy(frame["longitude"], frame["latitude"]),
        crs="EPSG:4326",
    ).to_crs("EPSG:26910")
    bus, van = mapmatch.read_traces(gdf)
    assert mapmatch.match(van, oakland_net).way_ids() == [CAMPBELL]
    assert mapmatch.match(bus, oakland_net).way_ids() == [EIGHTH]


def test_an_osmnx_graph_matches_after_from_graph_and_is_refused_before(
    data_dir: Path, traces: Path, oakland_net: roadnets.RoadNetwork
) -> None:
    ox = pytest.importorskip("osmnx")
    G = ox.graph_from_xml(data_dir / "west-oakland_us.osm.bz2", retain_all=True)
    bus, van = mapmatch.read_traces(traces / "fleet_interleaved.csv")
    with pytest.raises(InputTypeError, match=r"roadnets.from_graph\(G\)"):
        mapmatch.match(bus, G)
    with pytest.raises(TypeError, match=r"roadnets.load\(path\)"):
        mapmatch.match(bus, None)  # type: ignore[arg-type]
    with pytest.raises(InputTypeError, match="arguments are swapped"):
        mapmatch.match(oakland_net, bus)  # type: ignore[arg-type]
    net = roadnets.from_graph(G)
    for trace, way in ((bus, EIGHTH), (van, CAMPBELL)):
        from_graph = mapmatch.match(trace, net)
        from_file = mapmatch.match(trace, oakland_net)
        assert from_graph.way_ids() == [way]
        assert from_graph.matched_length_m == pytest.approx(from_file.matched_length_m, abs=0.5)
