"""Way names (``name``, else ``ref``) kept as three arrays, read like a dict.

A dict of hundreds of thousands of ``int -> str`` entries costs tens of MB of Python objects
per process and a JSON parse at every load. The names live in the network's arrays instead
(memory-mapped from the cache and shared between processes like the rest): the sorted way ids,
offsets, and the UTF-8 bytes of every name end to end. :class:`WayNames` reads them as a
mapping and looks many up at once (:meth:`WayNames.names_of`); :func:`edge_records` reads
what the network says about some edges, their ways' names included, in one compiled pass.
"""

from __future__ import annotations

from collections.abc import Iterator, MutableMapping
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from collections.abc import Mapping

    from roadnets.arrays import NetworkArrays

__all__ = ["EdgeRecords", "WayNames", "edge_records", "encode_names"]

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]
ByteArray = npt.NDArray[np.uint8]


def encode_names(names: Mapping[int, str]) -> tuple[IntArray, IntArray, ByteArray]:
    """
    Sorted way ids, offsets and UTF-8 bytes of a ``{way id: name}`` mapping.

    Examples
    --------
    >>> ids, ptr, blob = encode_names({7: "Rue Grimaldi", 3: "A8"})
    >>> ids.tolist(), ptr.tolist(), bytes(blob).decode()
    ([3, 7], [0, 2, 14], 'A8Rue Grimaldi')
    """
    ids = sorted(names)
    encoded = [names[i].encode("utf-8") for i in ids]
    ptr = np.zeros(len(ids) + 1, dtype=np.int64)
    np.cumsum([len(b) for b in encoded], out=ptr[1:])
    blob = np.frombuffer(b"".join(encoded), dtype=np.uint8).copy()
    return np.asarray(ids, dtype=np.int64), ptr, blob


def _decode_each(blob: ByteArray, start: IntArray, size: IntArray) -> list[str]:
    """The UTF-8 names ``blob[start:start + size]``, one slice and one decode each."""
    return [
        bytes(blob[a : a + n]).decode("utf-8") if n else ""
        for a, n in zip(start.tolist(), size.tolist(), strict=True)
    ]


def _decode_joined(ids: IntArray, ptr: IntArray, blob: ByteArray, ways: IntArray) -> list[str]:
    """
    The UTF-8 names of ``ways`` (``""`` where a way has none), gathered and decoded at once.

    The names are gathered NUL-separated by one compiled pass. Splitting the decoded text
    at NULs gives the names back unless a name holds a NUL itself (OSM text never does; then
    they are decoded one by one): one call and one decode instead of a slice and a decode
    per name (about 0.5 us each), or the dozen array operations of a gather in numpy.

    Examples
    --------
    >>> ids, ptr, blob = encode_names({7: "Rue Grimaldi", 3: "A8"})
    >>> _decode_joined(ids, ptr, blob, np.array([7, 5, 3]))
    ['Rue Grimaldi', '', 'A8']
    """
    from roadnets.names_kernel import gather_names  # numba only once names are read

    if not len(ways):
        return []
    joined, start, size = gather_names(ids, ptr, blob, ways)
    return _split(joined, blob, start, size)


def _split(joined: ByteArray, blob: ByteArray, start: IntArray, size: IntArray) -> list[str]:
    """The names a compiled gather joined with NULs (one by one if a name holds a NUL)."""
    if not len(start):
        return []
    names = joined.tobytes().decode("utf-8").split("\0")
    return names if len(names) == len(start) else _decode_each(blob, start, size)


