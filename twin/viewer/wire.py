"""The wire client as a controller of the live view (``ballbeam view --serve``): a program in any language
speaking protocol 1 (docs/protocol.md) over UDP drives the view's twin in real time.

``WireCatalogue`` puts one entry before the catalogue the application hands in; building it gives a
``WireClient``, the engine's ``Controller`` for the client at the other end of the shared
``twin.wire.server.Server``. Every datagram goes through the server's own code (``receive``: HELLOs, refusals,
counts; ``send_sample``, ``await_command``, ``accept``, ``missed``: the exchange and the watchdog), nothing
is re-implemented here. Each run of the view is one session:

* **waiting**: no controller has said HELLO. The rig stays held at its initial state (as the real rig holds
  the ball until the controller starts) and time does not advance.
* **held**: HELLO answered with CONFIG, the held block sent as SAMPLE 0 and repeated every 0.2 s until its
  COMMAND acknowledges it; no acknowledgement within the server's ``timeout_s`` ends the session (STOP 3) and
  a new one waits on the same held rig, as does a client's STOP before release.
* **running**: the release; every view tick sends SAMPLE k and awaits COMMAND k (below).
* **quit**: the client sent STOP: the run goes on without it, the DAC holding and then the watchdog.
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
from collections.abc import Mapping
from typing import Any, Literal

from twin.engine import Catalogue, CatalogueEntry, Firmware, StateLaw
from twin.interface import Controller, DaqSample
from twin.parameters import Parameters
from twin.rigs.sim import SimRig
from twin.viewer.common import _markdown_text, _printable
from twin.wire import protocol as p
from twin.wire.server import STOP_NAMES, Server

WIRE_MARGIN_S = 0.0005  # stop waiting this long before the frame's end: the loop's own work after the wait
MAX_DISCARD = 4096  # datagrams queued before a session began that are thrown away (bounded: a flood)
Phase = Literal["waiting", "held", "running", "quit", "ended"]


def _address(addr: object) -> str:
    """A UDP peer as ``host:port``."""
    if isinstance(addr, tuple) and len(addr) >= 2:
        return f"{addr[0]}:{addr[1]}"
    return str(addr)


class WireClient(Controller):
    """The client of the served session as the view's controller. The view calls ``begin`` with the run's
    rig, then each frame either ``service`` (not released: the handshake and the held sample) or the engine's
    tick with ``deadline`` set (released: ``update`` exchanges one sample), and ``end`` when the run ends."""

    def __init__(self, server: Server, name: str, period_s: float) -> None:
        super().__init__()
        self.server = server
        self.name = name
        self.period_s = period_s
        self.rig: SimRig | None = None
        self.phase: Phase = "waiting"
        self.deadline = -math.inf  # the end of the current frame (time.perf_counter), set before each tick
        self.note = ""  # why the last session of this run ended, for the status
        self._held: DaqSample | None = None
        self._held_out: p.Sample | None = None
        self._held_since = 0.0
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
                return server.missed(rig.command_v)
            if self.phase == "running" and isinstance(got, p.Command):
                return server.accept(got)
            if self.phase == "running" and isinstance(got, p.Stop):
                self.phase = "quit"
                self.note = (
                    f"the client quit (STOP {got.reason}): the run goes on under the watchdog; Reset starts "
                    "a new session"
                )
            # quit: the frame's datagrams are still handled (counted, HELLOs refused) until its end

    # --- the view's frame while not released, or paused -------------------------------------------
    def service(self, deadline: float) -> None:
        """Handle the link until ``deadline`` (time.perf_counter): HELLOs answered (``receive``), then the
        held sample sent and its acknowledgement awaited; once released (a paused run), datagrams counted."""
        server = self.server
        if self.phase == "ended":
            return
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
                give_up = self._held_since + server.settings.timeout_s
                if now >= give_up:
                    self._restart(
                        f"the client did not acknowledge the held sample within {server.settings.timeout_s:g} s "
                        "(STOP 3)",
                        p.STOP_ERROR,
                    )
                    continue
                got = server.await_command(
                    self._held_out, min(deadline, give_up), resend=True, clock=time.perf_counter
                )
                if isinstance(got, p.Command):
                    server.accept(got)
                    self.phase = "running"  # released at the next tick
                    self.note = ""
                    return
                if isinstance(got, p.Stop):
                    self._restart(f"the client quit before release (STOP {got.reason})", None)
                continue
            got = server.receive(deadline - now)
            if isinstance(got, p.Command):
                server.counts.late_commands += 1  # answers a sample whose tick has passed (a paused run)
            elif isinstance(got, p.Stop) and self.phase == "running":
                self.phase = "quit"
                self.note = f"the client quit (STOP {got.reason}); Reset starts a new session"

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
                "held": "connected, held: awaiting its acknowledgement of the held sample",
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

    def __init__(self, inner: Catalogue, server: Server) -> None:
        self.inner = inner
        self.server = server
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

    def make(self, name: str, params: Parameters | None = None) -> Controller | StateLaw | Firmware:
        if name == self.name:
            return WireClient(self.server, self.name, (params or self.server.settings.params).daq.period_s)
        return self.inner.make(name, params)
