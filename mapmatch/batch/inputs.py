"""
Input side of batch matching: find trace files, list the traces in each, name their outputs.

:func:`discover_inputs` expands the command line's INPUT arguments (files, folders searched
recursively, ``-`` for CSV on standard input) into :class:`InputFile` entries in a stable
order. :func:`scan_file` lists the traces of one file without validating them, so that the
batch knows its total, can skip finished traces on ``--resume`` and can split big files into
chunks. :func:`assign_output_names` gives every trace a safe, unique file name.
"""

from __future__ import annotations

import hashlib
import os
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO

from mapmatch.errors import MapMatchError
from mapmatch.trace.readers import infer_format, read_raw_traces

if TYPE_CHECKING:
    from collections.abc import Iterable, Sequence

__all__ = [
    "SIDECAR_PARTS",
    "STDIN",
    "BatchInputError",
    "Discovered",
    "FileScan",
    "InputFile",
    "TraceRef",
    "assign_output_names",
    "discover_inputs",
    "error_line",
    "printable",
    "safe_name",
    "scan_file",
]

#: The INPUT argument that means "CSV on standard input".
STDIN = "-"

#: Suffixes of trace files picked up when a folder is searched (``.json`` is left out on
#: purpose: folders often hold unrelated JSON such as ``run.json``).
_FOLDER_SUFFIXES = (
    ".csv",
    ".csv.gz",
    ".tsv",
    ".gpx",
    ".kml",
    ".nmea",
    ".nma",
    ".geojson",
    ".parquet",
    ".pq",
)
_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")
_MAX_NAME = 120


class BatchInputError(MapMatchError, ValueError):
    """The command line names inputs that do not exist or hold no trace files."""


@dataclass(frozen=True, slots=True)
class InputFile:
    """
    One trace file of a batch.

    Attributes
    ----------
    path
        Absolute path of the file to read (for standard input, a spooled copy).
    display
        How the file is named in ``summary.csv`` and messages: the path as given, or ``-``.
    format
        Trace format (``"csv"``, ``"gpx"`` ...), or ``None`` to infer it from the suffix.
    """

    path: str
    display: str
    format: str | None = None


@dataclass(frozen=True, slots=True)
class TraceRef:
    """
    One trace of a file, before it is read for matching.

    Attributes
    ----------
    index
        0-based position of the trace in its file (ids may repeat in GPX; positions do not).
    trace_id
        The trace's id.
    points
        Number of rows (fixes) in the source.
    """

    index: int
    trace_id: str
    points: int


@dataclass(frozen=True, slots=True)
class FileScan:
    """The traces of one file, or why the file cannot be read (``error``, one line)."""

    file: InputFile
    traces: tuple[TraceRef, ...]
    error: str | None = None


def printable(text: str) -> str:
    r"""
    ``text`` as UTF-8 can hold it: bytes a file name had that are not UTF-8 written ``\xNN``.

    A file name that is not UTF-8 reaches Python with lone surrogates (``os.fsdecode``);
    they cannot be written to ``summary.csv`` or printed, so they are spelled out.

    Examples
    --------
    >>> printable("caf\udce9.csv"), printable("café.csv")
    ('caf\\xe9.csv', 'café.csv')
    """
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        try:
            raw = text.encode("utf-8", "surrogateescape")
        except UnicodeEncodeError:
            return text.encode("utf-8", "backslashreplace").decode("utf-8")
        return raw.decode("utf-8", "backslashreplace")
    return text


def error_line(exc: BaseException) -> str:
    r"""
    One line naming an error: its class and the first line of its message.

    Examples
    --------
    >>> error_line(ValueError("bad value\nmore detail"))
    'ValueError: bad value'
    """
    text = printable(str(exc)).strip().splitlines()
    first = text[0].strip() if text else ""
    name = type(exc).__name__
    return f"{name}: {first}" if first else name


@dataclass(frozen=True, slots=True)
class Discovered:
    """
    The trace files of a batch's INPUT arguments.

    Attributes
    ----------
    files
        The files to read, in order.
    skipped
        Files of the folders searched that were left out because they lie in the output
        folder or in another batch's output folder (one holding ``run.json`` and
        ``summary.csv``): a batch never reads its own outputs back as traces.
    """

    files: list[InputFile]
    skipped: tuple[str, ...] = ()


