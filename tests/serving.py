"""A served twin for the wire tests: ``twin.wire.server.Server.serve`` in a thread, its session or error kept."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager

from twin.wire.server import Server, SessionResult


@contextmanager
def in_thread(server: Server) -> Iterator[dict[str, object]]:
    """Serve one session in a daemon thread; after the block ``box["session"]`` holds its result (an error in
    the server is raised here). The server is closed and must have ended within 30 s."""
    box: dict[str, object] = {}

    def target() -> None:
        try:
            box["session"] = server.serve()
        except BaseException as exc:  # noqa: BLE001 - reported to the test
            box["error"] = exc

    thread = threading.Thread(target=target, daemon=True)
    thread.start()
    try:
        yield box
    finally:
        thread.join(30.0)
        server.close()
        assert not thread.is_alive(), "the server hung"
    if "error" in box:
        raise box["error"]  # type: ignore[misc]


def session_of(box: dict[str, object]) -> SessionResult:
    s = box["session"]
    assert isinstance(s, SessionResult)
    return s
