"""The transports of protocol 1 (docs/protocol.md, "Transports"): a link carries whole frames to a peer.

* ``UdpLink``: one frame per datagram (the default). A listening link answers whoever sent (``peer`` is
  the sender's address); a connected link has one peer and the kernel drops datagrams from anyone else.
* ``SerialLink``: a tty (a USB board's ``/dev/ttyACM0``, or one end of a pseudo-terminal pair) in raw
  mode. Each frame goes out preceded by the sync bytes 0xA5 0x5A; the reader buffers bytes, searches for
  the sync followed by the magic, reads the frame of the length its header gives (one of the five frame
  lengths, else it resyncs) and drops a frame whose CRC fails. A serial line has one peer: ``SERIAL_PEER``.

``open_link(url)`` makes either from ``udp://HOST:PORT`` or ``serial:///dev/ttyX?baud=115200``.
"""

from __future__ import annotations

import os
import select
import socket
import sys
import termios
import time
import tty
import zlib
from collections.abc import Hashable
from dataclasses import asdict, dataclass
from typing import Any, Protocol, Self, cast
from urllib.parse import parse_qs, urlsplit

from twin.wire import protocol as p

__all__ = [
    "DEFAULT_BAUD",
    "SERIAL_PEER",
    "SYNC",
    "Link",
    "LinkError",
    "SerialCounts",
    "SerialLink",
    "UdpLink",
    "open_link",
    "parse_url",
]

SYNC = b"\xa5\x5a"
SERIAL_PEER = "serial"  # the one peer at the other end of a serial line
DEFAULT_BAUD = 115200
_START = SYNC + p.MAGIC  # what the reader searches for after losing sync
_LENGTHS = frozenset(p.LENGTHS.values())  # a length field that is none of these means a false sync
_LENGTH_AT = len(SYNC) + 6  # the header's u16 length, counted from the sync
_HEADER_END = len(SYNC) + 8
_RECV_BYTES = 4096  # UDP: larger than any frame, so that an oversized datagram is seen whole and refused
_RCVBUF_BYTES = 1 << 20  # room for a burst of datagrams, so that a flood drops less of the client's traffic
_READ_BYTES = 4096
_WRITE_WAIT_S = 0.1  # a serial write that cannot drain this long is dropped, as UDP drops a datagram
# Linux: a listening socket queues the ICMP errors of its datagrams (IP_RECVERR, IPV6_RECVERR), each with the
# address it was sent to, so that a peer whose socket closed is known by name (``UdpLink.unreachable``).
_RECVERR = {socket.AF_INET: (socket.IPPROTO_IP, 11), socket.AF_INET6: (socket.IPPROTO_IPV6, 25)}
_MAX_ERRORS = 64  # errors read from the queue at once (bounded: a flood of them waits for the next call)
_BAUDS = {
    int(name[1:]): getattr(termios, name)
    for name in dir(termios)
    if name.startswith("B") and name[1:].isdigit() and int(name[1:]) > 0
}

Peer = Hashable


class LinkError(RuntimeError):
    """A link that cannot be opened (bad URL, no such tty, port taken); the message names it."""


class Link(Protocol):
    """A transport of whole frames: ``send`` one to a peer, ``recv`` the next (bytes, peer) or ``None``."""

    url: str

    def send(self, frame: bytes, peer: Peer | None = None) -> None: ...

    def recv(self, wait_s: float) -> tuple[bytes, Peer] | None: ...

    def close(self) -> None: ...


def _family(host: str) -> socket.AddressFamily:
    return socket.AF_INET6 if ":" in host else socket.AF_INET


