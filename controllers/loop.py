"""The runtime shape every chapter 4–5 controller shares: state → control law → volts → DAC command.

    measured volts ──convert──► (x, θ) ──observer──► (x, θ, ẋ̂, θ̇̂) ──law──► u (V or N·m) ──► command (V)

``LoopController`` is a hardware ``Controller`` (twin.interface): the state comes from the measured volts,
converted with the rig software's calibration (``params.software``, received, not imported), and an
observer (§5.2) or a Kalman filter for the velocities. ``TrueStateLaw`` is the chapter 4 path: the same
laws on the plant's true state, simulation only (twin.engine.StateLaw), never through the hardware contract.
A torque law is turned into motor volts by inverting the motor law (eq 3.3.1, twin.dcmotor).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal, Protocol

import numpy as np

from controllers.design import ReducedObserver
from twin import converters
from twin import fixedorder as fo
from twin.dcmotor import volts_for_torque_v
from twin.interface import Controller, DaqSample, Telemetry
from twin.parameters import SoftwareCalibration

__all__ = [
    "LoopController",
    "MotorInverse",
    "ObserverState",
    "SetpointLoopController",
    "SetpointTrueStateLaw",
    "StateSource",
    "TrueStateLaw",
    "measured_xa",
]


class StateSource(Protocol):
    """Turns the measured (x, θ) of each tick into the full state estimate."""

    def start(self, xa: np.ndarray) -> np.ndarray: ...

    def update(self, xa: np.ndarray, u_prev: float) -> np.ndarray: ...


def measured_xa(sample: DaqSample, sw: SoftwareCalibration) -> np.ndarray:
    """(x, θ) from the raw volts with the rig software's converters (eq 6.3.1, eq 6.2.10)."""
    return np.array(
        [converters.ball_position_m(sample.ball_v, sw), converters.beam_angle_rad(sample.angle_v, sw)]
    )


class ObserverState:
    """(x, θ) measured, (ẋ, θ̇) from the reduced-order observer (eq 5.2.19), started at zero velocity."""

    def __init__(self, observer: ReducedObserver) -> None:
        self.observer = observer
        # The products in a fixed order (twin.fixedorder), on the design's rows as floats.
        self._f, self._ga, self._gain = observer.f.tolist(), observer.ga.tolist(), observer.gain.tolist()
        self._h0 = observer.h[:, 0].tolist()

    def start(self, xa: np.ndarray) -> np.ndarray:
        self._xa = np.asarray(xa, dtype=float).tolist()
        self._xb = [0.0, 0.0]
        return np.array([*self._xa, *self._xb])

    def update(self, xa: np.ndarray, u_prev: float) -> np.ndarray:
        """x̂_b(k) = F·x̂_b(k−1) + G_a·x_a(k−1) + G·x_a(k) + H·u(k−1) (eq 5.2.19), added in that order."""
        xa_now = np.asarray(xa, dtype=float).tolist()
        terms = zip(
            fo.matvec(self._f, self._xb),
            fo.matvec(self._ga, self._xa),
            fo.matvec(self._gain, xa_now),
            self._h0,
            strict=True,
        )
        self._xb = [f + ga + g + h * u_prev for f, ga, g, h in terms]
        self._xa = xa_now
        return np.array([*xa_now, *self._xb])


@dataclass(frozen=True)
class MotorInverse:
    """V = τ/k_τ + k_b·θ̇ with the constants a design assumes (twin.dcmotor, eq 3.3.1 inverted)."""

    torque_per_volt: float  # N·m/V at the beam (N·K_t/R)
    backemf_at_beam: float  # V·s/rad at the beam (N·K_b)

    def volts(self, torque_nm: float, thetadot_rad_s: float) -> float:
        return float(
            volts_for_torque_v(torque_nm, thetadot_rad_s, self.torque_per_volt, self.backemf_at_beam)
        )


def _volts(
    law_u: float, x: np.ndarray | Sequence[float], u_kind: str, motor: MotorInverse | None, name: str
) -> float:
    if not math.isfinite(law_u):
        raise FloatingPointError(f"{name}: control law returned {law_u!r} for state {np.asarray(x).tolist()}")
    if u_kind == "torque":
        assert motor is not None
        return motor.volts(law_u, float(x[3]))
    return law_u


