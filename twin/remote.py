"""``RemoteRig``: a ``Rig`` over protocol 1 (docs/protocol.md) on UDP or a serial line (``twin.links``) —
the served twin or any rig whose firmware speaks it. A controller runs on it in the one closed loop
(``twin.engine.run_on_rig``), with the log the rig software keeps.

The handshake repeats HELLO until CONFIG comes (bounded: ``connect_timeout_s``); ``read`` waits at most
``timeout_s`` for the next SAMPLE; a server that disappears is a ``RemoteError`` within that time, never a
hang. A sample that has not been answered when the next is read (the held block that ``start`` reads) is
acknowledged with the command the DAC holds, as the protocol's session requires.
"""

from __future__ import annotations

import math
import queue
import socket
import threading
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any
from urllib.parse import urlsplit

import numpy as np

from twin import protocol as p
from twin.interface import DaqSample, Rig, RigEnded
from twin.links import Link, LinkError, OverLink, UdpLink, open_link, parse_url
from twin.parameters import Parameters, SoftwareCalibration
from twin.rig import RigError

__all__ = [
    "Joined",
    "Observer",
    "ObserverCounts",
    "ObserverEvent",
    "RemoteError",
    "RemoteRig",
    "Refused",
    "SessionEnded",
    "block_dac_v",
    "held_dac_v",
    "open_observer",
    "open_remote",
    "parse_udp_url",
]

_HELLO_INTERVAL_S = 0.2  # the doc's HELLO repetition


class RemoteError(RigError, RigEnded):
    """The remote rig cannot be reached, refused us, or went silent; the message names it and the wait (in a
    run: the session ended, ``twin.interface.RigEnded``)."""


class Refused(RemoteError):
    """The server answered HELLO with role 0: another client controls the rig (its session still runs)."""


class SessionEnded(RemoteError):
    """The server sent STOP: ``reason`` is its code (docs/protocol.md)."""

    def __init__(self, message: str, reason: int) -> None:
        super().__init__(message)
        self.reason = reason


def open_remote(url: str, **kw: Any) -> RemoteRig:
    """The ``RemoteRig`` at ``udp://HOST:PORT`` or ``serial:///dev/ttyX?baud=N`` (``twin.links.open_link``);
    a ``ValueError`` naming a malformed URL, a ``RemoteError`` a rig that cannot be reached."""
    parse_url(url)  # a malformed URL is a ValueError (the caller's usage error), not an unreachable rig
    try:
        link = open_link(url)
    except LinkError as exc:
        raise RemoteError(str(exc)) from None
    return RemoteRig(link=link, **kw)


def parse_udp_url(url: str) -> tuple[str, int]:
    """``udp://HOST:PORT`` → (host, port); a ``ValueError`` naming the URL otherwise."""
    parts = urlsplit(url)
    try:
        port = parts.port
    except ValueError:
        port = None
    if parts.scheme != "udp" or not parts.hostname or port is None or port == 0:
        raise ValueError(f"--rig {url!r}: expected udp://HOST:PORT (port 1…65535)")
    return parts.hostname, port


