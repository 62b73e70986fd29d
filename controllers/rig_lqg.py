"""``rig-lqg``: LQR and a steady-state Kalman filter designed from a rig's own linearization, for any rig its
parts describe (the thesis's, a hobby servo on a lever, ...).

    board readings ─the parts' conversions─► (x[, θ]) ─Kalman filter─► x̂ ─LQR─► actuator control
                                                              ─the actuator's conversion─► board command

The design (``rig_lqg_design``): the reference model's linearization about the rig at rest
(``twin.linearize.linearize_reference``: ∂f/∂(x, θ, ẋ, θ̇, u) at the level beam, the ball at the track's centre,
the actuator's control that holds it there, ``twin.linearize.hold_control``: its rest control on a beam
balanced on its pivot, more on one hinged at its end), discretized with a zero-order hold at the board's
period; LQR with Bryson weights and the Kalman gain for the sensors the rig has (ball only when it measures
no angle). The runtime (``RigLqgController``) is a hardware ``Controller``: it reads the board's units and
writes the board's command through the parts' own conversions (``BallSensorPart.position_of``,
``AngleSensorPart.angle_of``, ``ActuatorPart.command_of``: what a sketch on the rig would compute), never the
twin's state.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from twin import fixedorder as fo
from twin.interface import Controller, DaqSample, Telemetry
from twin.parameters import Parameters

__all__ = ["RigLqgController", "RigLqgDesign", "rig_lqg", "rig_lqg_design"]

# Bryson's rule: the largest acceptable excursion of each state and of the actuator's control about its rest.
# A ball a quarter of the track out, the beam 0.1 rad, 0.5 m/s, 2 rad/s (the lqr's scales halved for the smaller
# beams of hobby rigs) and the actuator a fifth of its rest-to-limit span.
STATE_SCALE = (0.05, 0.1, 0.5, 2.0)
# A position actuator's control scale: what tilts the beam this far (half the state's angle scale).
POSITION_SCALE_RAD = 0.05
# The Kalman model: the actuator's control disturbed by a tenth of its scale; the ball's reading 2 mm and the
# beam's 1 mrad (standard deviations: lqr's figures, a hobby sensor's millimetre and a 12-bit angle's step).
INPUT_NOISE_FRACTION = 0.1
BALL_NOISE_M = 2e-3
ANGLE_NOISE_RAD = 1e-3


@dataclass(frozen=True)
class RigLqgDesign:
    """The gains and the discrete model: u = u₀ − K·x̂ about the rest control u₀, x̂ from the Kalman filter on
    (Φ, Γ) measuring the rows ``measured`` of the state."""

    phi: np.ndarray
    gamma: np.ndarray
    gain: np.ndarray  # K (1×4)
    kalman_gain: np.ndarray  # L (4×m)
    measured: tuple[int, ...]  # the state's rows the sensors read: (0,) or (0, 1)
    rest_control: float
    period_s: float


def rig_lqg_design(
    a: np.ndarray,
    b: np.ndarray,
    *,
    rest_control: float,
    input_scale: float,
    period_s: float,
    measured: Sequence[int],
    measurement_noise: Sequence[float],
) -> RigLqgDesign:
    """LQR (Bryson weights ``STATE_SCALE``, ``input_scale``) and the current-estimator Kalman gain on the zero-
    order-hold discretization of (A, B) at ``period_s``, the sensors reading the state's rows ``measured`` with
    the standard deviations ``measurement_noise``."""
    from controllers.design import kalman_current_gain, lqr_gain
    from twin.reference import discretize_zoh

    phi, gamma = discretize_zoh(a, b, period_s)
    gain = lqr_gain(phi, gamma, STATE_SCALE, input_scale)
    h = np.eye(4)[list(measured)]
    kalman = kalman_current_gain(phi, gamma, h, INPUT_NOISE_FRACTION * input_scale, measurement_noise)
    return RigLqgDesign(phi, gamma, gain, kalman, tuple(measured), rest_control, period_s)


class RigLqgController(Controller):
    """The runtime of ``rig-lqg`` (see the module's doc): each tick decodes the readings, runs the Kalman filter
    (its prediction with the control last applied), the state feedback, and encodes the control as the board's
    command within its range."""

    def __init__(
        self,
        design: RigLqgDesign,
        *,
        position_of: Callable[[float], float],
        angle_of: Callable[[float], float] | None,
        command_of: Callable[[float], float],
        control_of: Callable[[float], float],
        command_range: tuple[float, float],
        name: str = "rig-lqg",
    ) -> None:
        super().__init__()
        self.name = name
        self.period_s = design.period_s
        self.design = design
        self._position_of, self._angle_of = position_of, angle_of
        self._command_of, self._control_of = command_of, control_of
        self._low, self._high = command_range
        self._phi, self._gain, self._kalman = (
            design.phi.tolist(),
            design.gain[0].tolist(),
            design.kalman_gain.tolist(),
        )
        self._gamma = design.gamma[:, 0].tolist()
        self._rows = design.measured
        self._x = [0.0, 0.0, 0.0, 0.0]
        self._du = 0.0

    def _measured(self, sample: DaqSample) -> list[float]:
        x = self._position_of(sample.ball_v)
        if self._angle_of is None:
            return [x]
        return [x, self._angle_of(sample.angle_v)]

    def start(self, sample: DaqSample) -> None:
        y = [value if math.isfinite(value) else 0.0 for value in self._measured(sample)]
        self._x = [y[0], y[1] if len(y) > 1 else 0.0, 0.0, 0.0]
        self._du = 0.0
        self.telemetry = Telemetry(np.array(self._x), self.design.rest_control, self.design.rest_control)

    def update(self, sample: DaqSample) -> float:
        y = self._measured(sample)
        predicted = [
            p + g * self._du for p, g in zip(fo.matvec(self._phi, self._x), self._gamma, strict=True)
        ]
        # a reading that carries no position (a lost echo, out of range) corrects nothing: the prediction stands
        innovation = [
            value - predicted[row] if math.isfinite(value) else 0.0
            for value, row in zip(y, self._rows, strict=True)
        ]
        correction = fo.matvec(self._kalman, innovation)
        self._x = [p + c for p, c in zip(predicted, correction, strict=True)]
        du = -fo.dot(self._gain, self._x)
        if not math.isfinite(du):
            raise FloatingPointError(
                f"{self.name}: the state feedback gave {du!r} for the estimate {self._x}"
            )
        wanted = self.design.rest_control + du
        command = min(max(self._command_of(wanted), self._low), self._high)
        # the Kalman filter is told the control the board could give (a command clamped at its range)
        applied = self._control_of(command)
        self._du = applied - self.design.rest_control
        self.telemetry = Telemetry(np.array(self._x), applied, wanted)
        return command


def rig_lqg(params: Parameters) -> RigLqgController:
    """``rig-lqg`` for the rig ``params`` describes (its parts must give their conversions: a part without
    one is refused naming it)."""
    from twin.parts import rig_parts

    parts = rig_parts(params)
    missing = [
        f"parts.{part.role} = {part.name!r} ({field})"
        for part, field in (
            (parts.ball_sensor, "position_of"),
            (parts.actuator, "command_of"),
            (parts.actuator, "control_of"),
            *(((parts.angle_sensor, "angle_of"),) if parts.angle_sensor.measures_angle else ()),
        )
        if getattr(part, field) is None
    ]
    if missing:
        raise ValueError(
            f"rig-lqg needs the parts' software conversions; these give none: {', '.join(missing)}"
        )
    assert parts.ball_sensor.position_of and parts.actuator.command_of and parts.actuator.control_of
    position_of = parts.ball_sensor.position_of(params)
    angle_of = (
        parts.angle_sensor.angle_of(params)
        if parts.angle_sensor.angle_of and parts.angle_sensor.measures_angle
        else None
    )
    command_of = parts.actuator.command_of(params)
    control_of = parts.actuator.control_of(params)
    limits = parts.io_board.output_range(params)
    return RigLqgController(
        _design(params),
        position_of=position_of,
        angle_of=angle_of,
        command_of=command_of,
        control_of=control_of,
        command_range=(limits.low, limits.high),
    )


@functools.lru_cache(maxsize=64)
def _design(params: Parameters) -> RigLqgDesign:
    """The design for the rig ``params`` describes (the same for every run of a batch on one rig: computed once;
    a design is never changed by its controllers)."""
    from twin.linearize import hold_control, linearize_reference
    from twin.parts import rig_parts

    parts = rig_parts(params)
    assert parts.actuator.control_of is not None  # rig_lqg checked it
    control_of = parts.actuator.control_of(params)
    angle_measured = parts.angle_sensor.angle_of is not None and parts.angle_sensor.measures_angle
    # about the control that holds the level beam: a beam hinged at its end needs one to carry its weight
    rest_control = hold_control(params, control_of(parts.actuator.rest_command(params)))
    a, b = linearize_reference(params, rest_control)
    limits = parts.io_board.output_range(params)
    span = max(abs(control_of(limits.low) - rest_control), abs(control_of(limits.high) - rest_control))
    input_scale = span / 5.0
    if a[3, 1] < 0.0 and b[3, 0] != 0.0:
        # a position actuator (a servo, a stepper) holds the beam at θ = −B/A·u: its control's scale is what tilts
        # the beam by half the state's scale, not its board's whole span (a stepper's ±3200 microsteps are 1.5
        # turns); the half keeps the loop well inside a stepper's speed ramp (at the whole scale it is not: the
        # ramp's lag rocked the stepper preset's beam onto its stops, at half it held from every start tried)
        input_scale = min(input_scale, abs(POSITION_SCALE_RAD * a[3, 1] / b[3, 0]))
    measured = (0, 1) if angle_measured else (0,)
    noise = (BALL_NOISE_M, ANGLE_NOISE_RAD) if angle_measured else (BALL_NOISE_M,)
    design = rig_lqg_design(
        a,
        b,
        rest_control=rest_control,
        input_scale=input_scale,
        period_s=params.period_s,
        measured=measured,
        measurement_noise=noise,
    )
    for shared in (design.phi, design.gamma, design.gain, design.kalman_gain):
        shared.setflags(write=False)  # one design serves every controller of the rig
    return design
