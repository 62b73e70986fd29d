"""``RemoteRig``: a ``Rig`` over protocol 1 (docs/protocol.md) on UDP or a serial line (``twin.wire.links``) —
the served twin or any rig whose firmware speaks it. A controller runs on it in the one closed loop
(``twin.engine.run_on_rig``), with the log the rig software keeps.

The handshake repeats HELLO until CONFIG comes (bounded: ``connect_timeout_s``); ``read`` waits for the
next SAMPLE at most ``timeout_s`` of silence (no frame of the session at all), and at most ``timeout_s`` for
a sample that the server repeats without moving on (our answers do not reach it). A held sample repeated
after we answered it is a session that has not started yet (a live view waiting for its browser): that is
waited for ``start_wait_s`` (``None``: as long as the server keeps repeating it). Each ``RemoteError`` names
what was waited for, from whom, for how long, and the option that sets the wait; never a hang. A sample
that has not been answered when the next is read (the held block that ``start`` reads) is acknowledged
with the command the DAC holds, as the protocol's session requires.

The server is a boundary, as a file is: what it sends is checked on arrival, and what is wrong with it is a
``RemoteError`` naming the rig, the message, the field and its value (the rig's fault, not the controller's):

* CONFIG: every field in its documented range (``twin.wire.protocol`` decodes it so), the role the one asked
  for. A CONFIG refused for a field ends the handshake at once; CONFIG frames refused otherwise (a CRC that
  does not match) are counted, and a handshake that gets no acceptable one says how many came.
* SAMPLE: a finite ``time_s`` on the session's grid (``check_time``), ball and angle volts finite and within the
  ADC's range (the client's ``daq.adc_min_v`` … ``daq.adc_max_v``: CONFIG does not carry it). A bad sample is
  answered with STOP 3 (error), so that the rig does not wait for a command that will not come.
* Missing sequence numbers are counted (``sequence_gaps``).
"""

from __future__ import annotations

import math
import time
from typing import Any
from urllib.parse import urlsplit

from twin.interface import DaqSample, Rig, RigEnded, RigError
from twin.parameters import Daq, Parameters, SoftwareCalibration
from twin.wire import protocol as p
from twin.wire.links import Link, LinkError, OverLink, UdpLink, open_link, parse_url

__all__ = [
    "HELLO_INTERVAL_S",
    "LATE_PERIODS",
    "TIME_TOLERANCE_PERIODS",
    "RemoteError",
    "RemoteRig",
    "Refused",
    "SessionEnded",
    "open_remote",
    "parse_udp_url",
]

