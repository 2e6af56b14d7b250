"""
KML: Placemarks with a ``gx:Track`` or a ``LineString``.

Every Placemark with a ``gx:Track`` (``<when>`` and ``<gx:coord>``; several in a
``gx:MultiTrack`` are segments) or a ``LineString`` (no times) is one trace.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from mapmatch.trace.readers.pieces import Piece, pieces_to_traces
from mapmatch.trace.readers.xmldoc import child_name, local_tag, xml_root

if TYPE_CHECKING:
    from mapmatch.trace.readers.raw import Context, RawTrace

__all__ = ["read_kml"]


def read_kml(data: bytes, ctx: Context) -> list[RawTrace]:
    """One trace per Placemark with a ``gx:Track`` or a ``LineString``."""
    root = xml_root(data, ctx, "kml")
    pieces: list[Piece] = []
    marks = [el for el in root.iter() if local_tag(el.tag) == "placemark"]
    for k, mark in enumerate(marks, start=1):
        piece = Piece("Placemark", k, child_name(mark), "coord")
        for el in mark.iter():
            tag = local_tag(el.tag)
            if tag == "track":
                whens = [w.text for w in el if local_tag(w.tag) == "when"]
                coords = [c.text or "" for c in el if local_tag(c.tag) == "coord"]
                if whens and len(whens) != len(coords):
                    msg = (
                        f"Placemark {k}: a gx:Track has {len(whens)} <when> for "
                        f"{len(coords)} <gx:coord>; give one time per position"
                    )
                    raise ctx.error(msg)
                parts = [c.split() for c in coords]
                times = [w.strip() if w else None for w in whens] or [None] * len(coords)
                _add_segment(piece, parts, times)
            elif tag == "linestring":
                text = next((c.text or "" for c in el if local_tag(c.tag) == "coordinates"), "")
                parts = [t.split(",") for t in text.split()]
                _add_segment(piece, parts, [None] * len(parts))
        pieces.append(piece)
    if not any(p.records for p in pieces):
        msg = "has no Placemark with a gx:Track or a LineString (points alone are not a trace)"
        raise ctx.error(msg)
    return pieces_to_traces(pieces, ctx)


def _add_segment(piece: Piece, parts: list[list[str]], times: list[str | None]) -> None:
    if not parts:
        return
    number = piece.segment[-1] + 1 if piece.segment else 0
    for p, t in zip(parts, times, strict=True):
        lon, lat = (p[0], p[1]) if len(p) >= 2 else (None, None)
        piece.records.append({"time": t, "lon": lon, "lat": lat})
    piece.segment.extend([number] * len(parts))
