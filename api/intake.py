"""
Reading a request body under the request's cost limits, refusing it as soon as one is crossed.

What one request may make the service read is capped while the body streams in, before any
parser sees it (a parser's cost grows with what it is given, and some grow faster than that):

===========================  ===================================  =============================
limit                        counted                              answer when crossed
===========================  ===================================  =============================
``max_body_bytes``           bytes on the wire (Content-Length     413 ``body_too_large``
                             first, then as they arrive)
``max_decompressed_bytes``   bytes after gzip, decompressed a     413 ``body_too_large``
                             piece at a time (never more than
                             the limit held)
``max_points``               CSV lines; GPX ``<trkpt>``/          413 ``too_many_points``
                             ``<rtept>``; JSON/GeoJSON objects
                             and arrays (4 per point at most)
``max_columns``              fields of the CSV header line        413 ``too_many_columns``
``body_timeout_s``           seconds from the start of the body   408 ``body_timeout``
                             to its last byte
===========================  ===================================  =============================

A gzip body is read when it says ``Content-Encoding: gzip`` (any content type), and a CSV body
that is itself a gzip file (the reader accepts ``.csv.gz``) is decompressed here too, under the
same limit, so the reader never inflates a body on its own. A UTF-8 byte-order mark in front
of a JSON or GeoJSON document is dropped. The JSON parser itself is bounded in depth and number
length (:func:`api.service.parse_json`), so what is counted here bounds its work.
"""

from __future__ import annotations

import asyncio
import zlib
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

from starlette.requests import ClientDisconnect

from api.errors import (
    BodyTimeoutError,
    BodyTooLargeError,
    IncompleteBodyError,
    InvalidEncodingError,
    TooManyColumnsError,
    TooManyPointsError,
    UnsupportedEncodingError,
    UnsupportedMediaTypeError,
)

if TYPE_CHECKING:
    from collections.abc import Iterator, Mapping

    from starlette.requests import Request

    from api.settings import Settings

__all__ = ["MEDIA_TYPES", "BodyLimits", "body_format", "declared_length", "read_limited_body"]

#: Content types ``POST /v1/match`` reads, and the trace format of each.
MEDIA_TYPES: Final[Mapping[str, str]] = {
    "application/json": "json",
    "application/geo+json": "geojson",
    "application/gpx+xml": "gpx",
    "text/csv": "csv",
}

_GZIP_MAGIC: Final = b"\x1f\x8b"
_BOM: Final = b"\xef\xbb\xbf"
_CSV_SEPARATORS: Final = (b",", b";", b"\t", b"|")
_HEADER_BYTES: Final = 65_536  # a CSV header line longer than this is not a trace's header
_CONTAINERS_PER_POINT: Final = 4  # a GeoJSON Point feature: feature, geometry, properties, coords
_SLACK: Final = 64  # envelope, options, a few blank lines
_PIECE: Final = 1 << 20  # inflate at most this much at a time, so the counts stop it early


@dataclass(frozen=True, slots=True)
class BodyLimits:
    """
    What one body may cost (see the module docstring).

    Examples
    --------
    >>> BodyLimits(max_body_bytes=10, max_decompressed_bytes=20, max_points=5,
    ...            max_columns=8, body_timeout_s=1.0).max_points
    5
    """

    max_body_bytes: int
    max_decompressed_bytes: int
    max_points: int
    max_columns: int
    body_timeout_s: float

    @classmethod
    def of(cls, settings: Settings) -> BodyLimits:
        """The limits of a deployment."""
        return cls(
            max_body_bytes=settings.max_body_bytes,
            max_decompressed_bytes=settings.max_decompressed_bytes,
            max_points=settings.max_points,
            max_columns=settings.max_columns,
            body_timeout_s=settings.body_timeout_s,
        )


