"""Protocol 1, the twin's wire (docs/protocol.md), in one place:

    protocol   the messages and their encoding (HELLO, CONFIG, SAMPLE, COMMAND, STOP)
    links      UDP and serial links that carry them
    server     the served twin: a session of the one loop whose controller is across the link
               (``Server(SessionSettings(...)).serve()`` gives a ``SessionResult``)
    observer   a client that watches a session without driving it (``Observer``, ``open_observer(url)``)

The client side of a session is a rig (``twin.rigs.remote.RemoteRig``). The names load on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from twin.exports import lazy_exports

if TYPE_CHECKING:  # the names' real types for a type checker; at run time they load on first use (below)
    from twin.wire.observer import Observer, open_observer
    from twin.wire.server import Server, SessionResult, SessionSettings


__all__ = ["Observer", "Server", "SessionResult", "SessionSettings", "open_observer"]

_HOMES = {
    "Observer": "twin.wire.observer",
    "open_observer": "twin.wire.observer",
    "Server": "twin.wire.server",
    "SessionResult": "twin.wire.server",
    "SessionSettings": "twin.wire.server",
}

__getattr__ = lazy_exports(__name__, _HOMES)
