"""
How many cores this process may use: the one answer the batch, the service and its workers share.

A process may run on the cores of its CPU affinity, and no faster than its control group's CPU
quota allows (a container started with ``--cpus 2``, a Kubernetes CPU limit): on a 64-core host
such a container sees all 64 cores in its affinity but gets the time of two. Sizing pools by the
affinity alone would start 64 workers that share two cores' time and each hold a copy of the
matcher's memory.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

__all__ = ["CGROUP_ROOT", "available_cores", "cgroup_cpu_limit"]

#: Where Linux mounts the control-group file system.
CGROUP_ROOT = Path("/sys/fs/cgroup")


def cgroup_cpu_limit(root: Path = CGROUP_ROOT) -> float | None:
    """
    The CPU quota of this process's control group, in cores; ``None`` when there is none.

    Reads cgroup v2's ``cpu.max`` (``"<quota> <period>"`` or ``"max <period>"``) of the group
    ``/proc/self/cgroup`` names, else the one at ``root`` (a container's own group, mounted
    there), else cgroup v1's ``cpu/cpu.cfs_quota_us`` and ``cpu/cpu.cfs_period_us`` (quota
    ``-1``: none). Files missing or unreadable mean no limit; limits of parent groups are not
    looked for.

    Examples
    --------
    >>> import tempfile
    >>> folder = Path(tempfile.mkdtemp())
    >>> _ = (folder / "cpu.max").write_text("150000 100000")
    >>> cgroup_cpu_limit(folder)
    1.5
    >>> _ = (folder / "cpu.max").write_text("max 100000")
    >>> cgroup_cpu_limit(folder) is None
    True
    """
    groups = [root / group / "cpu.max" for group in _own_groups()]
    text = _first_readable([*groups, root / "cpu.max"])
    if text is not None:
        quota, _, period = text.partition(" ")
    else:
        quota = _first_readable([root / "cpu" / "cpu.cfs_quota_us"]) or ""
        period = _first_readable([root / "cpu" / "cpu.cfs_period_us"]) or ""
    try:
        cores = int(quota) / int(period)
    except (ValueError, ZeroDivisionError):  # "max", nothing, or not a number
        return None
    return cores if cores > 0 else None


def _own_groups() -> list[str]:
    """The cgroup v2 group of this process, relative to the mount (none when not known)."""
    text = _first_readable([Path("/proc/self/cgroup")]) or ""
    groups = [line[3:].strip("/") for line in text.splitlines() if line.startswith("0::/")]
    return [group for group in groups[:1] if group]


def _first_readable(paths: list[Path]) -> str | None:
    """The stripped text of the first of ``paths`` that can be read."""
    for path in paths:
        try:
            return path.read_text().strip()
        except OSError:
            continue
    return None


def available_cores(root: Path = CGROUP_ROOT) -> int:
    """
    Cores this process may use: its CPU affinity, cut to its control group's quota; at least 1.

    A fractional quota counts as the cores it starts to use (1.5 cores: 2).

    Examples
    --------
    >>> available_cores() >= 1
    True
    """
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        cores = os.cpu_count() or 1
    limit = cgroup_cpu_limit(root)
    if limit is not None:
        cores = min(cores, math.ceil(limit))
    return max(1, cores)
