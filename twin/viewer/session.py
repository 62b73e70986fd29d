"""The session: the simulation side of the live view. It owns the twin, the controller and the run's state, and
offers a small set of typed commands (``set_controller``, ``reset``, ``set_initial_state``, ``flick``, …). GUI
callbacks only enqueue actions (as mjlab's viewer does), which the loop applies between ticks, a burst coalesced
to its latest value, each through its handler (twin.viewer.actions: the control's input checked, then a
command). A bad value is refused with the state unchanged. A controller or rig that fails marks the run failed
(``_fail``: the one place the view handles a failing controller)."""

from __future__ import annotations

import html
import io
import math
import re
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from twin import log as log_io
from twin.engine import Catalogue, ClosedLoop, ControllerError
from twin.interface import DaqSample, Setpoint
from twin.parameters import Parameters
from twin.physics import beam_travel_rad, check_initial_state
from twin.rigs.sim import make_rig
from twin.verdict import Criteria, Verdict
from twin.viewer.actions import HANDLERS, Refused
from twin.viewer.channels import RigChannels, rig_channels
from twin.viewer.common import (
    FLICK_DEFAULT_M_S,
    FRAME_S,
    MAX_OWED_S,
    SPEED_MAX,
    ViewerError,
    _log,
    _markdown_text,
    _printable,
    _show,
)
from twin.viewer.monitor import MonitorFactory, ShadowWorker
from twin.viewer.wire import WireClient
from twin.wire import protocol as p

HISTORY_S = 10.0  # live plots show the last 10 s
MAX_PENDING_ACTIONS = 1024  # beyond this, actions are dropped (a flood, not a user)
NOTICE_S = 10.0  # a refusal stays in the status line this long
# The run is recorded from its start (Reset) for this long of simulated time (17 columns: about 4 MB).
RECORD_LIMIT_S = 600.0
VERDICT_EVERY_S = 1.0  # the live verdict is recomputed at most once a second of wall time
MAX_ACTIONS_PER_FRAME = 64  # a flood of GUI messages cannot starve the simulation
# Actions whose latest value is all that matters and whose applying costs (a new run is designed and built;
# a new start re-places the held rig): a burst of one of them (Reset clicked 5000 times, a slider dragged)
# waits in the queue as its last one.
LATEST_WINS = frozenset({"reset", "controller", "x0", "theta0", "initial", "drift"})
# Actions that start a new run: between two ticks only the last of them matters, so they are started once.
STARTS_A_RUN = frozenset({"reset", "controller"})


@dataclass
class History:
    """Bounded histories for the live plots (the last ``HISTORY_S`` seconds at 50 Hz)."""

    size: int = int(HISTORY_S / FRAME_S)
    columns: dict[str, deque] = field(default_factory=dict)

    def append(self, **values: float) -> None:
        for key, value in values.items():
            self.columns.setdefault(key, deque(maxlen=self.size)).append(value)

    def array(self, key: str) -> np.ndarray:
        # float32: plenty for a plot, half the bytes on the wire. A diverged observer's 1e307 is a gap.
        with np.errstate(over="ignore", invalid="ignore"):
            values = np.asarray(self.columns.get(key, ()), dtype=np.float32)
        return np.where(np.isfinite(values), values, np.float32(np.nan))

    def clear(self) -> None:
        self.columns.clear()


@dataclass(frozen=True)
class Refusal:
    """A GUI value the loop refused: the action, the value (as shown) and why."""

    action: str
    value: str
    reason: str


