from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
import pytest

from mapmatch.cli.fuse import add_parser, run
from mapmatch.fusion import RawLogError, RawLogSimConfig, simulate_raw_log

if TYPE_CHECKING:
    from pathlib import Path


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="mapmatch")
    add_parser(parser.add_subparsers(dest="command"))
    return parser


def _write_raw(trips, path: Path) -> None:
    raw, _ = simulate_raw_log(trips["arcs"](), RawLogSimConfig(), seed=0)
    pd.DataFrame({
        "time": raw.time_s, "odo_speed_mps": raw.odo_speed_mps, "gyro_z_dps": raw.gyro_z_dps,
        "lat": raw.lat, "lon": raw.lon, "hdop": raw.hdop, "sats": raw.sats,
    }).to_csv(path, index=False)  # fmt: skip


def test_fuse_writes_trace_csv(trips, tmp_path: Path) -> None:
    _write_raw(trips, tmp_path / "raw.csv")
    args = _parser().parse_args(
        ["fuse", str(tmp_path / "raw.csv"), "--out", str(tmp_path / "o.csv")]
    )
    assert args.run(args) == 0
    df = pd.read_csv(tmp_path / "o.csv")
    assert list(df.columns) == ["time", "lat", "lon", "heading", "speed", "accuracy", "odometer"]
    assert np.allclose(np.diff(df["time"].to_numpy()[:-1]), 1.0, atol=0.051)  # 1 Hz default
    assert df["odometer"].iloc[-1] == pytest.approx(2544.0, rel=0.01)


def test_fuse_to_stdout(trips, tmp_path: Path, capsys) -> None:
    _write_raw(trips, tmp_path / "raw.csv")
    args = _parser().parse_args(["fuse", str(tmp_path / "raw.csv"), "--interval-s", "0"])
    assert run(args) == 0
    out = capsys.readouterr().out
    assert out.startswith("time,lat,lon,heading,speed,accuracy,odometer\n")
    assert out.count("\n") == 2061 + 1


def test_fuse_bad_log_raises_clear_error(tmp_path: Path) -> None:
    (tmp_path / "raw.csv").write_text("time,odo_speed_mps\n0,1\n1,1\n")
    args = _parser().parse_args(["fuse", str(tmp_path / "raw.csv")])
    with pytest.raises(RawLogError, match="missing column"):
        run(args)
