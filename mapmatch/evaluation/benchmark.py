"""Speed and accuracy of the matcher on simulated traces (``mapmatch bench``, benchmarks/)."""

from __future__ import annotations

import statistics
import time
import tracemalloc
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

from mapmatch.config import MatchConfig
from mapmatch.evaluation.scoring import score_geojson, summarise
from mapmatch.evaluation.simulate import SimulationConfig, simulate_trips
from mapmatch.matcher import match

if TYPE_CHECKING:
    from collections.abc import Sequence

    from roadnets import RoadNetwork

__all__ = ["BenchRow", "bench_network", "markdown_table", "parse_sets"]


@dataclass(frozen=True, slots=True)
class BenchRow:
    """One benchmark line: a network and a sampling set."""

    network: str
    interval_s: float
    noise_m: float
    traces: int
    points: int
    seconds: float
    points_per_s: float
    peak_mb: float
    mismatch_mean: float
    mismatch_median: float
    point_accuracy: float
    length_error_mean: float
    length_error_abs_max: float

    def to_dict(self) -> dict[str, Any]:
        """Plain dictionary."""
        return asdict(self)


def parse_sets(text: str) -> list[tuple[float, float]]:
    """
    Parse ``"1:5,15:10"`` into ``[(interval_s, noise_m), ...]``.

    Examples
    --------
    >>> parse_sets("1:5,30:20")
    [(1.0, 5.0), (30.0, 20.0)]
    """
    out = []
    for part in text.split(","):
        interval, noise = part.split(":")
        out.append((float(interval), float(noise)))
    return out


def bench_network(
    net: RoadNetwork,
    sets: Sequence[tuple[float, float]],
    *,
    traces: int = 20,
    repeats: int = 3,
    outlier_rate: float = 0.02,
    route_length_m: float = 4000.0,
    seed: int = 100,
    config: MatchConfig | None = None,
) -> list[BenchRow]:
    """
    Time and score the matcher on simulated traces of one network.

    For each ``(interval_s, noise_m)`` set: simulate ``traces`` trips, match them once to warm
    up, then ``repeats`` times timing only the matching (network loaded, compiled kernels
    warm); points/s is the median over the repeats. Peak memory is the largest allocation
    peak (tracemalloc, numpy included) while matching one trace, measured in a separate pass.
    """
    config = config or MatchConfig()
    rows: list[BenchRow] = []
    for interval_s, noise_m in sets:
        sim = SimulationConfig(
            interval_s=interval_s,
            noise_m=noise_m,
            outlier_rate=outlier_rate,
            route_length_m=route_length_m,
        )
        trips = simulate_trips(net, sim, count=traces, seed=seed)
        results = [match(t.trace, net, config) for t in trips]
        elapsed = []
        for _ in range(repeats):
            started = time.perf_counter()
            for trip in trips:
                match(trip.trace, net, config)
            elapsed.append(time.perf_counter() - started)
        seconds = statistics.median(elapsed)
        points = sum(len(t.trace) for t in trips)
        peak = 0
        for trip in trips:
            tracemalloc.start()
            match(trip.trace, net, config)
            peak = max(peak, tracemalloc.get_traced_memory()[1])
            tracemalloc.stop()
        scores = [
            score_geojson(r.to_geojson(), t.truth_record())
            for r, t in zip(results, trips, strict=True)
        ]
        summary = summarise(scores)
        rows.append(
            BenchRow(
                network=net.network_id,
                interval_s=interval_s,
                noise_m=noise_m,
                traces=len(trips),
                points=points,
                seconds=seconds,
                points_per_s=points / seconds,
                peak_mb=peak / 2**20,
                mismatch_mean=summary["mismatch_mean"],
                mismatch_median=summary["mismatch_median"],
                point_accuracy=summary["point_accuracy"],
                length_error_mean=summary["length_error_mean"],
                length_error_abs_max=summary["length_error_abs_max"],
            )
        )
    return rows


def markdown_table(rows: Sequence[BenchRow]) -> str:
    """The rows as a markdown table."""
    lines = [
        "| network | interval | noise | traces | points | points/s | peak MB | mismatch mean "
        "| mismatch median | fixes on right edge | length error mean | worst abs length error |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r.network} | {r.interval_s:g} s | {r.noise_m:g} m | {r.traces} | {r.points:,} "
            f"| {r.points_per_s:,.0f} | {r.peak_mb:.1f} | {r.mismatch_mean:.2%} "
            f"| {r.mismatch_median:.2%} | {r.point_accuracy:.1%} | {r.length_error_mean:+.2%} "
            f"| {r.length_error_abs_max:.2%} |"
        )
    return "\n".join(lines)