class OverLink:
    """What talks over a ``link`` (the server, ``RemoteRig``): its UDP socket, ``close`` and with-blocks."""

    link: Link

    @property
    def sock(self) -> socket.socket:
        """The UDP link's socket (an ``AttributeError`` on a serial line)."""
        if not isinstance(self.link, UdpLink):
            raise AttributeError(f"{self.link.url} has no socket")
        return self.link.sock

    def close(self) -> None:
        self.link.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class UdpLink:
    """One frame per datagram on a UDP socket (``listen``: bound, any peer; ``connect``: one peer)."""

    def __init__(self, sock: socket.socket, url: str, *, connected: bool) -> None:
        self.sock = sock
        self.url = url
        self.connected = connected
        self.reports_errors = False  # the socket queues ICMP errors (listen, on Linux): ``unreachable``
        self._errors = select.poll()
        self._errors.register(sock.fileno(), 0)  # no events asked: POLLERR alone is reported

    @classmethod
    def listen(cls, host: str = "127.0.0.1", port: int = 0) -> UdpLink:
        sock = socket.socket(_family(host), socket.SOCK_DGRAM)
        try:
            sock.bind((host, port))
        except OSError as exc:
            sock.close()
            raise LinkError(f"cannot bind udp://{host}:{port}: {exc.strerror or exc}") from None
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, _RCVBUF_BYTES)
        except OSError:
            pass  # the system's default buffer: still correct, only less tolerant of bursts
        link = cls(sock, f"udp://{host}:{sock.getsockname()[1]}", connected=False)
        if sys.platform.startswith("linux"):
            level, option = _RECVERR[sock.family]
            try:
                sock.setsockopt(level, option, 1)
                link.reports_errors = True
            except OSError:
                pass  # vanished peers are then known by their silence alone
        return link

    @classmethod
    def connect(cls, host: str, port: int) -> UdpLink:
        url = f"udp://{host}:{port}"
        sock = socket.socket(_family(host), socket.SOCK_DGRAM)
        try:
            sock.connect((host, port))  # datagrams from any other address are dropped by the kernel
        except OSError as exc:
            sock.close()
            raise LinkError(f"{url}: {exc.strerror or exc}") from None
        return cls(sock, url, connected=True)

    @property
    def port(self) -> int:
        return int(self.sock.getsockname()[1])

    def send(self, frame: bytes, peer: Peer | None = None) -> None:
        # A socket that queues ICMP errors reports another peer's pending one on this call, which then sends
        # nothing: once reported it is cleared, and the frame goes on the second try.
        for _ in range(2 if self.reports_errors else 1):
            try:
                if self.connected or peer is None:
                    self.sock.send(frame)
                else:
                    self.sock.sendto(
                        frame, cast(tuple[Any, ...], peer)
                    )  # a listening link's peers: addresses
                return
            except OSError:
                pass  # a peer that went away (ICMP unreachable): its silence is handled by timeouts

    def recv(self, wait_s: float) -> tuple[bytes, Peer] | None:
        try:
            self.sock.settimeout(max(wait_s, 1e-6))
            data, addr = self.sock.recvfrom(_RECV_BYTES)
        except TimeoutError:
            return None
        except ConnectionRefusedError:  # a vanished peer's ICMP error, reported here once: no datagram lost
            return None
        except OSError:  # ICMP port unreachable from a vanished peer, or our socket closed under us
            time.sleep(min(max(wait_s, 0.0), 0.01))
            return None
        return data, addr

    def unreachable(self) -> list[Peer]:
        """The peers whose datagrams came back unreachable since the last call (their socket closed or their
        process died: the kernel's ICMP error, queued on a listening socket on Linux); [] elsewhere."""
        if not self.reports_errors or not self._errors.poll(0):  # POLLERR: an error is queued (a cheap check)
            return []
        peers: list[Peer] = []
        self.sock.settimeout(0.0)  # non-blocking: with a timeout the call would wait for data it never reads
        for _ in range(_MAX_ERRORS):
            try:
                _, _, _, addr = self.sock.recvmsg(1, 512, socket.MSG_ERRQUEUE | socket.MSG_DONTWAIT)
            except OSError:  # BlockingIOError: the queue is empty
                break
            if addr:
                peers.append(addr)
        return peers

    def close(self) -> None:
        self.sock.close()


