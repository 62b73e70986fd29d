"""``RemoteRig``: a ``Rig`` over protocol 1 (docs/protocol.md) on UDP or a serial line (``twin.wire.links``) —
the served twin or any rig whose firmware speaks it. A controller runs on it in the one closed loop
(``twin.engine.run_on_rig``), with the log the rig software keeps.

The handshake repeats HELLO until CONFIG comes (bounded: ``connect_timeout_s``); ``read`` waits at most
``timeout_s`` for the next SAMPLE; a server that disappears is a ``RemoteError`` within that time, never a
hang. A sample that has not been answered when the next is read (the held block that ``start`` reads) is
acknowledged with the command the DAC holds, as the protocol's session requires.
"""

from __future__ import annotations

import math
import time
from typing import Any
from urllib.parse import urlsplit

from twin.interface import DaqSample, Rig, RigEnded
from twin.parameters import Parameters, SoftwareCalibration
from twin.rigs.sim import RigError
from twin.wire import protocol as p
from twin.wire.links import Link, LinkError, OverLink, UdpLink, open_link, parse_url

__all__ = [
    "HELLO_INTERVAL_S",
    "RemoteError",
    "RemoteRig",
    "Refused",
    "SessionEnded",
    "open_remote",
    "parse_udp_url",
]

HELLO_INTERVAL_S = 0.2  # the doc's HELLO repetition (a client's and an observer's)


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
    """The ``RemoteRig`` at ``udp://HOST:PORT`` or ``serial:///dev/ttyX?baud=N`` (``twin.wire.links.open_link``);
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
                next_hello = now + HELLO_INTERVAL_S
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
                if msg.flags & p.FLAG_REFUSED and self.config.role == p.ROLE_CONTROL:
                    raise RemoteError(f"{self.url} refused COMMAND {after} (dac_v = {self.command_v!r} V)")
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
