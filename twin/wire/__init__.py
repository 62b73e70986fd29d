"""Protocol 1, the twin's wire (docs/protocol.md): the messages and the links that carry them, below every rig.

    protocol   the messages and their encoding (HELLO, CONFIG, SAMPLE, COMMAND, STOP)
    links      UDP and serial links that carry them (``Link``, ``UdpLink``, ``SerialLink``, ``parse_url``;
               ``LinkError``: a link that cannot be opened or broke)

Both ends use it: the client side of a session is a rig (``twin.rigs.remote.RemoteRig``), the served twin
and its watcher sit above the rigs (``twin.serving``). The names load on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from twin.exports import lazy_exports

if TYPE_CHECKING:  # the names' real types for a type checker; at run time they load on first use (below)
    from twin.wire.links import Link, LinkError, SerialLink, UdpLink, parse_url


__all__ = ["Link", "LinkError", "SerialLink", "UdpLink", "parse_url"]

_HOMES = {
    "Link": "twin.wire.links",
    "LinkError": "twin.wire.links",
    "SerialLink": "twin.wire.links",
    "UdpLink": "twin.wire.links",
    "parse_url": "twin.wire.links",
}

__getattr__ = lazy_exports(__name__, _HOMES)