class LiveTwin:
    """The simulation side of the viewer: a closed loop (twin.engine), its state, and the typed commands the
    loop applies (``set_controller``, ``reset``, ``set_running``, ``step``, ``set_initial_state``, ``flick``,
    ``set_flick_speed``, ``set_noise``, ``set_shadow``, ``set_drift``, ``set_speed``, ``set_reference``,
    ``client_connected``, ``download``).

    Everything here runs on the loop's thread; ``enqueue`` is the only method other threads call. A queued
    action reaches the commands through its handler (twin.viewer.actions, which checks the control's input);
    a bad value is refused with the state unchanged and recorded in ``refusals``. The controllers come from
    the catalogue the application hands in (the core never imports them). A controller or rig that fails
    (raises, a non-finite command, a diverged state, a stall) marks the run failed: ``error`` names the reason
    and the tick, the run pauses, and a reset or another controller starts a new one. A lost ball pauses the
    run where it left the track; the next run (Reset, another controller) then runs."""

    def __init__(
        self,
        params: Parameters,
        catalogue: Catalogue,
        controller: str,
        seed: int,
        speed: float,
        *,
        plant: str = "twin",
        ideal_sensors: bool = False,
        wait_for_client: bool = False,
        criteria: Criteria | None = None,
        monitor: MonitorFactory | None = None,
        initial: tuple[float, float] | None = None,
    ) -> None:
        self.params = params
        # What the view plots of the rig, in its board's units, and the software's conversions of its readings.
        self.channels: RigChannels = rig_channels(params)
        # The shadow (twin.viewer.monitor): off until asked for; it follows the runs at ``params``, while the
        # drift (% of motor resistance, from the next run) changes only the rig.
        self.monitor_factory = monitor
        self.shadow: ShadowWorker | None = None
        # The last shadow switched off, until its thread ends: switched on again meanwhile, it goes on
        # (a flood of toggles never has more than one band being built).
        self._shadow_stopping: ShadowWorker | None = None
        self.drift_pct = 0.0
        self._shadow_seq = 0
        self.catalogue = catalogue
        self.seed = seed
        self.speed = speed
        self.criteria = criteria or Criteria()
        self.achieved_speed: float | None = None  # measured by the pacing loop (simulated s per wall s)
        self.plant = plant
        self.ideal_sensors = ideal_sensors
        # The default start, inside a track or stops that a parameter file narrowed.
        self.x0_m = min(0.15, 0.5 * params.track.half_length_m)
        low, high = beam_travel_rad(params)  # the stops, or a lever's reach
        self.theta0_rad = min(0.1, 0.5 * min(-low, high))
        if initial is not None:  # a replayed run's start (ballbeam view --replay), checked as the rig's
            try:
                check_initial_state(params, initial[0], initial[1], 0.0, 0.0)
            except ValueError as exc:
                raise ViewerError(f"the initial state: {exc}") from None
            self.x0_m, self.theta0_rad = float(initial[0]), float(initial[1])
        self.noise = params.ball_sensor.noise_enabled
        self.reference_x_m = 0.0
        self.flick_m_s = FLICK_DEFAULT_M_S  # the last flick speed accepted (the slider is put back to it)
        # A first visitor sees the run from its start: the twin waits (paused) until a browser connects.
        self.awaiting_client = wait_for_client
        self.running = not wait_for_client
        self.error: str | None = None
        self.lost_paused = False  # the run paused itself when the ball left the track
        self.history = History()
        # Queued actions, oldest first. A lock, not queue.Queue: a burst of one kind is coalesced in place.
        self._actions: deque[tuple[str, Any]] = deque()
        self._actions_lock = threading.Lock()
        self._start_pending: tuple[str, str] | None = None  # (action, controller) of a run to start
        self.runs = 0  # runs started (each reset or controller change starts one)
        self.actions_applied = 0  # queued actions taken off the queue so far
        self.refusals: deque[Refusal] = deque(maxlen=100)  # refused values, oldest first (the viewer drains)
        self.refused = 0  # values refused so far
        self.failures = 0  # runs failed so far
        self.notice: tuple[float, str] | None = None  # (monotonic time, text) of the last refusal
        self.downloads_built = 0  # files built for Download (a click on an unchanged record builds none)
        self._download: tuple[tuple[str, int, int], str, bytes] | None = None  # (key, name, contents)
        self.controller_name = controller
        try:
            self._start_run(controller)
        except Refused as exc:
            raise ViewerError(str(exc)) from None

    # --- called from any thread ---------------------------------------------------------------------
    def enqueue(self, action: str, value: Any = None) -> None:
        """Queue an action for the loop. Of a burst of one kind whose latest value is all that matters (a
        dragged slider, Reset clicked thousands of times) only the latest waits."""
        with self._actions_lock:
            if self._actions and action in LATEST_WINS and self._actions[-1][0] == action:
                self._actions[-1] = (action, value)
                return
            if len(self._actions) < MAX_PENDING_ACTIONS:
                self._actions.append((action, value))
                return
        _log(f"{MAX_PENDING_ACTIONS} actions pending: dropped {action} {_show(value)}", key="flood")

    @property
    def pending_actions(self) -> int:
        with self._actions_lock:
            return len(self._actions)

    # --- loop thread --------------------------------------------------------------------------------
    def _start_run(self, name: str) -> None:
        """A fresh run of ``name`` from the set initial state: new controller, rig held at (x0, θ0), then
        released. Built completely before anything is replaced: a failure leaves the current run as it was."""
        try:
            controller = self.catalogue.make(name, self.params)
            params = self.params.with_overrides({"ball_sensor.noise_enabled": self.noise, **self._drift()})
            rig = make_rig(params, plant=self.plant, ideal_sensors=self.ideal_sensors, seed=self.seed)
            rig.reset(self.x0_m, self.theta0_rad)
            limit = int(RECORD_LIMIT_S / rig.period_s) + 1
            wire = controller if isinstance(controller, WireClient) else None
            # A wire client's budget is the view's frame (twin.viewer.wire), not the engine's watchdog.
            timeout = math.inf if wire is not None else None
            loop = ClosedLoop(rig, controller, record=True, record_limit=limit, controller_timeout_s=timeout)
        except Exception as exc:  # noqa: BLE001 - a controller or rig that cannot start is refused
            raise Refused(f"cannot start {_show(name)}: {type(exc).__name__}: {exc}") from exc
        old = self.wire if hasattr(self, "loop") else None
        if old is not None:  # the run is replaced: its client's session is over (STOP 0, the run is done)
            old.end(p.STOP_DONE, "the run was replaced (Reset, another controller): STOP 0")
        self._close_firmware()
        self.runs += 1
        self.error = None
        if self.lost_paused:  # the pause was the lost ball's, not the user's: the new run goes
            self.running = True
        self.lost_paused = False
        self.controller_name = name
        self.rig, self.loop = rig, loop
        if wire is not None:
            wire.begin(rig)  # a new session: the rig stays held until a client acknowledges its sample
        self.run_x0_m, self.run_theta0_rad = self.x0_m, self.theta0_rad  # this run's start
        # (tick, wall time, verdict, setpoint) of the last verdict
        self._verdict: tuple[int, float, Verdict, float] | None = None
        self.history.clear()
        try:
            self._apply_reference()
            self.loop.start()
            self._record()
            if self.shadow is not None:
                self.shadow.new_session(self.runs)
                self._feed_shadow(self.rig.command_v, held=True)
        except Exception as exc:  # noqa: BLE001 - the run failed; the server goes on
            self._fail(exc)

    def _drift(self) -> dict[str, float]:
        """The rig's parameter overrides of the drift slider (none at 0 %)."""
        if not self.drift_pct:
            return {}
        return {"motor.resistance_ohm": self.params.motor.resistance_ohm * (1.0 + self.drift_pct / 100.0)}

    def _feed_shadow(self, dac_v: float, *, held: bool = False) -> None:
        """The block just read, with the DAC volts held during it, to the shadow (seq 0: the run's first)."""
        shadow, s = self.shadow, self.last_sample
        if shadow is None or s is None:
            return
        seq = 0 if held else self._shadow_seq + 1
        self._shadow_seq = seq
        flags = (1 if held or self.rig.held else 0) | (2 if self.rig.ball_lost else 0)
        shadow.feed(seq, s.time_s, s.ball_v, s.angle_v, flags, dac_v)

    def _tick_once(self) -> None:
        """One control period; the shadow gets its block and the command that was held during it."""
        held_v = self.loop.command_v
        self.loop.tick()
        self._feed_shadow(held_v)

    @property
    def controller(self) -> Any:
        return self.loop.controller

    @property
    def wire(self) -> WireClient | None:
        """The wire client when it is this run's controller (``ballbeam view --serve``)."""
        controller = self.loop.controller
        return controller if isinstance(controller, WireClient) else None

    @property
    def last_sample(self) -> DaqSample | None:
        return self.loop.last_sample

    @property
    def supports_reference(self) -> bool:
        """Whether the running controller regulates to a settable setpoint: the catalogue's entry says so
        (``CatalogueEntry.setpoint``); a catalogue without entries is answered by the built controller."""
        entries = getattr(self.catalogue, "ENTRIES", None)
        entry = entries.get(self.controller_name) if entries is not None else None
        if entry is not None:
            return bool(entry.setpoint) and isinstance(self.controller, Setpoint)
        return isinstance(self.controller, Setpoint)

    @property
    def setpoint_reason(self) -> str:
        """Why the setpoint control does (or does not) act on this controller."""
        if self.supports_reference:
            return "The ball position the controller regulates to."
        if self.wire is not None:
            return "A wire client's setpoint is its own: protocol 1 carries none (docs/protocol.md)."
        return (
            f"{self.controller_name} regulates the ball to the centre: it declares no setpoint "
            "(twin.interface.Setpoint; the appendix programs and the sliding-mode law are written for x = 0)."
        )

    @property
    def setpoint_m(self) -> float:
        """The position the running controller regulates the ball to."""
        return self.reference_x_m if self.supports_reference else 0.0

    @property
    def initial_pending(self) -> bool:
        """x0/θ0 were changed since this run started: they apply on Reset."""
        return (self.x0_m, self.theta0_rad) != (self.run_x0_m, self.run_theta0_rad)

    def verdict(self) -> Verdict | None:
        """The verdict of the run so far (recomputed at most once a second while it runs), None before the
        first tick."""
        ticks = self.rig.ticks
        cached = self._verdict
        if cached is not None and (
            (cached[0] == ticks and cached[3] == self.setpoint_m)
            or (self.running and time.monotonic() - cached[1] < VERDICT_EVERY_S)
        ):
            return cached[2]
        recorder = self.loop.recorder
        if recorder is None or recorder.n < 2:
            return None
        verdict = self.loop.verdict(self.run_x0_m, self.criteria, x_ref_m=self.setpoint_m)
        self._verdict = (ticks, time.monotonic(), verdict, self.setpoint_m)
        return verdict

    def recording(self, kind: str) -> tuple[str, bytes]:
        """This run's record so far as a file: (file name, contents); ``kind`` is "mat" or "csv". Built once
        per record state (run, rows recorded) and format: a full record is the same file at every click."""
        writers = {"mat": log_io.write_mat, "csv": log_io.write_csv}
        if kind not in writers:
            raise Refused(f"download = {_show(kind)}: the formats are mat and csv")
        recorder = self.loop.recorder
        key = (kind, self.runs, recorder.n if recorder is not None else 0)
        if self._download is None or self._download[0] != key:
            self._download = None  # the previous file goes before the next is built (one held at a time)
            buffer = io.BytesIO()
            writers[kind](self.loop.log(), buffer)
            # A file name of letters, digits, '.', '_' and '-' ("wire client (udp://…)" has slashes).
            label = re.sub(r"[^A-Za-z0-9._-]+", "-", self.controller_name).strip("-") or "controller"
            name = f"ballbeam_run{self.runs}_{label}.{kind}"
            self._download = (key, name, buffer.getvalue())
            self.downloads_built += 1
        return self._download[1], self._download[2]

    def _apply_reference(self) -> None:
        if self.supports_reference:
            self.controller.setpoint_m = self.reference_x_m

    def _fail(self, exc: BaseException) -> None:
        """Mark the run failed with the reason and the tick, and pause it: the one place the view handles a
        failing controller or rig (a ControllerError from the engine, a stall included, names the
        controller and the tick itself)."""
        if isinstance(exc, ControllerError):
            reason = f"the controller failed: {exc}"
        else:
            try:
                where = f"at tick k = {self.rig.ticks} (t = {self.rig.time_s:.3f} s)"
            except Exception:  # noqa: BLE001 - a broken rig still gets its failure reported
                where = ""
            reason = f"the run failed {where}: {type(exc).__name__}: {exc}"
        self.error = _printable(reason, 500)
        self.running = False
        self.failures += 1
        wire = self.wire
        if wire is not None:
            wire.end(p.STOP_ERROR, "the run failed: STOP 3")
        _log(self.error, stream=sys.stdout)

    def _refuse(self, action: str, value: Any, reason: str) -> None:
        refusal = Refusal(action, _show(value), _printable(reason))
        self.refusals.append(refusal)
        self.refused += 1
        self.notice = (time.monotonic(), refusal.reason)
        _log(f"refused {action}: {refusal.reason}", key=f"refused {action}", stream=sys.stdout)

    def apply_actions(self) -> None:
        """Apply the queued actions (at most ``MAX_ACTIONS_PER_FRAME``, coalesced as they were queued); a new
        run is started once however many resets and controller changes came in a row. Never raises."""
        for _ in range(MAX_ACTIONS_PER_FRAME):
            with self._actions_lock:
                if not self._actions:
                    break
                action, value = self._actions.popleft()
            self._apply(action, value)
            self.actions_applied += 1
        self._start_pending_run()

    def apply(self, action: str, value: Any = None) -> None:
        """Apply one action now: a bad value is refused (state unchanged), a failure marks the run failed."""
        self._apply(action, value)
        self._start_pending_run()

    def _apply(self, action: str, value: Any) -> None:
        handler = HANDLERS.get(action) if isinstance(action, str) else None
        if action not in STARTS_A_RUN:
            self._start_pending_run()  # what follows a reset acts on the new run
        try:
            if handler is None:
                raise Refused(f"unknown action {_show(action)}")
            handler(self, value)
        except Refused as exc:
            self._refuse(str(action), value, str(exc))
        except Exception as exc:  # noqa: BLE001 - an action that breaks the rig fails the run, not the server
            self._fail(exc)
        else:
            shown = "" if value is None else f" {_show(value)}"
            _log(f"t = {self.rig.time_s:.2f} s: {action}{shown}", key=f"action {action}", stream=sys.stdout)

    def _start_pending_run(self) -> None:
        """Start the run that the last reset or controller change asked for, if any."""
        if self._start_pending is None:
            return
        action, name = self._start_pending
        self._start_pending = None
        try:
            self._start_run(name)
        except Refused as exc:
            self._refuse(action, name if action == "controller" else None, str(exc))

    # --- the commands (loop thread): what the GUI's handlers (twin.viewer.actions) call ----------------------
    # Typed values from code the view trusts; each refuses (``Refused``, the state unchanged) only what depends
    # on the session's own state. The controls' ranges are the handlers' to check.
    def client_connected(self) -> None:
        """A browser connected: the first one gets a fresh run from t = 0, running."""
        if self.awaiting_client:
            self.awaiting_client = False
            if self.wire is not None:  # never released while waiting; a client may hold its session
                self.runs = 1
            else:
                self.runs = 0  # nobody saw the run built while waiting: the first one watched is run 1
                self._start_run(self.controller_name)
            self.running = self.error is None

    def download(self, kind: str, send: Callable[[str, bytes], None]) -> None:
        """This run's record as a ``kind`` file ("mat" or "csv"), handed to ``send(name, contents)``."""
        name, data = self.recording(kind)
        send(name, data)

    def set_controller(self, name: str) -> None:
        """A new run of the catalogue's controller ``name``, started by the loop once, after the actions queued
        with it (``apply_actions``: a burst of resets and changes builds one run)."""
        if not isinstance(name, str) or name not in self.catalogue.NAMES:
            raise Refused(f"unknown controller {_show(name)}; known: {', '.join(self.catalogue.NAMES)}")
        pending = self._start_pending[1] if self._start_pending is not None else self.controller_name
        if name != pending:
            self._start_pending = ("controller", name)

    def reset(self) -> None:
        """A new run of the current (or the last asked for) controller from the set initial state, started as
        ``set_controller``'s."""
        pending = self._start_pending[1] if self._start_pending is not None else self.controller_name
        self._start_pending = ("reset", pending)

    def set_running(self, on: bool) -> None:
        """Run or pause; a failed run stays paused."""
        self.running = on and self.error is None

    def step(self) -> None:
        """Pause and advance one frame."""
        self.running = False
        self.tick()

    def set_initial_state(self, x0_m: float, theta0_rad: float) -> None:
        """The start of the next run (x0 m, θ0 rad), refused off the track or beyond the stops."""
        try:
            check_initial_state(self.params, x0_m, theta0_rad, 0.0, 0.0)  # the rig's own rule
        except ValueError as exc:
            raise Refused(str(exc)) from None
        self.x0_m, self.theta0_rad = x0_m, theta0_rad

    def flick(self, velocity_m_s: float) -> None:
        """Kick the ball along the beam by ``velocity_m_s`` (signed: + towards the + end)."""
        self.rig.kick_ball(velocity_m_s)

    def set_flick_speed(self, speed_m_s: float) -> None:
        """The flick speed last accepted (the flick slider is put back to it)."""
        self.flick_m_s = speed_m_s

    def set_noise(self, on: bool) -> None:
        """The ball sensor's contact noise on or off, from now on."""
        if on != self.noise:
            self.rig.set_noise(on)
            self.noise = on

    def set_shadow(self, on: bool) -> None:
        """The shadow (twin.viewer.monitor) on or off; refused on when the application gave none."""
        factory = self.monitor_factory
        if on and factory is None:
            raise Refused("this view was started without a shadow (the application gives none)")
        if on and factory is not None and self.shadow is None:
            stopping, self._shadow_stopping = self._shadow_stopping, None
            if stopping is not None and stopping.resume():
                self.shadow = stopping
                stopping.new_session(self.runs)  # the samples it missed while off: a new session
            else:
                self.shadow = ShadowWorker(factory, self.params, run=self.runs)
            self._feed_shadow(self.loop.command_v, held=True)  # its first session starts at this block
        elif not on and self.shadow is not None:
            self.shadow.stop()
            self._shadow_stopping, self.shadow = self.shadow, None

    def set_drift(self, percent: float) -> None:
        """The rig's motor resistance this many % above the parameters', from the next run."""
        self.drift_pct = percent

    def set_speed(self, speed: float) -> None:
        """Simulated seconds per wall second."""
        self.speed = speed

    def set_reference(self, x_m: float) -> None:
        """The setpoint (m); refused, not kept for later, when the controller takes none."""
        if not self.supports_reference:  # the greyed slider's number box still sends
            raise Refused(self.setpoint_reason)
        self.reference_x_m = x_m
        self._apply_reference()

    def tick(self, deadline: float | None = None) -> None:
        """One 20 ms frame of simulated time: as many control periods as fit in it. Never raises: a failure
        marks the run failed. A wire client's tick exchanges one sample, its command awaited until
        ``deadline`` (time.perf_counter; default one frame from now); until the client acknowledged the held
        sample the rig stays held and the frame only services the link."""
        if self.error is not None:
            return
        wire = self.wire
        try:
            n = max(1, int(round(FRAME_S / self.rig.period_s)))
            if wire is not None:
                until = deadline if deadline is not None else time.perf_counter() + FRAME_S
                if not wire.released:
                    wire.service(until)
                    return
                for i in range(
                    n
                ):  # a shorter period: its ticks' deadlines one period apart, the last at until
                    wire.deadline = until - (n - 1 - i) * self.rig.period_s
                    self._tick_once()
                    if self.rig.ball_lost:
                        break  # its sample was the session's last
            else:
                for _ in range(n):
                    self._tick_once()
            self._record()
        except Exception as exc:  # noqa: BLE001 - a failing controller or rig fails the run, not the server
            self._fail(exc)
            return
        if self.rig.ball_lost and not self.lost_paused:  # an event: pause on the state it left with
            self.lost_paused = True
            self.running = False
            if wire is not None:
                wire.end(p.STOP_BALL_LOST, "the ball was lost: STOP 2; Reset starts a new session")
            _log(
                f"ball lost at t = {self.rig.ball_lost_time_s:.2f} s: paused (Reset starts again)",
                stream=sys.stdout,
            )

    def service_wire(self, deadline: float) -> None:
        """A frame in which the run does not tick (paused, waiting for a browser): the wire client's link is
        still serviced until ``deadline`` (HELLOs, the held sample, refusals counted). Never raises."""
        wire = self.wire
        if wire is None:
            return
        try:
            wire.service(deadline, release=False)  # no run without the view running: the client waits, held
        except Exception as exc:  # noqa: BLE001 - the link's failure fails the run, not the server
            self._fail(exc)

    def _close_firmware(self) -> None:
        """A firmware's co-simulation (a process of its own) ends with its run."""
        loop = getattr(self, "loop", None)
        if loop is not None and loop.is_firmware:
            loop.controller.close()

    def close(self) -> None:
        """The view shuts down: a wire client's session ends with STOP 4; the shadow stops."""
        self._close_firmware()
        if self.shadow is not None:
            self.shadow.stop()
        wire = self.wire
        if wire is not None:
            wire.end(p.STOP_SHUTDOWN, "the view shut down: STOP 4")

    def _record(self) -> None:
        x, theta, xdot, thetadot = self.rig.true_state()
        est = self.controller.telemetry.estimate
        s = self.last_sample
        ch = self.channels  # the parts' conversions (the thesis's: its software's eq 6.3.1 and 6.2.10)
        nan = float("nan")
        self.history.append(
            t=self.rig.time_s,
            x_true=x,
            x_meas=ch.x_measured_m(s.ball_v) if s is not None else nan,
            x_est=est[0],
            x_ref=self.setpoint_m,
            th_true=theta,
            th_meas=ch.theta_measured_rad(s.angle_v) if s is not None else nan,
            th_est=est[1],
            xdot_true=xdot,
            xdot_est=est[2],
            thdot_true=thetadot,
            thdot_est=est[3],
            ball_v=s.ball_v if s is not None else nan,
            ball_read=ch.ball_shown(s.ball_v) if s is not None else nan,
            angle_v=s.angle_v if s is not None else nan,
            dac_v=ch.output_of(self.loop.command_v),
            volts=self.rig.motor_volts_v,
        )

    def status_markdown(self) -> str:
        wire = self.wire
        if self.awaiting_client:
            state = "waiting for a browser"
        elif wire is not None and not wire.released:  # the rig is held until the wire client answers
            state = "waiting for the wire client" if self.running else "paused"
        else:
            state = "running" if self.running else "paused"
        ball = (
            f"**ball lost** at {self.rig.ball_lost_time_s:.2f} s — paused; Reset starts again"
            if self.rig.ball_lost
            else "ball on the beam"
        )
        verdict = self.verdict()
        judged = (
            f"  \n{_markdown_text(verdict_text(verdict, self.setpoint_m, self.criteria, self.channels))}"
            if verdict is not None
            else ""
        )
        pending = ""
        if self.initial_pending:
            pending = (
                f"  \n*x0 = {self.x0_m:+.2f} m, θ0 = {self.theta0_rad:+.2f} rad apply on Reset* "
                f"(this run started at {self.run_x0_m:+.2f} m, {self.run_theta0_rad:+.2f} rad)"
            )
        error = f"  \n**run failed**: {_markdown_text(self.error)}" if self.error else ""
        speed = f"speed ×{self.speed:g}{self._speed_note()}"
        if wire is not None:
            speed = "real time ×1 (the wire client)"
            error = f"  \n{wire.status_markdown()}{error}"
        if self.shadow is not None:
            error += f"  \n{self.shadow.snapshot().status}"
        if self.drift_pct:
            drifted = self.rig.params.motor.resistance_ohm != self.params.motor.resistance_ohm
            error += f"  \nrig drift: motor resistance +{self.drift_pct:g} %" + (
                "" if drifted else " (from the next Reset)"
            )
        if self.loop.is_firmware:
            error += f"  \n{firmware_text(self.loop.firmware_figures() or {})}"
        notice = ""
        if self.notice is not None and time.monotonic() - self.notice[0] < NOTICE_S:
            notice = f"  \n**refused**: {_markdown_text(self.notice[1])}"
        return (
            f"run {self.runs} · **t = {self.rig.time_s:.2f} s** · {state} · controller: "
            f"**{_markdown_text(self.controller_name)}** · {ball}  \n"
            f"noise {'on' if self.noise else 'off'} · {speed} · "
            f"{self.channels.control_text(self.rig.motor_volts_v)}{judged}{pending}{error}{notice}"
        )

    def _speed_note(self) -> str:
        """The speed actually achieved, when the computer cannot keep up with the one asked for."""
        achieved = self.achieved_speed
        if not self.running or achieved is None or achieved >= 0.98 * self.speed:
            return ""
        return f" (achieved ×{achieved:.2f}: this computer cannot keep up)"

    def lost_text(self) -> str:
        """What a person must know while the ball is off the track (empty otherwise)."""
        if not self.rig.ball_lost:
            return ""
        verdict = self.verdict()
        x = float(self.rig.true_state()[0])
        half_m = self.rig.params.track.half_length_m
        if not math.isfinite(x):
            where = "it left the track"
        elif abs(x) >= half_m:  # rolled past an end of the wires
            where = f"it rolled off the {'+' if x > 0 else '−'} end of the track (x = {x:+.3f} m)"
        else:  # thrown off the wires along the beam
            where = f"it was thrown off the wires at x = {x:+.3f} m, on the beam"
        judged = (
            verdict_text(verdict, self.setpoint_m, self.criteria, self.channels)
            if verdict is not None
            else "no verdict"
        )
        return (
            f"Ball lost at t = {self.rig.ball_lost_time_s:.2f} s: {where}. The run is paused ({judged}). "
            "Press Reset to start again."
        )

    def lost_banner_html(self) -> str:
        """The banner shown while the ball is off the track (empty otherwise)."""
        text = self.lost_text()
        if not text:
            return ""
        return (
            '<div role="alert" style="box-sizing:border-box;background:#c92a2a;color:#fff;padding:8px 10px;'
            "border-radius:6px;"
            f'font-weight:600;font-size:0.9em">{html.escape(text)}</div>'
        )


