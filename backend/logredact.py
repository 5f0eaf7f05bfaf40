"""Keep tokens and secrets out of the logs.

:class:`RedactSecrets` is a :class:`logging.Filter` that rewrites every record passing a
handler: API tokens (``vc_...``), signed 3D-view links and ``Authorization: Bearer ...``
values become ``[redacted]``, in the message and in its arguments (uvicorn's access log
passes the request path as an argument, so a token put in a query string by a client is
redacted too).  ``visioncell serve`` installs it on the root handlers and uvicorn's.
The start-up banner's operator token is printed to standard output on purpose, never logged.
"""

from __future__ import annotations

import logging
import re

__all__ = ["REDACTED", "RedactSecrets", "install_redaction", "redact"]

REDACTED = "[redacted]"
_PATTERNS = (
    re.compile(r"vc_[A-Za-z0-9_-]{8,}"),
    re.compile(
        r"v1\.[0-9]+\.[0-9]+\.(?:viewer|operator|engineer)\.[0-9]+(?:\.[0-9a-f]+)?"
        r"\.[A-Za-z0-9_-]{20,}"
    ),
    re.compile(r"(?i)(bearer\s+)[^\s'\",]+"),
    re.compile(r"(?i)((?:token|secret|secret_key|password)=)[^\s&'\",]+"),
)


def redact(text: str) -> str:
    """``text`` with tokens, view links, bearer values and ``token=``/``secret=`` values
    replaced by :data:`REDACTED`."""
    for pattern in _PATTERNS:
        text = pattern.sub(lambda m: (m.group(1) if m.groups() else "") + REDACTED, text)
    return text


def _redact_arg(value: object) -> object:
    if isinstance(value, bool | int | float) or value is None:
        return value
    text = str(value)  # URLs, headers and the like are objects (httpx.URL, ...)
    clean = redact(text)
    return value if clean == text else clean


class RedactSecrets(logging.Filter):
    """Rewrites records so that no token or secret reaches a handler."""

    def filter(self, record: logging.LogRecord) -> bool:
        if isinstance(record.msg, str):
            record.msg = redact(record.msg)
        if isinstance(record.args, tuple):
            record.args = tuple(_redact_arg(a) for a in record.args)
        elif isinstance(record.args, dict):
            record.args = {k: _redact_arg(v) for k, v in record.args.items()}
        return True


def install_redaction(*logger_names: str) -> None:
    """Add one :class:`RedactSecrets` to every handler of the root logger and of
    ``logger_names`` (idempotent)."""
    for name in ("", *logger_names):
        for handler in logging.getLogger(name or None).handlers:
            if not any(isinstance(f, RedactSecrets) for f in handler.filters):
                handler.addFilter(RedactSecrets())
