"""The twin served as a virtual I/O card on protocol 1 (docs/protocol.md) over UDP or a serial line
(``twin.wire.links``): ``ballbeam serve``.

One session per ``Server.serve()``: a client says HELLO and gets CONFIG; the server then runs the engine's
own closed loop (``twin.engine.ClosedLoop``, the sequence of ``run_closed_loop``) with a ``Controller``
adapter whose ``start``/``update`` send the block as SAMPLE and return the client's COMMAND. The session
log, the true state and the verdict therefore come from the engine unchanged: a lock-step session
reproduces the in-process run of the same controller bit for bit.

* **Lock-step**: SAMPLE k, then wait (at most ``timeout_s``) for COMMAND k; a silent client ends the
  session with STOP 3.
* **Real time**: the ticks are paced by the wall clock (``twin.realtime.WallClockPacer``, as ``run
  --realtime``). The command answering SAMPLE k is awaited until the next tick's boundary and applied
  there: the simulation integrates a whole control period at once, so a command takes effect at the next
  period boundary (the granularity is one period, as the thesis software, which writes once per tick).
  A command that is not there by then is counted missing (and late if it arrives afterwards); the DAC
  holds its last value. After ``watchdog_periods`` missing periods in a row the output goes to the zero
  command and the samples carry the watchdog flag until a command arrives.
* **Observers** (at most ``MAX_OBSERVERS``) get every SAMPLE, every COMMAND the server accepts (the echo:
  what the DAC holds, from SAMPLE k's ``applied_seq``) and the STOP; a new session forgets them. An observer
  repeats HELLO while it watches (its keep-alive); one that vanishes — its socket closed (the transport
  reports the port unreachable) or silent for ``observer_silence_s`` — loses its place, which a new
  observer may then take.

Anything that is not a valid frame of this session from the right peer — malformed, oversized, another
session's, a replayed or out-of-order command, an observer's command, a non-finite or out-of-range DAC
value — is counted in ``SessionCounts`` and otherwise ignored.
"""

from __future__ import annotations

import math
import secrets
import sys
import time
from collections.abc import Callable, Hashable
from dataclasses import asdict, dataclass, field, replace

from twin.engine import ENDED_BALL_LOST, ClosedLoop, ControllerError, RunResult, update_ticks
from twin.interface import Controller, DaqSample
from twin.parameters import Parameters
from twin.realtime import TickTiming, WallClockPacer
from twin.rigs.sim import SimRig, make_rig
from twin.rigs.warm import warm
from twin.wire import protocol as p
from twin.wire.links import Link, LinkError, OverLink, SerialCounts, SerialLink, UdpLink

__all__ = [
    "DEFAULT_TIMEOUT_S",
    "DEFAULT_WATCHDOG_PERIODS",
    "STOP_NAMES",
    "Server",
    "ServeError",
    "SessionCounts",
    "SessionResult",
    "SessionSettings",
]

DEFAULT_WATCHDOG_PERIODS = 5  # 0.1 s at 50 Hz: a dead controller's last command drives the beam no longer
DEFAULT_TIMEOUT_S = 5.0  # lock-step: the longest wait for one command before the session ends (STOP 3)
MAX_OBSERVERS = 4  # further clients are refused: the samples sent per tick stay bounded
# An observer says HELLO every 0.2 s while it watches (twin.serving.observer): one silent this long (at least,
# or the session's timeout_s if longer) has vanished and its place is freed.
MIN_OBSERVER_SILENCE_S = 1.0
_RESEND_S = (
    0.2  # lock-step: SAMPLE k is repeated this often while its COMMAND is awaited (UDP may lose either)
)
_RT_MARGIN_S = 0.0005  # real time: stop waiting for a command this long before the next tick's boundary
_LOOPBACK = frozenset({"127.0.0.1", "localhost", "::1"})


class ServeError(RuntimeError):
    """A session that could not run (no client came, the socket failed); the message says which."""


