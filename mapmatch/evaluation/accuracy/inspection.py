"""
One trip of the matrix again, by the id the tables give it: its scores and where it turns back.

``--inspect <extract>:<condition>:<index>`` re-simulates that trip (same seed), matches it in
the chosen column specs, lists every U-turn and repeated edge of each match and, with
``--out``, writes its trace, truth, matches and maps.
"""

from __future__ import annotations

import json
import logging
from typing import TYPE_CHECKING

import numpy as np

from mapmatch.errors import ConfigError
from mapmatch.evaluation.accuracy.extracts import extract_named
from mapmatch.evaluation.accuracy.overrides import match_config
from mapmatch.evaluation.accuracy.runner import match_row, task_trip, worker_network
from mapmatch.evaluation.accuracy.tables import rows_markdown
from mapmatch.evaluation.accuracy.tasks import CellTask
from mapmatch.evaluation.accuracy.truth import TRUTH_SUBSETS
from mapmatch.evaluation.simulate import INPUT_CLASSES, write_trips

if TYPE_CHECKING:
    from collections.abc import Mapping, Sequence
    from pathlib import Path

    import roadnets
    from mapmatch.result import MatchResult

__all__ = ["inspect_trip", "parse_trip_id"]

_log = logging.getLogger("mapmatch")


def parse_trip_id(trip_id: str) -> tuple[str, str, int]:
    """
    ``<extract>:<condition>:<index>`` as its three parts.

    Raises
    ------
    ConfigError
        An id not of that form.

    Examples
    --------
    >>> parse_trip_id("monaco_2020:realistic-1s:7")
    ('monaco_2020', 'realistic-1s', 7)
    """
    extract, sep, rest = trip_id.rpartition(":")
    name, _, condition = extract.rpartition(":")
    if not sep or not name or not rest.isdigit():
        msg = f"trip id {trip_id!r} must be <extract>:<condition>:<index>"
        raise ConfigError(msg)
    return name, condition, int(rest)


def inspect_trip(
    trip_id: str,
    *,
    seed: int,
    match_overrides: Mapping[str, object],
    sim_overrides: Mapping[str, object],
    classes: Sequence[str] | None,
    out: Path | None,
) -> int:
    """
    Re-run one trip in the chosen classes; print its scores and where it turns back.

    ``classes`` ``None``: every input class (every column subset for a ``truth-`` condition);
    ``out``: write the trace, truth, each match's GeoJSON and map there. Returns 0.

    Raises
    ------
    ConfigError
        A malformed trip id, an unknown extract, condition or class.
    """
    name, condition, index = parse_trip_id(trip_id)
    path = extract_named(name)
    specs = tuple(
        classes or (INPUT_CLASSES if not condition.startswith("truth") else TRUTH_SUBSETS)
    )
    task = CellTask(
        str(path),
        condition,
        specs,
        1,
        seed,
        index,
        tuple(match_overrides.items()),
        tuple(sim_overrides.items()),
    )
    _log.setLevel(logging.ERROR)
    net = worker_network(task.extract)
    trip = task_trip(task, index)
    config = match_config(match_overrides)
    truth = trip.truth_record()
    if out is not None:
        write_trips([trip], out)
    print(
        f"{trip_id}: seed {task.seed + index}, {len(trip.trace)} fixes, "
        f"{trip.length_m:.1f} m, {len(trip.stops)} stops, {len(trip.outages)} outages, "
        f"{len(trip.canyons)} canyon stretches, odometer x{trip.odometer_scale:.4f}; the truth "
        f"has {trip.uturns} U-turns and {trip.loops} loops"
    )
    rows = []
    for spec in specs:
        row, result = match_row(task, trip, index, spec, config, truth)
        rows.append(row)
        if result is None:
            continue
        for line in _turnback_places(result, net):
            print(f"  {spec}: {line}")
        if out is not None:
            stem = trip.trace.trace_id.replace(":", "_")
            geojson = out / f"{stem}.{spec}.geojson"
            geojson.write_text(json.dumps(result.to_geojson()), encoding="utf-8")
            _write_map(result, net, out / f"{stem}.{spec}.html")
    print("\n" + rows_markdown(rows))
    if out is not None:
        print(f"\ntrace, truth and matches written to {out}")
    return 0


def _turnback_places(result: MatchResult, net: roadnets.RoadNetwork) -> list[str]:
    """Where a match turns back (twin edges in a row) or drives an edge again."""
    a = net.arrays
    lines = []
    for seg in result.segments:
        seen: dict[int, int] = {}
        driven = [e for e in seg.edges if e.driven_m > 0]  # as count_turnbacks counts them
        for i, e in enumerate(driven):
            before = driven[i - 1] if i else None
            if before is not None and a.edge_twin[before.edge] == e.edge:
                x, y = net.point_on_edge(np.array([e.edge]), np.array([e.start_offset_m]))
                lon, lat = net.unproject(x, y)
                lines.append(
                    f"U-turn in segment {seg.index} at driven edge #{i}: {before.u}->{before.v} "
                    f"for {before.driven_m:.0f} m, back {e.u}->{e.v} for {e.driven_m:.0f} m; "
                    f"turned at lon/lat {lon[0]:.6f},{lat[0]:.6f}"
                )
            if e.edge in seen:
                lines.append(
                    f"loop in segment {seg.index}: edge {e.u}->{e.v} (key {e.key}) driven again "
                    f"at #{i} (first at #{seen[e.edge]})"
                )
            seen.setdefault(e.edge, i)
    return lines


def _write_map(result: MatchResult, net: roadnets.RoadNetwork, path: Path) -> None:
    """The match's map as HTML, when the viz extra is installed (else nothing)."""
    try:
        from mapmatch.viz import match_map

        match_map(result, net).save(str(path))
    except ImportError:  # the viz extra is optional
        return
