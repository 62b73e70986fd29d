"""The rig simulated: ``TwinRig`` implements the ``Rig`` interface (twin.interface) on the MuJoCo twin.

Per tick (Table 6.4, appendix A): ``read()`` advances the twin by one control period with the amplifier
following the last command, and returns the block reduced as the thesis software reduces it (last sample
of the ball channel, mean of the angle channel, time of the last sample); the controller computes;
``write()`` sets the DAC, which the amplifier follows from then on (after the optional output latency).
"""

from __future__ import annotations

import math

import numpy as np

from twin.daq import block_time_s
from twin.interface import DaqSample, Rig
from twin.output_stage import motor_volts
from twin.parameters import Parameters
from twin.plant import Plant
from twin.sensors import AngleChain, BallPositionChain

__all__ = ["DaqSample", "Rig", "TwinRig", "RigError"]

# A control period or latency must be a whole number of physics steps to this relative precision.
_STEP_TOLERANCE = 1e-9


class RigError(ValueError):
    """A configuration the rig cannot run (period or latency not a whole number of physics steps, …)."""


def _whole_steps(duration_s: float, step_s: float, name: str) -> int:
    n = duration_s / step_s
    steps = int(round(n))
    if abs(n - steps) > _STEP_TOLERANCE * max(1.0, n):
        raise RigError(
            f"{name} = {duration_s!r} s is not a whole number of physics steps ({step_s!r} s): it would be "
            f"{n:.6f} steps"
        )
    return steps


class TwinRig(Rig):
    """The rig simulated: MuJoCo plant + output stage + sensor chains + DAQ block semantics.

    ``seed`` seeds the ball sensor's contact noise (same seed → bit-identical readings). ``noise`` overrides
    ``params.ball_sensor.noise_enabled``."""

    def __init__(self, params: Parameters | None = None, *, seed: int = 0, noise: bool | None = None) -> None:
        p = params or Parameters()
        if noise is not None:
            p = p.with_overrides({"ball_sensor.noise_enabled": bool(noise)})
        self.params = p
        self.seed = seed
        self._steps_per_tick = _whole_steps(p.daq.period_s, p.physics.timestep_s, "daq.period_s")
        if self._steps_per_tick < 1:
            raise RigError(f"daq.period_s = {p.daq.period_s!r} s is shorter than one physics step")
        self._latency_steps = _whole_steps(
            p.daq.output_latency_s, p.physics.timestep_s, "daq.output_latency_s"
        )
        self.plant = Plant(p)
        self._angle = AngleChain(p)
        self._ball = BallPositionChain(p, seed)
        self.reset()

    # --- the Rig interface ----------------------------------------------------------------------------
    @property
    def period_s(self) -> float:
        return self.params.daq.period_s

    def read(self) -> DaqSample:
        plant, n = self.plant, self._steps_per_tick
        t0 = plant.time_s
        times = np.empty(n + 1)
        xs = np.empty(n + 1)
        thetas = np.empty(n + 1)
        contact = np.empty(n + 1, dtype=bool)
        times[0], thetas[0] = t0, plant.state_angle_rad()
        xs[0] = plant.ball_in_beam_frame()[0]
        contact[0] = not plant.ball_lost
        for i in range(n):
            if i == self._latency_steps:
                self._applied_motor_v = self._pending_motor_v
            plant.step(self._applied_motor_v)
            times[i + 1] = t0 + (i + 1) * plant.model.opt.timestep
            xs[i + 1] = plant.ball_in_beam_frame()[0]
            thetas[i + 1] = plant.state_angle_rad()
            contact[i + 1] = not plant.ball_lost
        angle_v = self._angle.read_v(times, thetas)
        ball_v = self._ball.advance(times, xs, contact)
        self._ticks += 1
        return DaqSample(time_s=block_time_s(t0, self.params.daq), ball_v=ball_v, angle_v=angle_v)

    def write(self, command_v: float) -> None:
        if not isinstance(command_v, (int, float, np.floating, np.integer)) or not math.isfinite(command_v):
            raise ValueError(f"command_v = {command_v!r}: the DAC command must be a finite number of volts")
        self.command_v = float(command_v)
        self._pending_motor_v = float(motor_volts(self.command_v, self.params))
        if self._latency_steps == 0:
            self._applied_motor_v = self._pending_motor_v

    # --- twin-only ------------------------------------------------------------------------------------
    def reset(
        self,
        x_m: float = 0.0,
        theta_rad: float = 0.0,
        xdot_m_s: float = 0.0,
        thetadot_rad_s: float = 0.0,
        *,
        seed: int | None = None,
    ) -> None:
        """Put the rig in a state; the DAC at 2.5 V (zero volts at the motor, as the Start button does)."""
        self.plant.reset(x_m, theta_rad, xdot_m_s, thetadot_rad_s)
        if seed is not None:
            self.seed = seed
        self._ball.reset(x_m, 0.0, seed=self.seed)
        self._ticks = 0
        self.command_v = self.params.amplifier.zero_command_v
        self._pending_motor_v = self._applied_motor_v = float(motor_volts(self.command_v, self.params))

    def true_state(self) -> np.ndarray:
        """The twin's true (x_m, θ_rad, ẋ_m_s, θ̇_rad_s): for validation and logs, never for a controller."""
        return self.plant.state()

    @property
    def time_s(self) -> float:
        return self.plant.time_s

    @property
    def ticks(self) -> int:
        return self._ticks

    @property
    def ball_lost(self) -> bool:
        return self.plant.ball_lost

    @property
    def ball_lost_time_s(self) -> float | None:
        return self.plant.ball_lost_time_s

    @property
    def motor_volts_v(self) -> float:
        """Volts across the motor now (after DAC quantization and the amplifier's ±12 V)."""
        return self._applied_motor_v

    @property
    def dropout_count(self) -> int:
        """Contact losses of the ball-position wire since the last reset."""
        return self._ball.dropout_count

    @property
    def noise_enabled(self) -> bool:
        return self.params.ball_sensor.noise_enabled

    def set_noise(self, enabled: bool) -> None:
        """Switch the ball sensor's contact noise on or off from now on."""
        self.params = self.params.with_overrides({"ball_sensor.noise_enabled": bool(enabled)})
        self._ball.set_params(self.params)

    def kick_ball(self, dv_m_s: float) -> None:
        """Give the ball a velocity kick along the beam (a flick with a finger), keeping it rolling."""
        if not math.isfinite(dv_m_s):
            raise ValueError(f"dv_m_s = {dv_m_s!r} is not finite")
        x, theta, xdot, thetadot = self.plant.state()
        if self.plant.ball_lost:
            return
        self.plant.reset(x, theta, xdot + dv_m_s, thetadot, keep_time=True)
