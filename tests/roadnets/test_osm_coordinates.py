"""Corrupt node coordinates in an OSM file give one clear error (issue 14 item 10)."""

from __future__ import annotations

import bz2
import gzip
from typing import TYPE_CHECKING

import numpy as np
import osmium
import pytest

import roadnets

if TYPE_CHECKING:
    from pathlib import Path


def _osm(lat2: str, *, lon2: str = "7.4300000", split: bool = False) -> str:
    """A road of three nodes; node 2 (line 4) has the given ``lat``/``lon`` text."""
    node2 = f'<node id="2" lat="{lat2}" lon="{lon2}"/>'
    if split:  # one attribute per line, as some writers do
        node2 = f'<node id="2"\n  lat="{lat2}"\n  lon="{lon2}"/>'
    return "\n".join(
        [
            '<?xml version="1.0" encoding="UTF-8"?>',
            '<osm version="0.6">',
            '<node id="1" lat="43.7300000" lon="7.4200000"/>',
            node2,
            '<node id="3" lat="43.7400000" lon="7.4300000"/>',
            '<way id="9"><nd ref="1"/><nd ref="2"/><nd ref="3"/>'
            '<tag k="highway" v="residential"/></way>',
            "</osm>",
        ]
    )


def _load_error(path: Path) -> str:
    with pytest.raises(roadnets.InvalidNetworkSourceError) as caught:
        roadnets.load(path, use_cache=False)
    assert isinstance(caught.value, ValueError)
    assert caught.value.path == str(path)
    return str(caught.value)


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("nan", "not a decimal number"),
        ("NaN", "not a decimal number"),
        ("inf", "not a decimal number"),
        ("", "not a decimal number"),
        ("abc", "not a decimal number"),
        ("43.7x", "not a decimal number"),
        ("+43.7", "not a decimal number"),
        (" 43.7", "not a decimal number"),
        ("4.37e+1", "not a decimal number"),
        ("1e3", "outside -90..90 degrees"),
    ],
)
def test_a_coordinate_libosmium_cannot_read_names_the_node(
    tmp_path: Path, text: str, problem: str
) -> None:
    path = tmp_path / "bad.osm"
    path.write_text(_osm(text), encoding="utf-8")
    message = _load_error(path)
    assert f'node 2 (line 4) has lat="{text}": {problem}' in message
    assert "fix the node or export the extract again" in message
    assert "Traceback" not in message


@pytest.mark.parametrize("text", ["1e999", "1e99", "-4.373e99"])
def test_an_overflowing_exponent_libosmium_reads_as_zero_is_refused(
    tmp_path: Path, text: str
) -> None:
    path = tmp_path / "zero.osm"
    path.write_text(_osm(text), encoding="utf-8")
    message = _load_error(path)
    assert f'node 2 (line 4) has lat="{text}": outside -90..90 degrees' in message
    assert "libosmium read it as 0" in message


def test_an_overflowing_longitude_is_refused_too(tmp_path: Path) -> None:
    path = tmp_path / "zero-lon.osm"
    path.write_text(_osm("43.7350000", lon2="7e999"), encoding="utf-8")
    assert 'node 2 (line 4) has lon="7e999": outside -180..180 degrees' in _load_error(path)


@pytest.mark.parametrize(("lat", "lon"), [("91.5", "7.43"), ("43.735", "-181.0")])
def test_a_road_node_out_of_range_is_refused_not_taken_for_clipped(
    tmp_path: Path, lat: str, lon: str
) -> None:
    path = tmp_path / "range.osm"
    path.write_text(_osm(lat, lon2=lon), encoding="utf-8")
    message = _load_error(path)
    assert f"node 2 of way 9 is at lat {float(lat):g}, lon {float(lon):g}" in message
    assert "outside -90..90 / -180..180 degrees" in message


def test_a_pbf_node_out_of_range_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "range.osm.pbf"
    with osmium.SimpleWriter(str(path)) as writer:
        writer.add_node(osmium.osm.mutable.Node(id=1, location=(7.42, 43.73)))
        writer.add_node(osmium.osm.mutable.Node(id=2, location=(7.43, 91.5)))
        writer.add_node(osmium.osm.mutable.Node(id=3, location=(7.43, 43.74)))
        writer.add_way(osmium.osm.mutable.Way(id=9, nodes=[1, 2, 3], tags={"highway": "primary"}))
    assert "node 2 of way 9 is at lat 91.5, lon 7.43" in _load_error(path)


@pytest.mark.parametrize("suffix", [".osm.bz2", ".osm.gz"])
def test_compressed_files_name_the_node_and_line_too(tmp_path: Path, suffix: str) -> None:
    raw = _osm("nan", split=True).encode()
    path = tmp_path / f"bad{suffix}"
    path.write_bytes(bz2.compress(raw) if suffix == ".osm.bz2" else gzip.compress(raw))
    assert 'node 2 (line 4) has lat="nan": not a decimal number' in _load_error(path)


def test_a_bad_node_off_the_roads_still_stops_the_file(tmp_path: Path) -> None:
    # libosmium cannot go past it, so neither can we: the file is corrupt
    text = _osm("43.7350000").replace("</osm>", '<node id="77" lat="43.74" lon="nan"/>\n</osm>')
    path = tmp_path / "stray.osm"
    path.write_text(text, encoding="utf-8")
    assert 'node 77 (line 7) has lon="nan"' in _load_error(path)


@pytest.mark.parametrize("text", ["0", "0.0", "-0", "0.0000000", "1e-999", ".0", "0e-5"])
def test_a_road_on_the_equator_loads(tmp_path: Path, text: str) -> None:
    path = tmp_path / "equator.osm"
    body = _osm(text).replace('lat="43.7300000"', 'lat="-0.0010000"')
    path.write_text(body.replace('lat="43.7400000"', 'lat="0.0010000"'), encoding="utf-8")
    net = roadnets.load(path, use_cache=False)
    assert net.arrays.n_edges == 2
    _, lat = net.unproject(net.arrays.geom_x, net.arrays.geom_y)
    assert np.any(np.abs(lat) < 1e-9)  # node 2, on the equator


def test_the_cli_says_it_in_one_line_with_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from mapmatch.cli import main

    path = tmp_path / "bad.osm"
    path.write_text(_osm("nan"), encoding="utf-8")
    assert main(["network", "info", str(path), "--cache-dir", str(tmp_path / "cache")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert 'node 2 (line 4) has lat="nan"' in err
