"""A served twin for the wire tests: ``twin.serving.server.Server.serve`` in a thread, its session or error kept;
and a hand-written client's answer to a sample."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager

from twin.interface import Controller, DaqSample
from twin.serving.server import Server, SessionResult
from twin.wire import protocol as p


def answer(controller: Controller, sample: p.Sample) -> float:
    """The command a hand-written client sends for a SAMPLE: sequence 0 (the held rig) starts the controller
    and answers the zero command, 2.5 V; every later sample is an update."""
    block = DaqSample(sample.time_s, sample.ball_v, sample.angle_v)
    if sample.seq == 0:
        controller.start(block)
        return 2.5
    return controller.update(block)


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
