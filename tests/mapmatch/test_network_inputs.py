"""The network's kernel inputs: made once per network, route table and thread."""

from __future__ import annotations

import threading
from pathlib import Path

import roadnets
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trip
from mapmatch.hmm.network_inputs import NetworkInputs, network_inputs
from mapmatch.hmm.transition import route_inputs
from mapmatch.matcher import match

OAKLAND = Path(__file__).parents[1] / "data" / "west-oakland_us.osm.bz2"


def test_kept_per_thread_and_made_again_when_the_route_table_arrives(tmp_path: Path) -> None:
    net = roadnets.load(OAKLAND, cache_dir=tmp_path)
    first = network_inputs(net)
    assert isinstance(first, NetworkInputs)
    assert network_inputs(net) is first  # the same object for every match of this thread
    others: list[NetworkInputs] = []
    thread = threading.Thread(target=lambda: others.append(network_inputs(net)))
    thread.start()
    thread.join()
    assert others[0] is not first  # each thread its own search scratch
    trip = simulate_trip(net, SimulationConfig(interval_s=15.0, noise_m=10.0), seed=3).trace
    before = match(trip, net)
    assert net.route_table_requested  # a sparse trace asked for the table
    assert net.sparse_route_table() is not None
    assert route_inputs(net)[4][0] > 0  # the table's bound: the kernels may read it now
    assert network_inputs(net) is not first
    after = match(trip, net)
    assert after.matched_length_m == before.matched_length_m
    assert [s.edge.tolist() for s in after.segments] == [s.edge.tolist() for s in before.segments]