def body_format(content_type: str | None) -> str:
    """
    The trace format of a request's Content-Type (parameters such as charset are ignored).

    Raises
    ------
    UnsupportedMediaTypeError
        Any other content type, or none.

    Examples
    --------
    >>> body_format("text/csv; charset=utf-8")
    'csv'
    """
    media = (content_type or "").split(";", 1)[0].strip().lower()
    fmt = MEDIA_TYPES.get(media)
    if fmt is None:
        shown = repr(media) if media else "no Content-Type"
        msg = f"cannot read a body of {shown}; send one of {', '.join(MEDIA_TYPES)}"
        raise UnsupportedMediaTypeError(msg, field="Content-Type")
    return fmt


class _Counter:
    """Counts what a format's parser will have to build, chunk by chunk, and stops it early."""

    def __init__(self, fmt: str, limits: BodyLimits) -> None:
        self.fmt = fmt
        self.limits = limits
        self.count = 0
        self._tail = b""  # the end of the last chunk, for a token split across two
        self._header: bytearray | None = bytearray() if fmt == "csv" else None

    def feed(self, data: bytes) -> None:
        if self.fmt == "csv":
            self._csv(data)
        elif self.fmt in ("json", "geojson"):
            self.count += data.count(b"{") + data.count(b"[")
            cap = _CONTAINERS_PER_POINT * self.limits.max_points + _SLACK
            if self.count > cap:
                msg = (
                    f"the body holds more than {cap:,} JSON objects and arrays, more than "
                    f"{self.limits.max_points:,} points can need; split the trace"
                )
                raise TooManyPointsError(msg, field="points")
        elif self.fmt == "gpx":
            text = self._tail + data
            self.count += text.count(b"<trkpt") + text.count(b"<rtept")
            self.count -= self._tail.count(b"<trkpt") + self._tail.count(b"<rtept")
            self._tail = text[-5:]
            if self.count > self.limits.max_points:
                msg = (
                    f"the GPX body has more than {self.limits.max_points:,} track or route "
                    "points; this service matches at most that many per request; split the trace"
                )
                raise TooManyPointsError(msg, field="points")

    def _csv(self, data: bytes) -> None:
        self.count += data.count(b"\n")
        cap = self.limits.max_points + 2  # the header, and an Excel "sep=" line
        if self.count > cap:
            msg = (
                f"the CSV body has more than {cap:,} lines; this service matches at most "
                f"{self.limits.max_points:,} points per request; split the trace"
            )
            raise TooManyPointsError(msg, field="points")
        if self._header is None:
            return
        self._header += data[: _HEADER_BYTES + 1]
        lines = bytes(self._header).split(b"\n")
        if lines and lines[0].strip().lower().startswith(b"sep=") and len(lines) > 1:
            lines = lines[1:]  # Excel's separator line comes before the header
        header, complete = lines[0], len(lines) > 1
        fields = 1 + max(header.count(s) for s in _CSV_SEPARATORS)
        if fields > self.limits.max_columns:
            msg = (
                f"the CSV header has {'at least ' if not complete else ''}{fields:,} columns; "
                f"this service reads at most {self.limits.max_columns:,}; send only the "
                "trace's columns (time, lat, lon, heading, speed, accuracy, odometer ...)"
            )
            raise TooManyColumnsError(msg, field="columns")
        if complete:
            self._header = None
        elif len(self._header) > _HEADER_BYTES:
            msg = (
                f"the CSV header line is longer than {_HEADER_BYTES:,} bytes; send only the "
                "trace's columns"
            )
            raise TooManyColumnsError(msg, field="columns")


class _Inflater:
    """Gzip decompression (several members in a row allowed) that never exceeds a size."""

    def __init__(self, limit: int, *, declared: bool) -> None:
        self.limit = limit
        self.size = 0
        self._declared = declared
        self._gz = zlib.decompressobj(16 + zlib.MAX_WBITS)

    def feed(self, data: bytes) -> Iterator[bytes]:
        """The inflated pieces of ``data``, one at a time (the caller may stop early)."""
        while data:
            try:
                piece = self._gz.decompress(data, min(self.limit - self.size + 1, _PIECE))
            except zlib.error as exc:
                raise self._broken(str(exc)) from None
            self.size += len(piece)
            if self.size > self.limit:
                msg = (
                    f"the body decompresses to more than {self.limit:,} bytes, more than this "
                    "service reads; send less"
                )
                raise BodyTooLargeError(msg)
            yield piece
            data = self._gz.unconsumed_tail
            if not data and self._gz.eof:
                data = self._gz.unused_data
                if data:  # another gzip member follows
                    self._gz = zlib.decompressobj(16 + zlib.MAX_WBITS)

    def finish(self) -> None:
        if not self._gz.eof:
            why = "the gzip stream ends before its end"
            raise self._broken(why)

    def _broken(self, why: str) -> InvalidEncodingError:
        said = "Content-Encoding: gzip" if self._declared else "a gzip file (it starts like one)"
        return InvalidEncodingError(f"the body is {said} but cannot be decompressed: {why}")


