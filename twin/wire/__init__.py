"""Protocol 1, the twin's wire (docs/protocol.md), in one place:

    protocol   the messages and their encoding (HELLO, CONFIG, SAMPLE, COMMAND, STOP)
    links      UDP and serial links that carry them
    server     the served twin: a session of the one loop whose controller is across the link
               (``Server(SessionSettings(...)).serve()`` gives a ``SessionResult``)
    observer   a client that watches a session without driving it (``Observer``, ``open_observer(url)``)

The client side of a session is a rig (``twin.rigs.remote.RemoteRig``). The names load on first use.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["Observer", "Server", "SessionResult", "SessionSettings", "open_observer"]

_HOMES = {
    "Observer": "observer",
    "open_observer": "observer",
    "Server": "server",
    "SessionResult": "server",
    "SessionSettings": "server",
}


def __getattr__(name: str) -> Any:
    if name in _HOMES:
        return getattr(importlib.import_module(f"{__name__}.{_HOMES[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