class LoopController(Controller):
    """State source + control law + output stage, with the software's command limits.

    ``law(x)`` returns u in volts (``u_kind='volts'``) or N·m (``'torque'``). ``observer_input`` says what
    the observer is told the input was: the volts actually commanded after the limits (``'applied_volts'``,
    as the appendix's state feedback does) or the law's u as computed (``'law'``, as the appendix's control
    law partitioning feeds its torque)."""

    def __init__(
        self,
        name: str,
        state: StateSource,
        law: Callable[[np.ndarray], float],
        *,
        software: SoftwareCalibration,
        u_kind: Literal["volts", "torque"],
        motor: MotorInverse | None = None,
        observer_input: Literal["applied_volts", "law"] = "applied_volts",
        command_limits: bool = True,
        period_s: float = 0.02,
        description: str = "",
    ) -> None:
        super().__init__()
        if u_kind == "torque" and motor is None:
            raise ValueError(f"{name}: a torque law needs the motor inverse to produce volts")
        self.name = name
        self.description = description
        self.state = state
        self.law = law
        self.software = software
        self.u_kind = u_kind
        self.motor = motor
        self.observer_input = observer_input
        self.command_limits = command_limits
        self.period_s = period_s
        self._u_prev = 0.0

    def start(self, sample: DaqSample) -> None:
        x = self.state.start(measured_xa(sample, self.software))
        self._u_prev = 0.0
        self.telemetry = Telemetry(x, 0.0, 0.0)

    def update(self, sample: DaqSample) -> float:
        sw = self.software
        x = self.state.update(measured_xa(sample, sw), self._u_prev)
        u = float(self.law(x))
        volts = _volts(u, x, self.u_kind, self.motor, self.name)
        command = converters.dac_command_v(volts, sw)
        if self.command_limits:
            command = converters.clip_command_v(command, sw)
        applied_volts = converters.motor_volts_from_command(command, sw)
        self._u_prev = applied_volts if self.observer_input == "applied_volts" else u
        logged_u = u if self.u_kind == "torque" else applied_volts
        self.telemetry = Telemetry(x, logged_u, u if self.u_kind == "torque" else volts)
        return command


class TrueStateLaw:
    """A law on the plant's true state, every ``period_s`` (the thesis's chapter 4 simulations, all four
    states measured). Simulation only: a ``twin.engine.StateLaw``, not a ``Controller``. Its volts go to the
    motor directly (the amplifier's rails still apply; no DAC, no command limits)."""

    def __init__(
        self,
        name: str,
        law: Callable[[np.ndarray], float],
        *,
        u_kind: Literal["volts", "torque"],
        motor: MotorInverse | None = None,
        period_s: float = 0.001,
        description: str = "",
    ) -> None:
        if u_kind == "torque" and motor is None:
            raise ValueError(f"{name}: a torque law needs the motor inverse to produce volts")
        self.name = name
        self.description = description
        self.law = law
        self.u_kind = u_kind
        self.motor = motor
        self.period_s = period_s
        # The laws of controllers.laws also take the state as four Python floats (``of_floats``): no arrays
        # per physics step. Looked up once: ``law`` is this object's for good.
        self._of_floats: Callable[..., float] | None = getattr(law, "of_floats", None)
        self.reset()

    def reset(self) -> None:
        self._last: tuple[tuple[float, ...], float, float] | None = None
        self._telemetry = Telemetry()

    @property
    def telemetry(self) -> Telemetry:
        """The last evaluation's state, u and volts (built when read: the law runs every physics step, the
        log reads it once per tick)."""
        if self._last is not None:
            x, u, volts = self._last
            self._telemetry = Telemetry(np.array(x), u, volts)
            self._last = None
        return self._telemetry

    def motor_volts(self, state: np.ndarray) -> float:
        return self.motor_volts_of_floats(*np.asarray(state, dtype=float).tolist())

    def motor_volts_of_floats(
        self, x_m: float, theta_rad: float, xdot_m_s: float, thetadot_rad_s: float
    ) -> float:
        """``motor_volts`` on the state as four Python floats (twin.engine passes it so every physics step)."""
        x = (x_m, theta_rad, xdot_m_s, thetadot_rad_s)
        of_floats = self._of_floats
        u = float(of_floats(*x) if of_floats is not None else self.law(np.array(x)))
        volts = _volts(u, x, self.u_kind, self.motor, self.name)
        self._last = (x, u, volts)
        return volts


class _LawSetpoint:
    """``setpoint_m`` (twin.interface.Setpoint): the ball position the law regulates to, its ``ref_x_m``. A
    class of its own (not a property of every loop) so that only loops whose law has a setpoint declare one."""

    law: Any

    @property
    def setpoint_m(self) -> float:
        return self.law.ref_x_m

    @setpoint_m.setter
    def setpoint_m(self, value: float) -> None:
        self.law.ref_x_m = value


def _require_setpoint(name: str, law: object) -> None:
    if not hasattr(law, "ref_x_m"):
        raise TypeError(f"{name}: its law has no ball setpoint (ref_x_m)")


class SetpointLoopController(_LawSetpoint, LoopController):
    """A ``LoopController`` whose law has a ball setpoint. A law with an integrator (``reset``) starts it
    from zero at each ``start``, so that a reused controller runs as a fresh one."""

    def __init__(
        self, name: str, state: StateSource, law: Callable[[np.ndarray], float], **kwargs: Any
    ) -> None:
        _require_setpoint(name, law)
        super().__init__(name, state, law, **kwargs)

    def start(self, sample: DaqSample) -> None:
        reset = getattr(self.law, "reset", None)
        if reset is not None:
            reset()
        super().start(sample)


class SetpointTrueStateLaw(_LawSetpoint, TrueStateLaw):
    """A ``TrueStateLaw`` whose law has a ball setpoint."""

    def __init__(self, name: str, law: Callable[[np.ndarray], float], **kwargs: Any) -> None:
        _require_setpoint(name, law)
        super().__init__(name, law, **kwargs)
