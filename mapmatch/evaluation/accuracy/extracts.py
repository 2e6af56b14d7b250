"""Which OSM extracts the accuracy matrix runs on, and finding one by name."""

from __future__ import annotations

from pathlib import Path

import roadnets
from mapmatch.errors import ConfigError

__all__ = [
    "SHARED_EXTRACTS",
    "TEST_EXTRACTS",
    "default_extracts",
    "extract_name",
    "extract_named",
]

_ROOT = Path(__file__).resolve().parents[3]  # the repository (mapmatch/evaluation/accuracy/..)
SHARED_EXTRACTS = _ROOT.parent / "shared" / "data" / "osm"
TEST_EXTRACTS = _ROOT / "tests" / "data"
_QUICK = ("monaco_2020", "helsinki_center_2019")


def extract_name(path: Path) -> str:
    """The extract's name: its file name without the OSM suffixes (``monaco_2020``)."""
    return path.name.split(".osm")[0]


def default_extracts(*, quick: bool = False) -> list[Path]:
    """
    The extracts the matrix runs on.

    Every shared extract (``../shared/data/osm``), else the embedded network and the
    extracts in ``tests/data``; ``quick``: two of them (Monaco and Helsinki when present).
    """
    found = sorted(SHARED_EXTRACTS.glob("*.osm*"))
    if not found:
        found = [roadnets.default_network_path(), *sorted(TEST_EXTRACTS.glob("*.osm*"))]
    if quick:
        named = [p for name in _QUICK for p in found if extract_name(p) == name]
        found = (named + [p for p in found if p not in named])[:2]
    return found


def extract_named(name: str) -> Path:
    """
    An extract by name (as the tables give it) or path.

    Raises
    ------
    ConfigError
        No extract of that name and no such file.
    """
    for path in [*default_extracts(), roadnets.default_network_path()]:
        if extract_name(path) == name or str(path) == name:
            return path
    if Path(name).is_file():
        return Path(name)
    known = sorted({extract_name(p) for p in default_extracts()})
    msg = f"no extract named {name!r}; known: {known} (or give a path)"
    raise ConfigError(msg)
