"""Logging of the service: text for a terminal, or one JSON object per line for a log collector.

Every record carries the scene and batch it is about when they are known: the worker sets them
around each batch, the API around each request (from the path), with `log_context`; a record may
also name them itself (`extra={"batch_id": ...}`).

The JSON formatter is the standard library's logging plus orjson (already a dependency): a
dozen lines, with field names of our choosing, rather than another package.
"""

from __future__ import annotations

import contextvars
import logging
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from typing import Literal, TextIO

import orjson

LogFormat = Literal["text", "json"]
CONTEXT_FIELDS = ("scene_id", "batch_id")
_context: contextvars.ContextVar[dict[str, str] | None] = contextvars.ContextVar(
    "pbdag_log_context", default=None
)


@contextmanager
def log_context(**fields: str | None) -> Iterator[None]:
    """Records logged inside the block (in this thread or task) carry these fields."""
    known = {key: value for key, value in fields.items() if value is not None}
    token = _context.set({**(_context.get() or {}), **known})
    try:
        yield
    finally:
        _context.reset(token)


class ContextFilter(logging.Filter):
    """Puts the current log context on every record (a field the record names itself wins)."""

    def filter(self, record: logging.LogRecord) -> bool:
        """Always keeps the record."""
        for key, value in (_context.get() or {}).items():
            if not hasattr(record, key):
                setattr(record, key, value)
        return True


class JsonFormatter(logging.Formatter):
    """One JSON object per record: time (UTC, ISO 8601), level, logger, message, the context
    fields when known, and the traceback when there is one."""

    def format(self, record: logging.LogRecord) -> str:
        """The record as a JSON line."""
        document: dict[str, object] = {
            "time": datetime.fromtimestamp(record.created, UTC).isoformat(timespec="milliseconds"),
            "level": record.levelname,
            "logger": record.name,
            "message": record.getMessage(),
        }
        for key in CONTEXT_FIELDS:
            value = getattr(record, key, None)
            if value is not None:
                document[key] = value
        if record.exc_info:
            document["exception"] = self.formatException(record.exc_info)
        return orjson.dumps(document, default=str).decode()


class TextFormatter(logging.Formatter):
    """The classic line, with `[scene batch]` when known."""

    def __init__(self) -> None:
        super().__init__("%(asctime)s %(levelname)s %(name)s: %(message)s")

    def format(self, record: logging.LogRecord) -> str:
        """The line, the context inserted before the message."""
        known = [str(getattr(record, key)) for key in CONTEXT_FIELDS if hasattr(record, key)]
        line = super().format(record)
        if not known:
            return line
        head, _, message = line.partition(": ")
        return f"{head}: [{' '.join(known)}] {message}"


class StderrHandler(logging.StreamHandler[TextIO]):
    """Writes to whatever sys.stderr is when a record comes (as logging's last resort does)."""

    def __init__(self) -> None:
        logging.Handler.__init__(self)

    @property
    def stream(self) -> TextIO:
        """The current standard error."""
        return sys.stderr

    @stream.setter
    def stream(self, _value: TextIO) -> None:
        """Ignored: the stream is always the current standard error."""


def configure_logging(
    log_format: LogFormat = "text", level: int | str = logging.INFO
) -> logging.Handler:
    """Send every logger's records to standard error in `log_format`; the handler installed
    (it replaces the one an earlier call installed, and leaves other handlers alone)."""
    handler = StderrHandler()
    handler.setFormatter(JsonFormatter() if log_format == "json" else TextFormatter())
    handler.addFilter(ContextFilter())
    root = logging.getLogger()
    for old in list(root.handlers):
        if isinstance(old, StderrHandler):
            root.removeHandler(old)
    root.addHandler(handler)
    root.setLevel(level)
    logging.getLogger("alembic").setLevel(logging.WARNING)
    return handler
