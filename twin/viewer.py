"""Live browser view of the twin (viser): the rig in 3D at 50 Hz, controls, and live plots.

The simulation loop owns the twin and the controller. GUI callbacks run on viser's thread pool and only
enqueue actions, which the loop applies between ticks; each frame's scene updates are sent together.

Nothing a client sends is trusted. The websocket handshake is refused (HTTP 403) unless its ``Host`` header
names this server and its ``Origin`` is the page's own origin, so a web page on another site cannot drive
the twin through the user's browser. GUI messages that are not a plain value of the right type for a known
control are dropped before viser applies them; every value is then checked by the loop against the current
parameters and refused (notification, status line, one log line) with the state unchanged. A controller or
rig that fails marks the run failed; nothing a client sends stops the server.
"""

from __future__ import annotations

import contextlib
import functools
import html
import http
import io
import ipaddress
import logging
import math
import queue
import socket
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import urlsplit

import mujoco
import numpy as np
import trimesh
import viser
import viser.uplot
from viser import _messages as viser_messages

from twin import converters
from twin import log as log_io
from twin.engine import Catalogue, ClosedLoop, ControllerError
from twin.interface import DaqSample
from twin.parameters import Parameters
from twin.physics import check_initial_state
from twin.plant import Plant
from twin.rig import PlantKind, make_rig
from twin.verdict import Verdict

__all__ = ["LiveTwin", "OriginPolicy", "ViewerError", "serve"]

FRAME_S = 0.02  # scene updates at 50 Hz (the rig's tick)
PLOT_EVERY_FRAMES = 10  # plots and status at 5 Hz: enough for the eye, a tenth of the traffic
HISTORY_S = 10.0  # live plots show the last 10 s
MAX_CATCH_UP_S = 0.25  # after a stall longer than this the pacing restarts instead of racing to catch up
DEFAULT_CONTROLLER = "appendix-clp"

# The controls' ranges. Values are checked again in the loop against the parameters (a parameter file may
# narrow the track or the stops below the sliders' ranges: the sliders are narrowed too).
SPEED_MIN, SPEED_MAX = 0.1, 4.0  # simulated seconds per wall second
X0_SLIDER_M = 0.3
THETA0_SLIDER_RAD = 0.7
SETPOINT_SLIDER_M = 0.2
FLICK_MAX_M_S = 1.0  # the largest flick the loop accepts (the slider goes to 0.5 m/s)
FLICK_DEFAULT_M_S = 0.1
# Simulated time the pacing may owe the wall clock: one frame at the top speed plus one. Whatever the
# speed, a frame never runs more than this many ticks and a stall never builds a debt.
MAX_OWED_S = FRAME_S * (SPEED_MAX + 1.0)
SPEED_WINDOW_S = 2.0  # the achieved speed is measured over the last 2 s of wall time
MAX_ACTIONS_PER_FRAME = 64  # a flood of GUI messages cannot starve the simulation
MAX_PENDING_ACTIONS = 1024  # beyond this, actions are dropped (a flood, not a user)
MAX_MESSAGE_BYTES = 1 << 20  # a GUI message is a few hundred bytes; viser's own limit is 50 MB
NOTICE_S = 10.0  # a refusal stays in the status line this long
NOTIFY_EVERY_S = 0.5  # at most two refusal notifications a second (a flood shows as a count)

# The run is recorded from its start (Reset) for this long of simulated time (17 columns: about 4 MB).
RECORD_LIMIT_S = 600.0
VERDICT_EVERY_S = 1.0  # the live verdict is recomputed at most once a second of wall time

# Live plots: title, then (legend label, history key, colour) per trace. Estimated = the controller's own
# estimate (its observer or differentiator); measured = the raw readings through the software's converters.
PLOTS = (
    (
        "x (m)",
        (
            ("x true", "x_true", "#1f77b4"),
            ("measured", "x_meas", "#ff7f0e"),
            ("estimated", "x_est", "#2ca02c"),
            ("setpoint", "x_ref", "#000000"),
        ),
    ),
    (
        "θ (rad)",
        (
            ("θ true", "th_true", "#1f77b4"),
            ("measured", "th_meas", "#ff7f0e"),
            ("estimated", "th_est", "#2ca02c"),
        ),
    ),
    ("θ̇ (rad/s)", (("θ̇ true", "thdot_true", "#1f77b4"), ("estimated", "thdot_est", "#2ca02c"))),
    (
        "I/O card (V)",
        (
            ("ball ADC", "ball_v", "#ff7f0e"),
            ("angle ADC", "angle_v", "#8c564b"),
            ("DAC out", "dac_v", "#9467bd"),
        ),
    ),
    ("motor (V)", (("motor volts", "volts", "#d62728"),)),
)
PLOT_AXIS_PX = 58  # room for a y value such as "−0.005" with its minus sign (uPlot's default clips it)
PLOT_ASPECT = 3.4  # wide and low: all the plots fit the height of a 900 px window
PLOT_PANEL_PX = 460

# Camera presets: position, look-at point (m, world frame; the pivot is 0.25 m above the floor), up.
CAMERAS: dict[
    str, tuple[tuple[float, float, float], tuple[float, float, float], tuple[float, float, float]]
] = {
    "Three-quarter": ((0.2, -0.72, 0.52), (0.0, 0.0, 0.24), (0.0, 0.0, 1.0)),
    "Side": ((0.0, -0.7, 0.27), (0.0, 0.0, 0.25), (0.0, 0.0, 1.0)),
    "Top": ((0.0, -0.02, 0.95), (0.0, 0.0, 0.25), (0.0, 1.0, 0.0)),
}
DEFAULT_CAMERA = "Three-quarter"
SETPOINT_FLAG_M = (0.010, 0.028)  # the setpoint flag's extent above the ball centre (clear of the ball)


class ViewerError(RuntimeError):
    """The viewer cannot start (port taken, bad host, …)."""


# --- one-line logs ----------------------------------------------------------------------------------------
_log_lock = threading.Lock()
_log_last: dict[str, tuple[float, int]] = {}  # key → (time of the last line, lines suppressed since)


def _printable(text: str, limit: int = 300) -> str:
    """One line of printable text: control characters (a client's string may carry terminal escapes) shown
    escaped, long text cut."""
    text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in " ".join(text.split()))
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _show(value: Any, limit: int = 60) -> str:
    """A client's value for a message: its repr, cut."""
    try:
        text = repr(value)
    except Exception:  # noqa: BLE001 - a value whose repr fails is still shown
        text = f"<{type(value).__name__}>"
    return _printable(text, limit)


def _log(text: str, *, key: str | None = None, stream: Any = None) -> None:
    """Print one line ``ballbeam view: …`` (stderr unless told). With ``key``, at most one line a second per
    key; the lines held back are counted in the next one (a hostile client cannot flood the log)."""
    line = f"ballbeam view: {_printable(text)}"
    if key is not None:
        now = time.monotonic()
        with _log_lock:
            last, held = _log_last.get(key, (-math.inf, 0))
            if now - last < 1.0:
                _log_last[key] = (last, held + 1)
                return
            _log_last[key] = (now, 0)
        if held:
            line += f" ({held} more like it in the last second)"
    print(line, file=stream if stream is not None else sys.stderr, flush=True)


