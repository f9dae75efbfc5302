"""One structured INFO line per engine or ops event, for the service log.

``log_event("soak ended", campaign=3, step=2, chamber_c=-19.98)`` writes::

    event="soak ended" campaign=3 step=2 chamber_c=-19.98

(logfmt: ``key=value`` pairs, values with spaces or quotes JSON-quoted), on
the ``soakcal.events`` logger, so a log shipper can parse it and ``grep
'event="campaign suspended"'`` finds every suspension. Callers name the
event with a short fixed phrase and pass units in the key names
(``chamber_c``, ``soak_min``).
"""

from __future__ import annotations

import json
import logging
from typing import Any

logger = logging.getLogger("soakcal.events")

# The events the engine and scheduler are expected to log (docs/web.md, "Service log").
ENGINE_EVENTS = (
    "schedule fired",
    "campaign started",
    "soak ended",
    "campaign suspended",
    "campaign unsuspended",
    "campaign paused",
    "campaign resumed",
    "campaign ended",
)


def format_event(event: str, **fields: Any) -> str:
    """The logfmt line for ``event`` and ``fields`` (None values left out), one line always."""
    parts = [f"event={_value(event)}"]
    parts += [f"{key}={_value(value)}" for key, value in fields.items() if value is not None]
    return " ".join(parts)


def log_event(event: str, **fields: Any) -> None:
    """Log ``event`` at INFO as one logfmt line (see the module docstring)."""
    _ensure_handler()
    if logger.isEnabledFor(logging.INFO):
        logger.info("%s", format_event(event, **fields))


_handler_checked = False


def _ensure_handler() -> None:
    """Under ``soakcal serve`` nobody configures the root logger (uvicorn configures only
    its own), so INFO lines would be dropped: then give this logger a stderr handler in
    uvicorn's style. A process that configured logging (pytest, a deployment) is left alone.
    """
    global _handler_checked
    if _handler_checked:
        return
    _handler_checked = True
    if logger.handlers or logging.getLogger().handlers:
        return
    handler = logging.StreamHandler()
    handler.setFormatter(logging.Formatter("%(levelname)s:     %(name)s %(message)s"))
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    logger.propagate = False


def _value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, int):
        return str(value)
    text = str(value)
    if text and all(c.isalnum() or c in "-_.:/+@" for c in text):
        return text
    return json.dumps(text, ensure_ascii=False)  # quotes, escapes newlines: one line always
