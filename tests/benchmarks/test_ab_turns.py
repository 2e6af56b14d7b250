"""benchmarks/ab_turns.py: versions of the matcher timed in turns, their documents compared."""

from __future__ import annotations

import functools
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from tests.benchmarks.scripts import load_script

if TYPE_CHECKING:
    from collections.abc import Callable

ab_turns = load_script("ab_turns.py")
ROOT = Path(__file__).resolve().parents[2]


def test_two_variants_of_one_tree_take_turns_and_write_the_same_documents(
    capsys: pytest.CaptureFixture[str],
) -> None:
    code = ab_turns.main(
        [
            "--variant", f"base={ROOT}",
            "--variant", f"again={ROOT}:MAPMATCH_AB_TURNS_TEST=1",
            "--set", "sim:15:6:2",
            "--rounds", "2",
            "--passes", "1",
            "--evict-mb", "1",
            "--evict-pages",
        ]
    )  # fmt: skip
    assert code == 0
    out = capsys.readouterr().out
    assert "2 rounds of 1 passes, 1 MB read (a value a page, in a random order) before each" in out
    rows = [line.split("|")[1:-1] for line in out.splitlines() if line.startswith("| sim:")]
    assert [r[1].strip() for r in rows] == ["base", "again"]
    assert float(rows[0][2]) > 0
    assert float(rows[1][2]) > 0
    ratio = float(rows[1][3].split()[0])
    assert 0.2 < ratio < 5
    assert rows[1][4].strip() == "equal"  # the same code: the same documents
    assert rows[0][4].strip().startswith("`")


def test_variants_and_sets_are_read_or_refused_with_what_to_write(tmp_path: Path) -> None:
    v = ab_turns.parse_variant(f"new={ROOT}:NUMBA_OPT=2,OTHER=x")
    assert (v.name, v.tree, v.env) == ("new", ROOT, {"NUMBA_OPT": "2", "OTHER": "x"})
    with pytest.raises(SystemExit, match="write NAME=TREE"):
        ab_turns.parse_variant(str(ROOT))
    with pytest.raises(SystemExit, match="write KEY=VALUE"):
        ab_turns.parse_variant(f"new={ROOT}:NUMBA_OPT")
    with pytest.raises(SystemExit, match="holds no mapmatch package"):
        ab_turns.parse_variant(f"new={tmp_path}")
    with pytest.raises(SystemExit, match="write EXTRACT:SET:INPUT or sim:"):
        ab_turns.parse_set("krems", tmp_path)
    with pytest.raises(SystemExit, match="write EXTRACT:SET:INPUT or sim:"):
        ab_turns.parse_set("sim:fast:25:20", tmp_path)
    (tmp_path / "krems_at_2013" / "15s").mkdir(parents=True)
    (tmp_path / "krems_at_2013" / "15s" / "positions.csv").write_text("trace_id,time,lon,lat\n")
    with pytest.raises(SystemExit, match="named INTERVALs_NOISEm"):
        ab_turns.parse_set("krems_at_2013:15s:positions", tmp_path, tmp_path)
    with pytest.raises(SystemExit, match=r"compare_peers\.py writes the peer sets"):
        ab_turns.parse_set("nowhere_2000:15s_10m:positions", tmp_path)


def test_a_document_is_compared_without_its_timings() -> None:
    a = b'{"stats":{"points":2,"timings_s":{"total":0.001}},"features":[]}'
    b = b'{"stats":{"points":2,"timings_s":{"total":0.002}},"features":[]}'
    c = b'{"stats":{"points":3,"timings_s":{"total":0.001}},"features":[]}'
    assert ab_turns._without_timings(a) == ab_turns._without_timings(b)
    assert ab_turns._without_timings(a) != ab_turns._without_timings(c)
    assert ab_turns._without_timings(b"{not json") == b"{not json"  # compared as it is


