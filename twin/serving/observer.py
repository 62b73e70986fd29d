"""An observer of a served session (docs/protocol.md, role 1): it joins, receives every SAMPLE, the
COMMAND echoes and STOP, and may rejoin the next session; nothing it does reaches the rig."""

from __future__ import annotations

import math
import queue
import socket
import threading
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from twin.parameters import Parameters, SoftwareCalibration
from twin.rigs.remote import HELLO_INTERVAL_S, Refused, RemoteError
from twin.wire import protocol as p
from twin.wire.links import Link, LinkError, OverLink, UdpLink, parse_url

__all__ = [
    "Joined",
    "Observer",
    "ObserverCounts",
    "ObserverEvent",
    "block_dac_v",
    "held_dac_v",
    "open_observer",
]

# --- an observer ---------------------------------------------------------------------------------------
_OBSERVER_RCVBUF_BYTES = 4 << 20  # a lock-step session's burst while the reader thread waits for the GIL
_READER_WAIT_S = 0.1  # the reader's longest wait in one recv: how soon close() is noticed


@dataclass(frozen=True)
class Joined:
    """The observer joined a session: the first event of each observed session, before its frames."""

    session: int
    config: p.Config


ObserverEvent = Joined | p.Sample | p.Command | p.Stop


@dataclass
class ObserverCounts:
    """What the observer's reader received and dropped (the protocol's "counted and ignored")."""

    frames: int = 0  # datagrams received
    malformed: int = 0  # not a frame of protocol 1
    wrong_session: int = 0  # a valid frame of another session, or of the ended one after its STOP
    repeated: int = 0  # a SAMPLE of a seq already seen: not a new block
    unexpected: int = 0  # a valid frame an observer does not take (a HELLO)
    sessions: int = 0  # sessions joined


def open_observer(url: str, **kw: Any) -> Observer:
    """The ``Observer`` of the rig at ``udp://HOST:PORT``; a ``ValueError`` naming a malformed URL or a serial
    line (it has a single peer, the controller), a ``RemoteError`` a rig that cannot be reached."""
    return Observer(url, **kw)