class _OneLineHandler(logging.Handler):
    """The websocket library's errors (a malformed frame, a broken handshake) as one line, no traceback."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = f"websocket: {record.getMessage()}"
            exc = record.exc_info[1] if record.exc_info else None
            if exc is not None:
                text += f" ({type(exc).__name__}: {exc})"
            _log(text, key="websocket")
        except Exception:  # noqa: BLE001 - logging must never raise
            self.handleError(record)


_WS_LOGGER = logging.getLogger("twin.viewer.websocket")
_WS_LOGGER.setLevel(logging.WARNING)  # errors only; the library's INFO lines (rejections, opens) are noise
_WS_LOGGER.propagate = False
if not _WS_LOGGER.handlers:
    _WS_LOGGER.addHandler(_OneLineHandler())


def _markdown_text(text: str) -> str:
    """Plain text for viser's markdown, which renders raw HTML (scripts included): no tag, no markup and no
    link (GFM links bare URLs) gets through."""
    text = html.escape(" ".join(text.split()), quote=False)
    return "".join("\\" + c if c in "\\`*_{}[]()|~:.@" else c for c in text)


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


class _Refused(Exception):
    """An action's value is refused; the state is unchanged."""


def _number(name: str, value: Any, limit: float, unit: str, *, low: float | None = None) -> float:
    """A finite real number within [low, limit] (low = −limit by default), or refused naming the control."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise _Refused(f"{name} = {_show(value)} is not a number")
    try:
        number = float(value)
    except (OverflowError, ValueError):
        raise _Refused(f"{name} = {_show(value)} is not a finite number") from None
    if not math.isfinite(number):
        raise _Refused(f"{name} = {number!r} is not a finite number")
    low = -limit if low is None else low
    if not low <= number <= limit:
        unit = f" {unit}" if unit else ""
        raise _Refused(f"{name} = {number:g}{unit} is outside {low:g} … {limit:g}{unit}")
    return number


def _boolean(name: str, value: Any) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise _Refused(f"{name} = {_show(value)} is not a boolean")
    return bool(value)


class LiveTwin:
    """The simulation side of the viewer: a closed loop (twin.engine), and the actions the GUI asks for.

    Everything here runs on the loop's thread; ``enqueue`` is the only method other threads call. The
    controllers come from the catalogue the application hands in (the core never imports them).

    Actions and their values (each checked against the current parameters; a bad one is refused with
    the state unchanged and recorded in ``refusals``): ``controller`` (a catalogue name), ``reset``,
    ``run`` (bool), ``step``, ``x0`` (m, |x0| ≤ track.half_length_m), ``theta0`` (rad, |θ0| ≤
    beam.stop_angle_rad), ``initial`` ((x0, θ0)), ``flick`` (m/s, |v| ≤ 1), ``noise`` (bool), ``speed``
    (0.1 … 4), ``reference`` (the setpoint, m, within the track). A controller or rig that fails (raises,
    a non-finite command, a diverged state) marks the run failed: ``error`` names the reason and the tick,
    the run pauses, and a reset or another controller starts a new one. A lost ball pauses the run where
    it left the track; the next run (Reset, another controller) then runs."""

    def __init__(
        self,
        params: Parameters,
        catalogue: Catalogue,
        controller: str,
        seed: int,
        speed: float,
        *,
        plant: PlantKind = "twin",
        ideal_sensors: bool = False,
        wait_for_client: bool = False,
    ) -> None:
        self.params = params
        self.catalogue = catalogue
        self.seed = seed
        self.speed = speed
        self.achieved_speed: float | None = None  # measured by the pacing loop (simulated s per wall s)
        self.plant: PlantKind = plant
        self.ideal_sensors = ideal_sensors
        # The default start, inside a track or stops that a parameter file narrowed.
        self.x0_m = min(0.15, 0.5 * params.track.half_length_m)
        self.theta0_rad = min(0.1, 0.5 * params.beam.stop_angle_rad)
        self.noise = params.ball_sensor.noise_enabled
        self.reference_x_m = 0.0
        # A first visitor sees the run from its start: the twin waits (paused) until a browser connects.
        self.awaiting_client = wait_for_client
        self.running = not wait_for_client
        self.error: str | None = None
        self.lost_paused = False  # the run paused itself when the ball left the track
        self.history = History()
        self.actions: queue.Queue[tuple[str, Any]] = queue.Queue(maxsize=MAX_PENDING_ACTIONS)
        self.runs = 0  # runs started (each reset or controller change starts one)
        self.refusals: deque[Refusal] = deque(maxlen=100)  # refused values, oldest first (the viewer drains)
        self.refused = 0  # values refused so far
        self.failures = 0  # runs failed so far
        self.notice: tuple[float, str] | None = None  # (monotonic time, text) of the last refusal
        self.controller_name = controller
        try:
            self._start_run(controller)
        except _Refused as exc:
            raise ViewerError(str(exc)) from None

    # --- called from any thread ---------------------------------------------------------------------
    def enqueue(self, action: str, value: Any = None) -> None:
        try:
            self.actions.put_nowait((action, value))
        except queue.Full:
            _log(f"{MAX_PENDING_ACTIONS} actions pending: dropped {action} {_show(value)}", key="flood")

    # --- loop thread --------------------------------------------------------------------------------
    def _start_run(self, name: str) -> None:
        """A fresh run of ``name`` from the set initial state: new controller, rig held at (x0, θ0), then
        released. Built completely before anything is replaced: a failure leaves the current run as it was."""
        try:
            controller = self.catalogue.make(name, self.params)
            params = self.params.with_overrides({"ball_sensor.noise_enabled": self.noise})
            rig = make_rig(params, plant=self.plant, ideal_sensors=self.ideal_sensors, seed=self.seed)
            rig.reset(self.x0_m, self.theta0_rad)
            limit = int(RECORD_LIMIT_S / rig.period_s) + 1
            loop = ClosedLoop(rig, controller, record=True, record_limit=limit)
        except Exception as exc:  # noqa: BLE001 - a controller or rig that cannot start is refused
            raise _Refused(f"cannot start {_show(name)}: {type(exc).__name__}: {exc}") from exc
        self.runs += 1
        self.error = None
        if self.lost_paused:  # the pause was the lost ball's, not the user's: the new run goes
            self.running = True
        self.lost_paused = False
        self.controller_name = name
        self.rig, self.loop = rig, loop
        self.run_x0_m, self.run_theta0_rad = self.x0_m, self.theta0_rad  # this run's start
        # (tick, wall time, verdict, setpoint) of the last verdict
        self._verdict: tuple[int, float, Verdict, float] | None = None
        self.history.clear()
        try:
            self._apply_reference()
            self.loop.start()
            self._record()
        except Exception as exc:  # noqa: BLE001 - the run failed; the server goes on
            self._fail(exc)

    @property
    def controller(self) -> Any:
        return self.loop.controller

    @property
    def last_sample(self) -> DaqSample | None:
        return self.loop.last_sample

    @property
    def supports_reference(self) -> bool:
        return hasattr(getattr(self.controller, "law", None), "ref_x_m")

    @property
    def setpoint_reason(self) -> str:
        """Why the setpoint control does (or does not) act on this controller."""
        if self.supports_reference:
            return "The ball position the controller regulates to."
        return (
            f"{self.controller_name} regulates the ball to the centre: its law has no setpoint input "
            "(the appendix programs and the sliding-mode law are written for x = 0)."
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
        verdict = self.loop.verdict(self.run_x0_m, x_ref_m=self.setpoint_m)
        self._verdict = (ticks, time.monotonic(), verdict, self.setpoint_m)
        return verdict

    def recording(self, kind: str) -> tuple[str, bytes]:
        """This run's record so far as a file: (file name, contents); ``kind`` is "mat" or "csv"."""
        writers = {"mat": log_io.write_mat, "csv": log_io.write_csv}
        if kind not in writers:
            raise _Refused(f"download = {_show(kind)}: the formats are mat and csv")
        buffer = io.BytesIO()
        writers[kind](self.loop.log(), buffer)
        return f"ballbeam_run{self.runs}_{self.controller_name}.{kind}", buffer.getvalue()

    def _apply_reference(self) -> None:
        if self.supports_reference:
            self.controller.law.ref_x_m = self.reference_x_m

    def _fail(self, exc: BaseException) -> None:
        """Mark the run failed with the reason and the tick, and pause it."""
        if isinstance(exc, ControllerError):  # its message names the controller and the tick
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
        _log(self.error, stream=sys.stdout)

    def _refuse(self, action: str, value: Any, reason: str) -> None:
        refusal = Refusal(action, _show(value), _printable(reason))
        self.refusals.append(refusal)
        self.refused += 1
        self.notice = (time.monotonic(), refusal.reason)
        _log(f"refused {action}: {refusal.reason}", key=f"refused {action}", stream=sys.stdout)

    def apply_actions(self) -> None:
        """Apply the queued actions (at most ``MAX_ACTIONS_PER_FRAME``); never raises."""
        for _ in range(MAX_ACTIONS_PER_FRAME):
            try:
                action, value = self.actions.get_nowait()
            except queue.Empty:
                return
            self.apply(action, value)

    def apply(self, action: str, value: Any = None) -> None:
        """Apply one action now: a bad value is refused (state unchanged), a failure marks the run failed."""
        handler = self._HANDLERS.get(action) if isinstance(action, str) else None
        try:
            if handler is None:
                raise _Refused(f"unknown action {_show(action)}")
            handler(self, value)
        except _Refused as exc:
            self._refuse(str(action), value, str(exc))
        except Exception as exc:  # noqa: BLE001 - an action that breaks the rig fails the run, not the server
            self._fail(exc)
        else:
            shown = "" if value is None else f" {_show(value)}"
            _log(f"t = {self.rig.time_s:.2f} s: {action}{shown}", key=f"action {action}", stream=sys.stdout)

    def _do_connected(self, value: Any) -> None:
        if self.awaiting_client:  # the first browser: a fresh run from t = 0, running
            self.awaiting_client = False
            self.runs = 0  # nobody saw the run built while waiting: the first one watched is run 1
            self._start_run(self.controller_name)
            self.running = self.error is None

    def _do_download(self, value: Any) -> None:
        if not isinstance(value, tuple) or len(value) != 2 or not callable(value[1]):
            raise _Refused(f"download = {_show(value)} is not (format, receiver)")
        kind, send = value
        name, data = self.recording(kind)
        send(name, data)

    def _do_controller(self, value: Any) -> None:
        if not isinstance(value, str) or value not in self.catalogue.NAMES:
            raise _Refused(f"unknown controller {_show(value)}; known: {', '.join(self.catalogue.NAMES)}")
        if value != self.controller_name:
            self._start_run(value)

    def _do_reset(self, value: Any) -> None:
        self._start_run(self.controller_name)

    def _do_run(self, value: Any) -> None:
        self.running = _boolean("run", value) and self.error is None

    def _do_step(self, value: Any) -> None:
        self.running = False
        self.tick()

    def _check_initial(self, x0: Any, theta0: Any) -> tuple[float, float]:
        p = self.params
        x = _number("x0", x0, p.track.half_length_m, "m")
        th = _number("θ0", theta0, p.beam.stop_angle_rad, "rad")
        try:
            check_initial_state(p, x, th, 0.0, 0.0)  # the rig's own rule, should it ever be stricter
        except ValueError as exc:
            raise _Refused(str(exc)) from None
        return x, th

    def _do_x0(self, value: Any) -> None:
        self.x0_m, self.theta0_rad = self._check_initial(value, self.theta0_rad)

    def _do_theta0(self, value: Any) -> None:
        self.x0_m, self.theta0_rad = self._check_initial(self.x0_m, value)

    def _do_initial(self, value: Any) -> None:
        if not isinstance(value, (tuple, list)) or len(value) != 2:
            raise _Refused(f"initial = {_show(value)} is not a pair (x0, θ0)")
        self.x0_m, self.theta0_rad = self._check_initial(value[0], value[1])

    def _do_flick(self, value: Any) -> None:
        self.rig.kick_ball(_number("flick", value, FLICK_MAX_M_S, "m/s"))

    def _do_noise(self, value: Any) -> None:
        noise = _boolean("noise", value)
        if noise != self.noise:
            self.rig.set_noise(noise)
            self.noise = noise

    def _do_speed(self, value: Any) -> None:
        self.speed = _number("speed", value, SPEED_MAX, "", low=SPEED_MIN)

    def _do_reference(self, value: Any) -> None:
        self.reference_x_m = _number("setpoint", value, self.params.track.half_length_m, "m")
        self._apply_reference()

    _HANDLERS: dict[str, Callable[[LiveTwin, Any], None]] = {
        "controller": _do_controller,
        "reset": _do_reset,
        "run": _do_run,
        "step": _do_step,
        "x0": _do_x0,
        "theta0": _do_theta0,
        "initial": _do_initial,
        "flick": _do_flick,
        "noise": _do_noise,
        "speed": _do_speed,
        "reference": _do_reference,
        "connected": _do_connected,
        "download": _do_download,
    }

    def tick(self) -> None:
        """One 20 ms frame of simulated time: as many control periods as fit in it. Never raises: a failure
        marks the run failed."""
        if self.error is not None:
            return
        try:
            n = max(1, int(round(FRAME_S / self.rig.period_s)))
            for _ in range(n):
                self.loop.tick()
            self._record()
        except Exception as exc:  # noqa: BLE001 - a failing controller or rig fails the run, not the server
            self._fail(exc)
            return
        if self.rig.ball_lost and not self.lost_paused:  # an event: pause on the state it left with
            self.lost_paused = True
            self.running = False
            _log(
                f"ball lost at t = {self.rig.ball_lost_time_s:.2f} s: paused (Reset starts again)",
                stream=sys.stdout,
            )

    def _record(self) -> None:
        x, theta, xdot, thetadot = self.rig.true_state()
        est = self.controller.telemetry.estimate
        s = self.last_sample
        sw = self.rig.params.software
        nan = float("nan")
        self.history.append(
            t=self.rig.time_s,
            x_true=x,
            x_meas=converters.ball_position_m(s.ball_v, sw) if s is not None else nan,
            x_est=est[0],
            x_ref=self.setpoint_m,
            th_true=theta,
            th_meas=converters.beam_angle_rad(s.angle_v, sw) if s is not None else nan,
            th_est=est[1],
            xdot_true=xdot,
            xdot_est=est[2],
            thdot_true=thetadot,
            thdot_est=est[3],
            ball_v=s.ball_v if s is not None else nan,
            angle_v=s.angle_v if s is not None else nan,
            dac_v=self.loop.command_v,
            volts=self.rig.motor_volts_v,
        )

    def status_markdown(self) -> str:
        if self.awaiting_client:
            state = "waiting for a browser"
        else:
            state = "running" if self.running else "paused"
        ball = (
            f"**ball lost** at {self.rig.ball_lost_time_s:.2f} s — paused; Reset starts again"
            if self.rig.ball_lost
            else "ball on the beam"
        )
        verdict = self.verdict()
        judged = (
            f"  \n{_markdown_text(verdict_text(verdict, self.setpoint_m))}" if verdict is not None else ""
        )
        pending = ""
        if self.initial_pending:
            pending = (
                f"  \n*x0 = {self.x0_m:+.2f} m, θ0 = {self.theta0_rad:+.2f} rad apply on Reset* "
                f"(this run started at {self.run_x0_m:+.2f} m, {self.run_theta0_rad:+.2f} rad)"
            )
        error = f"  \n**run failed**: {_markdown_text(self.error)}" if self.error else ""
        notice = ""
        if self.notice is not None and time.monotonic() - self.notice[0] < NOTICE_S:
            notice = f"  \n**refused**: {_markdown_text(self.notice[1])}"
        return (
            f"run {self.runs} · **t = {self.rig.time_s:.2f} s** · {state} · controller: "
            f"**{_markdown_text(self.controller_name)}** · {ball}  \n"
            f"noise {'on' if self.noise else 'off'} · speed ×{self.speed:g}{self._speed_note()} · "
            f"motor {self.rig.motor_volts_v:+.2f} V{judged}{pending}{error}{notice}"
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
        where = f" at x = {x:+.3f} m" if math.isfinite(x) else ""
        return (
            f"Ball lost at t = {self.rig.ball_lost_time_s:.2f} s: it left the track{where}. The run is paused "
            f"({verdict_text(verdict, self.setpoint_m) if verdict is not None else 'no verdict'}). "
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


def verdict_text(v: Verdict, setpoint_m: float = 0.0) -> str:
    """One line for a person watching: the verdict of the run so far."""
    if v.ball_lost:
        return f"verdict: lost (ball off the track at {v.ball_lost_time_s:.2f} s)"
    if v.steady_x_m is None:
        return f"verdict so far: too early to tell ({v.reason})"
    parts = ["held" if v.held else f"not held: {v.reason}"]
    if v.settling_time_s is not None:
        parts.append(f"settled in {v.settling_time_s:.2f} s")
    parts.append(f"steady x {v.steady_x_m * 1e3:+.1f} mm" + (" from the setpoint" if setpoint_m else ""))
    if v.limit_cycle_x_pp_m is not None:
        parts.append(f"cycle {v.limit_cycle_x_pp_m * 1e3:.1f} mm p-p")
    parts.append(f"peak {v.peak_motor_voltage_v:.1f} V ({100 * v.saturated_fraction:.0f} % at the rails)")
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


# --- who may connect --------------------------------------------------------------------------------------
_LOOPBACK_NAMES = frozenset({"localhost", "127.0.0.1", "::1"})


def _is_ip(name: str) -> bool:
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True


def is_loopback(host: str) -> bool:
    """Whether ``host`` (as given to ``--host``) reaches this machine only."""
    name = host.strip().lower().strip("[]")
    if name in _LOOPBACK_NAMES:
        return True
    if _is_ip(name):
        return ipaddress.ip_address(name).is_loopback
    try:
        infos = socket.getaddrinfo(name, None)
    except (socket.gaierror, UnicodeError):
        return False
    return bool(infos) and all(
        ipaddress.ip_address(str(info[4][0]).split("%")[0]).is_loopback for info in infos
    )


def _is_wildcard(host: str) -> bool:
    name = host.strip().strip("[]")
    return name == "" or (_is_ip(name) and ipaddress.ip_address(name).is_unspecified)


def _split_host(value: str) -> tuple[str, int] | None:
    """A ``Host`` header as (name, port), or None if it is not a plain host[:port]."""
    if not value or "@" in value or "/" in value or any(c.isspace() for c in value):
        return None
    try:
        parts = urlsplit("//" + value)
        port = parts.port
    except ValueError:
        return None
    if not parts.hostname or parts.path or parts.query or parts.fragment:
        return None
    return parts.hostname.lower(), port if port is not None else 80


def _split_origin(value: str) -> tuple[str, str, int] | None:
    """An origin as (scheme, name, port), or None if it is not a plain http(s)://host[:port]."""
    try:
        parts = urlsplit(value)
        port = parts.port
    except ValueError:
        return None
    if parts.scheme not in ("http", "https") or not parts.hostname or parts.username or parts.password:
        return None
    if parts.path not in ("", "/") or parts.query or parts.fragment:
        return None
    return (
        parts.scheme,
        parts.hostname.lower(),
        port if port is not None else (80 if parts.scheme == "http" else 443),
    )


@dataclass(frozen=True)
class OriginPolicy:
    """Which HTTP requests and websocket handshakes the server accepts.

    A request's ``Host`` header must name this server: the bound host or ``localhost`` at the bound port
    (and 127.0.0.1 / ::1 when bound to loopback; any IP address or this machine's name when bound to every
    interface) — a name an attacker's DNS could point here (DNS rebinding) is refused. A websocket
    handshake must carry an ``Origin`` that is the page's own origin, http://HOST:PORT with HOST one of
    those names (bound to every interface: the Host header's own name), or one of ``extra_origins`` — a page
    on another site cannot open one through the user's browser."""

    port: int
    host_names: frozenset[str]
    any_ip: bool = False  # bound to every interface: any IP literal names this server
    extra_origins: frozenset[tuple[str, str, int]] = frozenset()

    @classmethod
    def for_bind(cls, host: str, port: int, extra_origins: Sequence[str] = ()) -> OriginPolicy:
        names = {host.strip().lower().strip("[]"), "localhost"}
        wildcard = _is_wildcard(host)
        if wildcard or is_loopback(host):
            names |= _LOOPBACK_NAMES
        if wildcard:
            names |= {socket.gethostname().lower(), socket.getfqdn().lower()}
        names.discard("")
        extra = set()
        for origin in extra_origins:
            parsed = _split_origin(origin.strip()) if isinstance(origin, str) else None
            if parsed is None:
                raise ViewerError(
                    f"allowed origin {_show(origin)} is not scheme://host[:port] (http or https, no path)"
                )
            extra.add(parsed)
        return cls(port, frozenset(names), wildcard, frozenset(extra))

    def _host_ok(self, name: str, port: int) -> bool:
        if port == self.port and (name in self.host_names or (self.any_ip and _is_ip(name))):
            return True
        return any((name, port) == (n, p) for _, n, p in self.extra_origins)  # behind a proxy of theirs

    def refusal(self, hosts: Sequence[str], origins: Sequence[str], *, websocket: bool) -> str | None:
        """Why a request with these ``Host`` and ``Origin`` header values is refused, or None."""
        if len(hosts) != 1:
            return f"{len(hosts)} Host headers"
        host = _split_host(hosts[0])
        if host is None or not self._host_ok(*host):
            return f"Host {_show(hosts[0])} does not name this server"
        if not origins:
            return "a websocket without an Origin header" if websocket else None
        if len(origins) != 1:
            return f"{len(origins)} Origin headers"
        origin = _split_origin(origins[0])
        if origin is None:
            return f"Origin {_show(origins[0])} is not this page's"
        scheme, name, port = origin
        if origin in self.extra_origins:
            return None
        if scheme == "http" and port == self.port and name in self.host_names:
            return None
        if self.any_ip and scheme == "http" and (name, port) == host:
            return None
        return f"Origin {_show(origins[0])} is not this page's"


class _WebsocketHook:
    """Installs the origin policy, a message size limit and one-line error logs on viser's websocket server.

    viser 1.1 builds its server inside its own thread with ``websockets.asyncio.server.serve(ws_handler, host,
    port, process_request=…, max_size=50 MB, …)`` and exposes no hook. While the ``ViserServer`` is being
    constructed, ``serve`` is replaced by a wrapper that, for viser's call only, puts the policy in front of
    viser's ``process_request`` (a refused handshake gets HTTP 403), lowers ``max_size`` and routes the
    library's logs through ``_WS_LOGGER``. The constructor returns only once viser's thread has called
    ``serve``; ``installed`` says whether it did (if not, the viewer refuses to start)."""

    _lock = threading.Lock()  # one construction at a time patches the module

    def __init__(self, policy: OriginPolicy, on_refused: Callable[[str], None]) -> None:
        self.policy = policy
        self.on_refused = on_refused
        self.installed = False

    def process_request(self, inner: Callable[..., Any] | None) -> Callable[..., Any]:
        def process_request(connection: Any, request: Any) -> Any:
            headers = request.headers
            websocket = any("websocket" in v.lower() for v in headers.get_all("Upgrade"))
            reason = self.policy.refusal(
                headers.get_all("Host"), headers.get_all("Origin"), websocket=websocket
            )
            if reason is not None:
                self.on_refused(reason)
                return connection.respond(http.HTTPStatus.FORBIDDEN, f"Forbidden: {reason}\n")
            return inner(connection, request) if inner is not None else None

        return process_request

    @contextlib.contextmanager
    def installed_on_viser(self) -> Iterator[None]:
        import websockets.asyncio.server as ws_server

        original = ws_server.serve

        def serve(handler: Any, *args: Any, **kwargs: Any) -> Any:
            if getattr(handler, "__module__", "") == "viser.infra._infra":
                kwargs["process_request"] = self.process_request(kwargs.get("process_request"))
                kwargs["max_size"] = MAX_MESSAGE_BYTES
                kwargs["logger"] = _WS_LOGGER
                self.installed = True
            return original(handler, *args, **kwargs)

        with self._lock:
            ws_server.serve = serve  # type: ignore[misc,assignment]
            try:
                yield
            finally:
                ws_server.serve = original  # type: ignore[misc]


def _loop_exception(loop: Any, context: dict[str, Any]) -> None:
    """viser's event loop: a client message whose handler raised is one line, not a traceback."""
    exc = context.get("exception")
    text = f"{type(exc).__name__}: {exc}" if exc is not None else str(context.get("message", ""))
    _log(f"a client message failed ({text})", key="message failed")


# --- scene ------------------------------------------------------------------------------------------------
def _rgb(model: mujoco.MjModel, geom: int) -> tuple[int, int, int]:
    mat = model.geom_matid[geom]
    rgba = model.mat_rgba[mat] if mat >= 0 else model.geom_rgba[geom]
    r, g, b = (int(round(255 * c)) for c in rgba[:3])
    return r, g, b


def build_scene(server: viser.ViserServer, model: mujoco.MjModel) -> dict[int, Any]:
    """Every geom of the MuJoCo model as a viser node under a frame per body; returns body id → frame."""
    frames: dict[int, Any] = {}
    for body in range(model.nbody):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, body) or "world"
        frames[body] = server.scene.add_frame(f"/{name}", show_axes=False)
    for g in range(model.ngeom):
        body = model.geom_bodyid[g]
        body_name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, body) or "world"
        name = f"/{body_name}/{mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g)}"
        px, py, pz = (float(v) for v in model.geom_pos[g])
        qw, qx, qy, qz = (float(v) for v in model.geom_quat[g])
        position, wxyz = (px, py, pz), (qw, qx, qy, qz)
        size, color, kind = model.geom_size[g], _rgb(model, g), model.geom_type[g]
        if kind == mujoco.mjtGeom.mjGEOM_PLANE:
            server.scene.add_box(
                name,
                color=color,
                dimensions=(2 * size[0], 2 * size[1], 0.002),
                position=(px, py, -0.001),
                wxyz=wxyz,
            )
        elif kind == mujoco.mjtGeom.mjGEOM_BOX:
            sx, sy, sz = (float(2 * v) for v in size)
            server.scene.add_box(name, color=color, dimensions=(sx, sy, sz), position=position, wxyz=wxyz)
        elif kind == mujoco.mjtGeom.mjGEOM_SPHERE:
            server.scene.add_icosphere(
                name, radius=float(size[0]), color=color, subdivisions=3, position=position, wxyz=wxyz
            )
        elif kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
            server.scene.add_cylinder(
                name,
                radius=float(size[0]),
                height=float(2 * size[1]),
                color=color,
                position=position,
                wxyz=wxyz,
            )
        elif kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
            mesh = trimesh.creation.capsule(height=float(2 * size[1]), radius=float(size[0]), count=[12, 12])
            server.scene.add_mesh_simple(
                name,
                vertices=np.asarray(mesh.vertices, dtype=np.float32),
                faces=np.asarray(mesh.faces, dtype=np.uint32),
                color=color,
                position=position,
                wxyz=wxyz,
            )
    return frames


