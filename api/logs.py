"""
Structured logs: one JSON object per line on stderr.

``api.access`` logs one line per request (method, path, route template, status, duration,
points, network, error code, request id); ``api`` logs the rest (startup, tracebacks of bugs),
with the request id when there is one, so a 500's answer can be traced to its traceback.
"""

from __future__ import annotations

import json
import logging
import sys
import time
from typing import Final

__all__ = ["ACCESS_LOGGER", "JsonFormatter", "configure_logging"]

ACCESS_LOGGER: Final = "api.access"
_HANDLER_NAME: Final = "mapmatch-json"
_STANDARD_ATTRS: Final = frozenset(
    {*vars(logging.LogRecord("x", logging.INFO, "x", 0, "x", None, None)), "message", "asctime"}
)


class JsonFormatter(logging.Formatter):
    """
    Format a record as one JSON object: time, level, logger, message and its ``extra`` fields.

    Examples
    --------
    >>> record = logging.LogRecord("api.access", logging.INFO, "", 0, "request", None, None)
    >>> record.status = 200
    >>> line = json.loads(JsonFormatter().format(record))
    >>> line["msg"], line["status"], line["logger"]
    ('request', 200, 'api.access')
    """

    def format(self, record: logging.LogRecord) -> str:
        """Return the record as a JSON line."""
        out: dict[str, object] = {
            "ts": time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(record.created))
            + f".{int(record.msecs):03d}Z",
            "level": record.levelname.lower(),
            "logger": record.name,
            "msg": record.getMessage(),
        }
        for key, value in vars(record).items():
            if key not in _STANDARD_ATTRS and not key.startswith("_"):
                out[key] = value
        if record.exc_info:
            out["traceback"] = self.formatException(record.exc_info)
        return json.dumps(out, default=str)


def configure_logging() -> None:
    """Send the ``api`` loggers to stderr as JSON lines (once per process)."""
    root = logging.getLogger("api")
    if not any(h.get_name() == _HANDLER_NAME for h in root.handlers):
        handler = logging.StreamHandler(sys.stderr)
        handler.set_name(_HANDLER_NAME)
        handler.setFormatter(JsonFormatter())
        root.addHandler(handler)
        root.setLevel(logging.INFO)
        root.propagate = False
