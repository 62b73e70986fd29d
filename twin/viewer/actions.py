"""The GUI's handlers: a browser's message (an action's name and its raw value) checked as the control's input
and turned into one of the session's typed commands (``Commands``, which ``twin.viewer.session.LiveTwin``
implements).

viser's callbacks (twin.viewer.gui) only enqueue an action on the session; the loop's thread takes it off the
queue and calls its handler here. A handler checks the value against its control (a number, a boolean, a
pair, within the slider's range and, where the parameters narrow the slider, within the track or the stops)
and calls the session's public commands only; the session refuses what depends on its own state (an unknown
controller, a start the rig refuses, a setpoint the controller does not take). A refusal is ``Refused``: the
state is unchanged.

The actions and their values: ``controller`` (a catalogue name), ``reset``, ``run`` (bool), ``step``,
``x0`` (m, within the x0 slider and the track), ``theta0`` (rad, within the θ0 slider and the stops),
``initial`` ((x0, θ0)), ``flick_left`` and ``flick_right`` (the flick slider's speed, m/s), ``flick`` (m/s,
signed, its size within the flick slider), ``noise`` (bool), ``shadow`` (bool), ``drift`` (%, the drift
slider), ``speed`` (the speed slider), ``reference`` (the setpoint, m, within the setpoint slider and the
track), ``connected`` (a browser connected) and ``download`` ((format, receiver))."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from twin.parameters import Parameters
from twin.physics import beam_travel_rad
from twin.viewer.common import DRIFT, FLICK, SETPOINT, SPEED, THETA0, X0, Slider, _show


class Refused(Exception):
    """An action's value is refused; the state is unchanged."""


class Commands(Protocol):
    """What a handler may do to the session: read the parameters and the set start, and call these commands
    (the loop applies each between ticks; a value the session's state refuses raises ``Refused``)."""

    @property
    def params(self) -> Parameters: ...

    @property
    def x0_m(self) -> float: ...

    @property
    def theta0_rad(self) -> float: ...

    def set_controller(self, name: str) -> None: ...

    def reset(self) -> None: ...

    def set_running(self, on: bool) -> None: ...

    def step(self) -> None: ...

    def set_initial_state(self, x0_m: float, theta0_rad: float) -> None: ...

    def flick(self, velocity_m_s: float) -> None: ...

    def set_flick_speed(self, speed_m_s: float) -> None: ...

    def set_noise(self, on: bool) -> None: ...

    def set_shadow(self, on: bool) -> None: ...

    def set_drift(self, percent: float) -> None: ...

    def set_speed(self, speed: float) -> None: ...

    def set_reference(self, x_m: float) -> None: ...

    def client_connected(self) -> None: ...

    def download(self, kind: str, send: Callable[[str, bytes], None]) -> None: ...


Handler = Callable[[Commands, Any], None]


# --- the controls' input ----------------------------------------------------------------------------------
def _number(name: str, value: Any, limit: float, unit: str, *, low: float | None = None) -> float:
    """A finite real number within [low, limit] (low = −limit by default), or refused naming the control."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise Refused(f"{name} = {_show(value)} is not a number")
    try:
        number = float(value)
    except (OverflowError, ValueError):
        raise Refused(f"{name} = {_show(value)} is not a finite number") from None
    if not math.isfinite(number):
        raise Refused(f"{name} = {number!r} is not a finite number")
    low = -limit if low is None else low
    if not low <= number <= limit:
        unit = f" {unit}" if unit else ""
        raise Refused(f"{name} = {number:g}{unit} is outside {low:g} … {limit:g}{unit}")
    return number


def _on_slider(name: str, value: Any, slider: Slider, within: float = math.inf) -> float:
    """A value of a slider's control: inside the slider's range and, where the parameters narrow it (the
    track, the stops), inside ±``within`` too; refused otherwise."""
    return _number(name, value, min(slider.high, within), slider.unit, low=max(slider.low, -within))


def _boolean(name: str, value: Any) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise Refused(f"{name} = {_show(value)} is not a boolean")
    return bool(value)


def _start(live: Commands, x0: Any, theta0: Any) -> None:
    """A new start: each coordinate on its slider, narrowed to the track and the stops."""
    p = live.params
    x = _on_slider("x0", x0, X0, p.track.half_length_m)
    low, high = beam_travel_rad(p)  # the stops, or a lever's reach
    th = _on_slider("θ0", theta0, THETA0, min(-low, high))
    live.set_initial_state(x, th)


# --- the handlers, one per action -------------------------------------------------------------------------
def _controller(live: Commands, value: Any) -> None:
    live.set_controller(value)  # the catalogue is the session's: it refuses a name (or non-name) it lacks


def _reset(live: Commands, value: Any) -> None:
    live.reset()


def _run(live: Commands, value: Any) -> None:
    live.set_running(_boolean("run", value))


def _step(live: Commands, value: Any) -> None:
    live.step()


def _x0(live: Commands, value: Any) -> None:
    _start(live, value, live.theta0_rad)


def _theta0(live: Commands, value: Any) -> None:
    _start(live, live.x0_m, value)


def _initial(live: Commands, value: Any) -> None:
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        raise Refused(f"initial = {_show(value)} is not a pair (x0, θ0)")
    _start(live, value[0], value[1])


def _flick(live: Commands, value: Any) -> None:
    """A signed flick (m/s): its size within the flick slider's range, its sign the direction."""
    velocity = _number("flick", value, FLICK.high, FLICK.unit)
    _on_slider("flick", abs(velocity), FLICK)
    live.flick(velocity)


def _flick_toward(direction: float, live: Commands, value: Any) -> None:
    # The slider's value is a speed: a negative one is refused, never a flick the other way.
    speed = _on_slider("flick", value, FLICK)
    live.set_flick_speed(speed)
    live.flick(direction * speed)


def _flick_left(live: Commands, value: Any) -> None:
    _flick_toward(-1.0, live, value)


def _flick_right(live: Commands, value: Any) -> None:
    _flick_toward(1.0, live, value)


def _noise(live: Commands, value: Any) -> None:
    live.set_noise(_boolean("noise", value))


def _shadow(live: Commands, value: Any) -> None:
    live.set_shadow(_boolean("shadow", value))


def _drift(live: Commands, value: Any) -> None:
    live.set_drift(_on_slider("drift", value, DRIFT))


def _speed(live: Commands, value: Any) -> None:
    live.set_speed(_on_slider("speed", value, SPEED))


def _reference(live: Commands, value: Any) -> None:
    live.set_reference(_on_slider("setpoint", value, SETPOINT, live.params.track.half_length_m))


def _connected(live: Commands, value: Any) -> None:
    live.client_connected()


def _download(live: Commands, value: Any) -> None:
    if not isinstance(value, tuple) or len(value) != 2 or not callable(value[1]):
        raise Refused(f"download = {_show(value)} is not (format, receiver)")
    kind, send = value
    live.download(kind, send)


HANDLERS: dict[str, Handler] = {
    "controller": _controller,
    "reset": _reset,
    "run": _run,
    "step": _step,
    "x0": _x0,
    "theta0": _theta0,
    "initial": _initial,
    "flick": _flick,
    "flick_left": _flick_left,
    "flick_right": _flick_right,
    "noise": _noise,
    "shadow": _shadow,
    "drift": _drift,
    "speed": _speed,
    "reference": _reference,
    "connected": _connected,
    "download": _download,
}
