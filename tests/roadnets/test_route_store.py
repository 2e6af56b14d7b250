"""The route table kept for sparse traces: its budget, its cache files, its background build."""

from __future__ import annotations

import json
import logging
import os
import pickle
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

import mapmatch
import roadnets
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trips
from mapmatch.export import geojson_bytes
from roadnets.route_store import ROUTE_TABLE_BOUND_M, ROUTES_FOLDER, estimate_bytes
from roadnets.turns import DEFAULT_UTURN_COST_M

if TYPE_CHECKING:
    import pytest


OAKLAND = Path(__file__).parents[1] / "data" / "west-oakland_us.osm.bz2"
MONACO = Path(roadnets.__file__).parent / "data" / "monaco_2020.osm.pbf"


def _pairs(net: roadnets.RoadNetwork) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(3)
    n = net.arrays.n_edges
    return rng.integers(0, n, 500), rng.integers(0, n, 500)


def test_the_table_is_built_within_budget_stored_in_the_entry_and_read_back(
    tmp_path: Path,
) -> None:
    net = roadnets.load(OAKLAND, cache_dir=tmp_path)
    assert net.route_table_note == "not looked for yet"
    table = net.sparse_route_table()
    assert table is not None
    assert net.route_table_note.startswith("built and stored in the cache entry: ")
    assert float(table.bounds_m.min()) == ROUTE_TABLE_BOUND_M
    assert net.cache_entry is not None
    assert (Path(net.cache_entry) / ROUTES_FOLDER / "meta.json").exists()

    again = roadnets.load(OAKLAND, cache_dir=tmp_path)
    read = again.sparse_route_table()
    assert read is not None
    assert again.route_table_note.startswith("read from the cache entry: ")
    a, b = _pairs(net)
    assert np.array_equal(read.records(a, b), table.records(a, b))
    assert np.array_equal(read.lookup(a, b)[0], table.lookup(a, b)[0])

    # a worker gets the entry's path, not the table, and maps the same file
    blob = pickle.dumps(again)
    assert len(blob) < 10_000
    worker = pickle.loads(blob)
    assert worker.precomputed_routes is None
    assert worker.sparse_route_table() is not None
    assert worker.route_table_note.startswith("read from the cache entry: ")


def test_a_table_over_the_budget_is_not_built_and_the_note_says_why(tmp_path: Path) -> None:
    net = roadnets.load(OAKLAND, cache_dir=tmp_path)
    net.route_table_budget_mb = 0.01
    assert net.sparse_route_table() is None
    assert "MB even for routes within 500 m, over the 0.01 MB budget" in net.route_table_note
    assert net.cache_entry is not None
    assert not (Path(net.cache_entry) / ROUTES_FOLDER).exists()

    off = roadnets.load(OAKLAND, cache_dir=tmp_path)
    off.route_table_budget_mb = 0
    assert off.sparse_route_table() is None
    assert off.route_table_note == "none: route_table_budget_mb is 0"


def test_a_table_made_by_precompute_routes_is_kept(tmp_path: Path) -> None:
    net = roadnets.load(OAKLAND, cache_dir=tmp_path)
    own = net.precompute_routes(300.0)
    assert net.sparse_route_table() is own
    assert net.route_table_note == "given (precompute_routes)"


def test_without_a_cache_entry_the_table_is_built_in_memory() -> None:
    net = roadnets.load(OAKLAND, use_cache=False)
    assert net.sparse_route_table() is not None
    assert net.route_table_note.startswith("built (no cache entry to keep it): ")