HELLO_INTERVAL_S = 0.2  # the doc's HELLO repetition (a client's and an observer's)
# SAMPLE k's time_s is due at t0 + (k - k0)·period_s, (k0, t0) the session's first sample. It may come this
# fraction of a period off that grid either way (a rig's clock rounding; the twin's is exact) ...
TIME_TOLERANCE_PERIODS = 0.01
# ... and, in real time (CONFIG mode 2), up to this many periods late (a timer that fired late: the blocks
# keep their seq, a later one is back on the grid). Never earlier, never backwards.
LATE_PERIODS = 25
_ROLES = {p.ROLE_REFUSED: "refused", p.ROLE_CONTROL: "control", p.ROLE_OBSERVE: "observe"}


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
        start_wait_s: float | None = None,
        adc_range_v: tuple[float, float] | None = None,
        wait_names: tuple[str, str] = ("timeout_s", "start_wait_s"),
    ) -> None:
        """``adc_range_v``: the card's analog input range, which SAMPLE volts must lie in (default the
        thesis's card, ``twin.parameters.Daq``'s; ``run --rig`` gives its parameters'). ``wait_names``: what
        the messages call ``timeout_s`` and ``start_wait_s`` (``run --rig``: its options)."""
        self.timeout_s = timeout_s
        self.start_wait_s = start_wait_s
        self.wait_names = wait_names
        daq = Daq()
        self.adc_range_v = adc_range_v if adc_range_v is not None else (daq.adc_min_v, daq.adc_max_v)
        if link is None:
            try:
                link = UdpLink.connect(host, port)
            except LinkError as exc:
                raise RemoteError(str(exc)) from None
        self.link: Link = link
        self.url = link.url
        self.counts_malformed = 0
        self.configs_received = 0  # CONFIG frames (valid or not) that came during the handshake
        self.configs_refused = 0  # ... of which this client refused
        self.sequence_gaps = 0  # seq numbers that never arrived (a lost block)
        self._config_problem = ""  # why the latest CONFIG was refused
        self._config_field_error = False  # ... and whether for a field (an intact frame)
        self._first: p.Sample | None = None  # the session's first sample: the anchor of the time grid
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
        data = got[0]
        try:
            return p.decode_frame(data)
        except p.ProtocolError as exc:
            self.counts_malformed += 1
            if len(data) > 5 and data[:4] == p.MAGIC and data[5] == p.TYPE_CONFIG:
                self.configs_received += 1
                self.configs_refused += 1
                self._config_problem = str(exc)
                # intact (its CRC matched) but a field out of its range: the rig's fault, not the line's
                self._config_field_error = isinstance(exc, p.FieldError)
        return None

    def _config_counts(self) -> str:
        return f"{self.configs_received} CONFIG received, {self.configs_refused} refused"

    def _handshake(self, role: int, client: str, timeout_s: float) -> tuple[p.Config, int]:
        deadline = time.monotonic() + timeout_s
        next_hello = 0.0
        while (now := time.monotonic()) < deadline:
            if now >= next_hello:
                self._send(p.Hello(role=role, client=client), 0)
                next_hello = now + HELLO_INTERVAL_S
            frame = self._recv(min(next_hello, deadline) - time.monotonic())
            if self._config_field_error:
                raise RemoteError(
                    f"{self.url} sent a CONFIG this client refuses: {self._config_problem} — the rig's fault "
                    f"({self._config_counts()})"
                )
            if frame is not None and isinstance(frame.msg, p.Config):
                self.configs_received += 1
                granted = frame.msg.role
                if granted == p.ROLE_REFUSED:
                    raise Refused(f"{self.url} refused this client (another client controls the rig)")
                if granted != role:
                    self.configs_refused += 1
                    raise RemoteError(
                        f"{self.url} granted the role {granted} ({_ROLES.get(granted)}) to a HELLO asking for "
                        f"{role} ({_ROLES.get(role, '?')}): CONFIG role = {granted} — the rig's fault "
                        f"({self._config_counts()})"
                    )
                return frame.msg, frame.session
        if self.configs_received:
            raise RemoteError(
                f"no acceptable CONFIG from {self.url} within {timeout_s:g} s: {self._config_counts()} "
                f"(the latest: {self._config_problem}) — the rig's fault"
            )
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
        start = time.monotonic()
        # Moved on only by a repeat of the sample we answered (the server is there, and says where it is,
        # bounded by ``_check_repeats``); any other frame, valid or not, does not prolong the wait.
        silence_until = start + self.timeout_s
        after = -1 if self.last is None else self.last.seq
        repeats = 0
        while True:
            now = time.monotonic()
            if now >= silence_until:
                raise RemoteError(self._silence(after, now - start))
            frame = self._recv(silence_until - now)
            if frame is None or frame.session != self.session:
                continue
            msg = frame.msg
            if isinstance(msg, p.Stop):
                raise SessionEnded(f"{self.url} ended the session (STOP {msg.reason})", msg.reason)
            if isinstance(msg, p.Sample) and msg.seq == after and self._answered and self.last is not None:
                if msg.flags & p.FLAG_REFUSED and self.config.role == p.ROLE_CONTROL:
                    self.stop()  # the session ends here: the rig does not wait out its timeout for us
                    raise RemoteError(f"{self.url} refused COMMAND {after} (dac_v = {self.command_v!r} V)")
                repeats += 1
                self._check_repeats(msg, repeats, time.monotonic() - start)
                silence_until = time.monotonic() + self.timeout_s
                if self.config.role == p.ROLE_CONTROL:  # a repeated sample: our answer was lost, repeat it
                    self._send(p.Command(seq=after, dac_v=self.command_v), self.session)
                continue
            if isinstance(msg, p.Sample) and msg.seq > after:
                self._check_sample(msg)
                self.sequence_gaps += msg.seq - after - 1
                if self._first is None:
                    self._first = msg
                self.last = msg
                self._answered = self.config.role != p.ROLE_CONTROL
                return DaqSample(time_s=msg.time_s, ball_v=msg.ball_v, angle_v=msg.angle_v)

    def _silence(self, after: int, waited_s: float) -> str:
        """The message of a server from which nothing came for ``timeout_s``."""
        what = "SAMPLE 0" if after < 0 else f"SAMPLE {after + 1}"
        return (
            f"no {what} from {self.url} for {waited_s:.1f} s ({self.wait_names[0]} {self.timeout_s:g} s): "
            "the server is gone, the link is down, or what it sent was not the session's next sample"
        )

    def _check_repeats(self, msg: p.Sample, repeats: int, waited_s: float) -> None:
        """A sample we answered, repeated ``repeats`` times over ``waited_s``: the held one is a session that
        has not started (waited ``start_wait_s``); another, answers that do not reach the server
        (``timeout_s``). A ``RemoteError`` (STOP 1 sent) once the wait is over."""
        held = bool(msg.flags & p.FLAG_HELD) and msg.seq == 0
        limit, name = (
            (self.start_wait_s, self.wait_names[1]) if held else (self.timeout_s, self.wait_names[0])
        )
        if limit is None or waited_s < limit:
            return
        self.stop()
        if held:
            raise RemoteError(
                f"the session at {self.url} did not start within {waited_s:.1f} s ({name} {limit:g} s): the "
                f"server held the rig, repeating SAMPLE 0 {repeats} times after our acknowledgement (a live "
                "view waits for its browser, or for Run); sent STOP 1"
            )
        raise RemoteError(
            f"no SAMPLE {msg.seq + 1} from {self.url} for {waited_s:.1f} s ({name} {limit:g} s): the server "
            f"repeated SAMPLE {msg.seq} {repeats} times — our COMMANDs do not reach it; sent STOP 1"
        )

    # --- the checks on arrival ------------------------------------------------------------------------
    def _check_sample(self, msg: p.Sample) -> None:
        """``msg`` (the next SAMPLE) as the protocol says, else STOP 3 and a ``RemoteError`` naming it."""
        lo, hi = self.adc_range_v
        problem = ""
        for name, value in (("ball_v", msg.ball_v), ("angle_v", msg.angle_v)):
            if not math.isfinite(value):
                problem = f"{name} = {value!r} V: not a finite number"
            elif not lo <= value <= hi:
                problem = f"{name} = {value!r} V: outside the ADC's range {lo!r} … {hi!r} V"
            if problem:
                break
        problem = self.check_time(msg) or problem
        if problem:
            self.stop(p.STOP_ERROR)  # the rig is not left waiting for the command of a sample we refuse
            kept = "nothing logged" if self.last is None else f"the log up to SAMPLE {self.last.seq} is kept"
            raise RemoteError(f"{self.url} sent SAMPLE {msg.seq} with {problem} — the rig's fault ({kept})")

    def check_time(self, msg: p.Sample) -> str:
        """What is wrong with SAMPLE ``msg``'s ``time_s`` ('' nothing): not finite; not after the previous
        sample's; off the session's grid t0 + (k − k0)·period_s (the first sample's k0, t0) by more than
        ``TIME_TOLERANCE_PERIODS`` of a period early, or late by more than that in lock-step and more than
        ``LATE_PERIODS`` periods in real time."""
        t = msg.time_s
        if not math.isfinite(t):
            return f"time_s = {t!r} s: not a finite number"
        prev, first = self.last, self._first
        if prev is None or first is None:
            return ""
        if not t > prev.time_s:
            return f"time_s = {t!r} s: not after SAMPLE {prev.seq}'s {prev.time_s!r} s (time runs backwards)"
        period = self.config.period_s
        due = first.time_s + (msg.seq - first.seq) * period
        tol = TIME_TOLERANCE_PERIODS * period
        late = LATE_PERIODS * period if self.config.mode == p.MODE_REALTIME else 0.0
        if t < due - tol:
            return (
                f"time_s = {t!r} s: earlier than its due time {due!r} s (SAMPLE {first.seq} + whole periods)"
            )
        if t > due + late + tol:
            allowed = f"{LATE_PERIODS} periods" if late else "none in lock-step"
            return (
                f"time_s = {t!r} s: {(t - due) / period:.6g} periods after its due time {due!r} s "
                f"(SAMPLE {first.seq} + whole periods; late allowed: {allowed})"
            )
        return ""

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
