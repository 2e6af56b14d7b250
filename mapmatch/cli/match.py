"""
``mapmatch match INPUT... --out DIR``: batch matching of trace files, locally or on Dask.

Examples::

    mapmatch match traces/ --out matched/ --format geojson
    mapmatch match day1.csv day2.gpx --network city.osm.pbf --out out/ --workers 4
    mapmatch fuse raw.csv | mapmatch match - --out out/
    mapmatch match traces/ --out out/ --scheduler tcp://10.0.0.5:8786 --resume
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mapmatch.batch import BatchOptions, BatchReport, run_batch
from mapmatch.batch.outputs import FORMATS, SUMMARY_NAME
from mapmatch.config import MatchConfig, add_config_flags, config_from_flags
from mapmatch.trace import SUPPORTED_CRS

if TYPE_CHECKING:
    from collections.abc import Sequence

    from tqdm import tqdm

    from mapmatch.batch.outputs import SummaryRow

__all__ = ["add_parser", "run"]

_SHOW_FAILED = 5


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        msg = f"must be a whole number >= 1 (got {text!r})"
        raise argparse.ArgumentTypeError(msg)
    return value


def add_parser(subparsers: argparse._SubParsersAction[Any]) -> argparse.ArgumentParser:
    """
    Register the ``match`` sub-command.

    Parameters
    ----------
    subparsers
        The object returned by ``ArgumentParser.add_subparsers()``.
    """
    p: argparse.ArgumentParser = subparsers.add_parser(
        "match",
        help="match trace files or folders; one output per trace plus summary.csv",
        description=(
            "Match every trace of the INPUT files and folders (CSV, GPX, KML, NMEA, GeoJSON, "
            "Parquet; folders searched recursively; - reads CSV from standard input) and write one "
            "file per trace, named by its trace id, plus summary.csv with one row per trace. "
            "Runs on all local cores, or on a Dask cluster with --scheduler. A bad file or "
            "trace is recorded in summary.csv and the batch goes on. Exit code 0 when every "
            "trace matched, 1 when any failed, 2 for usage errors."
        ),
    )
    p.add_argument("inputs", nargs="+", metavar="INPUT", help="trace file, folder, or -")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    p.add_argument(
        "--network",
        metavar="PATH",
        default=None,
        help="OSM extract (.osm, .osm.bz2, .osm.pbf); default: the embedded network",
    )
    p.add_argument(
        "--cache-dir",
        metavar="DIR",
        default=None,
        help="compiled-network cache shared by the workers (default $MAPMATCH_CACHE_DIR "
        "or ~/.cache/mapmatch); must be reachable by Dask workers",
    )
    p.add_argument(
        "--format",
        choices=FORMATS,
        default="geojson",
        help="geojson (one FeatureCollection per trace); csv/parquet: per-point table plus "
        "<id>.edges.csv|parquet; geoparquet: the same with geometries plus "
        "<id>.segments.parquet (geopandas.read_parquet); gpkg: one GeoPackage per trace with "
        "layers segments, edges, points (default geojson)",
    )
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=_positive_int,
        default=None,
        metavar="N",
        help="local worker processes (default: one per core; 1 runs in this process; more "
        "than the cores are cut to the cores unless --force-workers)",
    )
    where.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        default=None,
        help="run on an existing Dask cluster, e.g. tcp://host:8786 (workers must see "
        "the same files)",
    )
    p.add_argument(
        "--force-workers",
        action="store_true",
        help="start --workers processes even when there are fewer cores",
    )
    p.add_argument(
        "--crs",
        choices=SUPPORTED_CRS,
        default="wgs84",
        help="frame of the coordinates in the files: wgs84 (default), or gcj02 / bd09 from "
        "Chinese map SDKs (converted to WGS84)",
    )
    p.add_argument(
        "--scheduler-timeout-s",
        type=float,
        default=30.0,
        metavar="S",
        help="how long to try to reach the Dask scheduler (default 30)",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="skip traces whose outputs in --out are complete from an earlier run",
    )
    p.add_argument(
        "--id-column",
        metavar="NAME",
        default=None,
        help="column naming the traces of CSV/Parquet files (default: trace_id, trip_id, "
        "track_id, vehicle_id, device_id or id, case-insensitive; see the README)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar and no summary")
    p.add_argument(
        "--chunk-traces",
        type=_positive_int,
        default=None,
        metavar="N",
        help="traces per task (default: about four tasks per worker, at most 32)",
    )
    add_config_flags(p)
    p.set_defaults(run=run)
    return p


def config_from_args(args: argparse.Namespace) -> MatchConfig:
    """
    The :class:`~mapmatch.MatchConfig` the flags ask for (one flag per overridable field).

    Raises
    ------
    ConfigError
        A value breaks its rule (the message and ``field`` name the parameter).
    """
    return config_from_flags(vars(args))


class _Bar:
    """A tqdm progress bar: traces done/total, points/s, ETA."""

    def __init__(self) -> None:
        self._bar: tqdm[Any] | None = None
        self._points = 0
        self._failed = 0

    def start(self, *, total_traces: int, total_points: int, resumed: int) -> None:
        from tqdm import tqdm

        self._bar = tqdm(
            total=total_traces,
            initial=resumed,
            unit="trace",
            desc="matching",
            file=sys.stderr,
            dynamic_ncols=True,
        )

    def update(self, rows: Sequence[SummaryRow]) -> None:
        if self._bar is None:
            return
        self._points += sum(r.points for r in rows)
        self._failed += sum(1 for r in rows if not r.ok)
        elapsed = max(self._bar.format_dict.get("elapsed", 0.0), 1e-9)
        self._bar.set_postfix(
            points_s=f"{self._points / elapsed:,.0f}", failed=self._failed, refresh=False
        )
        self._bar.update(len(rows))

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()


def _time_line(report: BatchReport) -> str:
    """Wall time, and points/s over the time spent matching only (not loading, not waiting)."""
    if report.nothing_to_do:
        return (
            f"time      {report.seconds:.2f} s; nothing to do: every trace was complete from "
            "an earlier run"
        )
    rate = report.points_per_s
    if rate != rate:  # NaN: no trace matched in this run
        return f"time      {report.seconds:.2f} s on {report.executor}; no trace matched"
    warm = f" after {report.warmup_s:.2f} s of kernel warm-up" if report.warmup_s >= 0.005 else ""
    return (
        f"time      {report.seconds:.2f} s on {report.executor}; matching {report.match_s:.2f} s "
        f"of worker time{warm}: {rate:,.0f} points/s per worker"
    )


def _human_summary(report: BatchReport) -> str:
    rows = report.rows
    files = len({r.source for r in rows})
    failed = [r for r in rows if not r.ok]
    verdicts = ", ".join(f"{k} {v}" for k, v in report.verdicts.items()) or "none"
    resumed = f" ({report.resumed} from an earlier run)" if report.resumed else ""
    sources = report.time_sources
    untimed = sum(v for k, v in sources.items() if k != "ok")
    times = ", ".join(f"{k} {v}" for k, v in sources.items()) or "none"
    lines = [f"note      {note}" for note in report.notes]
    lines += [
        f"traces    {report.traces_ok} ok, {len(failed)} failed, from {files} file(s){resumed}",
        f"points    {report.points:,} matched traces' points",
        f"rows      {report.input_rows:,} read: {report.reordered_rows:,} reordered, "
        f"{report.merged_rows:,} merged (true duplicates), {report.dropped_rows:,} dropped; "
        f"{report.shared_time_rows:,} share a time (kept)",
        f"times     {times}" + (f" ({untimed} matched by distance only)" if untimed else ""),
        f"warnings  {report.traces_with_warnings} trace(s) with warnings (see {SUMMARY_NAME})",
        f"length    {report.matched_length_m / 1000:,.3f} km matched",
        f"verdicts  {verdicts}",
        _time_line(report),
        f"output    {report.out_dir} ({SUMMARY_NAME})",
    ]
    if report.skipped_inputs:
        lines.append(
            f"skipped   {len(report.skipped_inputs)} file(s) in output folders, not read as "
            f"traces (first: {report.skipped_inputs[0]})"
        )
    if report.retried:
        lines.append(
            f"retried   {report.retried} trace(s) in a fresh pool after a worker process died"
        )
    for r in failed[:_SHOW_FAILED]:
        what = f"{r.source} trace {r.trace_id!r}" if r.trace_id else r.source
        lines.append(f"failed    {what}: {r.error}")
    if len(failed) > _SHOW_FAILED:
        lines.append(f"failed    ... and {len(failed) - _SHOW_FAILED} more, see {SUMMARY_NAME}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    """
    Execute ``mapmatch match``; returns 0 when every trace matched, 1 when any failed.

    Usage errors (missing input, bad option value, unreachable scheduler, network that
    cannot be loaded) raise the project's errors, which the caller prints with exit code 2.
    """
    config = config_from_args(args)
    verbose = bool(getattr(args, "verbose", False))
    options = BatchOptions(
        inputs=tuple(args.inputs),
        out_dir=Path(args.out),
        network=args.network,
        cache_dir=args.cache_dir,
        format=args.format,
        config=config,
        workers=args.workers,
        force_workers=args.force_workers,
        scheduler=args.scheduler,
        scheduler_timeout_s=args.scheduler_timeout_s,
        resume=args.resume,
        chunk_traces=args.chunk_traces,
        log_level=logging.WARNING if verbose else logging.ERROR,
        id_column=args.id_column,
        crs=args.crs,
    )
    show_bar = not args.quiet and sys.stderr.isatty()
    bar = _Bar() if show_bar else None
    try:
        report = run_batch(options, progress=bar)
    finally:
        if bar is not None:
            bar.close()
    if not args.quiet:
        print(_human_summary(report))
    return report.exit_code
