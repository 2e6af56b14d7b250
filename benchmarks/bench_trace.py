"""Input-validation benchmark: the fixed cost of building a ``Trace`` (issue 15).

    .venv/bin/python benchmarks/bench_trace.py [--batch 300] [--repeats 40]

Times ``Trace(time=..., lon=..., lat=...)`` from float64 numpy arrays (the path the batch
and the peer harness take), with and without heading, speed and accuracy; the same trace
from Python lists of floats, and from point dicts (``Trace.from_records``, the service's JSON
body) with epoch or UTC ISO-8601 times; none of them needs pandas (other time text, id keys,
DataFrames and files do). At 2, 30 and 100 points; process CPU time per trace, best of
``--repeats`` batches of ``--batch`` (the machine is shared: the best batch is the least
disturbed one).

To compare with an older tree, run this file with that tree first on ``PYTHONPATH``.
"""

from __future__ import annotations

import argparse
import sys
import time
import timeit
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.append(str(ROOT))

from mapmatch import Trace  # noqa: E402

if TYPE_CHECKING:
    from collections.abc import Callable


def _cases(n: int) -> list[tuple[str, Callable[[], object]]]:
    rng = np.random.default_rng(n)
    t = np.arange(n, dtype=np.float64) * 15.0 + 1.7e9
    lon = 7.42 + np.cumsum(rng.uniform(0.0, 1e-3, n))
    lat = 43.73 + np.cumsum(rng.uniform(0.0, 1e-3, n))
    heading, speed, accuracy = np.full(n, 90.0), np.full(n, 5.0), np.full(n, 4.0)
    lists = {"time": t.tolist(), "lon": lon.tolist(), "lat": lat.tolist()}
    records = [{"time": a, "lon": b, "lat": c} for a, b, c in zip(*lists.values(), strict=True)]
    iso = np.datetime_as_string(t.astype("datetime64[s]"), timezone="UTC").tolist()
    text = [{**r, "time": stamp} for r, stamp in zip(records, iso, strict=True)]
    return [
        ("arrays: time, lon, lat", lambda: Trace(time=t, lon=lon, lat=lat)),
        (
            "arrays: + heading, speed, accuracy",
            lambda: Trace(
                time=t, lon=lon, lat=lat, heading=heading, speed=speed, accuracy=accuracy
            ),
        ),
        ("lists: time, lon, lat", lambda: Trace(**lists)),
        ("from_records", lambda: Trace.from_records(records)),
        ("from_records, ISO-8601 times", lambda: Trace.from_records(text)),
    ]


def main(argv: list[str] | None = None) -> int:
    """Print the cost per trace of each way of building one."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=300, help="traces per timed batch")
    parser.add_argument("--repeats", type=int, default=40, help="timed batches per case")
    args = parser.parse_args(argv)
    print(f"Trace construction, process CPU time per trace (best of {args.repeats} x {args.batch})")
    for n in (2, 30, 100):
        for name, build in _cases(n):
            build()
            best = min(
                timeit.repeat(
                    build, number=args.batch, repeat=args.repeats, timer=time.process_time
                )
            )
            print(f"  {n:3d} points  {name:36s} {best / args.batch * 1e6:8.1f} us")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