class WayNames(MutableMapping[int, str]):
    """
    ``{way id: name}`` over the network's name arrays.

    Reads like the dict it replaces (``names.get(way, "")``, ``len``, iteration in way id
    order). Writes go to a small overlay in this process only (tests relabel a street this
    way); the arrays are never changed.

    Examples
    --------
    >>> names = WayNames(*encode_names({7: "Rue Grimaldi", 3: "A8"}))
    >>> names[7], names.get(5, ""), len(names), list(names)
    ('Rue Grimaldi', '', 2, [3, 7])
    >>> names.names_of(np.array([7, 5, 3]))
    ['Rue Grimaldi', '', 'A8']
    """

    __slots__ = ("_blob", "_deleted", "_ids", "_overlay", "_ptr")

    def __init__(self, way_id: IntArray, ptr: IntArray, blob: ByteArray) -> None:
        self._ids, self._ptr, self._blob = way_id, ptr, blob
        self._overlay: dict[int, str] = {}
        self._deleted: set[int] = set()

    def _index(self, way: int) -> int:
        i = int(np.searchsorted(self._ids, way))
        return i if i < len(self._ids) and int(self._ids[i]) == way else -1

    def _decode(self, i: int) -> str:
        return bytes(self._blob[self._ptr[i] : self._ptr[i + 1]]).decode("utf-8")

    def __getitem__(self, way: int) -> str:
        if way in self._overlay:
            return self._overlay[way]
        i = self._index(int(way)) if way not in self._deleted else -1
        if i < 0:
            raise KeyError(way)
        return self._decode(i)

    def __contains__(self, way: object) -> bool:
        if way in self._overlay:
            return True
        if not isinstance(way, int | np.integer) or way in self._deleted:
            return False
        return self._index(int(way)) >= 0

    def __setitem__(self, way: int, name: str) -> None:
        self._overlay[int(way)] = name
        self._deleted.discard(int(way))

    def __delitem__(self, way: int) -> None:
        if way in self._overlay:
            del self._overlay[way]
            if self._index(int(way)) >= 0:
                self._deleted.add(int(way))
            return
        if way in self._deleted or self._index(int(way)) < 0:
            raise KeyError(way)
        self._deleted.add(int(way))

    def __iter__(self) -> Iterator[int]:
        extra = sorted(k for k in self._overlay if self._index(k) < 0)
        for way in self._ids.tolist():
            if way not in self._deleted:
                yield way
        yield from extra

    def __len__(self) -> int:
        extra = sum(1 for k in self._overlay if self._index(k) < 0)
        return len(self._ids) - len(self._deleted) + extra

    def __repr__(self) -> str:
        return f"<WayNames: {len(self):,} named ways>"

    def __eq__(self, other: object) -> bool:
        plain = isinstance(other, WayNames) and not (
            self._overlay or self._deleted or other._overlay or other._deleted
        )
        if plain and isinstance(other, WayNames):
            return bool(
                np.array_equal(self._ids, other._ids)
                and np.array_equal(self._ptr, other._ptr)
                and np.array_equal(self._blob, other._blob)
            )
        return super().__eq__(other)

    __hash__ = None  # type: ignore[assignment]  # mutable, as a dict

    def arrays(self) -> tuple[IntArray, IntArray, ByteArray] | None:
        """
        The names as the compiled gathers read them, or ``None`` once edited in this process.

        ``(ids, ptr, blob)``: the sorted named ways, where each one's UTF-8 name starts in
        ``blob`` (and the end). An edited mapping is read through its edits, not these.
        """
        if self._overlay or self._deleted:
            return None
        return self._ids, self._ptr, self._blob

    def names_of(self, way_ids: npt.NDArray[np.integer[Any]]) -> list[str]:
        """The name of each way of an array (``""`` where it has none), one search for all."""
        ways = np.asarray(way_ids, dtype=np.int64).ravel()
        if self._overlay or self._deleted or not len(self._ids):
            return [self.get(way, "") for way in ways.tolist()]
        return _decode_joined(self._ids, self._ptr, self._blob, ways)


#: What :func:`edge_records` returns, one entry per edge each: ``u``, ``v``, ``key`` (OSM
#: ids), way id, length (m), speed limit (km/h), road class index and name.
EdgeRecords = tuple[
    IntArray, IntArray, IntArray, IntArray, FloatArray, FloatArray, IntArray, list[str]
]


def edge_records(arrays: NetworkArrays, names: WayNames, edge: IntArray) -> EdgeRecords:
    """
    The OSM ids, way, length, speed limit, class and name of each of the edges ``edge``.

    ``u``, ``v`` and ``key`` are the edge's OSM ids, then its OSM way, its length, its
    ``maxspeed`` in km/h (or the class default), the index of its class in
    :data:`roadnets.drivable.ROAD_CLASSES` and its way's name (``""`` for none).

    One compiled pass over the edges (:func:`~roadnets.names_kernel.gather_edges`) instead of
    a dozen array gathers and the names' own.

    Parameters
    ----------
    arrays
        The network's arrays.
    names
        Its way names (an edited :class:`WayNames` is read through its edits).
    edge
        Edge indices.

    Raises
    ------
    IndexError
        If an edge is not one of the network's.
    """
    from roadnets.names_kernel import gather_edges  # numba only once edges are read

    a = arrays
    whole, real, joined = gather_edges(
        np.ascontiguousarray(edge, dtype=np.int64), a.node_osm_id, a.edge_u, a.edge_v,
        a.edge_key, a.edge_way_id, a.edge_length_m, a.edge_speed_mps, a.edge_class,
        names._ids, names._ptr, names._blob,
    )  # fmt: skip
    u, v, key, way, road_class, start, size = whole
    if names._overlay or names._deleted:
        found = names.names_of(way)
    else:
        found = _split(joined, names._blob, start, size)
    return u, v, key, way, real[0], real[1], road_class, found