def _on_camera(name: str, event: Any) -> None:
    _set_camera(event.client, name)


def _set_camera(client: Any, name: str) -> None:
    """One browser's camera to a preset (per client: other viewers keep their own view)."""
    if client is None or name not in CAMERAS:
        return
    position, look_at, up = CAMERAS[name]
    with client.atomic():
        client.camera.up_direction = up
        client.camera.position = position
        client.camera.look_at = look_at


def parameter_changes(params: Parameters) -> list[str]:
    """``group.name = value`` for every parameter that differs from the defaults."""
    ours, defaults = params.to_dict(), Parameters().to_dict()
    changes = []
    for group, values in ours.items():
        for name, value in values.items():
            if defaults.get(group, {}).get(name) != value:
                changes.append(f"{group}.{name} = {_show(value, 80)}")
    return changes


def _free_port_or_raise(host: str, port: int) -> None:
    """viser moves silently to the next free port; a taken port is an error here instead."""
    if not 1 <= port <= 65535:
        raise ViewerError(f"--port {port} is not a TCP port (1–65535)")
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except socket.gaierror as exc:
        raise ViewerError(f"--host {host!r} cannot be resolved: {exc}") from None
    family, _, _, _, address = infos[0]
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind(address)
        except OSError as exc:
            raise ViewerError(
                f"port {port} on {host} is taken ({exc.strerror}); choose another with --port"
            ) from None


