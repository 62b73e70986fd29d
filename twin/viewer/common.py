"""What every room of the live view shares: its pacing constants, the controls' ranges (one home each), the
error it raises when it cannot start, and its one-line logs."""

from __future__ import annotations

import html
import logging
import math
import sys
import threading
import time
from dataclasses import dataclass
from typing import Any

FRAME_S = 0.02  # scene updates at 50 Hz (the rig's tick)
DEFAULT_CONTROLLER = "appendix-clp"


@dataclass(frozen=True)
class Slider:
    """A control's range as its slider shows it; the loop refuses a value outside it (a parameter file may
    narrow it further: the track, the stops)."""

    low: float
    high: float
    step: float
    unit: str


# The controls' ranges: the GUI builds its sliders from these and the loop checks every value against them.
SPEED = Slider(0.1, 4.0, 0.1, "")  # simulated seconds per wall second
X0 = Slider(-0.3, 0.3, 0.01, "m")
THETA0 = Slider(-0.7, 0.7, 0.01, "rad")
SETPOINT = Slider(-0.2, 0.2, 0.01, "m")
FLICK = Slider(0.02, 0.5, 0.01, "m/s")  # the flick's speed; the button gives its direction
# The rig's motor resistance above the parameters' (%), from the next run: a warm motor for the shadow to catch
# (copper's resistance rises 0.39 %/K: +15 % is a winding 40 K warmer).
DRIFT = Slider(0.0, 50.0, 1.0, "%")
SPEED_MIN, SPEED_MAX = SPEED.low, SPEED.high
FLICK_DEFAULT_M_S = 0.1
# Simulated time the pacing may owe the wall clock: one frame at the top speed plus one. Whatever the
# speed, a frame never runs more than this many ticks and a stall never builds a debt.
MAX_OWED_S = FRAME_S * (SPEED_MAX + 1.0)


class ViewerError(RuntimeError):
    """The viewer cannot start (port taken, bad host, …)."""


# --- one-line logs ----------------------------------------------------------------------------------------
_log_lock = threading.Lock()
_log_last: dict[str, tuple[float, int]] = {}  # key → (time of the last line, lines suppressed since)


def _printable(text: str, limit: int = 300) -> str:
    """One line of printable text: control characters (a client's string may carry terminal escapes) shown
    escaped, long text cut."""
    text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in " ".join(text.split()))
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _show(value: Any, limit: int = 60) -> str:
    """A client's value for a message: its repr, cut."""
    try:
        text = repr(value)
    except Exception:  # noqa: BLE001 - a value whose repr fails is still shown
        text = f"<{type(value).__name__}>"
    return _printable(text, limit)


def _log(text: str, *, key: str | None = None, stream: Any = None) -> None:
    """Print one line ``ballbeam view: …`` (stderr unless told). With ``key``, at most one line a second per
    key; the lines held back are counted in the next one (a hostile client cannot flood the log)."""
    line = f"ballbeam view: {_printable(text)}"
    if key is not None:
        now = time.monotonic()
        with _log_lock:
            last, held = _log_last.get(key, (-math.inf, 0))
            if now - last < 1.0:
                _log_last[key] = (last, held + 1)
                return
            _log_last[key] = (now, 0)
        if held:
            line += f" ({held} more like it in the last second)"
    print(line, file=stream if stream is not None else sys.stderr, flush=True)


class _OneLineHandler(logging.Handler):
    """The websocket library's errors (a malformed frame, a broken handshake) as one line, no traceback."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = f"websocket: {record.getMessage()}"
            exc = record.exc_info[1] if record.exc_info else None
            if exc is not None:
                text += f" ({type(exc).__name__}: {exc})"
            _log(text, key="websocket")
        except Exception:  # noqa: BLE001 - logging must never raise
            self.handleError(record)


_WS_LOGGER = logging.getLogger("twin.viewer.websocket")
_WS_LOGGER.setLevel(logging.WARNING)  # errors only; the library's INFO lines (rejections, opens) are noise
_WS_LOGGER.propagate = False
if not _WS_LOGGER.handlers:
    _WS_LOGGER.addHandler(_OneLineHandler())


def _markdown_text(text: str) -> str:
    """Plain text for viser's markdown, which renders raw HTML (scripts included): no tag, no markup and no
    link (GFM links bare URLs) gets through."""
    text = html.escape(" ".join(text.split()), quote=False)
    return "".join("\\" + c if c in "\\`*_{}[]()|~:.@" else c for c in text)