def _encoding(request: Request) -> bool:
    """Whether the body is gzip, from ``Content-Encoding``; anything else but identity: 415."""
    value = request.headers.get("content-encoding", "").strip().lower()
    if value in ("", "identity"):
        return False
    if value in ("gzip", "x-gzip"):
        return True
    msg = f"cannot read a body of Content-Encoding {value!r}; send it as it is, or gzip"
    raise UnsupportedEncodingError(msg, field="Content-Encoding")


def declared_length(request: Request) -> int | None:
    """The body size the request's ``Content-Length`` declares; ``None`` without a number."""
    declared = request.headers.get("content-length", "")
    return int(declared) if declared.isdigit() else None


async def read_limited_body(request: Request, fmt: str, limits: BodyLimits) -> bytes:
    """
    The request body, decompressed, refused as soon as it would cost more than ``limits``.

    Parameters
    ----------
    request
        The request; its body is read here.
    fmt
        The body's trace format (``"json"``, ``"csv"`` ...), which says what to count.
    limits
        The caps.

    Raises
    ------
    BodyTooLargeError, TooManyPointsError, TooManyColumnsError
        A cap is crossed (413); nothing more is read.
    UnsupportedEncodingError
        A Content-Encoding other than gzip (415).
    InvalidEncodingError
        The gzip stream is corrupt or truncated (400).
    BodyTimeoutError
        The body did not arrive within ``body_timeout_s`` (408).
    IncompleteBodyError
        The client closed the connection before the end of the body (400).
    """
    gzipped = _encoding(request)
    msg = f"the body is larger than this service accepts ({limits.max_body_bytes:,} bytes)"
    declared = declared_length(request)
    if declared is not None and declared > limits.max_body_bytes:
        msg = f"{msg}: Content-Length is {declared:,}; send less"
        raise BodyTooLargeError(msg)
    counter = _Counter(fmt, limits)
    inflater = _Inflater(limits.max_decompressed_bytes, declared=True) if gzipped else None
    sniff = fmt == "csv" and not gzipped  # a gzip file sent as text/csv
    parts: list[bytes] = []
    head = b""
    size = 0
    try:
        async with asyncio.timeout(limits.body_timeout_s):
            async for chunk in request.stream():
                size += len(chunk)
                if size > limits.max_body_bytes:
                    msg = f"{msg}; send less"
                    raise BodyTooLargeError(msg)
                if sniff:
                    head += chunk
                    if len(head) < len(_GZIP_MAGIC):
                        continue
                    sniff = False
                    if head.startswith(_GZIP_MAGIC):
                        inflater = _Inflater(limits.max_decompressed_bytes, declared=False)
                    chunk, head = head, b""
                pieces = inflater.feed(chunk) if inflater is not None else (chunk,)
                for piece in pieces:
                    counter.feed(piece)
                    parts.append(piece)
    except TimeoutError:
        msg = (
            f"the body did not arrive within {limits.body_timeout_s:g} s ({size:,} bytes "
            "received); send it at once, and a Content-Length that matches it"
        )
        raise BodyTimeoutError(msg) from None
    except ClientDisconnect:
        msg = f"the client went away after {size:,} bytes of the body"
        raise IncompleteBodyError(msg) from None
    if head:  # a body shorter than the gzip magic
        counter.feed(head)
        parts.append(head)
    if inflater is not None:
        inflater.finish()
    body = b"".join(parts)
    if fmt in ("json", "geojson") and body.startswith(_BOM):
        body = body[len(_BOM) :]
    return body
