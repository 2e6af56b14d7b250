"""
Fusion on real roads: raw logs from simulated drives, and the fuse -> match -> feedback loop.

* :func:`true_trajectory_of` and :func:`simulate_trip_raw_log` turn a random drive on an OSM
  network (:func:`mapmatch.evaluation.simulate.simulate_trip`) into the raw GNSS + odometer +
  gyro log a car would have recorded, with its truth; :func:`write_raw_logs` writes them to files.
* :func:`fuse_and_match` fuses a raw log, matches the fused trace, feeds the matched road
  positions back to the filter (:func:`~mapmatch.fusion.road.road_feedback_from_match`),
  fuses again and matches again.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from mapmatch.fusion.fuse import fuse
from mapmatch.fusion.road import road_feedback_from_match
from mapmatch.fusion.simulate import RawLogSimConfig, SimTruth, simulate_raw_log
from mapmatch.fusion.trajectory import TrueTrajectory
from mapmatch.matcher import match
from mapmatch.trace import Trace

if TYPE_CHECKING:
    import os
    from collections.abc import Sequence

    from mapmatch.config import MatchConfig
    from mapmatch.distance import DistanceCheck
    from mapmatch.evaluation.simulate import SimulatedTrip
    from mapmatch.fusion.config import FusionConfig
    from mapmatch.fusion.feedback import RoadFeedback
    from mapmatch.fusion.rawlog import RawLog
    from mapmatch.fusion.track import FusedTrack
    from mapmatch.result import MatchResult
    from roadnets import RoadNetwork

__all__ = [
    "RAW_COLUMNS",
    "FusedMatch",
    "fuse_and_match",
    "raw_log_dataframe",
    "simulate_trip_raw_log",
    "true_trajectory_of",
    "write_raw_logs",
]

RAW_COLUMNS = (
    "time",
    "odo_speed_mps",
    "gyro_z_dps",
    "lat",
    "lon",
    "hdop",
    "sats",
    "gnss_speed_mps",
    "gnss_course_deg",
)
"""Columns :func:`write_raw_logs` writes (``odo_count`` replaces ``odo_speed_mps`` for pulse
logs), in the layout of :mod:`mapmatch.fusion.rawlog`."""


def true_trajectory_of(trip: SimulatedTrip) -> TrueTrajectory:
    """
    The dense (10 Hz) true trajectory of a simulated trip, as the raw-log simulator takes it.

    Parameters
    ----------
    trip
        A trip from :func:`mapmatch.evaluation.simulate.simulate_trip` (its ``dense_*`` arrays).

    Returns
    -------
    TrueTrajectory
        Time, position, heading, speed and cumulative distance at 10 Hz; its ``length_m``
        is the distance driven from the trip's first dense epoch to its last (it agrees with
        ``trip.length_m``, which runs from the first to the last 1 Hz fix, to within the last
        fraction of a second of driving).
    """
    return TrueTrajectory(
        time_s=np.asarray(trip.dense_time_s, dtype=np.float64).copy(),
        lon=np.asarray(trip.dense_lon, dtype=np.float64).copy(),
        lat=np.asarray(trip.dense_lat, dtype=np.float64).copy(),
        heading_deg=np.mod(np.asarray(trip.dense_heading_deg, dtype=np.float64), 360.0),
        speed_mps=np.asarray(trip.dense_speed_mps, dtype=np.float64).copy(),
        distance_m=np.asarray(trip.dense_distance_m, dtype=np.float64).copy(),
    )


def simulate_trip_raw_log(
    trip: SimulatedTrip, config: RawLogSimConfig, *, seed: int
) -> tuple[RawLog, SimTruth]:
    """
    Simulate the raw GNSS + odometer + gyro log of a drive on a real road network.

    Parameters
    ----------
    trip
        A trip from :func:`mapmatch.evaluation.simulate.simulate_trip`.
    config
        Sensor error model: HDOP, bad fixes, multipath jumps, outages (seconds after the
        trip's start), odometer scale and gyro errors.
    seed
        Seed of the sensor noise; the same trip and seed give the same log.

    Returns
    -------
    tuple of RawLog and SimTruth
        The validated log (its ``source`` is the trip's trace id) and the truth.
    """
    raw, sim = simulate_raw_log(true_trajectory_of(trip), config, seed=seed)
    return dataclasses.replace(raw, source=trip.trace.trace_id), sim


def raw_log_dataframe(raw: RawLog) -> pd.DataFrame:
    """
    The raw log as a table in the file layout of :mod:`mapmatch.fusion.rawlog`.

    Pulse logs (``raw.pulses_per_m`` set) get a cumulative ``odo_count`` column (from 0)
    instead of ``odo_speed_mps``; reading the table back with the same ``pulses_per_m``
    gives the same speeds.

    Examples
    --------
    >>> from mapmatch.fusion.trajectory import build_trajectory, straight
    >>> tr = build_trajectory([straight(50.0, 10.0)], origin_lon=7.42, origin_lat=43.73)
    >>> raw, _ = simulate_raw_log(tr, RawLogSimConfig(), seed=0)
    >>> list(raw_log_dataframe(raw).columns) == list(RAW_COLUMNS)
    True
    """
    data: dict[str, Any] = {name: getattr(raw, _FIELD[name]) for name in RAW_COLUMNS}
    if raw.pulses_per_m is not None:
        step = np.zeros(len(raw))
        step[1:] = raw.odo_speed_mps[1:] * np.diff(raw.time_s) * raw.pulses_per_m
        data.pop("odo_speed_mps")
        data = {"time": data.pop("time"), "odo_count": np.round(np.cumsum(step)), **data}
    return pd.DataFrame(data)


_FIELD = {
    "time": "time_s",
    "odo_speed_mps": "odo_speed_mps",
    "gyro_z_dps": "gyro_z_dps",
    "lat": "lat",
    "lon": "lon",
    "hdop": "hdop",
    "sats": "sats",
    "gnss_speed_mps": "gnss_speed_mps",
    "gnss_course_deg": "gnss_course_deg",
}


def write_raw_logs(
    trips: Sequence[SimulatedTrip],
    out_dir: str | os.PathLike[str],
    config: RawLogSimConfig,
    seed: int,
) -> list[Path]:
    """
    Write one raw log per trip, with its truth, for ``mapmatch simulate --raw``.

    Trip ``i`` gets sensor-noise seed ``seed + i``. Files in ``out_dir``:

    * ``<trace_id>.raw.csv``: the raw log (:data:`RAW_COLUMNS`, epoch seconds, WGS84), readable
      by :meth:`RawLog.from_file` and ``mapmatch fuse``;
    * ``<trace_id>.truth.csv``: the 10 Hz truth (``time, lat, lon, heading, speed,
      distance``, plus ``in_outage``, ``multipath``, ``bad_fix`` per row);
    * ``truth.jsonl``: one JSON object per trip: the route truth of
      :meth:`SimulatedTrip.truth_record` plus ``raw_file``, ``true_distance_m``,
      ``odo_scale``, ``gyro_scale``, ``pulses_per_m``, ``outages_s`` and ``seed``.

    Parameters
    ----------
    trips
        Trips from :func:`mapmatch.evaluation.simulate.simulate_trips`.
    out_dir
        Folder to write into (created if missing).
    config
        Sensor error model.
    seed
        Base seed of the sensor noise.

    Returns
    -------
    list of Path
        The raw-log files, in trip order.
    """
    folder = Path(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    paths: list[Path] = []
    records: list[str] = []
    for i, trip in enumerate(trips):
        tid = trip.trace.trace_id
        raw, sim = simulate_trip_raw_log(trip, config, seed=seed + i)
        path = folder / f"{tid}.raw.csv"
        _write_csv(raw_log_dataframe(raw), path)
        tr = sim.trajectory
        truth = pd.DataFrame(
            {
                "time": tr.time_s,
                "lat": tr.lat,
                "lon": tr.lon,
                "heading": tr.heading_deg,
                "speed": tr.speed_mps,
                "distance": tr.distance_m,
                "in_outage": sim.in_outage,
                "multipath": sim.multipath,
                "bad_fix": sim.bad_fix,
            }
        )
        _write_csv(truth, folder / f"{tid}.truth.csv")
        record = trip.truth_record()
        record.update(
            raw_file=path.name,
            true_distance_m=round(tr.length_m, 3),
            odo_scale=sim.odo_scale,
            gyro_scale=sim.gyro_scale,
            pulses_per_m=config.pulses_per_m,
            outages_s=[list(o) for o in config.outages_s],
            seed=seed + i,
        )
        records.append(json.dumps(record) + "\n")
        paths.append(path)
    truth_path = folder / "truth.jsonl"
    tmp = truth_path.with_suffix(".jsonl.tmp")
    tmp.write_text("".join(records), encoding="utf-8")
    tmp.replace(truth_path)
    return paths


def _write_csv(df: pd.DataFrame, path: Path) -> None:
    tmp = path.with_name(path.name + ".tmp")
    df.to_csv(tmp, index=False)  # shortest round-tripping repr: epoch seconds keep 0.1 s
    tmp.replace(path)


@dataclass(frozen=True, slots=True, eq=False)
class FusedMatch:
    """
    Outcome of :func:`fuse_and_match`.

    Attributes
    ----------
    track
        The fused track of the final pass (with road feedback when it was used).
    trace
        ``track`` as the matcher's input (one fix per ``interval_s``).
    result
        The match of ``trace``.
    first_track, first_result
        The first pass (no feedback); the same objects as ``track``/``result`` when
        feedback was off.
    feedback
        The road pseudo-measurements fed to the second pass, or None.
    """

    track: FusedTrack
    trace: Trace
    result: MatchResult
    first_track: FusedTrack
    first_result: MatchResult
    feedback: RoadFeedback | None

    @property
    def distance_check(self) -> DistanceCheck:
        """The fused trip distance against the matched length (final pass)."""
        return self.result.distance_check

    @property
    def distance_m(self) -> float:
        """Fused trip distance (final pass), metres."""
        return self.track.distance_m


def fuse_and_match(
    raw: RawLog,
    net: RoadNetwork,
    *,
    fusion_config: FusionConfig | None = None,
    match_config: MatchConfig | None = None,
    feedback: bool = True,
    interval_s: float = 1.0,
    trace_id: str | None = None,
) -> FusedMatch:
    """
    Fuse a raw log, match it, feed the matched road back and fuse and match again.

    1. :func:`fuse` the raw log; 2. thin it to one fix per ``interval_s``
    (:meth:`FusedTrack.to_dataframe`) and build a :class:`mapmatch.Trace`; 3.
    :func:`mapmatch.match` it; then, when ``feedback``: 4. build road pseudo-measurements
    from the snapped points (:func:`road_feedback_from_match`, along-road sigma from the
    fused accuracy); 5. fuse again with them (the filter uses them only where GNSS has been
    absent for ``fusion_config.road_feedback_min_gnss_gap_s``, i.e. in outages); 6. match
    again. The distance check of the final match compares the fused odometer (the trace's
    ``odometer`` column) with the matched length.

    Parameters
    ----------
    raw
        A validated raw log.
    net
        The road network to match on.
    fusion_config, match_config
        Filter and matcher parameters; defaults when None.
    feedback
        Run the second, map-aided pass.
    interval_s
        Seconds between fixes of the matched trace.
    trace_id
        Id of the trace; default: the raw log's source name.

    Returns
    -------
    FusedMatch

    Raises
    ------
    NoGnssFixError
        No usable GNSS fix.
    NoCandidatesError
        No fused position has a road nearby (wrong network?).
    """
    tid = trace_id or raw.source
    track = fuse(raw, fusion_config)
    trace = Trace.from_dataframe(track.to_dataframe(interval_s=interval_s), trace_id=tid)
    result = match(trace, net, match_config)
    if not feedback:
        return FusedMatch(track, trace, result, track, result, None)
    fb = road_feedback_from_match(result, net, accuracy_m=trace.accuracy_m)
    track2 = fuse(raw, fusion_config, road_feedback=fb)
    trace2 = Trace.from_dataframe(track2.to_dataframe(interval_s=interval_s), trace_id=tid)
    result2 = match(trace2, net, match_config)
    return FusedMatch(track2, trace2, result2, track, result, fb)