class Observer(OverLink):
    """A client that watches a rig's sessions (HELLO role observe) without commanding it: the samples, the
    commands the server accepted (their echo) and the STOP, as events in their order (``next_event``).

    A daemon thread drains the socket into an unbounded queue as fast as datagrams come, so that a consumer
    slower than a lock-step session loses none of them (the socket's buffer only absorbs the thread's
    pauses). The frames of other sessions are dropped, malformed ones counted (``counts``). Each session begins
    with a ``Joined`` event; while it lasts the reader repeats HELLO every 0.2 s (the keep-alive by which the
    server knows the observer is still there). With ``follow`` (the default) the reader says HELLO again as soon
    as a STOP comes, every 0.2 s until the server's next session admits it: a served job's sessions are seen one
    after another. That HELLO, sent on the STOP, waits at the server for its next session and so is taken before
    the next controller's unless that one is quicker; then the observer joins during the session and misses its
    first blocks. Without ``follow``, ``rejoin`` asks for the next session.

    ``config`` and ``session`` are the reader's latest session's (a slow consumer's events may be of an
    earlier one: each ``Joined`` carries its own)."""

    def __init__(
        self,
        url: str,
        *,
        client: str = "ballbeam-twin Observer",
        connect_timeout_s: float = 5.0,
        timeout_s: float = 5.0,
        follow: bool = True,
    ) -> None:
        kind, host, port = parse_url(url)  # a malformed URL is a ValueError (the caller's usage error)
        if kind != "udp":
            raise ValueError(
                f"{url!r}: an observer needs UDP (udp://HOST:PORT); a serial line has a single peer, the "
                "controlling client"
            )
        try:
            link = UdpLink.connect(host, port)
        except LinkError as exc:
            raise RemoteError(str(exc)) from None
        try:
            link.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, _OBSERVER_RCVBUF_BYTES)
        except OSError:
            pass  # the system's limit applies: the reader thread is what keeps up
        self.link: Link = link
        self.url = link.url
        self.client = client
        self.timeout_s = timeout_s
        self.follow = follow
        self.counts = ObserverCounts()
        self.session = 0  # none yet: the first CONFIG's is taken
        self.config: p.Config | None = None
        self._events: queue.SimpleQueue[ObserverEvent | RemoteError] = queue.SimpleQueue()
        self._failure: RemoteError | None = None  # raised by next_event once the events before it are taken
        self._joining = threading.Event()
        self._joining.set()
        self._answered = threading.Event()  # the first CONFIG came (granted or refused)
        self._closing = threading.Event()
        self._last_seq = -1
        self._watching = False  # admitted to a session that has not ended: the keep-alive HELLOs go
        self._reader = threading.Thread(target=self._read, name=f"observer {self.url}", daemon=True)
        self._reader.start()
        if not self._answered.wait(connect_timeout_s) or self.config is None:
            failure = self._failure  # a refusal, or a reader that failed
            self.close()
            raise failure or RemoteError(
                f"no CONFIG from {self.url} within {connect_timeout_s:g} s: is `ballbeam serve` running?"
            )

    # --- the reader thread -----------------------------------------------------------------------------
    def _read(self) -> None:
        try:
            self._drain()
        except BaseException as exc:  # noqa: BLE001 - a reader that dies must not leave the consumer waiting
            self._failure = RemoteError(f"{self.url}: the observer's reader failed: {exc!r}")
            self._events.put(self._failure)
            self._answered.set()

    def _drain(self) -> None:
        next_hello = 0.0
        while not self._closing.is_set():
            wait_s = _READER_WAIT_S
            # HELLO until a session admits us, then as the keep-alive while we watch it: the server frees the
            # place of an observer that falls silent (docs/protocol.md, "Observers and sessions").
            if self._joining.is_set() or self._watching:
                now = time.monotonic()
                if now >= next_hello:
                    self.link.send(p.encode(p.Hello(role=p.ROLE_OBSERVE, client=self.client), 0))
                    next_hello = now + HELLO_INTERVAL_S
                wait_s = min(wait_s, next_hello - now)
            got = self.link.recv(wait_s)
            if got is None:
                continue
            self.counts.frames += 1
            try:
                frame = p.decode_frame(got[0])
            except p.ProtocolError:
                self.counts.malformed += 1
                continue
            if self._take(frame):
                next_hello = 0.0  # a STOP: say HELLO for the next session at once

    def _take(self, frame: p.Frame) -> bool:
        """One valid frame: queued, or counted and dropped. True when it was a STOP and we are to rejoin."""
        msg, c = frame.msg, self.counts
        if isinstance(msg, p.Config):
            # A CONFIG of the session we watch or watched answers a repeated HELLO: nothing new.
            if self._joining.is_set() and frame.session != self.session:
                self._join(msg, frame.session)
            return False
        if isinstance(msg, p.Hello):
            c.unexpected += 1
            return False
        if frame.session != self.session or self._joining.is_set():
            c.wrong_session += 1
            return False
        if isinstance(msg, p.Sample):
            if msg.seq <= self._last_seq:
                c.repeated += 1
                return False
            self._last_seq = msg.seq
        self._events.put(msg)
        if isinstance(msg, p.Stop):
            self._watching = False
            if self.follow:
                self._joining.set()
                return True
        return False

    def _join(self, config: p.Config, session: int) -> None:
        if config.role != p.ROLE_OBSERVE:
            # Refused (no more observers in that session): the stream ends here, after its events.
            self._failure = Refused(f"{self.url} refused this observer (it admits no more observers)")
            self._events.put(self._failure)
            self._closing.set()
        else:
            self.config, self.session, self._last_seq = config, session, -1
            self.counts.sessions += 1
            self._watching = True
            self._joining.clear()
            self._events.put(Joined(session, config))
        self._answered.set()

    # --- the consumer's side ---------------------------------------------------------------------------
    @property
    def software(self) -> SoftwareCalibration:
        """The rig's software calibration (the latest CONFIG): volts to metres and radians."""
        assert self.config is not None
        return self.config.software

    def parameters(self, base: Parameters | None = None) -> Parameters:
        """``base`` with the rig's period, DAC range and software calibration (``Config.to_parameters``)."""
        assert self.config is not None
        return self.config.to_parameters(base)

    def next_event(self, wait_s: float | None = None) -> ObserverEvent | None:
        """The next event (waiting at most ``wait_s``, default ``timeout_s``), or ``None`` if none came. A
        ``Refused`` once the events before a refusal of a later session have been taken."""
        wait = self.timeout_s if wait_s is None else wait_s
        try:
            item = self._events.get(timeout=wait) if wait > 0 else self._events.get_nowait()
        except queue.Empty:
            if self._failure is not None and not self._reader.is_alive() and self._events.empty():
                raise self._failure from None
            return None
        if isinstance(item, RemoteError):
            raise item
        return item

    def until_stop(self, wait_s: float | None = None) -> list[ObserverEvent]:
        """The events up to and including the next STOP; a ``RemoteError`` if none comes for ``wait_s``
        (default ``timeout_s``) between two events."""
        out: list[ObserverEvent] = []
        while not out or not isinstance(out[-1], p.Stop):
            event = self.next_event(wait_s)
            if event is None:
                wait = self.timeout_s if wait_s is None else wait_s
                raise RemoteError(f"no frame from {self.url} within {wait:g} s: the session is gone")
            out.append(event)
        return out

    def rejoin(self) -> None:
        """Say HELLO for the server's next session (after a STOP, without ``follow``); its ``Joined`` follows."""
        self._joining.set()

    def close(self) -> None:
        self._closing.set()
        if self._reader.is_alive() and self._reader is not threading.current_thread():
            self._reader.join(2 * _READER_WAIT_S + 1.0)
        self.link.close()


