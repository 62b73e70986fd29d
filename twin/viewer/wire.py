"""The wire client as a controller of the live view (``ballbeam view --serve``): a program in any language
speaking protocol 1 (docs/protocol.md) over UDP drives the view's twin in real time.

``WireCatalogue`` puts one entry before the catalogue the application hands in; building it gives a
``WireClient``, the engine's ``Controller`` for the client at the other end of the shared
``twin.serving.server.Server``. Every datagram goes through the server's own code (``receive``: HELLOs, refusals,
counts; ``send_sample``, ``await_command``, ``accept``, ``missed``: the exchange and the watchdog), nothing
is re-implemented here. Each run of the view is one session:

* **waiting**: no controller has said HELLO. The rig stays held at its initial state (as the real rig holds
  the ball until the controller starts) and time does not advance.
* **held**: HELLO answered with CONFIG, the held block sent as SAMPLE 0 and repeated every 0.2 s until its
  COMMAND acknowledges it; no acknowledgement within the server's ``timeout_s`` ends the session (STOP 3) and
  a new one waits on the same held rig, as does a client's STOP before release. The run is released only when
  the view runs too (a browser came, the run is not paused): until then the held sample goes on being repeated
  and the client's answers to it show it is still there; one that stops answering for ``timeout_s`` loses the
  session (STOP 3) before it began, and a new one waits. A session therefore never starts without its client.
* **running**: the release; every view tick sends SAMPLE k and awaits COMMAND k (below). A client that sends
  no valid command for ``timeout_s`` has gone: its session ends (STOP 3) and a new run waits, held, for the
  next client (``on_vacant``), so that a vanished client does not keep the view's one session.
* **quit**: the client sent STOP: the run goes on without it, the DAC holding and then the watchdog, for
  ``timeout_s`` after its last command; then a new run waits for the next client (``on_vacant``).
* **ended**: the view ended the session (a new run: STOP 0; ball lost: STOP 2; a failed run: STOP 3;
  shutdown: STOP 4). The link is left alone until the next run's session begins.

The waiting scheme: the view's loop publishes its frame first and runs the wire tick last, with the frame's
end as the deadline (``Viewer.loop``). SAMPLE k goes out and COMMAND k is awaited on the socket until that
boundary, so the loop's idle time is spent receiving: a quick client's command is applied at the next tick,
as ``ballbeam serve --mode realtime`` applies it at the next period boundary, and a stalled client costs the
frame its idle time, never more — the view keeps its 50 Hz, the period counts missing, the DAC holds and after
``watchdog_periods`` the output goes to the zero command.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from typing import Any, Literal

from twin.engine import Catalogue, CatalogueEntry, StateLaw
from twin.firmware import Firmware
from twin.interface import Controller, DaqSample
from twin.parameters import Parameters
from twin.rigs.sim import SimRig
from twin.serving.server import STOP_NAMES, Server
from twin.viewer.common import _log, _markdown_text, _printable
from twin.wire import protocol as p

WIRE_MARGIN_S = 0.0005  # stop waiting this long before the frame's end: the loop's own work after the wait
MAX_DISCARD = 4096  # datagrams queued before a session began that are thrown away (bounded: a flood)
Phase = Literal["waiting", "held", "running", "quit", "ended"]
OnVacant = Callable[[], None]  # the view's "start a new run" (its Reset), for a session whose client went


def _address(addr: object) -> str:
    """A UDP peer as ``host:port``."""
    if isinstance(addr, tuple) and len(addr) >= 2:
        return f"{addr[0]}:{addr[1]}"
    return str(addr)


class WireClient(Controller):
    """The client of the served session as the view's controller. The view calls ``begin`` with the run's
    rig, then each frame either ``service`` (not released: the handshake and the held sample) or the engine's
    tick with ``deadline`` set (released: ``update`` exchanges one sample), and ``end`` when the run ends."""

    def __init__(self, server: Server, name: str, period_s: float, on_vacant: OnVacant | None = None) -> None:
        super().__init__()
        self.server = server
        self.name = name
        self.period_s = period_s
        self.on_vacant = on_vacant
        self.rig: SimRig | None = None
        self.phase: Phase = "waiting"
        self.deadline = -math.inf  # the end of the current frame (time.perf_counter), set before each tick
        self.note = ""  # why the last session of this run ended, for the status
        self._held: DaqSample | None = None
        self._held_out: p.Sample | None = None
        self._held_since = 0.0
        # The client's latest answer (time.perf_counter; None: none yet in this session).
        self._answered_at: float | None = None
        self.exchanged = 0  # samples sent after the held one

    @property
    def released(self) -> bool:
        """Whether the run goes: the client acknowledged the held sample (and may since have quit)."""
        return self.phase in ("running", "quit")

    # --- the session ----------------------------------------------------------------------------------
    def begin(self, rig: SimRig) -> None:
        """The run's first session, on ``rig`` (reset, held)."""
        self.rig = rig
        self._open()

    def _open(self) -> None:
        assert self.rig is not None
        # Datagrams queued while no session listened (another controller ran, the last run was paused)
        # belong to no session of this run: a client still there repeats its HELLO within 0.2 s.
        for _ in range(MAX_DISCARD):
            if self.server.link.recv(0.0) is None:
                break
        self.server.open_session(self.rig)
        self.phase = "waiting"
        self._held_out = None
        self._answered_at = None

    def _restart(self, note: str, stop: int | None) -> None:
        """End a session before release (``stop`` sent, unless the client ended it) and wait for the next."""
        if stop is not None:
            self.server.stop_clients(stop)
        self.note = note
        self._open()

    def end(self, reason: int, note: str = "") -> None:
        """End this run's session: STOP ``reason`` to the client and the observers (once)."""
        if self.phase == "ended":
            return
        self.server.stop_clients(reason)
        self.phase = "ended"
        self.note = note or f"session ended (STOP {reason}, {STOP_NAMES.get(reason, '?')})"

    # --- the engine's calls ---------------------------------------------------------------------------
    def start(self, sample: DaqSample) -> None:
        self._held = sample  # the held block, sent as SAMPLE 0 when a client says HELLO

    def update(self, sample: DaqSample) -> float:
        server, rig = self.server, self.rig
        assert rig is not None
        # The view pauses on a lost ball: its sample is the session's last, unanswered in real time.
        last = rig.ball_lost
        self.exchanged += 1
        out = server.send_sample(sample, start=False, last=last)
        if last:
            return rig.command_v
        while True:
            got = server.await_command(out, self.deadline, resend=False, clock=time.perf_counter)
            if got is None:
                self._check_silence()
                return server.missed(rig.command_v)
            if self.phase == "running" and isinstance(got, p.Command):
                self._answered_at = time.perf_counter()
                return server.accept(got)
            if self.phase == "running" and isinstance(got, p.Stop):
                self.phase = "quit"
                self.note = (
                    f"the client quit (STOP {got.reason}): the run goes on under the watchdog; Reset, or "
                    f"{server.settings.timeout_s:g} s (the wire wait), starts a new session"
                )
            # quit: the frame's datagrams are still handled (counted, HELLOs refused) until its end

    def _check_silence(self) -> None:
        """Running: a client without a valid command for ``timeout_s`` has gone (its socket closed, its process
        died, it stopped answering), and one that quit (STOP) is gone. Its session ends (STOP 3 to the former)
        and the view is asked for a new run, whose session the next client may take."""
        wait_s = self.server.settings.timeout_s
        if self.phase not in ("running", "quit") or self._answered_at is None:
            return
        if time.perf_counter() - self._answered_at < wait_s:
            return
        if self.phase == "running":
            self.end(
                p.STOP_ERROR, f"no COMMAND in time from the client for {wait_s:g} s (the wire wait): STOP 3"
            )
        else:  # it sent STOP: its session is over; the run went on under the watchdog for the wait
            self.phase = "ended"
        if self.on_vacant is not None:
            _log(f"{self.note}; a new run waits for a client", key="wire vacant")
            self.on_vacant()

    # --- the view's frame while not released, or paused -------------------------------------------
    def service(self, deadline: float, *, release: bool = True) -> None:
        """Handle the link until ``deadline`` (time.perf_counter): HELLOs answered (``receive``), then the
        held sample sent and its acknowledgement awaited; once released (a paused run), datagrams counted.
        ``release``: whether the run may start now (the view runs); if not, an acknowledged held sample goes on
        being repeated, and answered, until it may, and the run is released on an answer that comes once it may
        (within a repeat, 0.2 s): never on an old one, from a client that may have gone since."""
        server = self.server
        if self.phase == "ended":
            return
        wait_s = server.settings.timeout_s
        while True:
            now = time.perf_counter()
            if self.phase == "waiting" and server.controller_addr is not None:
                assert self._held is not None
                self._held_out = server.send_sample(self._held, start=True, last=False)
                self._held_since = now
                self.phase = "held"
            if now >= deadline:
                return
            if self.phase == "held":
                assert self._held_out is not None
                give_up = (self._held_since if self._answered_at is None else self._answered_at) + wait_s
                if now >= give_up:
                    what = "acknowledge" if self._answered_at is None else "answer the repeats of"
                    self._restart(
                        f"the client did not {what} the held sample within {wait_s:g} s (the wire wait): "
                        "STOP 3",
                        p.STOP_ERROR,
                    )
                    continue
                got = server.await_command(
                    self._held_out, min(deadline, give_up), resend=True, clock=time.perf_counter
                )
                if isinstance(got, p.Command):
                    if self._answered_at is None:
                        server.accept(got)  # the acknowledgement, echoed once to the observers
                    self._answered_at = time.perf_counter()  # its wait for commands starts again
                    if release:  # an answer while the view runs: the client is there, released next tick
                        self.phase = "running"
                        self.note = ""
                        return
                if isinstance(got, p.Stop):
                    self._restart(f"the client quit before release (STOP {got.reason})", None)
                continue
            if self.phase == "running":
                self._answered_at = now  # paused: nothing is asked of the client, its wait starts again
            got = server.receive(deadline - now)
            if isinstance(got, p.Command):
                server.counts.late_commands += 1  # answers a sample whose tick has passed (a paused run)
            elif isinstance(got, p.Stop) and self.phase == "running":
                self.phase = "quit"
                self.note = (
                    f"the client quit (STOP {got.reason}); Reset, or {server.settings.timeout_s:g} s of the run "
                    "(the wire wait), starts a new session"
                )

    # --- the status -----------------------------------------------------------------------------------
    def status_markdown(self) -> str:
        """The session for the status panel: where, which session, who, and the session's counts."""
        s = self.server
        c = s.counts
        url = _markdown_text(s.url)
        head = f"wire {url} · session {s.session:#010x} · "
        if self.phase == "waiting":
            head += f"**waiting for a client on {url}** (the ball is held until one says HELLO)"
        else:
            client = f"**{_markdown_text(_printable(s.client_name, 40) or '(no name)')}**"
            where = _markdown_text(_address(s.controller_addr)) if s.controller_addr is not None else "?"
            state = {
                "held": "connected, held: awaiting its acknowledgement of the held sample"
                if self._answered_at is None
                else "connected and acknowledged, held until the run starts (a browser, Run)",
                "running": "connected",
                "quit": "the client quit",
                "ended": "session ended",
            }[self.phase]
            if self.phase == "running" and self.exchanged == 0:
                state = "connected, held until the run starts"
            head += f"client {client} at {where} · {state}" if s.controller_addr is not None else state
        refused = (
            c.wrong_session + c.stale_commands + c.unauthorised_commands + c.refused_commands + c.unexpected
        )
        counts = (
            f"late {c.late_commands} · missing {c.missing_commands} · watchdog trips {c.watchdog_trips}"
            f"{' (output at zero now)' if s.watchdog else ''} · malformed {c.malformed} · refused {refused} · "
            f"observers {len(s.observers)} · clients refused {c.refused_clients}"
        )
        note = f"  \n*{_markdown_text(self.note)}*" if self.note else ""
        return f"{head}  \n{counts}{note}"