def test_a_cut_ends_each_match_after_its_kernel_and_replays_what_came_after(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import mapmatch.export
    import roadnets

    traces = load_script("bench_fixed_cost.py").traces_of(roadnets.load(), 15.0, 6, 2)
    net = roadnets.load()

    def document(trace: object) -> Callable[[], object]:
        return functools.partial(ab_turns._document, trace, net, None)

    for trace in traces:  # every kernel compiled before the stand-ins
        document(trace)()
    stage = ab_turns.StageCut("mapmatch.hmm.assemble._assemble_kernel:kernels")
    stage.install()
    try:
        for t, trace in enumerate(traces):
            stage.learn(t, document(trace))
        after = {kernel.py_func.__name__ for kernel, _, _ in stage.after[0]}
        assert {"_from_network", "_write_rows"} <= after
        assert not after & {"solve_kernel", "_assemble_kernel", "nearby_kernel"}
        stage.stop_learning()
        replayed: list[int] = []
        stage.after[0] = [(lambda value: replayed.append(value), (), {"value": 1})]
        written: list[int] = []
        real = mapmatch.export.geojson_bytes
        monkeypatch.setattr(
            mapmatch.export, "geojson_bytes", lambda r: written.append(1) or real(r)
        )
        stage.run(0, document(traces[0]))
        assert (replayed, written) == ([1], [])  # stopped at the cut, then the kept calls
        stage.mode = "free"
        stage.run(0, document(traces[0]))
        assert (replayed, written) == ([1], [])
    finally:
        stage.uninstall()
    assert len(real(mapmatch.match(traces[0], net))) > 0  # the kernels are bound again


def test_a_cut_names_what_it_needs() -> None:
    with pytest.raises(SystemExit, match=r"write MODULE\.KERNEL:free or MODULE\.KERNEL:kernels"):
        ab_turns.StageCut("mapmatch.hmm.assemble._assemble_kernel")
    with pytest.raises(SystemExit, match=r"write MODULE\.KERNEL:free"):
        ab_turns.StageCut("nowhere:free")
    stage = ab_turns.StageCut("mapmatch.nowhere.kernel:free")
    with pytest.raises(SystemExit, match=r"nothing loaded is named mapmatch\.nowhere\.kernel"):
        stage.install()
    stage.uninstall()


def test_the_processes_of_one_version_are_pooled_round_by_round() -> None:
    old, new = Path("/trees/old"), Path("/trees/new")
    variants = [
        ab_turns.Variant("base", old, {}),
        ab_turns.Variant("new", new, {}),
        ab_turns.Variant("new2", new, {}),
        ab_turns.Variant("base2", old, {}),
        ab_turns.Variant("tuned", new, {"NUMBA_OPT": "2"}),
    ]
    sets = [ab_turns.TraceSet("x", "x.csv", None, None)]
    # the first started runs 10 % slow: pooled, the versions' ratio is the started-late mean's
    times = {
        "base": [[110.0], [110.0], [110.0]],
        "new": [[90.0], [90.0], [90.0]],
        "new2": [[90.0], [90.0], [90.0]],
        "base2": [[100.0], [100.0], [100.0]],
        "tuned": [[80.0], [85.0], [90.0]],
    }
    rows = [
        [cell.strip() for cell in line.split("|")[1:-1]]
        for line in ab_turns.pooled_report(variants, sets, times).splitlines()[2:]
    ]
    assert [r[1] for r in rows] == ["base + base2", "new + new2", "tuned"]
    assert [float(r[2]) for r in rows] == [105.0, 90.0, 85.0]
    assert rows[0][3] == ""
    assert rows[1][3] == "0.857 (0.857-0.857)"  # 90 / 105
    assert rows[2][3].startswith("0.810 ")  # 85 / 105, the middle round
    # one process a version: nothing to pool
    assert ab_turns.pooled_report(variants[:2], sets, {k: times[k] for k in ("base", "new")}) == ""