# --- server -----------------------------------------------------------------------------------------------
class Viewer:
    """viser server + GUI around a ``LiveTwin``, paced by the wall clock."""

    def __init__(
        self,
        live: LiveTwin,
        host: str,
        port: int,
        allowed_origins: Sequence[str] = (),
        params_source: str = "",
    ) -> None:
        _free_port_or_raise(host, port)
        self.live = live
        self.params_source = params_source
        self.policy = OriginPolicy.for_bind(host, port, allowed_origins)
        self.refused_connections = 0  # handshakes refused by the origin policy
        self.dropped_messages = 0  # GUI messages dropped before viser applied them
        self.owed_s = self.max_owed_s = 0.0  # the pacing's debt now and at most (seconds of simulated time)
        hook = _WebsocketHook(self.policy, self._refused_connection)
        with hook.installed_on_viser():
            self.server = viser.ViserServer(host=host, port=port, verbose=False)
        if not hook.installed:
            self.server.stop()
            raise ViewerError(
                f"viser {viser.__version__} builds its websocket server differently from 1.1: the Origin/Host "
                "check cannot be installed, so the live view does not start"
            )
        if self.server.get_port() != port:
            self.server.stop()
            raise ViewerError(f"port {port} on {host} is taken; choose another with --port")
        self.host, self.port = host, port
        self._harden_messages()
        self.server.gui.configure_theme(show_share_button=False, control_width="medium")
        position, look_at, up = CAMERAS[DEFAULT_CAMERA]
        self.server.initial_camera.position = position
        self.server.initial_camera.look_at = look_at
        self.server.initial_camera.up = up
        # The reference model has no geometry: a MuJoCo model of the same rig shows its state.
        self._display = Plant(live.params)
        self.frames = build_scene(self.server, self._display.model)
        # The setpoint on the beam: a thin flag across both wires above the ball's path, in the beam's frame.
        p = live.params
        self._setpoint_flag_z_m = p.ball_centre_height_m + 0.5 * sum(SETPOINT_FLAG_M)
        self.setpoint_marker = self.server.scene.add_box(
            "/beam/setpoint",
            color=(20, 20, 20),
            dimensions=(0.002, 0.04, SETPOINT_FLAG_M[1] - SETPOINT_FLAG_M[0]),
            position=(live.setpoint_m, 0.0, self._setpoint_flag_z_m),
        )
        self._shown_setpoint = live.setpoint_m
        self._build_gui()
        self.server.on_client_connect(lambda _client: live.enqueue("connected"))
        self._frame_count = 0
        self._pending: list[Refusal] = []  # refusals not yet notified
        self._last_notify = -math.inf
        self._notified_error: str | None = None
        self._last_loop_error = ""
        self._lost_run: int | None = None  # the run whose lost ball is notified
        self._lost_notices: list[Any] = []

    def _refused_connection(self, reason: str) -> None:
        self.refused_connections += 1
        _log(f"refused a connection: {reason}", key="refused connection")

    def _harden_messages(self) -> None:
        """What a client's messages can reach: only the value of a known control, of its own type (checked
        here, before viser applies it; the loop checks the value itself); never the share tunnel (which the
        hidden Share button would otherwise still open to the internet on request) nor file uploads; and a
        handler that raises is one log line."""
        ws = self.server._websock_server
        handlers = ws._incoming_handlers.get(viser_messages.GuiUpdateMessage, [])
        original = self.server.gui._handle_gui_updates
        index = next((i for i, cb in enumerate(handlers) if cb == original), None)
        if index is None:
            self.server.stop()
            raise ViewerError(f"viser {viser.__version__}: its GUI update handler was not found")

        async def checked(client_id: Any, message: Any) -> None:
            reason = self._gui_update_refusal(message)
            if reason is not None:
                self.dropped_messages += 1
                _log(f"dropped a GUI message: {reason}", key="dropped message")
                return
            await original(client_id, message)

        handlers[index] = checked
        for message_type in (
            viser_messages.ShareUrlRequest,  # the share tunnel
            viser_messages.ShareUrlDisconnect,
            viser_messages.FileTransferStartUpload,  # uploads (there is no upload button: only memory to fill)
            viser_messages.FileTransferPart,
        ):
            if message_type in ws._incoming_handlers:
                ws.unregister_handler(message_type)
        loop = ws._background_event_loop
        if loop is not None:
            loop.call_soon_threadsafe(loop.set_exception_handler, _loop_exception)

    def _gui_update_refusal(self, message: Any) -> str | None:
        uuid, updates = getattr(message, "uuid", None), getattr(message, "updates", None)
        handle = self.server.gui._gui_input_handle_from_uuid.get(uuid) if isinstance(uuid, str) else None
        if handle is None:
            return f"no control {_show(uuid)}"
        if not isinstance(updates, dict) or set(updates) != {"value"}:
            return f"only a control's value may change, not {_show(updates)}"
        value, kind = updates["value"], type(handle.value)
        if kind is bool:
            ok = isinstance(value, bool)
        elif kind is str:
            ok = isinstance(value, str) and len(value) <= 200
        elif kind in (int, float):
            ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        else:
            ok = False
        return None if ok else f"{handle.label!r} = {_show(value)} is not a {kind.__name__}"

    def _build_gui(self) -> None:
        gui, live, p = self.server.gui, self.live, self.live.params
        # The sliders stay inside the track and the stops of these parameters.
        x_max = min(X0_SLIDER_M, p.track.half_length_m)
        th_max = min(THETA0_SLIDER_RAD, p.beam.stop_angle_rad)
        ref_max = min(SETPOINT_SLIDER_M, p.track.half_length_m)
        self.banner = gui.add_html("", visible=False)
        self.status = gui.add_markdown(live.status_markdown())
        with gui.add_folder("Run"):
            controller = gui.add_dropdown(
                "Controller", options=live.catalogue.NAMES, initial_value=live.controller_name
            )
            run = gui.add_button("Pause")
            step = gui.add_button("Step 20 ms")
            reset = gui.add_button("Reset", hint="Start a new run from x0, θ0 (and re-place a lost ball)")
            speed = gui.add_slider("Speed", min=SPEED_MIN, max=SPEED_MAX, step=0.1, initial_value=live.speed)
            noise = gui.add_checkbox("Sensor noise", initial_value=live.noise)
        with gui.add_folder("Initial state (applies on Reset)"):
            x0 = gui.add_slider(
                "x0 (m)",
                min=-x_max,
                max=x_max,
                step=0.01,
                initial_value=live.x0_m,
                hint="Where the ball is held before release; press Reset to apply",
            )
            th0 = gui.add_slider(
                "θ0 (rad)",
                min=-th_max,
                max=th_max,
                step=0.01,
                initial_value=live.theta0_rad,
                hint="Where the beam is held before release; press Reset to apply",
            )
        with gui.add_folder("Disturb"):
            kick = gui.add_slider(
                "Flick (m/s)", min=0.02, max=0.5, step=0.01, initial_value=FLICK_DEFAULT_M_S
            )
            flick_left = gui.add_button("Flick ◀")
            flick_right = gui.add_button("Flick ▶")
            reference = gui.add_slider(
                "Setpoint x (m)",
                min=-ref_max,
                max=ref_max,
                step=0.01,
                initial_value=0.0,
                disabled=not live.supports_reference,
                hint=live.setpoint_reason,
            )
            self.setpoint_note = gui.add_markdown(
                "" if live.supports_reference else f"*{_markdown_text(live.setpoint_reason)}*"
            )
        with gui.add_folder("Record"):
            gui.add_markdown(
                f"Each run is recorded from its start (Reset) for up to {RECORD_LIMIT_S / 60:g} min of "
                "simulated time: the thesis software's `data_file.mat` variables and the twin's true state."
            )
            download_mat = gui.add_button("Download .mat")
            download_csv = gui.add_button("Download CSV")
        with gui.add_folder("Camera"):
            cameras = {name: gui.add_button(name) for name in CAMERAS}
        with gui.add_folder("Parameters", expand_by_default=False):
            gui.add_markdown(self._parameters_markdown())
        self.reference_slider = reference
        self.run_button = run
        self.controls: dict[str, Any] = {
            "controller": controller,
            "run": run,
            "step": step,
            "reset": reset,
            "speed": speed,
            "noise": noise,
            "x0": x0,
            "theta0": th0,
            "flick": kick,
            "flick_left": flick_left,
            "flick_right": flick_right,
            "setpoint": reference,
            "download_mat": download_mat,
            "download_csv": download_csv,
            **{f"camera_{name}": button for name, button in cameras.items()},
        }

        controller.on_update(lambda _: live.enqueue("controller", controller.value))
        run.on_click(lambda _: live.enqueue("run", not live.running))
        step.on_click(lambda _: live.enqueue("step"))
        reset.on_click(lambda _: live.enqueue("reset"))
        speed.on_update(lambda _: live.enqueue("speed", speed.value))
        noise.on_update(lambda _: live.enqueue("noise", noise.value))
        x0.on_update(lambda _: live.enqueue("x0", x0.value))
        th0.on_update(lambda _: live.enqueue("theta0", th0.value))
        flick_left.on_click(lambda _: live.enqueue("flick", -kick.value))
        flick_right.on_click(lambda _: live.enqueue("flick", kick.value))
        reference.on_update(lambda _: live.enqueue("reference", reference.value))
        download_mat.on_click(lambda event: self._download(event.client, "mat"))
        download_csv.on_click(lambda event: self._download(event.client, "csv"))
        for name, button in cameras.items():
            button.on_click(functools.partial(_on_camera, name))

        # The plots in their own panel, docked left of the view: all of them visible at 1400 × 900.
        # Compact: the quantity as the y-axis label (no title), a static legend, a low time axis.
        scales: dict[str, viser.uplot.Scale] = {"x": {"time": False, "auto": True}}
        legend: viser.uplot.Legend = {"live": False}
        self.plots = []
        self.plot_panel = gui.add_panel()
        with self.plot_panel.add_tab("Plots (last 10 s, time in s)"):
            for label, traces in PLOTS:
                series = [viser.uplot.Series(label="t (s)")] + [
                    viser.uplot.Series(label=name, stroke=colour, width=1.5) for name, _, colour in traces
                ]
                axes: tuple[viser.uplot.Axis, ...] = (
                    {"size": 26},
                    {"size": PLOT_AXIS_PX, "label": label, "labelSize": 18},
                )
                data = tuple(np.zeros(2) for _ in series)
                handle = gui.add_uplot(
                    data, tuple(series), aspect=PLOT_ASPECT, scales=scales, axes=axes, legend=legend
                )
                self.plots.append((handle, [key for _, key, _ in traces]))
        self.plot_panel.dock_left()
        gui.main_panel.dock_right()  # the view between the two: nothing covers the rig
        self.plot_panel.set_width(PLOT_PANEL_PX)

    def _download(self, client: Any, kind: str) -> None:
        """The loop builds the file (it owns the record); the clicking browser receives it."""
        if client is None:
            return

        def send(name: str, data: bytes) -> None:
            client.send_file_download(name, data, save_immediately=True)

        self.live.enqueue("download", (kind, send))

    def _parameters_markdown(self) -> str:
        """Where the parameters come from, and every value that differs from the thesis's defaults."""
        source = self.params_source or "the thesis's values (no --params, no --set)"
        changed = parameter_changes(self.live.params)
        lines = [f"parameters: **{_markdown_text(source)}**"]
        if changed:
            lines.append("changed from the defaults:")
            lines += [f"- `{_markdown_text(item)}`" for item in changed[:40]]
            if len(changed) > 40:
                lines.append(f"- … and {len(changed) - 40} more")
        else:
            lines.append("every value is the default (see `ballbeam params`)")
        return "  \n".join(lines[:2]) + ("\n\n" + "\n".join(lines[2:]) if len(lines) > 2 else "")

    def _resync(self, action: str) -> None:
        """Put a control whose value was refused back to the state the twin runs with."""
        live, c = self.live, self.controls
        values: dict[str, tuple[tuple[str, Any], ...]] = {
            "controller": (("controller", live.controller_name),),
            "speed": (("speed", live.speed),),
            "noise": (("noise", live.noise),),
            "x0": (("x0", live.x0_m),),
            "theta0": (("theta0", live.theta0_rad),),
            "initial": (("x0", live.x0_m), ("theta0", live.theta0_rad)),
            "reference": (("setpoint", live.reference_x_m),),
            "flick": (("flick", FLICK_DEFAULT_M_S),),
        }
        for name, value in values.get(action, ()):
            c[name].value = value

    def report(self) -> None:
        """Refusals and failures to the browsers: controls put back, a notification (at most two a second)."""
        live = self.live
        while live.refusals:
            refusal = live.refusals.popleft()
            self._pending.append(refusal)
            self._resync(refusal.action)
        now = time.monotonic()
        if self._pending and now - self._last_notify >= NOTIFY_EVERY_S:
            last, more = self._pending[-1], len(self._pending) - 1
            body = last.reason + (f" (and {more} more refused)" if more else "")
            self._notify("Refused", body, "red")
            self._pending.clear()
            self._last_notify = now
        if live.error is not None and live.error != self._notified_error:
            self._notify("Run failed", live.error, "orange")
        self._notified_error = live.error
        # A lost ball stays on screen (the banner may be scrolled away) until the run it belongs to ends.
        lost = live.runs if live.rig.ball_lost else None
        if lost != self._lost_run:
            for handle in self._lost_notices:
                handle.remove()
            self._lost_notices = []
            if lost is not None:
                self._lost_notices = self._notify("Ball lost", live.lost_text(), "red", seconds=None)
            self._lost_run = lost

    def _notify(self, title: str, body: str, color: Any, seconds: float | None = 8.0) -> list[Any]:
        return [
            client.add_notification(title, body, auto_close_seconds=seconds, color=color)
            for client in self.server.get_clients().values()
        ]

    def publish(self) -> None:
        """Send one frame: body poses (and every tenth frame the plots and status), as one batch."""
        live = self.live
        physics = live.rig.physics
        if isinstance(physics, Plant):
            model, data = physics.model, physics.data
        else:
            x, theta = (float(v) for v in live.rig.true_state()[:2])
            p = live.params
            model, data = self._display.model, self._display.data
            self._display.reset(
                float(np.clip(x, -p.track.half_length_m, p.track.half_length_m)) if math.isfinite(x) else 0.0,
                float(np.clip(theta, -p.beam.stop_angle_rad, p.beam.stop_angle_rad))
                if math.isfinite(theta)
                else 0.0,
            )
        mujoco.mj_kinematics(model, data)  # poses of the current state (mj_step leaves xpos one step behind)
        self._frame_count += 1
        with self.server.atomic():
            for body, frame in self.frames.items():
                if body == 0:
                    continue
                frame.position = tuple(data.xpos[body])
                frame.wxyz = tuple(data.xquat[body])
            if self._frame_count % PLOT_EVERY_FRAMES == 0 or not live.running:
                h = live.history
                t = h.array("t")
                if t.size >= 2:
                    for handle, keys in self.plots:
                        handle.data = (t, *(h.array(key) for key in keys))
                self.status.content = live.status_markdown()
                # Only send what changed: re-sending a button's props re-renders it under the user's click.
                label = "Pause" if live.running else "Start"
                if self.run_button.label != label:
                    self.run_button.label = label
                if self.reference_slider.disabled == live.supports_reference:
                    self.reference_slider.disabled = not live.supports_reference
                    self.reference_slider.hint = live.setpoint_reason
                    note = "" if live.supports_reference else f"*{_markdown_text(live.setpoint_reason)}*"
                    self.setpoint_note.content = note
                banner = live.lost_banner_html()
                if self.banner.content != banner:
                    self.banner.content = banner
                    self.banner.visible = bool(banner)
            if self._shown_setpoint != live.setpoint_m:
                self._shown_setpoint = live.setpoint_m
                self.setpoint_marker.position = (live.setpoint_m, 0.0, self._setpoint_flag_z_m)

    def _safely(self, step: Callable[[], None]) -> None:
        """The loop's last line of defence: whatever fails in a frame is one log line, never the server."""
        try:
            step()
        except Exception as exc:  # noqa: BLE001 - the live view keeps serving
            text = f"{getattr(step, '__name__', 'frame')} failed: {type(exc).__name__}: {exc}"
            if text != self._last_loop_error:
                _log(text, key="loop")
                self._last_loop_error = text

    def loop(self, duration_s: float | None, stop: threading.Event) -> dict[str, float]:
        """Run until ``stop`` is set or ``duration_s`` of wall time passed; return pacing figures."""
        live = self.live
        start = time.perf_counter()
        cpu_start = time.process_time()
        sim_ticks = 0
        next_frame = start
        owed_s = 0.0  # simulated time owed to the wall clock at the current speed (at most MAX_OWED_S)
        # Simulated time run against wall time over the last SPEED_WINDOW_S of running: the speed achieved.
        recent: deque[tuple[float, int]] = deque()
        while not stop.is_set():
            now = time.perf_counter()
            if live.running:
                recent.append((now, sim_ticks))
                while recent and now - recent[0][0] > SPEED_WINDOW_S:
                    recent.popleft()
                span = now - recent[0][0]
                live.achieved_speed = (
                    (sim_ticks - recent[0][1]) * FRAME_S / span if span > 0.5 * SPEED_WINDOW_S else None
                )
            else:
                recent.clear()
                live.achieved_speed = None
            if duration_s is not None and now - start >= duration_s:
                break
            self._safely(live.apply_actions)
            if live.running:
                owed_s = owe(owed_s, live.speed)
                self.owed_s, self.max_owed_s = owed_s, max(self.max_owed_s, owed_s)
                while owed_s >= FRAME_S - 1e-12 and live.running:
                    self._safely(live.tick)
                    sim_ticks += 1
                    owed_s -= FRAME_S
            self._safely(self.report)
            self._safely(self.publish)
            next_frame += FRAME_S
            delay = next_frame - time.perf_counter()
            if delay > 0:
                stop.wait(delay)
            elif -delay > MAX_CATCH_UP_S:
                next_frame = time.perf_counter()
        wall = time.perf_counter() - start
        return {
            "wall_s": wall,
            "ticks": sim_ticks,
            "tick_rate_hz": sim_ticks / wall if wall else 0.0,
            "cpu_s_per_tick": (time.process_time() - cpu_start) / max(sim_ticks, 1),
            "sim_time_s": live.rig.time_s,
        }


