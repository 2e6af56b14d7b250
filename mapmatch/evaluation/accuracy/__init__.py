"""
The accuracy matrix: how well the matched *length* holds up, whatever the input.

Every extract x input class (:data:`mapmatch.evaluation.simulate.INPUT_CLASSES`: positions only, +
accuracy, + heading & speed, + odometer) x condition (:data:`CONDITIONS`: clean 1 s / 15 s /
30 s, and realistic 1 s / 15 s noise with a 2 % high odometer). The same simulated trips (fixed
seeds) feed every input class of a condition, stripped to that class's columns. Per cell: route
mismatch, length error, share of trips within 1 % / 2 %, share of trips with a U-turn or loop
the truth does not have, and whether the distance verdict is the one the true length gives.

The noise-free truth check (:func:`truth_tasks`) matches exact traces at several sampling
rates with every subset of the true columns (speed, heading, odometer): the matched length
must be within 0.1 % of the true one on every trip.

Run it as ``benchmarks/bench_accuracy.py`` or ``mapmatch bench --matrix`` / ``--truth``; see
:func:`add_arguments` for the options.

One job per module: ``conditions`` (the conditions and column specs), ``extracts`` (which
networks), ``overrides`` (``--config`` / ``--sim`` ``key=value``), ``tasks`` (a cell's task,
a trip's row), ``runner`` (simulate and match a cell, in processes), ``summary`` (a cell's
figures), ``tables`` (markdown), ``rules`` (the acceptance rules), ``matrix`` / ``truth`` /
``inspection`` (the three modes: tasks and report) and ``cli`` (options and entry point).
"""

from __future__ import annotations

from mapmatch.evaluation.accuracy.cli import add_arguments, run_cli
from mapmatch.evaluation.accuracy.conditions import (
    CONDITIONS,
    columns_of,
    condition_config,
)
from mapmatch.evaluation.accuracy.extracts import (
    SHARED_EXTRACTS,
    TEST_EXTRACTS,
    default_extracts,
)
from mapmatch.evaluation.accuracy.inspection import inspect_trip
from mapmatch.evaluation.accuracy.matrix import matrix_report, matrix_tasks
from mapmatch.evaluation.accuracy.overrides import match_config, parse_overrides
from mapmatch.evaluation.accuracy.rules import acceptance
from mapmatch.evaluation.accuracy.runner import run_cell, run_tasks
from mapmatch.evaluation.accuracy.summary import Cell, cells
from mapmatch.evaluation.accuracy.tables import (
    extract_markdown,
    matrix_markdown,
    rows_markdown,
    worst_rows,
)
from mapmatch.evaluation.accuracy.tasks import CellTask, TripRow
from mapmatch.evaluation.accuracy.truth import (
    TRUTH_INTERVALS,
    TRUTH_SUBSETS,
    truth_markdown,
    truth_report,
    truth_tasks,
)

__all__ = [
    "CONDITIONS",
    "SHARED_EXTRACTS",
    "TEST_EXTRACTS",
    "TRUTH_INTERVALS",
    "TRUTH_SUBSETS",
    "Cell",
    "CellTask",
    "TripRow",
    "acceptance",
    "add_arguments",
    "cells",
    "columns_of",
    "condition_config",
    "default_extracts",
    "extract_markdown",
    "inspect_trip",
    "match_config",
    "matrix_markdown",
    "matrix_report",
    "matrix_tasks",
    "parse_overrides",
    "rows_markdown",
    "run_cell",
    "run_cli",
    "run_tasks",
    "truth_markdown",
    "truth_report",
    "truth_tasks",
    "worst_rows",
]