@dataclass
class SerialCounts:
    """What the serial reader threw away (the protocol's "counted and ignored", before a frame exists)."""

    frames: int = 0  # frames delivered (sync, magic, a frame length, a good CRC)
    garbage_bytes: int = 0  # bytes skipped while searching for the sync and magic
    resyncs: int = 0  # times the reader had to search: garbage, a wrong length or a bad CRC
    bad_lengths: int = 0  # a length field that is none of the five frame lengths
    crc_errors: int = 0  # a frame of a right length whose CRC fails
    dropped_writes: int = 0  # frames not sent because the line would not drain

    def to_json(self) -> dict[str, int]:
        return asdict(self)


class FrameReader:
    """The serial receiver's framing, apart from the tty so that it can be tested on any byte stream."""

    def __init__(self) -> None:
        self.buf = bytearray()
        self.counts = SerialCounts()

    def feed(self, data: bytes) -> None:
        self.buf += data

    def _skip(self, n: int) -> None:
        del self.buf[:n]
        self.counts.garbage_bytes += n

    def next_frame(self) -> bytes | None:
        """The next whole frame in the buffer (without its sync), or ``None`` until more bytes come."""
        buf, c = self.buf, self.counts
        while True:
            at = buf.find(_START)
            if at < 0:
                # Keep a tail that may be the start of a sync and magic cut by the read; the rest is garbage.
                keep = len(_START) - 1
                if len(buf) > keep:
                    c.resyncs += 1
                    self._skip(len(buf) - keep)
                return None
            if at > 0:
                c.resyncs += 1
                self._skip(at)
            if len(buf) < _HEADER_END:
                return None
            length = int.from_bytes(buf[_LENGTH_AT:_HEADER_END], "little")
            if length not in _LENGTHS:
                c.bad_lengths += 1
                c.resyncs += 1
                self._skip(len(SYNC))  # a false sync (or a corrupt header): search after it
                continue
            end = len(SYNC) + length
            if len(buf) < end:
                return None  # bounded: a frame is at most p.MAX_FRAME bytes
            frame = bytes(buf[len(SYNC) : end])
            if int.from_bytes(frame[-4:], "little") != zlib.crc32(frame[:-4]):
                c.crc_errors += 1
                c.resyncs += 1
                self._skip(len(SYNC))  # the frame may have started later: search inside it
                continue
            del buf[:end]
            c.frames += 1
            return frame


def _raw(fd: int, baud: int | None) -> None:
    """Raw mode (no echo, no line editing, no translation of bytes) and, if given, the line's speed."""
    tty.setraw(fd, termios.TCSANOW)
    attrs = termios.tcgetattr(fd)
    attrs[2] |= termios.CLOCAL | termios.CREAD  # no modem lines: a USB board has none
    if baud is not None:
        attrs[4] = attrs[5] = _BAUDS[baud]
    termios.tcsetattr(fd, termios.TCSANOW, attrs)