def firmware_text(f: dict[str, Any]) -> str:
    """A firmware's load and timing for the status line (``twin.avr.firmware.AvrFirmware.figures``)."""
    if not f.get("updates"):
        return f"firmware on a simulated {f.get('mcu', 'MCU')}: booting"
    clock = f["clock_hz"]
    return (
        f"firmware on a simulated {f['mcu']} at {clock / 1e6:g} MHz: load {100 * f['load']:.1f} % · longest "
        f"update {f['update_cycles_max']:.0f} cycles ({1e3 * f['update_max_s']:.2f} ms, margin "
        f"{1e3 * f['deadline_margin_s']:.2f} ms) · stack {f['stack_high_water_bytes']} of "
        f"{f['stack_room_bytes']:g} bytes · {f['missed_periods']} periods missed"
    )


def verdict_text(
    v: Verdict, setpoint_m: float = 0.0, criteria: Criteria | None = None, channels: RigChannels | None = None
) -> str:
    """One line for a person watching: the verdict of the run so far (the peak of the actuator's control in
    its unit, ``channels``: the thesis motor's volts and its share at the rails by default). Until the final window
    (``Criteria.window_s``) lies after a first window of the run, or the ball settled before it, that window
    still holds the release's transient: it is called the transient, not a limit cycle or an offset."""
    c = criteria or Criteria()
    if v.ball_lost:
        return f"verdict: lost (ball off the track at {v.ball_lost_time_s:.2f} s)"
    if v.steady_x_m is None:
        return f"verdict so far: too early to tell ({v.reason})"
    judged_from_s = 2.0 * c.window_s
    if v.settling_time_s is None and v.duration_s < judged_from_s:
        return (
            f"verdict so far: transient (the final {c.window_s:g} s window is judged once the ball settles, "
            f"at the latest from t = {judged_from_s:g} s)"
        )
    parts = ["held" if v.held else f"not held: {v.reason}"]
    if v.settling_time_s is not None:
        parts.append(f"settled in {v.settling_time_s:.2f} s")
    parts.append(f"steady x {v.steady_x_m * 1e3:+.1f} mm" + (" from the setpoint" if setpoint_m else ""))
    if v.limit_cycle_x_pp_m is not None:
        parts.append(f"cycle {v.limit_cycle_x_pp_m * 1e3:.1f} mm p-p")
    if channels is None or channels.thesis:
        parts.append(f"peak {v.peak_motor_voltage_v:.1f} V ({100 * v.saturated_fraction:.0f} % at the rails)")
    else:
        parts.append(f"peak {channels.control_name} {v.peak_motor_voltage_v:.4g} {channels.control_unit}")
    judged = " · ".join(parts)
    about = f" (about the setpoint x = {setpoint_m:+.2f} m)" if setpoint_m else ""
    return f"verdict so far{about}: {judged}"


def owe(owed_s: float, speed: float) -> float:
    """The pacing's debt after one more wall frame at ``speed``: never negative, never more than
    ``MAX_OWED_S`` (a few frames), whatever ``speed`` holds."""
    rate = float(speed) if isinstance(speed, (int, float)) and math.isfinite(speed) else 0.0
    rate = min(max(rate, 0.0), SPEED_MAX)
    owed = owed_s if math.isfinite(owed_s) else 0.0
    return min(max(owed, 0.0) + FRAME_S * rate, MAX_OWED_S)
