"""
GPX 1.0 and 1.1: tracks and routes.

Every ``<trk>`` is one trace, its ``<trkseg>`` kept as known gaps
(:attr:`~mapmatch.trace.readers.RawTrace.segment`); every ``<rte>`` (``<rtept>``) is one
trace too. ``<time>`` and the point columns (``<speed>``, ``<course>``/``<heading>``/
``<bearing>``, ``<hdop>``, by the names of :mod:`mapmatch.trace.columns`) are read, also
from ``<extensions>``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Final

from mapmatch.trace.columns import canonical
from mapmatch.trace.readers.pieces import Piece, pieces_to_traces
from mapmatch.trace.readers.xmldoc import child_name, local_tag, xml_root

if TYPE_CHECKING:
    import xml.etree.ElementTree as ET

    from mapmatch.trace.readers.raw import Context, RawTrace

__all__ = ["read_gpx"]

_GPX_FIELDS: Final = frozenset({"heading", "speed", "hdop"})  # read from a trkpt's children


def read_gpx(data: bytes, ctx: Context) -> list[RawTrace]:
    """One trace per ``<trk>`` (segments kept) and per ``<rte>``."""
    root = xml_root(data, ctx, "gpx")
    pieces: list[Piece] = []
    for k, trk in enumerate((el for el in root if local_tag(el.tag) == "trk"), start=1):
        piece = Piece("trk", k, child_name(trk), "trkpt")
        for child in trk:
            if local_tag(child.tag) != "trkseg":
                continue
            points = [_gpx_point(pt) for pt in child if local_tag(pt.tag) == "trkpt"]
            if points:
                number = piece.segment[-1] + 1 if piece.segment else 0
                piece.records.extend(points)
                piece.segment.extend([number] * len(points))
        pieces.append(piece)
    for k, rte in enumerate((el for el in root if local_tag(el.tag) == "rte"), start=1):
        piece = Piece("rte", k, child_name(rte), "rtept")
        piece.records = [_gpx_point(pt) for pt in rte if local_tag(pt.tag) == "rtept"]
        pieces.append(piece)
    if not any(p.records for p in pieces):
        msg = (
            "has no <trk>/<trkseg>/<trkpt> points and no <rte>/<rtept> points "
            "(waypoints alone are not a trace)"
        )
        raise ctx.error(msg)
    return pieces_to_traces(pieces, ctx)


def _gpx_point(pt: ET.Element) -> dict[str, object]:
    rec: dict[str, object] = {"lat": pt.get("lat"), "lon": pt.get("lon"), "time": None}
    for el in pt.iter():
        if el is pt or el.text is None:
            continue
        tag = local_tag(el.tag)
        if tag == "time":
            rec["time"] = el.text.strip()
        elif canonical(tag) in _GPX_FIELDS:
            rec[str(canonical(tag))] = el.text.strip()
    return rec
