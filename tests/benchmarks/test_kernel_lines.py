"""benchmarks/kernel_lines.py: a kernel's time statement by statement."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numba import njit

from tests.benchmarks.scripts import load_script

kernel_lines = load_script("kernel_lines.py")
EMBEDDED = Path(__file__).resolve().parents[2] / "roadnets" / "data" / "monaco_2020.osm.pbf"


@njit
def _sum_of_squares(values, limit):  # type: ignore[no-untyped-def]
    total = 0.0
    for v in values:
        if v > limit:
            return -1.0
        total += v * v
    return total


@njit
def _twice(values, limit):  # type: ignore[no-untyped-def]
    return 2.0 * _sum_of_squares(values, limit)


def test_the_profiled_copy_computes_what_the_kernel_does_and_counts_each_statement() -> None:
    ticks = np.zeros(kernel_lines.MAX_STATEMENTS, dtype=np.uint64)
    statements: list = []
    copy, target = kernel_lines.profiled_chain(
        _twice, ["_sum_of_squares"], ticks.ctypes.data, 3, statements
    )
    assert target is _sum_of_squares
    values = np.arange(200.0)
    assert copy(values, 1e9) == _twice(values, 1e9)
    assert copy(values, 50.0) == _twice(values, 50.0) == -2.0  # the early return
    texts = [s.text for s in statements]
    assert texts == [
        "total = 0.0",
        "return -1.0",
        "if v > limit:",
        "total += v * v",
        "for v in values:",
        "return total",
    ]
    assert [s.level for s in statements] == [0, 2, 1, 1, 0, 0]
    lines = Path(__file__).read_text().splitlines()  # lines of the file, not of the function
    assert all(lines[s.line - 1].strip() == s.text for s in statements)
    counted = ticks[: len(statements)]
    assert counted[texts.index("total += v * v")] > 0
    assert counted[texts.index("return -1.0")] > 0  # counted before it returns


def test_a_name_that_is_no_callee_is_refused() -> None:
    with pytest.raises(SystemExit, match="not a kernel"):
        kernel_lines.profiled_chain(_twice, ["np"], 0, 1, [])


def test_the_table_of_a_kernel_reached_from_the_solve(capsys: pytest.CaptureFixture[str]) -> None:
    import mapmatch.hmm.trellis as trellis

    solve = trellis.solve_kernel
    argv = ["--extract", str(EMBEDDED), "--interval", "15", "--fixes", "8", "--traces", "2"]
    argv += ["--reach", "transitions_kernel", "--loops", "3", "--top", "500"]
    assert kernel_lines.main(argv) == 0
    assert trellis.solve_kernel is solve  # the stand-in is gone again
    out = capsys.readouterr().out
    head, _, table = out.partition("\n\n")
    assert head.startswith("solve_kernel.transitions_kernel: 2 calls from 2 traces")
    rows = [line.split(" | ") for line in table.splitlines()[2:]]
    assert any("_pair_routes(" in row[3] for row in rows)
    assert all(row[2].startswith("transition.py:") for row in rows)
    shares = [float(row[1].rstrip("%")) for row in rows]
    assert shares == sorted(shares, reverse=True)
    # the statements are part of the copy's calls: the counter's rate agrees with the clock
    copy_us = float(head.split("the profiled copy ")[1].split(" us")[0])
    statements_us = float(
        head.split("of which the statements of transitions_kernel ")[1].split()[0]
    )
    assert 0.1 * copy_us < statements_us < 1.5 * copy_us
