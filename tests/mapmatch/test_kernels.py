"""The compiled matching stages: the same numbers as numpy, the same matches from any thread."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest

import mapmatch
from mapmatch._sums import pairwise_sum
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trips, strip_to_class

if TYPE_CHECKING:
    import roadnets

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("n", [0, 1, 7, 8, 9, 127, 128, 129, 200, 1031, 4097, 70_000])
def test_pairwise_sum_adds_as_numpy_does(n: int) -> None:
    # the loop pricing sums log-likelihoods as np.sum did: the same bits, not just close
    rng = np.random.default_rng(n)
    a = rng.normal(size=n + 5) * 10 ** rng.uniform(-4, 4, n + 5)
    assert pairwise_sum(a, 0, n) == np.sum(a[:n])
    assert pairwise_sum(a, 3, n) == np.sum(a[3 : 3 + n])


def _outcome(result: mapmatch.MatchResult) -> tuple[object, ...]:
    points = result.points
    edges = tuple(tuple(s.edge.tolist()) for s in result.segments)
    return (edges, result.matched_length_m, points.edge.tolist(), points.offset_m.tobytes())


def _traces(net: roadnets.RoadNetwork) -> list[mapmatch.Trace]:
    out = []
    for interval in (1.0, 15.0):
        cfg = SimulationConfig(interval_s=interval, noise_m=8.0, outlier_rate=0.05)
        for trip in simulate_trips(net, cfg, count=4, seed=31):
            out.append(strip_to_class(trip.trace, "heading_speed"))
    return out


def test_threads_matching_at_once_get_what_one_thread_gets(
    default_net: roadnets.RoadNetwork,
) -> None:
    # the kernels run without the GIL and every thread has its own router scratch
    traces = _traces(default_net)
    alone = [_outcome(mapmatch.match(t, default_net)) for t in traces]
    with ThreadPoolExecutor(4) as pool:
        together = list(pool.map(lambda t: _outcome(mapmatch.match(t, default_net)), traces * 4))
    assert together == alone * 4


def test_a_process_loading_the_kernels_from_the_cache_matches_the_same(
    default_net: roadnets.RoadNetwork, tmp_path: Path
) -> None:
    # numba caches each kernel on disk; a process that loads them all from there (a second
    # run) must compute what the process that compiled them did
    code = (
        "import json, sys, roadnets, mapmatch\n"
        "from mapmatch.evaluation.simulate import SimulationConfig, simulate_trips\n"
        "net = roadnets.load(cache_dir=sys.argv[1])\n"
        "cfg = SimulationConfig(interval_s=5.0, noise_m=15.0, outlier_rate=0.1)\n"
        "trips = simulate_trips(net, cfg, count=6, seed=8)\n"
        "print(json.dumps([mapmatch.match(t.trace, net).matched_length_m for t in trips]))\n"
    )
    env = {"NUMBA_CACHE_DIR": str(tmp_path / "numba"), "PATH": "/usr/bin:/bin"}
    runs = []
    for _ in range(2):  # the first compiles and writes the cache, the second loads it
        out = subprocess.run(
            [sys.executable, "-c", code, str(tmp_path / "nets")],
            capture_output=True,
            text=True,
            check=True,
            cwd=ROOT,
            env={**env, "PYTHONPATH": str(ROOT)},
            timeout=900,
        )
        runs.append(out.stdout.strip().splitlines()[-1])
    cfg = SimulationConfig(interval_s=5.0, noise_m=15.0, outlier_rate=0.1)
    trips = simulate_trips(default_net, cfg, count=6, seed=8)
    here = [mapmatch.match(t.trace, default_net).matched_length_m for t in trips]
    assert runs[0] == runs[1]
    assert json.loads(runs[0]) == here


def test_a_fresh_install_is_told_that_the_first_match_compiles(tmp_path: Path) -> None:
    # an empty numba cache is a fresh install: the first match says it compiles, once
    code = (
        "import logging, sys\n"
        "logging.basicConfig(stream=sys.stdout, level=logging.WARNING)\n"
        "from mapmatch.hmm.kernels import kernels_on_disk\n"
        "from mapmatch.matcher import _announce_compile\n"
        "print(kernels_on_disk())\n"
        "_announce_compile(); _announce_compile()\n"
    )
    out = _python(code, NUMBA_CACHE_DIR=str(tmp_path))
    lines = out.stdout.splitlines()
    assert lines[0] == "False", out.stderr
    assert sum("compiling the matcher's kernels" in line for line in lines) == 1


def test_import_mapmatch_loads_no_compiler_and_no_heavy_library() -> None:
    # `import mapmatch` stays light: the kernels (and numba) load when a match first needs them,
    # also those the result and the distance check call (imported inside their functions)
    code = (
        "import sys, mapmatch\n"
        "heavy = ('numba', 'networkx', 'shapely', 'osmnx', 'pyproj', 'rtree', 'pandas')\n"
        "print([m for m in heavy if m in sys.modules])\n"
    )
    out = _python(code, PYTHONPATH=str(ROOT))
    assert out.stdout.strip() == "[]", out.stderr


def _python(code: str, **env: str) -> subprocess.CompletedProcess[str]:
    """``code`` run by a new interpreter with ``env`` added to this process's environment."""
    return subprocess.run(
        [sys.executable, "-c", code],
        env={**os.environ, **env},
        capture_output=True,
        text=True,
        timeout=120,
    )
