"""GeoPandas in and out: typed tables, every batch format read back, match_many anywhere."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

import geopandas as gpd
import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import mapmatch
from mapmatch import export
from mapmatch.cli import main as cli_main
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trips

if TYPE_CHECKING:
    from collections.abc import Iterator
    from pathlib import Path

    import roadnets

UTC_US = "datetime64[us, UTC]"


@pytest.fixture(scope="module")
def trips(default_net: roadnets.RoadNetwork) -> list[mapmatch.Trace]:
    cfg = SimulationConfig(interval_s=2.0, noise_m=4.0, route_length_m=900.0)
    traces = [t.trace for t in simulate_trips(default_net, cfg, count=6, seed=31)]
    lat = traces[0].lat.copy()
    lat[5:9] -= 0.03  # out at sea: unmatched fixes and a break
    traces[0] = mapmatch.Trace(time=traces[0].time_s, lon=traces[0].lon, lat=lat, trace_id="sea")
    return traces


@pytest.fixture(scope="module")
def result(trips: list[mapmatch.Trace], default_net: roadnets.RoadNetwork) -> mapmatch.MatchResult:
    r = mapmatch.match(trips[0], default_net)
    assert len(r.segments) > 1
    assert not r.points.matched.all()
    return r


def test_segments_are_the_default_kind(result: mapmatch.MatchResult) -> None:
    gdf = result.to_geodataframe()
    assert isinstance(gdf, gpd.GeoDataFrame)
    assert gdf.crs.to_epsg() == 4326
    assert len(gdf) == len(result.segments)
    assert set(gdf.geom_type) == {"LineString"}
    assert gdf["segment"].tolist() == [s.index for s in result.segments]
    assert str(gdf["start_time"].dtype) == UTC_US
    assert gdf["length_m"].sum() == pytest.approx(result.matched_length_m)


def test_edges_table_has_typed_ids_times_and_the_driven_lines(
    result: mapmatch.MatchResult, default_net: roadnets.RoadNetwork
) -> None:
    gdf = result.to_geodataframe("edges")
    dtypes = gdf.dtypes.astype(str).to_dict()
    assert {dtypes[c] for c in ("u", "v", "key", "osm_way_id")} == {"Int64"}
    assert dtypes["entry_time"] == dtypes["exit_time"] == UTC_US
    assert set(gdf.geom_type) == {"LineString"}
    # each line is its driven stretch: projected, its length is the driven length
    metres = gdf.to_crs(default_net.crs).length.to_numpy()
    driven = (gdf["end_offset_m"] - gdf["start_offset_m"]).to_numpy()
    np.testing.assert_allclose(metres, driven, rtol=2e-3, atol=0.05)
    first = gdf.loc[gdf["segment"] == 0, "entry_time"]
    assert first.is_monotonic_increasing


def test_points_table_is_null_where_unmatched_never_minus_one(
    result: mapmatch.MatchResult,
) -> None:
    gdf = result.to_geodataframe("points")
    dtypes = gdf.dtypes.astype(str).to_dict()
    assert {dtypes[c] for c in ("u", "v", "key", "segment", "edge_index")} == {"Int64"}
    assert {dtypes[c] for c in ("matched", "interpolated", "outlier")} == {"bool"}
    assert dtypes["time"] == UTC_US
    off = ~gdf["matched"]
    assert off.any()
    assert gdf.loc[off, ["u", "v", "key", "segment", "edge_index"]].isna().all().all()
    assert (gdf[["u", "v", "key"]].fillna(0) >= 0).all().all()  # no -1 anywhere
    assert gdf.geometry[off].isna().all()
    assert set(gdf.geometry[~off].geom_type) == {"Point"}
    np.testing.assert_allclose(gdf.geometry[~off].x, result.points.lon[~off.to_numpy()])
    t = gdf["time"].astype("int64").to_numpy() / 1e6
    np.testing.assert_allclose(t, result.points.time_s, atol=1e-6)


def test_an_unknown_kind_is_refused(result: mapmatch.MatchResult) -> None:
    with pytest.raises(
        ValueError, match="unknown kind 'roads'; use one of segments, edges, points"
    ):
        result.to_geodataframe("roads")  # type: ignore[arg-type]


# --------------------------------------------------------------------------- batch files


@pytest.fixture(scope="module")
def trips_file(trips: list[mapmatch.Trace], tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("geo-in")
    frames = []
    for t in trips[:3]:
        frame = t.to_dataframe()
        frame.insert(0, "trace_id", t.trace_id)
        frames.append(frame)
    path = folder / "trips.csv"
    pd.concat(frames).to_csv(path, index=False)
    return path


def _batch(fmt: str, source: Path, cache_dir: Path, out: Path) -> dict[str, dict[str, str]]:
    argv = ["match", str(source), "--out", str(out), "--format", fmt, "--workers", "1"]
    code = cli_main([*argv, "--cache-dir", str(cache_dir), "--quiet"])
    summary = pd.read_csv(out / "summary.csv", dtype=str, keep_default_na=False)
    assert code == 0, summary["error"].tolist()
    return {r["trace_id"]: r for r in summary.to_dict("records")}


def _expected(trips: list[mapmatch.Trace], net: roadnets.RoadNetwork) -> dict[str, Any]:
    return {t.trace_id: mapmatch.match(t, net) for t in trips[:3]}


def test_geoparquet_files_have_geo_metadata_and_round_trip(
    trips_file: Path,
    trips: list[mapmatch.Trace],
    default_net: roadnets.RoadNetwork,
    cache_dir: Path,
    tmp_path: Path,
) -> None:
    rows = _batch("geoparquet", trips_file, cache_dir, tmp_path)
    expected = _expected(trips, default_net)
    for tid, row in rows.items():
        name = row["output"]
        for kind, suffix in (("segments", ".segments"), ("edges", ".edges"), ("points", "")):
            path = tmp_path / f"{name}{suffix}.parquet"
            geo = json.loads(pq.read_schema(path).metadata[b"geo"])
            assert geo["primary_column"] == "geometry"
            assert geo["columns"]["geometry"]["encoding"] == "WKB"
            assert geo["version"].startswith("1.")
            back = gpd.read_parquet(path)
            assert back.crs.to_epsg() == 4326
            made = expected[tid].to_geodataframe(kind)
            pd.testing.assert_frame_equal(back, made, check_dtype=True)


def test_plain_parquet_and_csv_tables_round_trip_with_their_dtypes(
    trips_file: Path,
    trips: list[mapmatch.Trace],
    default_net: roadnets.RoadNetwork,
    cache_dir: Path,
    tmp_path: Path,
) -> None:
    expected = _expected(trips, default_net)
    rows = _batch("parquet", trips_file, cache_dir, tmp_path / "pq")
    for tid, row in rows.items():
        points = pd.read_parquet(tmp_path / "pq" / f"{row['output']}.parquet")
        pd.testing.assert_frame_equal(points, expected[tid].to_dataframe())
        edges = pd.read_parquet(tmp_path / "pq" / f"{row['output']}.edges.parquet")
        pd.testing.assert_frame_equal(edges, export.edges_frame(expected[tid]))
    rows = _batch("csv", trips_file, cache_dir, tmp_path / "csv")
    for tid, row in rows.items():
        text = (tmp_path / "csv" / f"{row['output']}.csv").read_text()
        assert "T" in text.splitlines()[1].split(",")[2]  # ISO 8601, not a float epoch
        points = pd.read_csv(tmp_path / "csv" / f"{row['output']}.csv", parse_dates=["time"])
        made = expected[tid].to_dataframe()
        assert str(points["time"].dtype).startswith("datetime64[")
        assert str(points["time"].dtype).endswith(", UTC]")
        pd.testing.assert_series_equal(points["time"].dt.as_unit("us"), made["time"])
        ints = pd.read_csv(
            tmp_path / "csv" / f"{row['output']}.csv",
            dtype=dict.fromkeys(("u", "v", "key"), "Int64"),
        )
        pd.testing.assert_series_equal(ints["u"], made["u"])


def test_geopackage_holds_every_layer_with_integer_fields(
    trips_file: Path,
    trips: list[mapmatch.Trace],
    default_net: roadnets.RoadNetwork,
    cache_dir: Path,
    tmp_path: Path,
) -> None:
    import pyogrio

    rows = _batch("gpkg", trips_file, cache_dir, tmp_path)
    expected = _expected(trips, default_net)
    nullable = {pa.int64(): pd.Int64Dtype()}.get
    for tid, row in rows.items():
        path = tmp_path / f"{row['output']}.gpkg"
        assert [layer for layer, _ in pyogrio.list_layers(path)] == ["segments", "edges", "points"]
        for kind in ("segments", "edges", "points"):
            info = pyogrio.read_info(path, layer=kind)
            fields = dict(zip(info["fields"], info["dtypes"], strict=True))
            made = expected[tid].to_geodataframe(kind)
            for column in ("u", "v", "key", "segment"):
                if column in made:
                    assert fields[column] == "int64", (kind, column)
            back = gpd.read_file(
                path,
                layer=kind,
                use_arrow=True,
                arrow_to_pandas_kwargs={"types_mapper": nullable},
            )
            assert back.crs.to_epsg() == 4326
            assert len(back) == len(made)
            for column in made.columns:
                if str(made[column].dtype) == "Int64":
                    pd.testing.assert_series_equal(back[column], made[column], check_names=False)
            if kind == "points":
                assert back["matched"].dtype == bool
                assert back.geometry.isna().sum() == (~made["matched"]).sum()


def test_geojson_output_reads_into_geopandas(
    trips_file: Path, cache_dir: Path, tmp_path: Path
) -> None:
    rows = _batch("geojson", trips_file, cache_dir, tmp_path)
    for row in rows.values():
        gdf = gpd.read_file(tmp_path / f"{row['output']}.geojson")
        kinds = gdf["kind"].tolist()
        assert kinds.count("point") == int(row["points"])
        assert set(gdf.geom_type[gdf["kind"] == "segment"]) == {"LineString"}


# --------------------------------------------------------------------------- match_many


def _without_timings(results: list[Any]) -> list[Any]:
    docs = []
    for r in results:
        doc = r.to_geojson() if isinstance(r, mapmatch.MatchResult) else repr(r)
        if isinstance(doc, dict):
            doc["stats"].pop("timings_s")
        docs.append(doc)
    return docs


def test_match_many_in_a_pool_gives_the_in_process_results(
    trips: list[mapmatch.Trace], default_net: roadnets.RoadNetwork
) -> None:
    here = [mapmatch.match(t, default_net) for t in trips]
    pooled = mapmatch.match_many(trips, default_net, workers=2, progress=False, chunk_traces=2)
    assert [r.trace_id for r in pooled] == [t.trace_id for t in trips]
    assert _without_timings(pooled) == _without_timings(here)
    assert pooled[0].config == mapmatch.MatchConfig()


def test_match_many_raises_or_returns_a_trace_error(
    trips: list[mapmatch.Trace], default_net: roadnets.RoadNetwork
) -> None:
    paris = mapmatch.Trace(lon=[2.35, 2.351], lat=[48.85, 48.851], trace_id="paris")
    batch = [trips[1], paris, trips[2]]
    got = mapmatch.match_many(batch, default_net, workers=1, progress=False, return_exceptions=True)
    assert [type(g).__name__ for g in got] == ["MatchResult", "NoCandidatesError", "MatchResult"]
    with pytest.raises(mapmatch.NoCandidatesError, match="trace 'paris'"):
        mapmatch.match_many(batch, default_net, workers=1, progress=False)
    with pytest.raises(mapmatch.MapMatchError, match="Trace"):
        mapmatch.match_many([trips[1], "not a trace"], default_net, progress=False)  # type: ignore[list-item]
    assert mapmatch.match_many([], default_net) == []


@pytest.fixture(scope="module")
def dask_client(dask_cluster: str) -> Iterator[Any]:
    from distributed import Client

    client = Client(dask_cluster)
    try:
        yield client
    finally:
        client.close()


def test_match_many_on_a_dask_cluster_shares_one_network(
    trips: list[mapmatch.Trace], default_net: roadnets.RoadNetwork, dask_client: Any
) -> None:
    here = [mapmatch.match(t, default_net) for t in trips]
    there = mapmatch.match_many(trips, default_net, client=dask_client, progress=False)
    assert _without_timings(there) == _without_timings(here)
    assert dask_client.status == "running"  # a client given is left open


def test_write_table_refuses_an_unknown_kind_or_format_before_writing(
    result: mapmatch.MatchResult, tmp_path: Path
) -> None:
    target = tmp_path / "t.csv"
    with pytest.raises(ValueError, match="unknown table kind 'lines'; use one of segments"):
        export.write_table(result, "lines", target, "csv")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="unknown table format 'xlsx'; use one of csv"):
        export.write_table(result, "edges", target, "xlsx")
    assert not target.exists()
