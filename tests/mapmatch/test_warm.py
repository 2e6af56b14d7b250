"""The warm-up (``mapmatch network build``, the batch's fork server) compiles what users send."""

from __future__ import annotations

import json
import subprocess
import sys
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from pathlib import Path

#: Run in a fresh process: the warm-up, then a match of every kind of input a user sends,
#: printing each kernel that needed a new compiled variant for it (numba compiles one per
#: argument types: a first request of a kind the warm-up missed waits for the compiler, half a
#: minute on a slow machine, past a service's time budget). The kinds run on the warm-up's
#: block and on the embedded network with its route table read from a cache entry (memory
#: mapped, as a service or a batch worker reads it): every column set, with and without
#: usable times, dense traces (routes searched) and sparse ones (routes from the table), with
#: the options that choose a path through the model; records with gaps; two live trips.
_PROBE = """
import itertools, json, sys
from mapmatch.batch.warm import WARMUP_S
from mapmatch.online.warm import warm_up_live
from mapmatch.warm_block import BLOCK_FIXES, OPTIONAL_COLUMNS, block_network
import mapmatch, roadnets
from mapmatch.export import geojson_bytes
from numba.core.registry import CPUDispatcher

def variants():
    out = {}
    for name, module in list(sys.modules.items()):
        if name.startswith(("mapmatch", "roadnets")):
            for attr, value in list(vars(module).items()):
                if isinstance(value, CPUDispatcher):
                    out[name + "." + attr] = len(value.signatures)
    return out

def kinds(lon, lat, time, columns):
    # every set of optional columns, with times and without, and times too far apart to be
    # believed (the model then ignores them, as a file without times)
    times = {"times": time, "no times": None, "implausible times": [t * 1e-3 for t in time]}
    for (said, given), on in itertools.product(
        times.items(), itertools.product((False, True), repeat=len(columns))
    ):
        chosen = {k: v for (k, v), o in zip(columns.items(), on) if o}
        name = ", ".join([said, *chosen]) if chosen else said
        yield name, mapmatch.Trace(time=given, lon=lon, lat=lat, **chosen)

assert WARMUP_S > 0, "the warm-up failed"
assert warm_up_live() > 0, "the live warm-up failed"  # as network build does
block = block_network()
lon, lat, time = ([fix[k] for fix in BLOCK_FIXES] for k in ("lon", "lat", "time"))
columns = {k: [fix[k] for fix in BLOCK_FIXES] for k in OPTIONAL_COLUMNS}
cases = [("block: " + name, trace, block) for name, trace in kinds(lon, lat, time, columns)]
# points as a service receives them: a column given on some points only, repeated places
records = [
    {"time": 10.0, "lon": lon[0], "lat": lat[0], "accuracy": 60.0},
    {"time": 0.0, "lon": lon[1], "lat": lat[1], "heading": 1e-300, "odometer": 1e-38},
    {"time": 5.0, "lon": lon[1], "lat": lat[1], "speed": 0.0, "heading": -110.0},
    {"time": 12.0, "lon": lon[4], "lat": lat[4], "accuracy": 200.0},
]
cases.append(("block: records with gaps", mapmatch.Trace.from_records(records), block))

cache = sys.argv[1]
roadnets.load(roadnets.default_network_path(), cache_dir=cache).sparse_route_table()
net = roadnets.load(roadnets.default_network_path(), cache_dir=cache)
assert net.sparse_route_table() is not None
assert net.route_table_note.startswith("read from the cache entry"), net.route_table_note
(sample,) = mapmatch.read_traces(mapmatch.__path__[0] + "/data/sample_trace.csv")
for every in (1, 30):  # a dense trace (routes searched) and a sparse one (from the table)
    part = slice(None, None, every)
    lon, lat = sample.lon[part].tolist(), sample.lat[part].tolist()
    time = sample.time_s[part].tolist()
    columns = {
        "heading": sample.heading_deg[part].tolist(),
        "speed": sample.speed_mps[part].tolist(),
        "accuracy": sample.accuracy_m[part].tolist(),
        "odometer": sample.odometer_m[part].tolist(),
    }
    for name, trace in kinds(lon, lat, time, columns):
        cases.append((f"embedded, every {every}: {name}", trace, net))

# the options a request may set that choose a path through the model rather than a number
options = [
    {"use_travel": False}, {"estimate_sigma": False}, {"thinning_sigmas": 0.0},
    {"outlier_sigmas": 0.0}, {"max_candidates": 1}, {"standstill_m": 0.0},
]
for name, trace, network in cases[-2 * 3 * 16:]:
    if name.endswith(("times", "heading, speed, accuracy, odometer")):
        for option in options:
            cases.append((f"{name} ({option})", trace, network, option))
compiled = {}
for kind, trace, network, *option in cases:
    before = variants()
    config = mapmatch.MatchConfig(**option[0]) if option else None
    geojson_bytes(mapmatch.match(trace, network, config))
    compiled[kind] = sorted(k for k, v in variants().items() if v != before.get(k, 0))
# a live trip (the online matcher matches the open tail of the trip as fixes arrive)
for name, fields in (
    ("live: positions", ("time", "lon", "lat")),
    ("live: every column", ("time", "lon", "lat", "heading", "speed", "accuracy", "odometer")),
):
    columns = {
        "time": sample.time_s, "lon": sample.lon, "lat": sample.lat,
        "heading": sample.heading_deg, "speed": sample.speed_mps,
        "accuracy": sample.accuracy_m, "odometer": sample.odometer_m,
    }
    before = variants()
    live = mapmatch.OnlineMatcher(net, lag=30.0, trip_id="probe")
    for i in range(0, 120, 3):
        live.push({k: float(columns[k][i]) for k in fields})
    geojson_bytes(live.close())
    compiled[name] = sorted(k for k, v in variants().items() if v != before.get(k, 0))
print(json.dumps({"compiled": compiled, "variants": variants()}))
"""

#: The kernels that have more than one compiled variant once every kind of input has run, and
#: why: each variant is compiled at install and loaded by every process that matches, so a
#: kernel has one unless its callers' arrays truly differ in type (numba's type of an array
#: includes whether it is writable: the model hands its kernels read-only per-fix arrays).
SEVERAL_VARIANTS = {
    # a trace's read-only columns, and a network's own node arrays as it is built
    "_forward": 2,
}


def test_the_warm_up_compiles_every_kind_of_input(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-c", _PROBE, str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=900,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    found = json.loads(done.stdout.strip().splitlines()[-1])
    compiled = found["compiled"]
    assert len(compiled) == 3 * 16 + 1 + 2 * 3 * 16 + 2 * 6 * 6 + 2
    missed = {kind: kernels for kind, kernels in compiled.items() if kernels}
    assert not missed, missed
    several = {
        name: count
        for name, count in found["variants"].items()
        if count > SEVERAL_VARIANTS.get(name.rsplit(".", 1)[1], 1)
    }
    assert not several, several
