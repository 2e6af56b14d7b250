"""
Traces of documents made of named pieces.

GPX tracks and routes, KML Placemarks and GeoJSON LineStrings are pieces: each is one
trace, named by its own name, else the file stem, else (several unnamed) ``<stem>-<k>``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from mapmatch.trace.readers.raw import Context, RawTrace

__all__ = ["Piece", "pieces_to_traces"]


@dataclass(slots=True)
class Piece:
    """One trace of an XML or GeoJSON file before it is named."""

    what: str  # "trk", "rte", "Placemark", "LineString"
    k: int  # 1-based number among its kind
    name: str | None
    label: str
    records: list[dict[str, object]] = field(default_factory=list)
    segment: list[int] = field(default_factory=list)


def pieces_to_traces(pieces: list[Piece], ctx: Context) -> list[RawTrace]:
    """One trace per non-empty piece, named by the rule above."""
    traces = []
    for tid, piece in _name_pieces(pieces, ctx):
        numbers = np.arange(1, len(piece.records) + 1, dtype=np.int64)
        frame = pd.DataFrame.from_records(piece.records)
        segment = None
        if piece.segment and piece.segment[-1] > 0:
            segment = np.asarray(piece.segment, dtype=np.int64)
        source = f"{ctx.name} {piece.what} {piece.k}"
        traces.append(RawTrace(tid, frame, numbers, piece.label, source, segment))
    return traces


def _name_pieces(pieces: list[Piece], ctx: Context) -> list[tuple[str, Piece]]:
    """Give every non-empty piece an id: its own name, the stem, or ``<stem>-<k>``."""
    full = [p for p in pieces if p.records]
    unnamed = sum(1 for p in full if p.name is None)
    seen: dict[str, Piece] = {}
    out = []
    for position, piece in enumerate(full, start=1):
        k = piece.k if len({p.what for p in full}) == 1 else position
        tid = (
            piece.name
            if piece.name is not None
            else (ctx.default_id if unnamed == 1 else f"{ctx.default_id}-{k}")
        )
        if tid in seen:
            first = seen[tid]
            msg = (
                f"{first.what} {first.k} and {piece.what} {piece.k} are both named {tid!r}; "
                "give each trace its own name (or merge them)"
            )
            raise ctx.error(msg)
        seen[tid] = piece
        out.append((tid, piece))
    return out