class WireCatalogue:
    """``inner``'s controllers with the wire client of ``server`` first (``name``, e.g. "wire client
    (udp://127.0.0.1:5750)"): a ``twin.engine.Catalogue`` for the view."""

    def __init__(self, inner: Catalogue, server: Server, on_vacant: OnVacant | None = None) -> None:
        self.inner = inner
        self.server = server
        self.on_vacant = on_vacant  # handed to each wire client: the view's new run when a client went
        self.name = f"wire client ({server.url})"
        self.NAMES = (self.name, *inner.NAMES)
        self._entry = CatalogueEntry(
            name=self.name,
            build=lambda params: self.make(self.name, params),
            description=f"a controller in any language on protocol 1 at {server.url} (docs/protocol.md)",
            simulation_only=False,
            batched=False,
            setpoint=False,  # protocol 1 carries no setpoint: the client's is its own business
        )

    # The inner entries and the wire's, built when first read (a registry designs a controller for its
    # entries: the view reads them, a parser must not).
    ENTRIES: Mapping[str, CatalogueEntry]

    def __getattr__(self, name: str) -> Any:
        if name != "ENTRIES":
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        self.ENTRIES = {self.name: self._entry, **self.inner.ENTRIES}
        return self.ENTRIES

    def _vacant(self) -> None:
        if self.on_vacant is not None:  # set once the view exists (after its first run was built)
            self.on_vacant()

    def make(self, name: str, params: Parameters | None = None) -> Controller | StateLaw | Firmware:
        if name == self.name:
            period_s = (params or self.server.settings.params).period_s
            return WireClient(self.server, self.name, period_s, self._vacant)
        return self.inner.make(name, params)