@dataclass(frozen=True)
class SessionSettings:
    """The served rig (every option of ``run`` that shapes it) and the session's timing."""

    x0_m: float = 0.0
    theta0_rad: float = 0.0
    duration_s: float = 15.0
    seed: int = 0
    noise: bool = True
    params: Parameters = field(default_factory=Parameters)
    plant: str = "twin"
    ideal_sensors: bool = False
    mode: int = p.MODE_LOCKSTEP
    timeout_s: float = DEFAULT_TIMEOUT_S  # the wait for a command (lock-step; the view: for an answer)
    watchdog_periods: int = DEFAULT_WATCHDOG_PERIODS
    wait_client_s: float | None = None  # how long to wait for a controlling client (None: until one comes)
    stop_when_lost: bool = True
    rig_name: str = "ballbeam-twin"


@dataclass
class SessionCounts:
    """What the server received and refused, and how the commands kept time."""

    frames: int = 0  # datagrams received
    malformed: int = 0  # not a frame of protocol 1 (length, magic, version, type, crc, field)
    wrong_session: int = 0  # a valid frame of another session
    stale_commands: int = 0  # a replayed or out-of-order command (seq not the latest sample's)
    unauthorised_commands: int = 0  # a command from an observer or an unknown peer
    refused_commands: int = 0  # a non-finite or out-of-range dac_v: not an answer, the DAC keeps its value
    unexpected: int = 0  # a valid frame the server does not take (a SAMPLE or CONFIG sent to it)
    refused_clients: int = 0  # HELLOs answered with role 0
    observers: int = 0
    observers_gone: int = 0  # observers whose place was freed: their port unreachable, or silent
    late_commands: int = 0  # real time: a command that arrived after its tick's boundary
    missing_commands: int = 0  # real time: periods that ended without their command
    watchdog_trips: int = 0  # times the watchdog put the output at the zero command
    watchdog_ticks: int = 0  # samples sent with the watchdog flag
    resent_samples: int = 0  # lock-step: a sample repeated because its command had not come

    def to_json(self) -> dict[str, int]:
        return asdict(self)


STOP_NAMES = {  # a STOP reason in words (docs/protocol.md)
    p.STOP_DONE: "done",
    p.STOP_CLIENT_QUIT: "client quit",
    p.STOP_BALL_LOST: "ball lost",
    p.STOP_ERROR: "error",
    p.STOP_SHUTDOWN: "server shutting down",
}


@dataclass
class SessionResult:
    """One served session: the engine's result (log and verdict), why it ended, what was counted."""

    result: RunResult
    stop_reason: int
    stop_detail: str
    counts: SessionCounts
    client: str
    timing: TickTiming | None = None
    serial: SerialCounts | None = None  # a serial line: what its reader threw away during the session

    def summary(self) -> dict[str, object]:
        out: dict[str, object] = {
            "client": self.client,
            "stop": STOP_NAMES.get(self.stop_reason, str(self.stop_reason)),
            **({"stop_detail": self.stop_detail} if self.stop_detail else {}),
            **self.counts.to_json(),
        }
        if self.timing is not None:
            out["realtime"] = self.timing.to_json()
        if self.serial is not None:
            out["serial"] = self.serial.to_json()
        return out


def _reply_to(addr: Hashable, reply_port: int) -> Hashable:
    """Where a client that said HELLO from ``addr`` is sent to: ``addr``, or its host at ``reply_port`` (UDP;
    a client whose sending and receiving sockets differ, as Simulink's UDP Send and Receive blocks)."""
    if reply_port and isinstance(addr, tuple):
        return (addr[0], reply_port, *addr[2:])
    return addr


class _SessionOver(Exception):
    """Raised inside the adapter's start/update to end the session (a silent or quitting client)."""


class _ServePacer(WallClockPacer):
    """The wall-clock pacer of ``run --realtime``, telling the adapter when the next tick begins."""

    def next_boundary(self) -> float:
        """The wall-clock deadline of the tick after the current one (``wait(k)`` was the last call)."""
        return self._start + (len(self._late) + 1) * self.period_s


