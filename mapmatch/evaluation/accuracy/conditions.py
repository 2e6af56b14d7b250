"""
What the accuracy matrix varies: its conditions (how trips are observed) and column specs.

A condition names a :class:`SimulationConfig` (:data:`CONDITIONS`, or ``truth-<s>s`` for the
noise-free truth at an interval); a column spec names the optional columns a trace keeps (an
input class of :data:`INPUT_CLASSES`, ``none``, or columns joined by ``+``).
"""

from __future__ import annotations

import re

from mapmatch.errors import ConfigError
from mapmatch.evaluation.simulate import INPUT_CLASSES, TRUE_COLUMNS, SimulationConfig

__all__ = ["CONDITIONS", "ROUTE_M", "SEED", "columns_of", "condition_config"]

#: Target length of every trip of the matrix, metres.
ROUTE_M = 3000.0
#: Seed of a cell's first trip (trip ``i`` has ``SEED + i``).
SEED = 1000

#: The matrix's conditions: clean sampling sets (white noise, 2 % outliers of 40 m, the
#: simulator's brief stops and +-0.5 % odometer) and the realistic preset
#: (:meth:`SimulationConfig.realistic`: AR(1) 0.95/s 6 m, canyons, stops at a third of the
#: junctions for 5-40 s, heading noise 3 + 87 exp(-v) deg, 20-60 s outages, odometer 2 % high).
CONDITIONS: dict[str, SimulationConfig] = {
    "1s-5m": SimulationConfig(
        interval_s=1.0, noise_m=5.0, outlier_rate=0.02, route_length_m=ROUTE_M
    ),
    "15s-10m": SimulationConfig(
        interval_s=15.0, noise_m=10.0, outlier_rate=0.02, route_length_m=ROUTE_M
    ),
    "30s-20m": SimulationConfig(
        interval_s=30.0, noise_m=20.0, outlier_rate=0.02, route_length_m=ROUTE_M
    ),
    "realistic-1s": SimulationConfig.realistic(interval_s=1.0, route_length_m=ROUTE_M),
    "realistic-15s": SimulationConfig.realistic(interval_s=15.0, route_length_m=ROUTE_M),
}


def condition_config(name: str) -> SimulationConfig:
    """
    The simulation settings of a condition.

    A key of :data:`CONDITIONS`, or ``truth-<s>s``: noise-free at that interval (e.g.
    ``truth-0.1s``).

    Raises
    ------
    ConfigError
        An unknown condition.
    """
    if name in CONDITIONS:
        return CONDITIONS[name]
    found = re.fullmatch(r"truth-([0-9]*\.?[0-9]+)s", name)
    if found:
        return SimulationConfig.noise_free(interval_s=float(found.group(1)), route_length_m=ROUTE_M)
    msg = f"unknown condition {name!r}; known: {sorted(CONDITIONS)} or truth-<interval>s"
    raise ConfigError(msg)


def columns_of(spec: str) -> tuple[str, ...]:
    """
    The optional columns a spec keeps: an input class, ``none``, or columns joined by ``+``.

    Examples
    --------
    >>> columns_of("heading_speed"), columns_of("odometer+speed"), columns_of("none")
    (('accuracy', 'heading', 'speed'), ('odometer', 'speed'), ())
    """
    if spec in INPUT_CLASSES:
        return INPUT_CLASSES[spec]
    if spec == "none":
        return ()
    parts = tuple(spec.split("+"))
    unknown = sorted(set(parts) - set(TRUE_COLUMNS))
    if unknown:
        msg = (
            f"unknown input class or column(s) {unknown} in {spec!r}; classes: "
            f"{list(INPUT_CLASSES)}, columns: {list(TRUE_COLUMNS)} joined by '+', or 'none'"
        )
        raise ConfigError(msg)
    return parts