class RemoteRig(OverLink, Rig):
    """The I/O card of a rig across UDP at ``host:port``, or across the ``link`` given (``open_remote``
    makes either from a URL): ``twin.interface.Rig``'s three calls, plus the session's flags."""

    def __init__(
        self,
        host: str = "",
        port: int = 0,
        *,
        link: Link | None = None,
        role: int = p.ROLE_CONTROL,
        client: str = "ballbeam-twin RemoteRig",
        connect_timeout_s: float = 5.0,
        timeout_s: float = 5.0,
    ) -> None:
        self.timeout_s = timeout_s
        if link is None:
            try:
                link = UdpLink.connect(host, port)
            except LinkError as exc:
                raise RemoteError(str(exc)) from None
        self.link: Link = link
        self.url = link.url
        self.counts_malformed = 0
        try:
            self.config, self.session = self._handshake(role, client, connect_timeout_s)
        except RemoteError:
            link.close()
            raise
        self.command_v = self.config.zero_command_v  # the DAC's value as we last set it (reset: zero volts)
        self.last: p.Sample | None = None
        self._answered = True

    # --- the session ---------------------------------------------------------------------------------
    def _send(self, msg: p.Message, session: int) -> None:
        self.link.send(p.encode(msg, session))  # nobody listening: the bounded wait for an answer reports it

    def _recv(self, wait_s: float) -> p.Frame | None:
        got = self.link.recv(wait_s)
        if got is None:
            return None
        try:
            return p.decode_frame(got[0])
        except p.ProtocolError:
            self.counts_malformed += 1
            return None

    def _handshake(self, role: int, client: str, timeout_s: float) -> tuple[p.Config, int]:
        deadline = time.monotonic() + timeout_s
        next_hello = 0.0
        while (now := time.monotonic()) < deadline:
            if now >= next_hello:
                self._send(p.Hello(role=role, client=client), 0)
                next_hello = now + _HELLO_INTERVAL_S
            frame = self._recv(min(next_hello, deadline) - time.monotonic())
            if frame is not None and isinstance(frame.msg, p.Config):
                if frame.msg.role == p.ROLE_REFUSED:
                    raise Refused(f"{self.url} refused this client (another client controls the rig)")
                return frame.msg, frame.session
        raise RemoteError(f"no CONFIG from {self.url} within {timeout_s:g} s: is `ballbeam serve` running?")

    # --- the Rig interface ---------------------------------------------------------------------------
    @property
    def period_s(self) -> float:
        return self.config.period_s

    @property
    def software(self) -> SoftwareCalibration:
        """The rig's software calibration (CONFIG): build controllers with ``software=`` this."""
        return self.config.software

    def parameters(self, base: Parameters | None = None) -> Parameters:
        """``base`` with the rig's period, DAC range and software calibration (``Config.to_parameters``)."""
        return self.config.to_parameters(base)

    def read(self) -> DaqSample:
        """The next SAMPLE (an unanswered previous one acknowledged first with the DAC's value)."""
        if not self._answered and self.last is not None:
            self.write(self.command_v)
        deadline = time.monotonic() + self.timeout_s
        after = -1 if self.last is None else self.last.seq
        while (left := deadline - time.monotonic()) > 0:
            frame = self._recv(left)
            if frame is None or frame.session != self.session:
                continue
            msg = frame.msg
            if isinstance(msg, p.Stop):
                raise SessionEnded(f"{self.url} ended the session (STOP {msg.reason})", msg.reason)
            if isinstance(msg, p.Sample) and msg.seq == after and self._answered and self.last is not None:
                if self.config.role == p.ROLE_CONTROL:  # a repeated sample: our answer was lost, repeat it
                    self._send(p.Command(seq=after, dac_v=self.command_v), self.session)
                continue
            if isinstance(msg, p.Sample) and msg.seq > after:
                self.last = msg
                self._answered = self.config.role != p.ROLE_CONTROL
                return DaqSample(time_s=msg.time_s, ball_v=msg.ball_v, angle_v=msg.angle_v)
        raise RemoteError(f"no SAMPLE from {self.url} within {self.timeout_s:g} s: the server is gone")

    def write(self, command_v: float) -> None:
        """COMMAND answering the latest sample (the DAC then holds ``command_v``)."""
        if not (isinstance(command_v, (int, float)) and math.isfinite(command_v)):
            raise ValueError(f"command_v = {command_v!r}: the DAC command must be a finite number of volts")
        if self.last is None:
            raise RemoteError(f"{self.url}: write before the first read")
        self.command_v = float(command_v)
        self._send(p.Command(seq=self.last.seq, dac_v=self.command_v), self.session)
        self._answered = True

    def stop(self, reason: int = p.STOP_CLIENT_QUIT) -> None:
        self._send(p.Stop(reason), self.session)

    # --- the latest sample's flags --------------------------------------------------------------------
    def _flag(self, bit: int) -> bool:
        return self.last is not None and bool(self.last.flags & bit)

    @property
    def held(self) -> bool:
        return self._flag(p.FLAG_HELD)

    @property
    def ball_lost(self) -> bool:
        return self._flag(p.FLAG_BALL_LOST)

    @property
    def watchdog(self) -> bool:
        return self._flag(p.FLAG_WATCHDOG)

    @property
    def is_last(self) -> bool:
        return self._flag(p.FLAG_LAST)


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
    pauses). The frames of other sessions are dropped, malformed ones counted (``counts``). Each session
    begins with a ``Joined`` event. With ``follow`` (the default) the reader says HELLO again as soon as a
    STOP comes, every 0.2 s until the server's next session admits it: a served job's sessions are seen
    one after another. That HELLO, sent on the STOP, waits at the server for its next session and so is
    taken before the next controller's unless that one is quicker; then the observer joins during the
    session and misses its first blocks. Without ``follow``, ``rejoin`` asks for the next session.

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
            if self._joining.is_set():
                now = time.monotonic()
                if now >= next_hello:
                    self.link.send(p.encode(p.Hello(role=p.ROLE_OBSERVE, client=self.client), 0))
                    next_hello = now + _HELLO_INTERVAL_S
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
        if isinstance(msg, p.Stop) and self.follow:
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
