"""Fixtures of the mapmatch tests that start processes: one local Dask cluster for all."""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from collections.abc import Iterator


@pytest.fixture(scope="session")
def dask_cluster() -> Iterator[str]:
    """The address of a two-worker local Dask cluster (processes, one thread each)."""
    from distributed import LocalCluster

    cluster = LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address=":0",  # any free port: None still serves HTTP on 8787, which
        # a second test run on the machine may be binding at the same moment
        silence_logs=logging.ERROR,
    )
    try:
        yield str(cluster.scheduler_address)
    finally:
        cluster.close()
