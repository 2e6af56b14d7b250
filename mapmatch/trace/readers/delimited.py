"""
CSV (also gzipped): the separator, decimal mark and encoding told from the file.

``,``, ``;``, tab or ``|`` between fields (told from the header line, or from an Excel
``sep=;`` first line); with ``;``, tab or ``|``, a decimal comma (``43,73``) is read when the
numbers use one; a UTF-8 byte-order mark is ignored, UTF-16 (Excel's "Unicode text") is
converted, and a file that is not UTF-8 is read as Latin-1 (with a note). Blank lines are
skipped, the line numbers of the others kept right.
"""

from __future__ import annotations

import gzip
import io
import re

import numpy as np
import pandas as pd

from mapmatch.errors import TraceFileError
from mapmatch.trace.readers.grouping import group_rows, select_id_columns
from mapmatch.trace.readers.raw import Context, RawTrace, with_notes

__all__ = ["read_csv"]


def _decode_text(data: bytes) -> bytes:
    """The bytes without a UTF-8 byte-order mark; UTF-16 (with its mark) converted to UTF-8."""
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        return data.decode("utf-16").encode("utf-8")
    if data.startswith(b"\xef\xbb\xbf"):
        return data[3:]
    return data


def _latin1_note(data: bytes) -> str:
    """Why a CSV is read as Latin-1: where it stops being UTF-8."""
    try:
        data.decode("utf-8")
    except UnicodeDecodeError as exc:
        where = f" (byte {exc.start + 1})"
    else:  # pragma: no cover - only called after pandas failed to decode
        where = ""
    return f"the file is not UTF-8{where}; it was read as Latin-1, so check accented text"


_COMMA_NUMBER = re.compile(r"^\s*\"?[-+]?\d+,\d+\"?\s*$")


_DOT_NUMBER = re.compile(r"^\s*\"?[-+]?\d+\.\d+\"?\s*$")


def _csv_dialect(data: bytes) -> tuple[str, str, int]:
    r"""
    ``(separator, decimal mark, lines to skip)`` told from the first lines of a CSV.

    Examples
    --------
    >>> _csv_dialect(b"time;lat;lon\n0;43,73;7,42\n")
    (';', ',', 0)
    >>> _csv_dialect(b"sep=|\ntime|lat|lon\n")
    ('|', '.', 1)
    """
    lines = data[:65536].decode("utf-8", errors="replace").splitlines()
    skip = 0
    head = next((line for line in lines if line.strip()), "")
    if head.lower().startswith("sep=") and len(head.strip()) == 5:
        sep, skip = head.strip()[4], lines.index(head) + 1
    else:
        counts = {s: head.count(s) for s in (",", ";", "\t", "|")}
        sep = max(counts, key=lambda s: counts[s]) if any(counts.values()) else ","
    decimal = "."
    if sep != ",":
        cells = [c for line in lines[skip + 1 : skip + 51] for c in line.split(sep)]
        commas = sum(1 for c in cells if _COMMA_NUMBER.match(c))
        dots = sum(1 for c in cells if _DOT_NUMBER.match(c))
        if commas > dots:
            decimal = ","
    return sep, decimal, skip


def read_csv(data: bytes, ctx: Context) -> list[RawTrace]:
    """The traces of a CSV file (gzipped or not), grouped by its id columns."""
    compressed = data[:2] == b"\x1f\x8b"
    if compressed:
        try:
            data = gzip.decompress(data)
        except (OSError, EOFError) as exc:
            msg = f"is not valid gzip: {exc}"
            raise ctx.error(msg) from exc
    data = _decode_text(data)
    sep, decimal, skip = _csv_dialect(data)
    notes: tuple[str, ...] = ()
    try:
        frame = _csv_frame(data, ctx, sep=sep, decimal=decimal, skip=skip, encoding="utf-8")
    except UnicodeDecodeError:
        notes = (_latin1_note(data),)
        frame = _csv_frame(data, ctx, sep=sep, decimal=decimal, skip=skip, encoding="latin-1")
    # Blank lines are not data: drop them but keep the line numbers of the others right
    # (header = line 1 + skip, first data row = line 2 + skip; one line per record assumed).
    keep = frame.notna().any(axis=1).to_numpy()
    numbers = np.flatnonzero(keep).astype(np.int64) + 2 + skip
    if not keep.all():
        frame = frame.loc[keep]
    traces = group_rows(frame.reset_index(drop=True), numbers=numbers, label="line", ctx=ctx)
    return [with_notes(t, notes) for t in traces]


def _csv_frame(
    data: bytes, ctx: Context, *, sep: str, decimal: str, skip: int, encoding: str
) -> pd.DataFrame:
    """The CSV's table, id columns read as text; UnicodeDecodeError passes through."""
    try:
        header = pd.read_csv(io.BytesIO(data), nrows=0, sep=sep, skiprows=skip, encoding=encoding)
        id_cols = select_id_columns([str(c) for c in header.columns], ctx)
        return pd.read_csv(
            io.BytesIO(data),
            sep=sep,
            decimal=decimal,
            skiprows=skip,
            skip_blank_lines=False,
            encoding=encoding,
            dtype=dict.fromkeys(id_cols, str) if id_cols else None,
        )
    except pd.errors.EmptyDataError as exc:
        msg = "is empty; expected a header line and rows"
        raise ctx.error(msg) from exc
    except UnicodeDecodeError:
        raise
    except TraceFileError:
        raise
    except (pd.errors.ParserError, ValueError) as exc:
        msg = f"is not readable as CSV: {exc}"
        raise ctx.error(msg) from exc
