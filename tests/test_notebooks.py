"""Every notebook runs top to bottom on a fresh clone, and none is committed with outputs."""

from __future__ import annotations

import html
import re
import sys
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOKS = Path(__file__).resolve().parent.parent / "notebooks"
EXPECTED = ["01_quickstart.ipynb", "02_inspect_a_match.ipynb", "03_trip_distance_audit.ipynb"]
PATHS = sorted(NOTEBOOKS.glob("*.ipynb"))


def test_the_notebooks_are_all_here() -> None:
    assert [p.name for p in PATHS] == EXPECTED


@pytest.mark.parametrize("path", PATHS, ids=[p.stem for p in PATHS])
def test_committed_notebook_has_no_outputs(path: Path) -> None:
    nb = nbformat.read(path, as_version=4)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert code
    assert [c.outputs for c in code] == [[] for _ in code]
    assert [c.execution_count for c in code] == [None for _ in code]


@pytest.mark.slow
@pytest.mark.parametrize("path", PATHS, ids=[p.stem for p in PATHS])
def test_notebook_runs_top_to_bottom(
    path: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the kernel inherits these: no display for matplotlib, network cache in a scratch folder
    monkeypatch.setenv("MPLBACKEND", "Agg")
    monkeypatch.setenv("MAPMATCH_CACHE_DIR", str(tmp_path / "cache"))
    nb = nbformat.read(path, as_version=4)
    nb.cells.append(nbformat.v4.new_code_cell("import sys; print(sys.executable)"))
    client = NotebookClient(
        nb,
        timeout=120,
        kernel_name="python3",
        allow_errors=False,
        resources={"metadata": {"path": str(tmp_path)}},
    )
    client.execute()  # raises CellExecutionError naming the failing cell
    # the kernel ran on this interpreter (the venv's), so it tested this checkout
    printed = "".join(o.get("text", "") for o in nb.cells[-1].outputs)
    assert printed.strip() == sys.executable
    errors = [
        o for c in nb.cells if c.cell_type == "code" for o in c.outputs if o.output_type == "error"
    ]
    assert errors == []
    # "no internet needed": every map shown carries Leaflet and links no CDN file
    pages = [
        o["data"]["text/html"]
        for c in nb.cells
        if c.cell_type == "code"
        for o in c.outputs
        if "text/html" in o.get("data", {}) and "leaflet" in o["data"]["text/html"].lower()
    ]
    draws_maps = any("match_map(" in c.source for c in nb.cells if c.cell_type == "code")
    assert bool(pages) == draws_maps
    for page in pages:
        source = html.unescape(page)
        assert re.findall(r"<script[^>]+src=", source) == []
        assert re.findall(r"<link[^>]+stylesheet", source) == []
        assert "L.map(" in source
