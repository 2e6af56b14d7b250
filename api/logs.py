"""
Structured logs: one JSON object per line on stderr.

``api.access`` logs one line per request (method, path, route template, status, duration,
points, network, error code, request id); ``api`` logs the rest (startup, tracebacks of bugs),
with the request id when there is one, so a 500's answer can be traced to its traceback.
Every other line of the process (uvicorn, the matcher, Python warnings) is written in the same
JSON shape by the same handler.
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
    """
    Make every log line of the process one JSON object on stderr (once per process).

    The ``api`` loggers log at INFO; everything else (uvicorn's own lines, the matcher's
    warnings, Python ``warnings``, captured through logging) goes through the root logger at
    WARNING, with the same formatter, so no plain-text line lands in the JSON log. Handlers
    other code put on the root logger (the CLI's plain-text one) are replaced.
    """
    root = logging.getLogger()
    ours = [h for h in root.handlers if h.get_name() == _HANDLER_NAME]
    if not ours:
        handler = logging.StreamHandler(sys.stderr)
        handler.set_name(_HANDLER_NAME)
        handler.setFormatter(JsonFormatter())
        for other in list(root.handlers):
            root.removeHandler(other)
        root.addHandler(handler)
        root.setLevel(logging.WARNING)
    logging.captureWarnings(True)
    api = logging.getLogger("api")
    api.setLevel(logging.INFO)
    for stale in [h for h in api.handlers if h.get_name() == _HANDLER_NAME]:
        api.removeHandler(stale)  # an older configuration of ours: the root one now serves
    api.propagate = True
