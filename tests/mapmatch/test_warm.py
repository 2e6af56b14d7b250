"""The warm-up (``mapmatch network build``, the batch's fork server) compiles what users send."""

from __future__ import annotations

import json
import subprocess
import sys

#: Run in a fresh process: the warm-up, then a match of every kind of input a user sends,
#: printing each kernel that needed a new compiled variant for it (numba compiles one per
#: argument types: a first request of a kind the warm-up missed waits for the compiler).
_PROBE = """
import json, sys
from mapmatch.batch.warm import WARMUP_S, block_graph
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

assert WARMUP_S > 0, "the warm-up failed"
net = roadnets.from_graph(block_graph(), network_id="probe")
lon = [7.4201, 7.4206, 7.4211, 7.4212, 7.4212]
lat = [43.73001, 43.73002, 43.73001, 43.7304, 43.7308]
time = [0.0, 5.0, 10.0, 15.0, 20.0]
kinds = {
    "no times": mapmatch.Trace(lon=lon, lat=lat),
    "positions": mapmatch.Trace(time=time, lon=lon, lat=lat),
    "heading": mapmatch.Trace(time=time, lon=lon, lat=lat, heading=[90, 90, 90, 0, 0]),
    "accuracy": mapmatch.Trace(time=time, lon=lon, lat=lat, accuracy=[5.0] * 5),
    "speed": mapmatch.Trace(time=time, lon=lon, lat=lat, speed=[4.0] * 5),
    "odometer": mapmatch.Trace(time=time, lon=lon, lat=lat, odometer=[0, 40, 80, 110, 150]),
    "heading, speed": mapmatch.Trace(
        time=time, lon=lon, lat=lat, heading=[90, 90, 90, 0, 0], speed=[4.0] * 5
    ),
}
compiled = {}
for kind, trace in kinds.items():
    before = variants()
    geojson_bytes(mapmatch.match(trace, net))
    compiled[kind] = sorted(k for k, v in variants().items() if v != before.get(k, 0))
print(json.dumps(compiled))
"""


def test_the_warm_up_compiles_every_kind_of_input() -> None:
    done = subprocess.run(
        [sys.executable, "-c", _PROBE], capture_output=True, text=True, timeout=600, check=False
    )
    assert done.returncode == 0, done.stderr
    compiled = json.loads(done.stdout.strip().splitlines()[-1])
    assert compiled == {kind: [] for kind in compiled}, compiled