def serve(
    catalogue: Catalogue,
    *,
    host: str = "127.0.0.1",
    port: int = 8080,
    controller: str = DEFAULT_CONTROLLER,
    speed: float = 1.0,
    seed: int = 0,
    duration_s: float | None = None,
    params: Parameters | None = None,
    plant: PlantKind = "twin",
    ideal_sensors: bool = False,
    announce: bool = True,
    allowed_origins: tuple[str, ...] = (),
    params_source: str = "",
    wait_for_client: bool = True,
    stop: threading.Event | None = None,
    on_ready: Callable[[Viewer], None] | None = None,
) -> dict[str, float]:
    """Start the live view and block until interrupted, ``stop`` is set or ``duration_s`` of wall time passed.

    Browsers connect from the page's own origin only; ``allowed_origins`` adds others (e.g.
    ``("https://twin.lab.example",)`` behind a reverse proxy). A host other than loopback is served with a
    warning on stderr: anyone who can reach it can drive the twin. ``on_ready(viewer)`` is called once the
    server listens (tests). The twin waits, paused, until the first browser connects (``wait_for_client``),
    so that a visitor sees the run from its start; ``params_source`` is shown in the panel."""
    if not (isinstance(speed, (int, float)) and math.isfinite(speed) and SPEED_MIN <= speed <= SPEED_MAX):
        raise ViewerError(
            f"--speed = {speed!r} must be within {SPEED_MIN:g} … {SPEED_MAX:g} (the speed slider)"
        )
    if controller not in catalogue.NAMES:
        raise ViewerError(f"unknown controller {controller!r}; known: {', '.join(catalogue.NAMES)}")
    live = LiveTwin(
        params or Parameters(),
        catalogue,
        controller,
        seed,
        speed,
        plant=plant,
        ideal_sensors=ideal_sensors,
        wait_for_client=wait_for_client,
    )
    viewer = Viewer(live, host, port, allowed_origins, params_source)
    if not is_loopback(host):
        where = "every interface" if _is_wildcard(host) else host
        _log(
            f"warning: serving on {where} (port {port}): anyone who can reach this machine there can watch "
            "and drive the twin — there is no authentication. Serve on 127.0.0.1 (the default) unless that "
            "is what you want."
        )
    if announce:
        print(
            f"ballbeam view: http://{host}:{viewer.server.get_port()} (controller {controller}, speed ×{speed:g})",
            flush=True,
        )
    stop = stop if stop is not None else threading.Event()
    try:
        if on_ready is not None:
            on_ready(viewer)
        return viewer.loop(duration_s, stop)
    except KeyboardInterrupt:
        return {}
    finally:
        viewer.server.stop()
