"""
Prometheus metrics of the service (``GET /metrics``).

Per process by default. When ``PROMETHEUS_MULTIPROC_DIR`` is set (``mapmatch serve --workers N``
with N > 1 sets it to a fresh folder), every worker writes its values there and ``/metrics``
answers the sum over all workers, whichever worker takes the scrape. Only counters and
histograms are used, which sum correctly across workers (a worker that died keeps its counts).
"""

from __future__ import annotations

import os

from prometheus_client import (
    CONTENT_TYPE_LATEST,
    CollectorRegistry,
    Counter,
    Histogram,
    generate_latest,
)
from prometheus_client import multiprocess as prom_multiprocess

__all__ = ["MULTIPROC_ENV", "ServiceMetrics"]

#: Environment variable that switches prometheus_client to multi-process mode.
MULTIPROC_ENV = "PROMETHEUS_MULTIPROC_DIR"

_LATENCY_BUCKETS_S = (0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0)


class ServiceMetrics:
    """The metrics of one app, in a registry of their own (several apps may share a process)."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry(auto_describe=True)
        self.requests = Counter(
            "mapmatch_http_requests",
            "HTTP requests answered, by route template, method and status.",
            ("route", "method", "status"),
            registry=self.registry,
        )
        self.latency = Histogram(
            "mapmatch_http_request_duration_seconds",
            "Time from request to the end of the answer, by route template and status.",
            ("route", "status"),
            buckets=_LATENCY_BUCKETS_S,
            registry=self.registry,
        )
        self.matches = Counter(
            "mapmatch_matches",
            "Match requests by outcome (the error code, or ok).",
            ("outcome",),
            registry=self.registry,
        )
        self.points = Counter(
            "mapmatch_points_matched",
            "Points of successfully matched traces (after dropping repeated times).",
            registry=self.registry,
        )
        self.matched_points = Counter(
            "mapmatch_points_on_road",
            "Points placed on a road.",
            registry=self.registry,
        )
        self.breaks = Counter(
            "mapmatch_breaks",
            "Breaks (splits of a trace into unconnected segments) in matched traces.",
            registry=self.registry,
        )
        self.match_seconds = Histogram(
            "mapmatch_match_duration_seconds",
            "Time spent in a match thread per request (parse, match, serialise).",
            buckets=_LATENCY_BUCKETS_S,
            registry=self.registry,
        )

    def render(self) -> tuple[bytes, str]:
        """The exposition text and its content type; summed over workers in multi-process mode."""
        if os.environ.get(MULTIPROC_ENV):
            registry = CollectorRegistry()
            prom_multiprocess.MultiProcessCollector(registry)  # type: ignore[no-untyped-call]
            return generate_latest(registry), CONTENT_TYPE_LATEST
        return generate_latest(self.registry), CONTENT_TYPE_LATEST