def _is_batch_output(folder: Path) -> bool:
    return (folder / "run.json").is_file() and (folder / "summary.csv").is_file()


def discover_inputs(
    inputs: Sequence[str],
    *,
    spool_dir: str | os.PathLike[str],
    stdin: BinaryIO | None = None,
    out_dir: str | os.PathLike[str] | None = None,
) -> Discovered:
    """
    Expand INPUT arguments into trace files.

    Parameters
    ----------
    inputs
        Files, folders (searched recursively for ``.csv``, ``.csv.gz``, ``.tsv``, ``.gpx``,
        ``.kml``, ``.nmea``, ``.nma``, ``.geojson``, ``.parquet`` and ``.pq`` files, hidden
        entries skipped) and at most one ``-`` (CSV on standard input). File names need not
        be UTF-8.
    spool_dir
        Folder where standard input is copied (as ``.stdin-<hash>.csv``) so that worker
        processes can read it like any file.
    stdin
        Binary stream read for ``-``; default ``sys.stdin.buffer``.
    out_dir
        The batch's output folder: files under it, and under any folder holding a batch's
        ``run.json`` and ``summary.csv``, are skipped when a folder is searched.

    Returns
    -------
    Discovered
        Arguments in the order given; the files of a folder sorted by path. A file named
        twice is kept once.

    Raises
    ------
    BatchInputError
        An input does not exist, ``-`` is given twice, or nothing was found.
    """
    found: list[InputFile] = []
    skipped: list[str] = []
    seen: set[str] = set()
    stdin_used = False
    outputs = os.path.realpath(out_dir) if out_dir is not None else None
    for arg in inputs:
        if arg == STDIN:
            if stdin_used:
                msg = "'-' (standard input) is given twice; name it once"
                raise BatchInputError(msg)
            stdin_used = True
            stream = stdin if stdin is not None else sys.stdin.buffer
            found.append(_spool_stdin(stream, Path(spool_dir)))
            continue
        path = Path(arg)
        if path.is_dir():
            files, left_out = _search(path, outputs)
            skipped += left_out
            candidates = [(p, str(p)) for p in files]
        elif path.is_file():
            candidates = [(path, arg)]
        else:
            msg = (
                f"input {printable(arg)!r} does not exist; give trace files, folders or - for stdin"
            )
            raise BatchInputError(msg)
        for p, display in candidates:
            key = os.path.realpath(p)
            if key not in seen:
                seen.add(key)
                found.append(InputFile(path=os.path.abspath(p), display=printable(display)))
    if not found:
        shown = ", ".join(repr(printable(a)) for a in inputs) or "none"
        more = f" ({len(skipped)} file(s) in output folders left out)" if skipped else ""
        msg = (
            f"no trace files found in {shown}{more}; folders are searched for "
            f"{', '.join(_FOLDER_SUFFIXES)} files"
        )
        raise BatchInputError(msg)
    return Discovered(files=found, skipped=tuple(skipped))


def _trace_file(name: str) -> bool:
    return not name.startswith(".") and name.lower().endswith(_FOLDER_SUFFIXES)


def _search(folder: Path, outputs: str | None) -> tuple[list[Path], list[str]]:
    """Trace files under ``folder`` (sorted), and those left out as batch outputs."""
    keep: list[Path] = []
    left_out: list[str] = []
    for root, dirs, names in os.walk(folder):
        here = Path(root)
        dirs[:] = [d for d in dirs if not d.startswith(".")]
        if (outputs is not None and os.path.realpath(here) == outputs) or _is_batch_output(here):
            left_out += [
                printable(str(Path(r) / n))
                for r, _, ns in os.walk(here)
                if not any(part.startswith(".") for part in Path(r).relative_to(here).parts)
                for n in ns
                if _trace_file(n)
            ]
            dirs[:] = []  # nothing below an output folder is read
            continue
        keep += [here / n for n in names if _trace_file(n)]
    return sorted(keep), sorted(left_out)