def held_dac_v(events: Iterable[ObserverEvent], zero_command_v: float) -> np.ndarray:
    """The DAC's volts during each observed block (docs/protocol.md, COMMAND: the echo): one value per
    SAMPLE of ``events``, in their order (the i-th is the block of the i-th ``p.Sample``).

    Block k holds ``zero_command_v`` when SAMPLE k carries the watchdog flag or its ``applied_seq`` is 0
    (COMMAND 0 only acknowledges the held block), else the echoed COMMAND whose seq is its ``applied_seq``:
    NaN where that echo was lost. A ``Joined`` event begins a new session (seq numbers start again);
    ``zero_command_v`` is the CONFIG's. A held block's value is the DAC's, which does not move the held rig."""
    samples: list[tuple[int, p.Sample]] = []
    commands: dict[int, dict[int, float]] = {}  # session → seq → volts
    session = 0  # the index of the session in ``events``: its seqs are its own
    for event in events:
        if isinstance(event, Joined):
            session += 1
        elif isinstance(event, p.Sample):
            samples.append((session, event))
        elif isinstance(event, p.Command):
            commands.setdefault(session, {})[event.seq] = event.dac_v
    return np.array(
        [block_dac_v(sample, commands.get(s, {}), zero_command_v) for s, sample in samples], dtype=float
    )


def block_dac_v(sample: p.Sample, commands: Mapping[int, float], zero_command_v: float) -> float:
    """The DAC's volts during ``sample``'s block (docs/protocol.md, COMMAND: the echo): ``zero_command_v``
    under the watchdog or before any command applied (``applied_seq`` 0: COMMAND 0 only acknowledges the
    held block), else the echoed command of that seq in ``commands`` (seq → volts; NaN if it was lost)."""
    if sample.flags & p.FLAG_WATCHDOG or sample.applied_seq == 0:
        return zero_command_v
    return commands.get(sample.applied_seq, math.nan)
