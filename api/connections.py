"""
Connection hygiene: a client may not hold a connection without sending a request.

uvicorn closes a keep-alive connection that stays idle after a response
(``MAPMATCH_KEEPALIVE_TIMEOUT_S``), but sets no limit on how long a client may take to send a
request's headers: a client that trickles one header byte every few seconds holds its
connection, and a few hundred such clients starve real ones. :class:`GuardedH11Protocol` is
uvicorn's HTTP/1.1 protocol that also closes a connection which has not sent a complete request
head within ``MAPMATCH_HEADER_TIMEOUT_S`` of opening or of its last response (answering 408
first); it reads the timeout from its :class:`ServiceConfig`.
The body has its own limit, enforced where it is read (:mod:`api.intake`, 408
``body_timeout``), which also ends a request whose Content-Length promises more than it sends.

The other limits are uvicorn's own, set from the settings by :mod:`api.server`: connections
and requests at once per worker (``MAPMATCH_MAX_CONNECTIONS``; more answer 503), the size of a
request head (``MAPMATCH_MAX_HEADER_BYTES``; more answer 400) and the keep-alive timeout.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Any

import uvicorn
from uvicorn.protocols.http.h11_impl import H11Protocol

from api.errors import error_body

if TYPE_CHECKING:
    import asyncio

__all__ = ["DEFAULT_HEADER_TIMEOUT_S", "GuardedH11Protocol", "ServiceConfig"]

#: Seconds to send a request head when the configuration does not say.
DEFAULT_HEADER_TIMEOUT_S = 10.0


class ServiceConfig(uvicorn.Config):
    """uvicorn's configuration plus the request-head timeout (pickled to the workers with it)."""

    def __init__(self, *args: Any, header_timeout_s: float, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.header_timeout_s = header_timeout_s


def _timeout_answer(seconds: float) -> bytes:
    body = json.dumps(
        error_body(
            "header_timeout",
            f"the request head did not arrive within {seconds:g} s; send it at once",
        )
    ).encode()
    head = (
        b"HTTP/1.1 408 Request Timeout\r\ncontent-type: application/json\r\n"
        b"connection: close\r\ncontent-length: %d\r\n\r\n" % len(body)
    )
    return head + body


class GuardedH11Protocol(H11Protocol):
    """uvicorn's h11 protocol with a deadline for each request head (see the module)."""

    def __init__(self, config: uvicorn.Config, *args: Any, **kwargs: Any) -> None:
        super().__init__(config, *args, **kwargs)
        self.header_timeout_s = float(getattr(config, "header_timeout_s", DEFAULT_HEADER_TIMEOUT_S))
        self._head_timer: asyncio.TimerHandle | None = None

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        """Start waiting for the first request head."""
        super().connection_made(transport)
        self._arm()

    def connection_lost(self, exc: Exception | None) -> None:
        """Stop the timer with the connection."""
        self._disarm()
        super().connection_lost(exc)

    def handle_events(self) -> None:
        """Stop waiting once a request head has arrived (a request cycle is running)."""
        super().handle_events()
        if self.cycle is not None and not self.cycle.response_complete:
            self._disarm()

    def on_response_complete(self) -> None:
        """Wait for the next request head (the keep-alive timer also runs meanwhile)."""
        super().on_response_complete()
        if not self.transport.is_closing() and (self.cycle is None or self.cycle.response_complete):
            self._arm()

    def _arm(self) -> None:
        self._disarm()
        self._head_timer = self.loop.call_later(self.header_timeout_s, self._expired)

    def _disarm(self) -> None:
        if self._head_timer is not None:
            self._head_timer.cancel()
            self._head_timer = None

    def _expired(self) -> None:
        self._head_timer = None
        busy = self.cycle is not None and not self.cycle.response_complete
        if busy or self.transport.is_closing():
            return
        self.transport.write(_timeout_answer(self.header_timeout_s))
        self.transport.close()
