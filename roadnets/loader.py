"""``roadnets.load``: an OSM extract (or the embedded default) to a :class:`RoadNetwork`."""

from __future__ import annotations

import logging
import time
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

from roadnets.cache import (
    default_cache_dir,
    ensure_writable,
    entry_folder,
    file_digest,
    read_entry,
    write_entry,
)
from roadnets.compile import choose_projector, compile_network
from roadnets.errors import (
    CacheError,
    InvalidNetworkSourceError,
    NetworkReopenError,
    NetworkSourceNotFoundError,
    NoDrivableRoadsError,
)
from roadnets.network import RoadNetwork
from roadnets.projection import Projector

if TYPE_CHECKING:
    import os

__all__ = ["DEFAULT_NETWORK", "default_network_path", "load", "network_id_of", "reopen"]

#: File name of the embedded default network (Monaco, OSM 2020-07; ODbL, see data/README.md).
DEFAULT_NETWORK = "monaco_2020.osm.pbf"

_log = logging.getLogger("roadnets")
_SUFFIXES = (".osm.pbf", ".osm.bz2", ".osm.gz", ".pbf", ".osm")


def default_network_path() -> Path:
    """Path of the OSM extract shipped inside the package."""
    return Path(str(resources.files("roadnets") / "data" / DEFAULT_NETWORK))


def network_id_of(path: Path) -> str:
    """A network's id: its file name without the OSM suffixes (``monaco_2020``)."""
    name = path.name
    for suffix in _SUFFIXES:
        if name.endswith(suffix):
            return name[: -len(suffix)]
    return path.stem


def load(
    source: str | os.PathLike[str] | None = None,
    *,
    cache_dir: str | os.PathLike[str] | None = None,
    use_cache: bool = True,
) -> RoadNetwork:
    """
    Load an OSM extract as a routable, R-tree indexed road network.

    The first load of an extract parses and compiles it and stores the result in the cache;
    later loads of the same content read (memory-map) the cache instead.

    Parameters
    ----------
    source
        An OSM XML (``.osm``, ``.osm.bz2``, ``.osm.gz``) or PBF (``.osm.pbf``) file. ``None``
        loads the embedded default network (Monaco).
    cache_dir
        Folder of compiled networks; default ``$MAPMATCH_CACHE_DIR`` or ``~/.cache/mapmatch``.
        An explicit folder that cannot be written is an error; an unusable default only
        disables caching (with a warning).
    use_cache
        ``False`` always compiles from the source and writes nothing.

    Returns
    -------
    RoadNetwork
        The network; ``net.info()`` summarises it.

    Raises
    ------
    NetworkSourceNotFoundError
        ``source`` does not exist.
    InvalidNetworkSourceError
        ``source`` is not a readable OSM extract (not OSM, truncated, corrupt).
    NoDrivableRoadsError
        The extract holds no drivable road.
    CacheError
        ``cache_dir`` was given and cannot be written.
    """
    started = time.perf_counter()
    path = Path(source) if source is not None else default_network_path()
    if not path.exists():
        raise NetworkSourceNotFoundError(str(path))
    if not path.is_file():
        raise InvalidNetworkSourceError(str(path), "it is a folder, not a file")

    folder = None
    if use_cache:
        folder = _cache_folder(path, cache_dir)
    digest = file_digest(path)
    if folder is not None:
        cached = _open_entry(path, entry_folder(folder, digest), digest, started)
        if cached is not None:
            return cached

    from roadnets.osm_reader import read_osm  # libosmium: only to compile

    extract = read_osm(path)
    if not extract.ways:
        raise NoDrivableRoadsError(str(path))
    projector = choose_projector(extract, str(path))
    arrays = compile_network(extract, projector)
    entry = None
    if folder is not None:
        entry = entry_folder(folder, digest)
        meta = {
            "source_name": path.name,
            "source_sha256": digest,
            "crs": projector.crs,
            "clipped_ways": extract.clipped_ways,
            "nodes": arrays.n_nodes,
            "edges": arrays.n_edges,
        }
        write_entry(entry, arrays, meta)
    return RoadNetwork(
        network_id=network_id_of(path),
        source=str(path),
        source_sha256=digest,
        arrays=arrays,
        projector=projector,
        clipped_ways=extract.clipped_ways,
        from_cache=False,
        load_s=time.perf_counter() - started,
        cache_entry=str(entry) if entry is not None else None,
    )


def _open_entry(path: Path, entry: Path, digest: str, started: float) -> RoadNetwork | None:
    """The network of a cache entry (memory-mapped), ``None`` when it is missing or corrupt."""
    cached = read_entry(entry)
    if cached is None:
        return None
    arrays, meta = cached
    return RoadNetwork(
        network_id=network_id_of(path),
        source=str(path),
        source_sha256=digest,
        arrays=arrays,
        projector=Projector(str(meta["crs"])),
        clipped_ways=int(meta["clipped_ways"]),
        from_cache=True,
        load_s=time.perf_counter() - started,
        cache_entry=str(entry),
    )


def reopen(network_id: str, source: str, source_sha256: str, cache_entry: str) -> RoadNetwork:
    """
    Open a network again from its cache entry, in this process (how a pickle is loaded).

    The entry is memory-mapped as :func:`load` does; when it is gone (the cache was cleared,
    or this is another machine) the source is compiled again into the same cache folder,
    provided it is still there with the same content.

    Raises
    ------
    NetworkReopenError
        Neither the entry nor the unchanged source can be read here.
    """
    started = time.perf_counter()
    path, entry = Path(source), Path(cache_entry)
    net = _open_entry(path, entry, source_sha256, started)
    if net is None:
        if not path.is_file():
            reason = (
                f"its cache entry {cache_entry!r} and its source are not in this process's reach"
            )
            raise NetworkReopenError(network_id, reason)
        if file_digest(path) != source_sha256:
            raise NetworkReopenError(network_id, f"its source {source!r} changed since")
        net = load(path, cache_dir=entry.parent)
    net.network_id = network_id
    return net


def _cache_folder(path: Path, cache_dir: str | os.PathLike[str] | None) -> Path | None:
    if cache_dir is not None:
        folder = Path(cache_dir)
        ensure_writable(folder)
        return folder
    folder = default_cache_dir()
    try:
        ensure_writable(folder)
    except CacheError as exc:
        _log.warning("%s; loading %s without a cache", exc, path.name)
        return None
    return folder
