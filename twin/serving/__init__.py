"""The twin served over protocol 1 (docs/protocol.md), above the rigs it serves:

    server     the served twin: a session of the one loop whose controller is across the link
               (``Server(SessionSettings(...)).serve()`` gives a ``SessionResult``)
    observer   a client that watches a session without driving it (``Observer``, ``open_observer(url)``)

The messages and links are ``twin.wire``'s; the client side of a session is a rig
(``twin.rigs.remote.RemoteRig``). The names load on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from twin.exports import lazy_exports

if TYPE_CHECKING:  # the names' real types for a type checker; at run time they load on first use (below)
    from twin.serving.observer import Observer, open_observer
    from twin.serving.server import Server, SessionResult, SessionSettings


__all__ = ["Observer", "Server", "SessionResult", "SessionSettings", "open_observer"]

_HOMES = {
    "Observer": "twin.serving.observer",
    "open_observer": "twin.serving.observer",
    "Server": "twin.serving.server",
    "SessionResult": "twin.serving.server",
    "SessionSettings": "twin.serving.server",
}

__getattr__ = lazy_exports(__name__, _HOMES)
