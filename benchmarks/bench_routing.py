"""Routing benchmark: node-based Dijkstra (today's matcher) vs the edge-based router.

    .venv/bin/python benchmarks/bench_routing.py [--extract PATH ...] [--traces 8] [--repeats 7]
        [--table-bound 500]

Default extracts: Monaco and Andorra from ../shared/data/osm (else the embedded Monaco), and
Bayfront from tests/data (via-way restrictions).

1. Matcher-like work: simulated traces (1 s / 5 m, 5 s / 8 m, 30 s / 20 m, 2 % outliers), the
   candidates ``mapmatch.hmm.candidates.find_candidates`` gives each fix with the default
   ``MatchConfig``, every candidate pair of consecutive fixes, bound ``2 x great-circle +
   300 m`` per step. CPU time summed over the traces, best of ``--repeats``:
   ``node``: one bounded node Dijkstra per distinct end node of the ``from`` edges, then the
   pairs' look-up (what the matcher does today); ``edge``: :meth:`RoadNetwork.edge_routes`
   (one search per distinct ``from`` edge, stopping at its targets); ``edge full``: complete
   edge-based trees, then the look-up. (Every fix's candidates are paired, as the matcher
   does, but without its thinning of fixes, so there are more pairs than it routes.)
2. Random edges, bound 600 m (``2 x 300 m``): complete trees, node vs edge, per source.
3. Precomputed network-wide tables (``precompute_paths`` vs ``precompute_routes``): build
   time and size.
4. Every returned route is checked against the banned pairs and banned sequences.
5. The route table for sparse traces in the matcher (:mod:`roadnets.route_store`, on by
   default): its build time and size, then ``mapmatch.match`` on simulated positions-only
   trips per interval with and without it, interleaved, the median wall time of
   ``--repeats`` passes: points/s both ways, their ratio, the trips' mean search bound
   (a trace asks for the table from ``TABLE_FROM_MEAN_BOUND_M`` on) and the trips whose match
   differs (must be 0: the table answers what the searches would).
"""

from __future__ import annotations

import argparse
import datetime
import itertools
import logging
import os
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import roadnets  # noqa: E402
from mapmatch.config import MatchConfig  # noqa: E402
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trips  # noqa: E402
from mapmatch.hmm.candidates import find_candidates  # noqa: E402
from roadnets.routing import shortest_path_table  # noqa: E402

if TYPE_CHECKING:
    from collections.abc import Callable

    import mapmatch

SHARED = ROOT.parent / "shared" / "data" / "osm"
SETS = [(1.0, 5.0), (5.0, 8.0), (30.0, 20.0)]