class _WireController(Controller):
    """The remote client as the engine's ``Controller``: a block out as SAMPLE, the DAC command back."""

    name = "udp client"

    def __init__(self, server: Server, period_s: float) -> None:
        super().__init__()
        self.server = server
        self.period_s = period_s

    def start(self, sample: DaqSample) -> None:
        self.server._exchange(sample, start=True)

    def update(self, sample: DaqSample) -> float:
        return self.server._exchange(sample, start=False)


class Server(OverLink):
    """A UDP socket bound to ``host:port`` (port 0: any free one, see ``port``) serving sessions, or the
    ``link`` given (``twin.wire.links.SerialLink``: a serial line, whose one peer is the controller)."""

    def __init__(
        self,
        settings: SessionSettings,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        session_id: int | None = None,
        log: Callable[[str], None] | None = None,
        link: Link | None = None,
    ) -> None:
        self.settings = settings
        self.host = host
        self._log = log or (lambda line: print(line, file=sys.stderr, flush=True))
        if link is None:
            try:
                link = UdpLink.listen(host, port)
            except LinkError as exc:
                raise ServeError(str(exc)) from None
        self.link: Link = link
        self.port: int = link.port if isinstance(link, UdpLink) else 0
        if isinstance(link, UdpLink) and host not in _LOOPBACK:
            where = "every interface" if host in ("", "0.0.0.0", "::") else host
            self._log(
                f"warning: serving on {where} (port {self.port}): anyone who can reach this machine there can "
                "drive the twin — there is no authentication. Serve on 127.0.0.1 (the default) unless that "
                "is what you want."
            )
        # The session id only tells sessions apart (never a result): not seeded, as a restarted server's must differ.
        self.session = session_id if session_id is not None else (secrets.randbits(32) or 1)
        self._sessions = 0
        self._reset_session()

    @property
    def url(self) -> str:
        return self.link.url

    # --- a session ----------------------------------------------------------------------------------
    def _reset_session(self) -> None:
        self.counts = SessionCounts()
        self.controller_addr: Hashable | None = None
        self.client_name = ""
        self.observers: list[Hashable] = []
        self._heard: dict[Hashable, float] = {}  # an observer → when it was last heard (time.monotonic)
        self._reply: dict[Hashable, Hashable] = {}  # an admitted client's address → where it is sent to
        self._seq = 0
        self._n_ticks = 0
        self._rig: SimRig | None = None
        self._pacer: _ServePacer | None = None
        self._applied_seq = 0
        self._late_flag = False
        self._missing_streak = 0
        self._watchdog = False
        self._end: tuple[int, str] | None = None
        self._resend_at: float | None = None  # when the latest sample is repeated (set by its first wait)
        self._refused_seq: int | None = None  # the latest sample's seq once an answer to it was refused
        link = getattr(self, "link", None)
        self._serial_at_start = replace(link.counts) if isinstance(link, SerialLink) else None

    def _new_session(self) -> None:
        """A new session id (the previous session's late datagrams are dropped), counts and clients reset."""
        if self._sessions:
            self.session = (self.session + 1) & 0xFFFFFFFF or 1
        self._sessions += 1
        self._reset_session()

    def _config(self, role: int) -> p.Config:
        s = self.settings
        return p.Config.from_parameters(
            s.params, role=role, mode=s.mode, watchdog_periods=s.watchdog_periods, rig=s.rig_name
        )

    def _send(self, msg: p.Message, addr: Hashable) -> None:
        self.link.send(p.encode(msg, self.session), addr)

    def serve(self, settings: SessionSettings | None = None) -> SessionResult:
        """Wait for a controlling client, run one session, send STOP; the result of the session.
        ``settings``: this session's and the next ones' (a served job's runs each have their own start,
        seed, parameters and duration); default the server's."""
        if settings is not None:
            self.settings = settings
        s = self.settings
        warm(s.params, plant=s.plant, ideal_sensors=s.ideal_sensors)  # before the clock: no tick stalls
        self._new_session()
        self._await_controller()
        rig = make_rig(s.params, plant=s.plant, ideal_sensors=s.ideal_sensors, seed=s.seed, noise=s.noise)
        rig.reset(s.x0_m, s.theta0_rad)
        self._rig = rig
        adapter = _WireController(self, rig.period_s)
        # The budget is this server's own (lock-step timeout, real-time boundary): no engine watchdog.
        loop = ClosedLoop(rig, adapter, controller_timeout_s=math.inf)
        self._n_ticks = update_ticks(s.duration_s, rig.params)
        pacer = self._pacer = _ServePacer(rig.period_s) if s.mode == p.MODE_REALTIME else None
        reason, detail = p.STOP_DONE, ""
        try:
            try:
                if loop.run(self._n_ticks, pacer=pacer, stop_when_lost=s.stop_when_lost) == ENDED_BALL_LOST:
                    reason = p.STOP_BALL_LOST
            except ControllerError:
                if self._end is None:
                    raise
                reason, detail = self._end
        except KeyboardInterrupt:
            self.stop_clients(p.STOP_SHUTDOWN)
            raise
        self.stop_clients(reason)
        if not loop.started:  # nothing was logged: no session to report
            raise ServeError(f"the session ended before the client acknowledged the held sample: {detail}")
        result = loop.result(x0_m=s.x0_m)
        timing = pacer.timing() if pacer is not None else None
        serial = self._serial_counts()
        return SessionResult(result, reason, detail, self.counts, self.client_name, timing, serial)

    def _serial_counts(self) -> SerialCounts | None:
        """A serial line's reader counts since this session began (``None`` on UDP)."""
        if not isinstance(self.link, SerialLink) or self._serial_at_start is None:
            return None
        now, then = asdict(self.link.counts), asdict(self._serial_at_start)
        return SerialCounts(**{name: now[name] - then[name] for name in now})

    # --- a session another loop drives (the live view: twin.viewer.wire) ----------------------------
    def open_session(self, rig: SimRig) -> None:
        """Begin a session on ``rig`` (already reset) that the caller's loop runs: a new session id, as
        ``serve`` begins one (the previous session's late datagrams are dropped), counts and clients reset.
        The loop then calls ``receive`` until a controller has said HELLO (``controller_addr``) and, per
        tick, ``send_sample``, ``await_command`` to its own deadline, then ``accept`` or ``missed``."""
        self._new_session()
        self._rig = rig

    @property
    def observer_silence_s(self) -> float:
        """How long an observer may be silent (no keep-alive HELLO) before its place is freed."""
        return max(self.settings.timeout_s, MIN_OBSERVER_SILENCE_S)

    def forget_vanished_observers(self) -> None:
        """Free the places of observers that went: the transport reported their port unreachable (a closed
        socket, a dead process), or they have been silent for ``observer_silence_s``."""
        # Drained on every call: the queued errors are charged to the socket's receive buffer.
        gone = set(self.link.unreachable()) if isinstance(self.link, UdpLink) else set()
        if not self.observers:
            return
        oldest = time.monotonic() - self.observer_silence_s
        for addr in list(self.observers):
            if self._reply.get(addr, addr) in gone or self._heard.get(addr, math.inf) < oldest:
                self.observers.remove(addr)
                self._heard.pop(addr, None)
                self._reply.pop(addr, None)
                self.counts.observers_gone += 1

    @property
    def watchdog(self) -> bool:
        """Whether the watchdog holds the output at the zero command now (commands stopped)."""
        return self._watchdog

    def _peers(self) -> list[Hashable]:
        """Where this session's samples and STOP go: the controller (once it said HELLO), the observers (each
        at its HELLO's address, or that host's reply port if its HELLO named one)."""
        admitted = ([self.controller_addr] if self.controller_addr else []) + self.observers
        return [self._reply.get(addr, addr) for addr in admitted]

    def stop_clients(self, reason: int) -> None:
        """STOP ``reason`` to the controller and the observers of this session."""
        for addr in self._peers():
            self._send(p.Stop(reason), addr)

    def _await_controller(self) -> None:
        wait_s = self.settings.wait_client_s
        deadline = math.inf if wait_s is None else time.monotonic() + wait_s
        while self.controller_addr is None:
            left = deadline - time.monotonic()
            if left <= 0:
                raise ServeError(
                    f"no controlling client said HELLO to {self.url} within {wait_s:g} s (--wait-client)"
                )
            self.receive(min(left, 0.5))

    # --- receiving ----------------------------------------------------------------------------------
    def receive(self, wait_s: float) -> p.Command | p.Stop | None:
        """Handle one datagram (waiting at most ``wait_s``): HELLOs answered, refusals counted; the
        controller's valid COMMAND for the latest sample or its STOP returned, else ``None``."""
        got = self.link.recv(wait_s)
        if got is None:
            return None
        data, addr = got
        c = self.counts
        c.frames += 1
        if addr in self._heard:
            self._heard[addr] = time.monotonic()  # any datagram: the observer is there
        try:
            frame = p.decode_frame(data)
        except p.ProtocolError:
            c.malformed += 1
            return None
        msg = frame.msg
        if isinstance(msg, p.Hello):
            self._hello(msg, addr)
            return None
        if frame.session != self.session:
            c.wrong_session += 1
            return None
        if addr != self.controller_addr:
            if isinstance(msg, p.Command):
                c.unauthorised_commands += 1
            else:
                c.unexpected += 1
            return None
        if isinstance(msg, p.Stop):
            return msg
        if not isinstance(msg, p.Command):
            c.unexpected += 1
            return None
        if msg.seq != self._seq:
            if msg.seq < self._seq and self.settings.mode == p.MODE_REALTIME:
                c.late_commands += 1  # the answer to an earlier sample, after its boundary
            else:
                c.stale_commands += 1
            return None
        daq = self.settings.params.daq
        if not (math.isfinite(msg.dac_v) and daq.dac_min_v <= msg.dac_v <= daq.dac_max_v):
            c.refused_commands += 1  # not an answer: the DAC keeps its last value, the wait goes on
            self._refused_seq = msg.seq  # the sample's 0.2 s repeats tell the client (the refused flag)
            return None
        return msg

    def _hello(self, msg: p.Hello, addr: Hashable) -> None:
        c = self.counts
        if msg.role == p.ROLE_OBSERVE and addr not in self.observers:
            self.forget_vanished_observers()  # a place a vanished observer held is free for this one
        if addr == self.controller_addr:  # a repeated HELLO: our CONFIG was lost (the first reply port stays)
            self._send(self._config(p.ROLE_CONTROL), self._reply[addr])
        elif addr in self.observers:
            self._send(self._config(p.ROLE_OBSERVE), self._reply[addr])
        elif msg.role == p.ROLE_CONTROL and self.controller_addr is None:
            self.controller_addr, self.client_name = addr, p.printable(msg.client)  # printed: escaped
            self._reply[addr] = _reply_to(addr, msg.reply_port)
            self._send(self._config(p.ROLE_CONTROL), self._reply[addr])
        elif msg.role == p.ROLE_OBSERVE and len(self.observers) < MAX_OBSERVERS:
            self.observers.append(addr)
            self._heard[addr] = time.monotonic()
            self._reply[addr] = _reply_to(addr, msg.reply_port)
            c.observers += 1
            self._send(self._config(p.ROLE_OBSERVE), self._reply[addr])
        else:
            c.refused_clients += 1
            self._send(self._config(p.ROLE_REFUSED), _reply_to(addr, msg.reply_port))

    # --- one block out, one command back ------------------------------------------------------------
    # The pieces of one tick's exchange (``send_sample``, ``await_command``, ``accept``, ``missed``) are
    # public: ``serve`` runs them in ``_exchange`` to its own deadlines, the live view (``twin.viewer.wire``)
    # to the boundaries of its frames.
    def _exchange(self, sample: DaqSample, *, start: bool) -> float:
        rig = self._rig
        assert rig is not None
        s = self.settings
        seq = 0 if start else self._seq + 1
        last = not start and (seq == self._n_ticks or (s.stop_when_lost and rig.ball_lost))
        out = self.send_sample(sample, start=start, last=last)
        realtime = s.mode == p.MODE_REALTIME and not start and self._pacer is not None
        if realtime and last:
            return rig.command_v  # real time: the last sample is not answered (docs/protocol.md)
        deadline = time.monotonic() + s.timeout_s
        if realtime:
            assert self._pacer is not None
            deadline = self._pacer.next_boundary() - _RT_MARGIN_S
        clock = time.perf_counter if realtime else time.monotonic
        got = self.await_command(out, deadline, resend=not realtime, clock=clock)
        if isinstance(got, p.Stop):
            self._end = (p.STOP_CLIENT_QUIT, f"the client sent STOP {got.reason}")
            raise _SessionOver(self._end[1])
        if isinstance(got, p.Command):
            return self.accept(got)
        if not realtime:
            self._end = (p.STOP_ERROR, f"no COMMAND {seq} within {s.timeout_s:g} s (--timeout)")
            raise _SessionOver(self._end[1])
        return self.missed(rig.command_v)

    def send_sample(self, sample: DaqSample, *, start: bool, last: bool) -> p.Sample:
        """``sample`` as SAMPLE to the controller and the observers: seq 0 for the held block that ``start``
        reads, else the next; the flags from the rig and the session (``last``: the session ends after it)."""
        rig = self._rig
        assert rig is not None
        seq = 0 if start else self._seq + 1
        self._seq = seq
        flags = p.FLAG_HELD if (start or rig.held) else 0
        flags |= p.FLAG_BALL_LOST if rig.ball_lost else 0
        flags |= p.FLAG_WATCHDOG if self._watchdog else 0
        flags |= p.FLAG_LATE if self._late_flag else 0
        flags |= p.FLAG_LAST if last else 0
        if self._watchdog:
            self.counts.watchdog_ticks += 1
        out = p.Sample(seq, sample.time_s, sample.ball_v, sample.angle_v, flags, self._applied_seq)
        self.forget_vanished_observers()
        for addr in self._peers():
            self._send(out, addr)
        self._resend_at = None
        self._refused_seq = None
        return out

    def await_command(
        self,
        out: p.Sample,
        deadline: float,
        *,
        resend: bool,
        clock: Callable[[], float] = time.monotonic,
    ) -> p.Command | p.Stop | None:
        """Handle datagrams until ``deadline`` (on ``clock``): the controller's valid COMMAND answering ``out``
        (the latest sample) or its STOP, else ``None``. With ``resend`` (lock-step, a held sample), ``out``
        is repeated every 0.2 s meanwhile, with the refused flag once a COMMAND answering it was refused (the
        client learns it from the next repeat, not the timeout); a caller may wait for one sample in several
        calls."""
        if self._resend_at is None:
            self._resend_at = clock() + _RESEND_S
        while True:
            now = clock()
            left = deadline - now
            if left <= 0:
                return None
            if resend and now >= self._resend_at and self.controller_addr is not None:
                # the sample or its answer may have been lost, or its answer refused (then flagged so)
                refused = self._refused_seq == out.seq
                again = replace(out, flags=out.flags | p.FLAG_REFUSED) if refused else out
                self._send(again, self._reply[self.controller_addr])
                self.counts.resent_samples += 1
                self._resend_at = now + _RESEND_S
            got = self.receive(min(left, max(self._resend_at - now, 1e-4)) if resend else left)
            if got is not None:
                return got

    def accept(self, cmd: p.Command) -> float:
        """The controller's COMMAND answered in time: the DAC takes its volts, the watchdog is reset, and the
        observers get it (docs/protocol.md, COMMAND: the echo), so that they know the rig's input."""
        self._late_flag = False
        self._missing_streak = 0
        self._watchdog = False
        self._applied_seq = cmd.seq
        for addr in self.observers:  # usually none: the tick pays nothing
            self._send(cmd, addr)
        return cmd.dac_v

    def missed(self, hold_v: float) -> float:
        """Real time: the period ended without its command. The DAC holds ``hold_v`` (its value); after
        ``watchdog_periods`` such periods in a row the output is the zero command (the watchdog)."""
        s = self.settings
        self.counts.missing_commands += 1
        self._late_flag = True
        self._missing_streak += 1
        if self._missing_streak >= s.watchdog_periods:
            if not self._watchdog:
                self.counts.watchdog_trips += 1
            self._watchdog = True
            return s.params.amplifier.zero_command_v
        return hold_v
