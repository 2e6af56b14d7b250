"""How many cores the batch and the service size their pools by: affinity cut to the CPU quota."""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

import pytest

from mapmatch.cli import build_parser
from mapmatch.machine import available_cores, cgroup_cpu_limit

if TYPE_CHECKING:
    from pathlib import Path

AFFINITY = len(os.sched_getaffinity(0))


def _v1(root: Path, quota: str, period: str = "100000") -> Path:
    (root / "cpu").mkdir(parents=True)
    (root / "cpu" / "cpu.cfs_quota_us").write_text(quota + "\n")
    (root / "cpu" / "cpu.cfs_period_us").write_text(period + "\n")
    return root


@pytest.mark.parametrize(
    ("text", "cores"),
    [
        ("200000 100000\n", 2.0),
        ("50000 100000", 0.5),
        ("max 100000\n", None),
        ("", None),
        ("lots 100000", None),
        ("100000 0", None),
    ],
)
def test_a_cgroup_v2_quota_is_read_in_cores(tmp_path: Path, text: str, cores: float | None) -> None:
    (tmp_path / "cpu.max").write_text(text)
    assert cgroup_cpu_limit(tmp_path) == cores


def test_a_cgroup_v1_quota_is_read_and_minus_one_means_none(tmp_path: Path) -> None:
    assert cgroup_cpu_limit(_v1(tmp_path / "a", "150000")) == 1.5
    assert cgroup_cpu_limit(_v1(tmp_path / "b", "-1")) is None


def test_no_cgroup_files_mean_no_limit(tmp_path: Path) -> None:
    assert cgroup_cpu_limit(tmp_path) is None
    assert available_cores(tmp_path) == AFFINITY


def test_the_quota_cuts_the_affinity_and_a_part_of_a_core_counts_as_one(tmp_path: Path) -> None:
    (tmp_path / "cpu.max").write_text("50000 100000")
    assert available_cores(tmp_path) == 1
    (tmp_path / "cpu.max").write_text(f"{(AFFINITY + 4) * 100000} 100000")
    assert available_cores(tmp_path) == AFFINITY  # a quota above the affinity does not add
    if AFFINITY >= 2:
        (tmp_path / "cpu.max").write_text("150000 100000")
        assert available_cores(tmp_path) == 2


def test_serve_auto_runs_a_worker_per_usable_core() -> None:
    parser = build_parser()
    assert parser.parse_args(["serve", "--workers", "auto"]).workers == available_cores()
    assert parser.parse_args(["serve"]).workers == 1  # a live trip lives in one worker