def workload(
    net: roadnets.RoadNetwork, trace: mapmatch.Trace, config: MatchConfig
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(from edge, to edge, bound)`` of every candidate pair of consecutive fixes."""
    x, y = net.project(trace.lon, trace.lat)
    radius = np.full(len(x), config.search_radius_m)
    cands = find_candidates(net, x, y, radius, config)
    counts = np.diff(cands.ptr)
    step_m = np.hypot(np.diff(x), np.diff(y))
    bound = config.route_factor * step_m + config.route_slack_m
    a_list, b_list, bound_list = [], [], []
    for t in range(len(x) - 1):
        ea = cands.edge[cands.ptr[t] : cands.ptr[t + 1]]
        eb = cands.edge[cands.ptr[t + 1] : cands.ptr[t + 2]]
        if counts[t] and counts[t + 1]:
            a_list.append(np.repeat(ea, len(eb)))
            b_list.append(np.tile(eb, len(ea)))
            bound_list.append(np.full(len(ea) * len(eb), bound[t]))
    return np.concatenate(a_list), np.concatenate(b_list), np.concatenate(bound_list)


def node_based(net: roadnets.RoadNetwork, a: np.ndarray, b: np.ndarray, bound: np.ndarray) -> None:
    arrays = net.arrays
    table = shortest_path_table(arrays, arrays.edge_v[a], bound)
    table.lookup(arrays.edge_v[a], arrays.edge_u[b])


def edge_full(net: roadnets.RoadNetwork, a: np.ndarray, b: np.ndarray, bound: np.ndarray) -> None:
    net.route_table(a, bound).lookup(a, b)


def edge_pairs(net: roadnets.RoadNetwork, a: np.ndarray, b: np.ndarray, bound: np.ndarray) -> None:
    net.edge_routes(a, b, bound)


def timed(fn: Callable[[], object], repeats: int) -> float:
    """Best CPU time of ``repeats`` runs (other processes share the cores)."""
    runs = []
    for _ in range(repeats):
        started = time.process_time()
        fn()
        runs.append(time.process_time() - started)
    return min(runs)


def check_routes(net: roadnets.RoadNetwork, routes: roadnets.EdgeRoutes, limit: int = 3000) -> int:
    """Assert that no route of ``routes`` breaks a restriction; return how many were checked."""
    arrays = net.arrays
    banned = set(zip(arrays.banned_in.tolist(), arrays.banned_out.tolist(), strict=True))
    seqs = [
        tuple(arrays.banned_seq_edge[lo:hi].tolist())
        for lo, hi in zip(arrays.banned_seq_ptr[:-1], arrays.banned_seq_ptr[1:], strict=True)
    ]
    found = np.flatnonzero(routes.record >= 0)[:limit]
    for i in found.tolist():
        a, b = int(routes.from_edge[i]), int(routes.to_edge[i])
        drive = [a, *routes.table.path(int(routes.record[i])), b]
        pairs = set(itertools.pairwise(drive))
        assert not pairs & banned, (a, b, drive)
        text = "," + ",".join(map(str, drive)) + ","
        for seq in seqs:
            assert "," + ",".join(map(str, seq)) + "," not in text, (a, b, drive, seq)
    return len(found)


def bench_matcher_work(net: roadnets.RoadNetwork, traces: int, repeats: int) -> list[str]:
    config = MatchConfig()
    lines = []
    for interval, noise in SETS:
        cfg = SimulationConfig(interval_s=interval, noise_m=noise, outlier_rate=0.02)
        trips = simulate_trips(net, cfg, count=traces, seed=11)
        work = [workload(net, trip.trace, config) for trip in trips]
        points = sum(len(trip.trace) for trip in trips)
        pairs = sum(len(w[0]) for w in work)
        sources_e = sum(len(np.unique(w[0])) for w in work)
        sources_n = sum(len(np.unique(net.arrays.edge_v[w[0]])) for w in work)
        for w in work[:1]:  # compile / warm
            node_based(net, *w)
            edge_full(net, *w)
            edge_pairs(net, *w)
        t_node = timed(lambda work=work: [node_based(net, *w) for w in work], repeats)
        t_edge = timed(lambda work=work: [edge_pairs(net, *w) for w in work], repeats)
        t_full = timed(lambda work=work: [edge_full(net, *w) for w in work], repeats)
        checked = sum(check_routes(net, net.edge_routes(*w)) for w in work)
        lines.append(
            f"| {net.network_id} | {interval:g} s | {points:,} | {pairs:,} | {sources_n:,} / "
            f"{sources_e:,} | {1000 * t_node:.1f} | {1000 * t_edge:.1f} | {1000 * t_full:.1f} "
            f"| {t_edge / t_node:.2f} | {t_full / t_node:.2f} | {checked:,} |"
        )
        print(lines[-1], flush=True)
    return lines


def bench_random(net: roadnets.RoadNetwork, count: int, repeats: int) -> str:
    rng = np.random.default_rng(5)
    arrays = net.arrays
    edges = rng.choice(arrays.n_edges, size=min(count, arrays.n_edges), replace=False)
    bound = 600.0
    shortest_path_table(arrays, arrays.edge_v[edges[:2]], bound)
    net.route_table(edges[:2], bound)
    t_node = timed(
        lambda: shortest_path_table(arrays, np.unique(arrays.edge_v[edges]), bound), repeats
    )
    t_edge = timed(lambda: net.route_table(edges, bound), repeats)
    n_nodes = len(np.unique(arrays.edge_v[edges]))
    records = len(net.route_table(edges, bound).state)
    return (
        f"| {net.network_id} | {len(edges):,} edges / {n_nodes:,} nodes | "
        f"{1e6 * t_node / n_nodes:.0f} | {1e6 * t_edge / len(edges):.0f} | "
        f"{t_edge / t_node:.2f} | {records / len(edges):.0f} |"
    )


def bench_tables(net: roadnets.RoadNetwork, bound: float) -> str:
    started = time.perf_counter()
    node_table = net.precompute_paths(bound)
    t_node = time.perf_counter() - started
    started = time.perf_counter()
    edge_table = net.precompute_routes(bound)
    edge_table.records(np.array([0]), np.array([0]))  # builds the look-up index
    t_edge = time.perf_counter() - started
    net.precomputed = None
    net.precomputed_routes = None
    return (
        f"| {net.network_id} | {bound:g} | {net.arrays.n_nodes:,} / {net.arrays.n_edges:,} | "
        f"{t_node:.2f} | {node_table.nbytes / 2**20:.1f} | {t_edge:.2f} | "
        f"{edge_table.nbytes / 2**20:.1f} | {len(edge_table.state):,} |"
    )


SPARSE_SETS = [(1.0, 5.0), (5.0, 8.0), (10.0, 10.0), (15.0, 10.0), (30.0, 20.0)]


def bench_sparse_table(net: roadnets.RoadNetwork, traces: int, repeats: int) -> list[str]:
    """Rows of section 5 for one network (the table is built here, in memory)."""
    from mapmatch.evaluation.accuracy.conditions import columns_of
    from mapmatch.evaluation.simulate import with_columns
    from mapmatch.hmm.routes import route_search_bounds
    from mapmatch.hmm.transition import TABLE_FROM_MEAN_BOUND_M
    from mapmatch.matcher import match
    from roadnets.route_store import ROUTE_TABLE_BOUND_M, build_table, table_bytes
    from roadnets.turns import DEFAULT_UTURN_COST_M

    started = time.perf_counter()
    table = build_table(
        net.arrays, net.turns, ROUTE_TABLE_BOUND_M, uturn_cost_m=DEFAULT_UTURN_COST_M
    )
    build_s = time.perf_counter() - started
    net.route_table_budget_mb = 0  # no background table of its own during the runs
    rows = []
    for interval, noise in SPARSE_SETS:
        cfg = SimulationConfig(interval_s=interval, noise_m=noise)
        simulated = simulate_trips(net, cfg, count=traces, seed=11)
        trips = [with_columns(trip.trace, columns_of("positions")) for trip in simulated]
        points = sum(len(t) for t in trips)
        bounds = []
        for t in trips:
            x, y = net.project(t.lon, t.lat)
            step = np.hypot(np.diff(x), np.diff(y))
            bounds.append(route_search_bounds(step, np.diff(t.time_s), MatchConfig()).mean())
        wall: dict[bool, list[float]] = {False: [], True: []}
        results: dict[bool, list[tuple[float, list[int]]]] = {}
        for _ in range(repeats):
            for use in (False, True):
                net.precomputed_routes = table if use else None
                match(trips[0], net)
                started = time.perf_counter()
                out = [match(t, net) for t in trips]
                wall[use].append(time.perf_counter() - started)
                results[use] = [
                    (r.matched_length_m, [e for s in r.segments for e in s.edge.tolist()])
                    for r in out
                ]
        net.precomputed_routes = None
        searched, answered = (float(np.median(wall[u])) for u in (False, True))
        differ = sum(a != b for a, b in zip(results[False], results[True], strict=True))
        rows.append(
            f"| {net.network_id} | {interval:g} s / {noise:g} m | {points:,} | "
            f"{np.mean(bounds):.0f} | {points / searched:,.0f} | {points / answered:,.0f} | "
            f"{searched / answered:.2f} | {differ} |"
        )
    head = (
        f"- {net.network_id}: table of routes within {ROUTE_TABLE_BOUND_M:g} m built in "
        f"{build_s:.2f} s, {table_bytes(table) / 1e6:,.0f} MB; a trace asks for it from a "
        f"mean bound of {TABLE_FROM_MEAN_BOUND_M:g} m, and any uses it once it is there"
    )
    return [head, *rows]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--extract", action="append", type=Path, default=None)
    parser.add_argument("--traces", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--random", type=int, default=500, help="random source edges")
    parser.add_argument("--table-bound", type=float, action="append", default=None)
    args = parser.parse_args()
    logging.getLogger("mapmatch").setLevel(logging.ERROR)
    default = [SHARED / "monaco_2020.osm.pbf", SHARED / "andorra_2020.osm.pbf"]
    extracts = args.extract or [
        *([p for p in default if p.exists()] or [roadnets.default_network_path()]),
        ROOT / "tests" / "data" / "bayfront_singapore_2019.osm.pbf",  # via-way restrictions
    ]
    nets = [roadnets.load(path) for path in extracts]
    print(f"{datetime.date.today()}, {os.cpu_count()} cores, best CPU time of {args.repeats}\n")
    for net in nets:
        info = net.info()
        print(
            f"- {net.network_id}: {info.nodes:,} nodes, {info.edges:,} edges, "
            f"{info.turn_restrictions} banned pairs, {info.banned_sequences} banned sequences, "
            f"{net.turns.n_states - info.edges} restricted copies"
        )
    print(
        "\n| network | set | points | pairs | sources node / edge | node ms | edge ms "
        "| edge full ms | edge / node | full / node | routes checked |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for net in nets:
        bench_matcher_work(net, args.traces, args.repeats)
    print(
        "\n| network | sources | node µs/source | edge µs/source | edge / node (total) "
        "| records/source |"
    )
    print("|---|---|---:|---:|---:|---:|")
    for net in nets:
        print(bench_random(net, args.random, args.repeats), flush=True)
    print(
        "\n| network | bound m | nodes / edges | node table s | node table MB | edge table s "
        "| edge table MB | edge records |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for net in nets:
        for bound in args.table_bound or [500.0, 1000.0]:
            print(bench_tables(net, bound), flush=True)
    print(f"\nRoute table for sparse traces, median wall time of {args.repeats} passes:\n")
    rows = [bench_sparse_table(net, args.traces, args.repeats) for net in nets]
    print("\n".join(r[0] for r in rows))
    print(
        "\n| network | set | points | mean bound m | searched points/s | table points/s "
        "| table / searched | trips differing |"
    )
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    print("\n".join(line for r in rows for line in r[1:]))


if __name__ == "__main__":
    main()