class SerialLink:
    """Frames over a tty in raw mode, each preceded by 0xA5 0x5A (docs/protocol.md, "Transports")."""

    def __init__(self, fd: int, url: str, *, owns_fd: bool = True) -> None:
        self.fd = fd
        self.url = url
        self.owns_fd = owns_fd
        self.reader = FrameReader()
        os.set_blocking(fd, False)  # a line that does not drain drops frames, never blocks the tick

    @property
    def counts(self) -> SerialCounts:
        return self.reader.counts

    @classmethod
    def open(cls, path: str, baud: int = DEFAULT_BAUD) -> SerialLink:
        url = f"serial://{path}?baud={baud}"
        if baud not in _BAUDS:
            raise LinkError(f"{url}: baud {baud} is not a speed this system's termios knows")
        try:
            fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError as exc:
            raise LinkError(f"{url}: cannot open {path}: {exc.strerror or exc}") from None
        try:
            if not os.isatty(fd):
                raise LinkError(f"{url}: {path} is not a tty")
            _raw(fd, baud)
        except (LinkError, termios.error) as exc:
            os.close(fd)
            raise LinkError(str(exc) if isinstance(exc, LinkError) else f"{url}: {exc}") from None
        return cls(fd, url)

    @classmethod
    def from_fd(cls, fd: int, name: str = "fd", *, baud: int | None = None) -> SerialLink:
        """An already open tty (e.g. the master of ``os.openpty()``), put in raw mode; the caller closes it."""
        _raw(fd, baud)
        return cls(fd, f"serial://{name}", owns_fd=False)

    def send(self, frame: bytes, peer: Peer | None = None) -> None:
        data = memoryview(SYNC + frame)
        deadline = time.monotonic() + _WRITE_WAIT_S
        while data:
            try:
                n = os.write(self.fd, data)
            except BlockingIOError:
                n = 0
            except OSError:
                self.counts.dropped_writes += 1  # the line went away: its silence is handled by timeouts
                return
            data = data[n:]
            left = deadline - time.monotonic()
            if data and left <= 0:
                self.counts.dropped_writes += 1  # the peer's resync skips the part that went out
                return
            if data:
                select.select([], [self.fd], [], left)

    def recv(self, wait_s: float) -> tuple[bytes, Peer] | None:
        deadline = time.monotonic() + max(wait_s, 0.0)
        while True:
            frame = self.reader.next_frame()
            if frame is not None:
                return frame, SERIAL_PEER
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            try:
                ready, _, _ = select.select([self.fd], [], [], left)
                data = os.read(self.fd, _READ_BYTES) if ready else b""
            except BlockingIOError:
                continue
            except OSError:  # EIO: the other end of a pty closed; wait as for silence
                time.sleep(min(left, 0.01))
                continue
            self.reader.feed(data)

    def close(self) -> None:
        if self.owns_fd:
            try:
                os.close(self.fd)
            except OSError:
                pass
        self.owns_fd = False


def parse_url(url: str) -> tuple[str, str, int]:
    """``udp://HOST:PORT`` → ("udp", host, port); ``serial:///dev/ttyX?baud=N`` → ("serial", path, baud).
    A ``ValueError`` naming the URL otherwise."""
    parts = urlsplit(url)
    if parts.scheme == "udp":
        try:
            port = parts.port
        except ValueError:
            port = None
        if not parts.hostname or port is None or port == 0:
            raise ValueError(f"{url!r}: expected udp://HOST:PORT (port 1…65535)")
        return "udp", parts.hostname, port
    if parts.scheme == "serial":
        query = parse_qs(parts.query)
        bauds = query.get("baud", [str(DEFAULT_BAUD)])
        if (
            not parts.path
            or parts.netloc
            or set(query) - {"baud"}
            or len(bauds) != 1
            or not bauds[0].isdigit()
        ):
            raise ValueError(f"{url!r}: expected serial:///dev/ttyX?baud=N")
        baud = int(bauds[0])
        if baud not in _BAUDS:
            raise ValueError(f"{url!r}: baud {baud} is not a speed this system's termios knows")
        return "serial", parts.path, baud
    raise ValueError(f"{url!r}: expected udp://HOST:PORT or serial:///dev/ttyX?baud=N")


def open_link(url: str, *, listen: bool = False) -> UdpLink | SerialLink:
    """The link a URL names: UDP connected to HOST:PORT (``listen``: bound there), or the serial line."""
    try:
        kind, where, number = parse_url(url)
    except ValueError as exc:
        raise LinkError(str(exc)) from None
    if kind == "udp":
        return UdpLink.listen(where, number) if listen else UdpLink.connect(where, number)
    return SerialLink.open(where, number)
