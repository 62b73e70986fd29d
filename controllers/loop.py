"""The runtime shape every chapter 4–5 controller shares: state → control law → volts → DAC command.

    measured volts ──convert──► (x, θ) ──observer──► (x, θ, ẋ̂, θ̇̂) ──law──► u (V or N·m) ──► command (V)

The state comes either from the reduced-order observer (the rig's way, §5.2) or, for the chapter 4
simulations, from the twin's true state (``TrueState``: simulation only, all four states "measured").
A torque law is turned into motor volts by inverting the motor law (eq 3.3.1), as the rig software does.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np

from controllers.design import ReducedObserver
from twin import converters
from twin.interface import Controller, DaqSample, Telemetry

__all__ = ["StateSource", "ObserverState", "TrueState", "MotorInverse", "LoopController"]


class StateSource(Protocol):
    uses_true_state: bool

    def start(self, sample: DaqSample, truth: np.ndarray | None) -> np.ndarray: ...

    def update(self, sample: DaqSample, truth: np.ndarray | None, u_prev: float) -> np.ndarray: ...


def measured_xa(sample: DaqSample) -> np.ndarray:
    """(x, θ) from the raw volts with the rig software's converters (eq 6.3.1, eq 6.2.10)."""
    return np.array([converters.ball_position_m(sample.ball_v), converters.beam_angle_rad(sample.angle_v)])


class ObserverState:
    """(x, θ) measured, (ẋ, θ̇) from the reduced-order observer (eq 5.2.19), started at zero velocity."""

    uses_true_state = False

    def __init__(self, observer: ReducedObserver) -> None:
        self.observer = observer

    def start(self, sample: DaqSample, truth: np.ndarray | None) -> np.ndarray:
        self._xa = measured_xa(sample)
        self._xb = np.zeros(2)
        return np.concatenate([self._xa, self._xb])

    def update(self, sample: DaqSample, truth: np.ndarray | None, u_prev: float) -> np.ndarray:
        xa = measured_xa(sample)
        obs = self.observer
        self._xb = obs.f @ self._xb + obs.ga @ self._xa + obs.gain @ xa + obs.h[:, 0] * u_prev
        self._xa = xa
        return np.concatenate([xa, self._xb])


class TrueState:
    """All four states from the twin (the thesis's chapter 4 simulations). Not available on hardware."""

    uses_true_state = True

    def start(self, sample: DaqSample, truth: np.ndarray | None) -> np.ndarray:
        return self.update(sample, truth, 0.0)

    def update(self, sample: DaqSample, truth: np.ndarray | None, u_prev: float) -> np.ndarray:
        if truth is None:
            raise ValueError("this controller needs the true state (simulation only); the rig cannot give it")
        return np.asarray(truth, dtype=float).copy()


@dataclass(frozen=True)
class MotorInverse:
    """V = τ/k_τ + k_b·θ̇: the volts that give torque τ at rate θ̇ (eq 3.3.1 inverted)."""

    torque_per_volt: float  # N·m/V at the beam (N·K_t/R)
    backemf_at_beam: float  # V·s/rad at the beam (N·K_b)

    def volts(self, torque_nm: float, thetadot_rad_s: float) -> float:
        return torque_nm / self.torque_per_volt + self.backemf_at_beam * thetadot_rad_s


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
        u_kind: Literal["volts", "torque"],
        motor: MotorInverse | None = None,
        observer_input: Literal["applied_volts", "law"] = "applied_volts",
        command_limits_v: tuple[float, float] | None = (converters.COMMAND_LOW_V, converters.COMMAND_HIGH_V),
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
        self.u_kind = u_kind
        self.motor = motor
        self.observer_input = observer_input
        self.command_limits_v = command_limits_v
        self.period_s = period_s
        self.uses_true_state = state.uses_true_state
        self.reference_x_m = 0.0
        self._u_prev = 0.0

    def start(self, sample: DaqSample, true_state: np.ndarray | None = None) -> None:
        x = self.state.start(sample, true_state)
        self._u_prev = 0.0
        self.telemetry = Telemetry(x, 0.0, 0.0)

    def update(self, sample: DaqSample, true_state: np.ndarray | None = None) -> float:
        x = self.state.update(sample, true_state, self._u_prev)
        u = float(self.law(x))
        if not math.isfinite(u):
            raise FloatingPointError(f"{self.name}: control law returned {u!r} for state {x.tolist()}")
        volts = self.motor.volts(u, x[3]) if self.u_kind == "torque" else u
        command = converters.dac_command_v(volts)
        if self.command_limits_v is not None:
            command = converters.clip_command_v(command, *self.command_limits_v)
        applied_volts = converters.motor_volts_from_command(command)
        self._u_prev = applied_volts if self.observer_input == "applied_volts" else u
        logged_u = u if self.u_kind == "torque" else applied_volts
        self.telemetry = Telemetry(x, logged_u, u if self.u_kind == "torque" else volts)
        return command