def test_a_corrupt_stored_table_is_removed_and_built_again(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    net = roadnets.load(OAKLAND, cache_dir=tmp_path)
    table = net.sparse_route_table()
    assert table is not None
    assert net.cache_entry is not None
    a, b = _pairs(net)
    expected = table.records(a, b)  # before the file under its mapping is overwritten
    state = Path(net.cache_entry) / ROUTES_FOLDER / "state.npy"
    raw = bytearray(state.read_bytes())
    raw[-1] ^= 0xFF
    state.write_bytes(bytes(raw))
    again = roadnets.load(OAKLAND, cache_dir=tmp_path)
    with caplog.at_level(logging.WARNING, logger="roadnets"):
        rebuilt = again.sparse_route_table()
    assert "checksum of state.npy differs" in caplog.text
    assert rebuilt is not None
    assert again.route_table_note.startswith("built and stored in the cache entry: ")
    assert np.array_equal(rebuilt.records(a, b), expected)


def test_a_table_stored_in_another_format_gives_way_to_a_new_one(tmp_path: Path) -> None:
    net = roadnets.load(OAKLAND, cache_dir=tmp_path)
    table = net.sparse_route_table()
    assert table is not None
    assert net.cache_entry is not None
    meta_path = Path(net.cache_entry) / ROUTES_FOLDER / "meta.json"
    meta = json.loads(meta_path.read_text())
    meta["format"] -= 1  # as an older release stored it
    meta_path.write_text(json.dumps(meta))
    again = roadnets.load(OAKLAND, cache_dir=tmp_path)
    assert again.sparse_route_table() is not None
    assert again.route_table_note.startswith("built and stored in the cache entry: ")
    assert json.loads(meta_path.read_text())["format"] == meta["format"] + 1
    third = roadnets.load(OAKLAND, cache_dir=tmp_path)
    assert third.sparse_route_table() is not None
    assert third.route_table_note.startswith("read from the cache entry: ")


def test_a_forked_child_looks_for_the_table_afresh() -> None:
    net = roadnets.load(OAKLAND, use_cache=False)
    assert net.sparse_route_table() is not None
    assert net.route_table_requested
    read, write = os.pipe()
    child = os.fork()
    if child == 0:  # the parent's job thread and lock are not in the child
        report = f"{net.route_table_requested}|{net.route_table_note}"
        os.write(write, report.encode())
        os._exit(0)
    os.close(write)
    _, status = os.waitpid(child, 0)
    with os.fdopen(read) as answer:
        report = answer.read()
    assert os.waitstatus_to_exitcode(status) == 0
    assert report == "False|not looked for yet"
    assert net.route_table_requested  # the parent's own is untouched


def _budget_between(net: roadnets.RoadNetwork, shorter: float, longer: float) -> float:
    """A budget (MB) that holds the table of ``shorter`` but not the one of ``longer``."""
    sizes = [
        estimate_bytes(net.arrays, net.turns, bound, uturn_cost_m=DEFAULT_UTURN_COST_M)
        for bound in (shorter, longer)
    ]
    assert sizes[0] < sizes[1]
    return (sizes[0] + sizes[1]) / 2e6


def _read_back(cache: Path, budget_mb: float, bound_m: float) -> None:
    """A later process with ``budget_mb`` reads the stored table of ``bound_m`` as it is."""
    again = roadnets.load(MONACO, cache_dir=cache)
    again.route_table_budget_mb = budget_mb
    read = again.sparse_route_table()
    assert read is not None
    assert float(read.bounds_m.min()) == bound_m
    assert again.route_table_note.startswith("read from the cache entry: ")


def test_a_budget_short_of_the_longest_bound_keeps_the_longest_that_fits(tmp_path: Path) -> None:
    net = roadnets.load(MONACO, cache_dir=tmp_path)
    budget = _budget_between(net, 1000.0, 1100.0)
    net.route_table_budget_mb = budget
    table = net.sparse_route_table()
    assert table is not None
    assert float(table.bounds_m.min()) == 1000.0
    assert net.route_table_note.startswith("built and stored in the cache entry: ")
    assert net.route_table_note.endswith("MB, routes within 1,000 m")

    # the next process with the same budget (or a smaller one) reads it
    for later in (budget, 1.0, 0.0):
        _read_back(tmp_path, later, 1000.0)

    # a larger budget: the longest bound that fits it now is built in its place, and kept
    larger = roadnets.load(MONACO, cache_dir=tmp_path)
    larger.route_table_budget_mb = _budget_between(larger, 1500.0, 1750.0)
    wider = larger.sparse_route_table()
    assert wider is not None
    assert float(wider.bounds_m.min()) == 1500.0
    assert larger.route_table_note.startswith("built and stored in the cache entry: ")
    unbounded = roadnets.load(MONACO, cache_dir=tmp_path)
    unbounded.route_table_budget_mb = 10_000.0
    longest = unbounded.sparse_route_table()
    assert longest is not None
    assert float(longest.bounds_m.min()) == ROUTE_TABLE_BOUND_M
    for later in (10_000.0, 1.0):  # the longest bound is read whatever the budget
        again = roadnets.load(MONACO, cache_dir=tmp_path)
        again.route_table_budget_mb = later
        assert again.sparse_route_table() is not None
        assert again.route_table_note.startswith("read from the cache entry: ")
        assert again.route_table_note.endswith("routes within 2,000 m")


def test_sparse_traces_match_the_same_with_a_shorter_table_as_with_searches() -> None:
    with_table = roadnets.load(MONACO, use_cache=False)
    with_table.route_table_budget_mb = _budget_between(with_table, 800.0, 900.0)
    table = with_table.sparse_route_table()
    assert table is not None
    assert float(table.bounds_m.min()) == 800.0
    searching = roadnets.load(MONACO, use_cache=False)
    searching.route_table_budget_mb = 0.0
    assert searching.sparse_route_table() is None
    for interval, seed in ((15.0, 5), (30.0, 6)):  # 15 s steps fit in 800 m, 30 s ones not all
        cfg = SimulationConfig(interval_s=interval, noise_m=10.0, route_length_m=4000.0)
        for trip in simulate_trips(searching, cfg, count=4, seed=seed):
            documents = []
            for net in (with_table, searching):
                document = json.loads(geojson_bytes(mapmatch.match(trip.trace, net)))
                document["stats"].pop("timings_s")
                documents.append(document)
            assert documents[0] == documents[1]


def test_a_larger_budget_that_fits_no_longer_bound_is_recorded_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import roadnets.route_store as store

    net = roadnets.load(MONACO, cache_dir=tmp_path)
    net.route_table_budget_mb = _budget_between(net, 1000.0, 1100.0)
    assert net.sparse_route_table() is not None
    assert net.cache_entry is not None
    meta = Path(net.cache_entry) / ROUTES_FOLDER / "meta.json"
    stored = json.loads(meta.read_text())
    # a little more budget, still short of 1,100 m: the same table, the new budget noted
    more = net.route_table_budget_mb * 1.01
    _read_back(tmp_path, more, 1000.0)
    noted = json.loads(meta.read_text())
    assert noted["budget_mb"] == more
    assert noted["checksums"] == stored["checksums"]
    assert not [p for p in meta.parent.iterdir() if p.name.startswith(".meta-")]

    def no_estimates(*args: object, **kwargs: object) -> int:
        msg = "estimated again"
        raise AssertionError(msg)

    monkeypatch.setattr(store, "estimate_bytes", no_estimates)
    _read_back(tmp_path, more, 1000.0)  # at once, no estimate