def _spool_stdin(stream: BinaryIO, spool_dir: Path) -> InputFile:
    data = stream.read()
    digest = hashlib.sha256(data).hexdigest()[:16]
    spool_dir.mkdir(parents=True, exist_ok=True)
    target = spool_dir / f".stdin-{digest}.csv"
    if not target.exists():
        tmp = spool_dir / f".stdin-{digest}.csv.tmp-{os.getpid()}"
        tmp.write_bytes(data)
        os.replace(tmp, target)
    return InputFile(path=str(target.resolve()), display=STDIN, format="csv")


def scan_file(file: InputFile, *, id_column: str | None = None) -> FileScan:
    """
    List the traces of a file without validating their rows.

    Never raises for a bad file: the reason goes to :attr:`FileScan.error`.

    Parameters
    ----------
    file
        The file to scan.
    id_column
        The column naming the traces of a table (default: the usual id columns).
    """
    try:
        fmt = file.format or infer_format(file.path)
        default_id = "stdin" if file.display == STDIN else None
        raws = read_raw_traces(
            file.path, format=fmt, default_trace_id=default_id, id_column=id_column
        )
    except Exception as exc:
        return FileScan(file=file, traces=(), error=error_line(exc))
    refs = tuple(
        TraceRef(index=i, trace_id=printable(str(raw.trace_id)), points=len(raw.frame))
        for i, raw in enumerate(raws)
    )
    return FileScan(file=file, traces=refs)


def safe_name(trace_id: str) -> str:
    """
    A file name for a trace id: letters, digits, ``.``, ``_`` and ``-`` only, at most 120.

    Runs of other characters become ``_``; a leading dot is dropped; an empty result
    becomes ``trace``. Names that were changed get a short hash of the id, so ``a/b`` and
    ``a_b`` stay apart.

    Examples
    --------
    >>> safe_name("bus-12")
    'bus-12'
    >>> safe_name("../etc/passwd")
    'etc_passwd-e96c47ea'
    """
    cleaned = _UNSAFE.sub("_", trace_id).strip("._") or "trace"
    if cleaned == trace_id and len(cleaned) <= _MAX_NAME:
        return cleaned
    digest = hashlib.sha1(trace_id.encode("utf-8")).hexdigest()[:8]
    return f"{cleaned[: _MAX_NAME - 9]}-{digest}"


#: Name endings the per-trace sidecar files add (``<name>.edges.csv`` ...): a trace whose
#: name ends in one would write over another trace's sidecar, so names are kept apart on
#: every file they make (see :func:`assign_output_names`).
SIDECAR_PARTS = (".edges", ".segments")
#: Names of the batch's own files in the output folder (``summary.csv``, ``run.json``).
_RESERVED = ("summary", "run")


def _stems(name: str) -> set[str]:
    """Every file name a trace's outputs may start with (case-folded), sidecars included."""
    low = name.lower()
    return {low, *(low + part for part in SIDECAR_PARTS)}


def assign_output_names(keys: Iterable[tuple[str, int, str]]) -> dict[tuple[str, int, str], str]:
    """
    Unique output names for ``(source, index, trace_id)`` keys, in the order given.

    The first trace with a given safe name keeps it; a later one whose files would meet an
    earlier one's (the same id in another file, an id differing only in case, or one like
    ``x.edges`` whose files are trace ``x``'s sidecars) gets ``~2``, ``~3`` ... Names are
    compared case-insensitively, so outputs stay apart on case-insensitive file systems.

    Examples
    --------
    >>> names = assign_output_names([("a.csv", 0, "t"), ("b.csv", 0, "t"), ("b.csv", 1, "T")])
    >>> list(names.values())
    ['t', 't~2', 'T~3']
    >>> keys = [("a", 0, "x"), ("a", 1, "x.edges"), ("a", 2, "y.Edges")]
    >>> list(assign_output_names(keys).values())
    ['x', 'x.edges~2', 'y.Edges']
    """
    taken: set[str] = {stem for name in _RESERVED for stem in _stems(name)}
    out: dict[tuple[str, int, str], str] = {}
    for key in keys:
        base = safe_name(key[2])
        name, n = base, 1
        while _stems(name) & taken:
            n += 1
            name = f"{base}~{n}"
        taken |= _stems(name)
        out[key] = name
    return out
