"""benchmarks/kernel_time.py: each kernel's time in the flow, and the Python between them."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.benchmarks.scripts import load_script

kernel_time = load_script("kernel_time.py")
EMBEDDED = Path(__file__).resolve().parents[2] / "roadnets" / "data" / "monaco_2020.osm.pbf"


def _table(out: str, header: str) -> list[list[str]]:
    """The rows of the markdown table under ``header`` (cells stripped)."""
    lines = out.splitlines()
    start = lines.index(header) + 2
    rows = []
    for line in lines[start:]:
        if not line.startswith("|"):
            break
        rows.append([cell.strip() for cell in line.split("|")[1:-1]])
    return rows


def test_kernels_and_the_python_between_them_add_up_to_the_pass(
    capsys: pytest.CaptureFixture[str],
) -> None:
    import mapmatch.hmm.trellis as trellis

    solve = trellis.solve_kernel
    argv = ["--extract", str(EMBEDDED), "--interval", "15", "--fixes", "8", "--traces", "2"]
    assert kernel_time.main([*argv, "--passes", "2", "--warm", "1"]) == 0
    assert trellis.solve_kernel is solve  # the stand-ins are gone again
    out = capsys.readouterr().out
    head = out.splitlines()[0]
    total, in_kernels, python = (
        float(head.split(marker)[0].split()[-1])
        for marker in (" us a trace", " in kernels", " in the Python")
    )
    assert 0 < in_kernels < total
    assert python == pytest.approx(total - in_kernels, abs=1.5)
    kernels = _table(
        out, "| kernel | calls a trace | in the flow us | code warm us | all warm us |"
    )
    assert "mapmatch.hmm.trellis.solve_kernel" in {row[0] for row in kernels}
    between = _table(out, "| after | before | us a trace |")
    assert all(row[0] and row[1] for row in between)
    assert {row[0] for row in between} >= {kernel_time.MATCH_CALLED}
    assert {row[1] for row in between} >= {kernel_time.DOCUMENT_WRITTEN}
    # every stretch of Python is counted once: the stretches add up to the Python of the pass
    assert sum(float(row[2]) for row in between) == pytest.approx(python, rel=0.05, abs=2)
