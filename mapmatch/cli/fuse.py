"""``mapmatch fuse RAW``: raw GNSS/odometer/gyro log in, fused trace CSV out."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

from mapmatch.fusion import FusionConfig, RawLog, fuse

if TYPE_CHECKING:
    import argparse
    from typing import Any

__all__ = ["add_parser", "run"]


def add_parser(subparsers: argparse._SubParsersAction[Any]) -> argparse.ArgumentParser:
    """
    Register the ``fuse`` sub-command.

    Parameters
    ----------
    subparsers
        The object returned by ``ArgumentParser.add_subparsers()``.
    """
    p: argparse.ArgumentParser = subparsers.add_parser(
        "fuse",
        help="fuse a raw GNSS + odometer + gyro log into a trace ready for matching",
        description=(
            "Fuse a raw sensor log (CSV/Parquet, layout in mapmatch.fusion.rawlog) with an "
            "extended Kalman filter and write the trace columns time, lat, lon, heading, "
            "speed, accuracy, odometer as CSV."
        ),
    )
    p.add_argument("raw", help="raw log file (.csv, .csv.gz, .parquet) or - for CSV on stdin")
    p.add_argument(
        "--crs",
        choices=("wgs84", "gcj02", "bd09"),
        default="wgs84",
        help="frame of the lat/lon columns (Chinese map SDKs: gcj02 or bd09)",
    )
    p.add_argument(
        "--pulses-per-m",
        type=float,
        default=None,
        help="odometer pulses per metre (needed when the log has odo_count)",
    )
    p.add_argument(
        "--interval-s",
        type=float,
        default=1.0,
        help="output one point per this many seconds (0 = every sensor epoch; default 1)",
    )
    p.add_argument("--out", default="-", help="output CSV file, or - for stdout (default)")
    p.set_defaults(run=run)
    return p


def run(args: argparse.Namespace) -> int:
    """
    Execute ``mapmatch fuse``; returns the process exit code.

    Errors of the input (:class:`~mapmatch.MapMatchError`) propagate to the caller, which
    prints them and exits non-zero.
    """
    raw = RawLog.from_file(args.raw, crs=args.crs, pulses_per_m=args.pulses_per_m)
    track = fuse(raw, FusionConfig())
    interval = args.interval_s if args.interval_s and args.interval_s > 0 else None
    df = track.to_dataframe(interval_s=interval)
    if args.out in (None, "-"):
        df.to_csv(sys.stdout, index=False)
    else:
        df.to_csv(args.out, index=False)
    return 0
