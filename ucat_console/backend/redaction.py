"""Secrets kept out of the log: every log record's text has the registered secrets (the
pilot token, configuration fields declared ``secret``) replaced by ``<redacted>``.

The console prints the pilot token once on its own terminal (that is how the operator gets
it); it never reaches a log line, whatever module writes one, because the check sits in
the log record factory that every logger uses.
"""

from __future__ import annotations

import logging
import threading
from typing import Any, Iterable

REDACTED = "<redacted>"
_lock = threading.Lock()
_secrets: dict[str, int] = {}  # secret -> how many holders registered it
_installed = False


def _install() -> None:
    global _installed
    make = logging.getLogRecordFactory()

    def factory(*args: Any, **kwargs: Any) -> logging.LogRecord:
        record = make(*args, **kwargs)
        if _secrets:
            try:
                text = record.getMessage()
            except Exception:
                return record
            cleaned = redact(text)
            if cleaned != text:
                record.msg, record.args = cleaned, None
        return record

    logging.setLogRecordFactory(factory)
    _installed = True


def redact(text: str) -> str:
    """``text`` with every registered secret replaced."""
    for s in sorted(_secrets, key=len, reverse=True):
        if s in text:
            text = text.replace(s, REDACTED)
    return text


def keep_out_of_logs(secrets: Iterable[str]) -> None:
    """Register ``secrets`` (empty strings are ignored); :func:`release` them when done."""
    with _lock:
        if not _installed:
            _install()
        for s in secrets:
            if s:
                _secrets[s] = _secrets.get(s, 0) + 1


def release(secrets: Iterable[str]) -> None:
    with _lock:
        for s in secrets:
            n = _secrets.get(s, 0) - 1
            if n > 0:
                _secrets[s] = n
            else:
                _secrets.pop(s, None)
