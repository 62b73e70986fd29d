"""The rig simulated: ``SimRig`` implements the ``Rig`` interface (twin.interface) on a physics backend.

Per tick (Table 6.4, appendix A): ``read()`` advances the physics by one control period with the amplifier
following the last command, and returns the block reduced as the thesis software reduces it (last sample
of the ball channel, mean of the angle channel, time of the last sample); the controller computes;
``write()`` sets the DAC, which the amplifier follows from then on (after the optional output latency).

Three rigs share this code (``make_rig``):

    TwinRig        the MuJoCo twin with the full I/O chain (encoder, counter, DAC, wiper curve, contact
                   noise, RC filter, 12-bit ADC and DAC, block semantics)
    ideal sensors  the MuJoCo twin with ideal converters (twin.sensors.IdealSensors, an exact DAC)
    ReferenceRig   the analytic reference model (twin.reference.ReferencePlant) with ideal converters

Start timing (``params.start``, appendix A's button sequence): after ``reset`` the rig is held at its
initial state while the software reads it; it is released at t = 0 and runs at 0 V until the first command
reaches the amplifier at t = ``start.free_run_s``. The DAQ's blocks end at t = free_run + k·T: block k = −1
is the one ``Controller.start`` reads, block 0 the first ``update`` (its command acts from t = free_run).
Blocks, or parts of blocks, before t = 0 see the held rig. The schedule (when blocks end, when a command
takes effect) is ``twin.daq.TickSchedule``, which the batch (``twin.rigs.batch``) follows too.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from twin.daq import TickSchedule, block_span_s
from twin.engine import ENDED_TICKS, ClosedLoop, Pacer, RunResult, Scenario, StateLaw, update_ticks
from twin.firmware import Firmware, FirmwareBoard
from twin.interface import CommandRange, Controller, DaqSample, Rig, RigError, Setpoint
from twin.model import drive_joint
from twin.output_stage import (
    CommandClampedWarning,
    amplifier_volts,
    clamped_command_text,
    ideal_motor_volts,
)
from twin.parameters import Parameters, PartNames
from twin.parts import AngleSensorChain, BallSensorChain, RigParts, rig_parts
from twin.parts.contract import StepLaw
from twin.physics import PhysicsBackend, PhysicsBlock, check_on_track, whole_steps
from twin.plant import Plant
from twin.rigs.backends import DEFAULT_PLANT, backend
from twin.sensors import IdealSensors
from twin.verdict import Criteria

__all__ = ["DaqSample", "ReferenceRig", "Rig", "RigError", "SimRig", "TwinRig", "make_rig"]


def tick_schedule(params: Parameters) -> TickSchedule:
    """The rig's ``TickSchedule`` from its board's period (``Parameters.period_s``), ``daq.output_latency_s``
    and ``start.free_run_s``, each a whole number of physics steps (else ``RigError`` naming it)."""
    dt = params.physics.timestep_s
    steps_per_tick = whole_steps(params.period_s, dt, params.period_field)
    if steps_per_tick < 1:
        raise RigError(f"{params.period_field} = {params.period_s!r} s is shorter than one physics step")
    latency = whole_steps(params.daq.output_latency_s, dt, "daq.output_latency_s")
    return TickSchedule(steps_per_tick, latency, whole_steps(params.start.free_run_s, dt, "start.free_run_s"))


# The parts whose converters the ideal ones (``twin.sensors.IdealSensors``, ``ideal_motor_volts``) stand in for:
# the thesis's sensors, card and amplifier, in its volts.
IDEAL_CONVERTER_ROLES = ("actuator", "ball_sensor", "angle_sensor", "io_board")


def refuse_ideal_converters(params: Parameters, ideal_sensors: bool) -> None:
    """``RigError`` for ideal converters on a rig whose sensors, board or actuator are not the thesis's: the ideal
    converters are the thesis software's volts, which another board neither reads nor writes."""
    if not ideal_sensors:
        return
    thesis = PartNames()
    other = [
        f"parts.{r} = {getattr(params.parts, r)!r}"
        for r in IDEAL_CONVERTER_ROLES
        if getattr(params.parts, r) != getattr(thesis, r)
    ]
    if other:
        raise RigError(
            f"ideal sensors are the thesis's converters in its volts; this rig has {', '.join(other)}: run it with "
            "its own sensor chains (no --ideal-sensors)"
        )


class SimRig(Rig):
    """A simulated rig: a physics backend + output stage + sensors + DAQ block semantics + start timing.

    ``seed`` seeds the ball sensor's contact noise (same seed → bit-identical readings). ``noise`` overrides
    ``params.ball_sensor.noise_enabled``. ``ideal_sensors`` replaces the sensor chains and the DAC's
    quantization by ideal converters. ``parts``: the rig's parts (``twin.parts.RigParts``; by default the parts
    ``params.parts`` names, ``twin.parts.rig_parts``), whose sensor chains and output stage the rig runs."""

    def __init__(
        self,
        params: Parameters | None = None,
        *,
        seed: int = 0,
        noise: bool | None = None,
        plant: str = DEFAULT_PLANT,
        ideal_sensors: bool = False,
        parts: RigParts | None = None,
    ) -> None:
        p = params or Parameters()
        if noise is not None:
            p = p.with_overrides({"ball_sensor.noise_enabled": bool(noise)})
        try:
            single = backend(plant).single  # the backend's single run (twin.rigs.backends)
        except ValueError as exc:
            raise RigError(str(exc)) from None
        self.params = p
        self.seed = seed
        self.plant_kind = plant
        self.ideal_sensors = bool(ideal_sensors)
        self._schedule = tick_schedule(p)
        self._steps_per_tick = self._schedule.steps_per_tick
        self.physics: PhysicsBackend = single(p)
        self._chains = not self.ideal_sensors  # the sensor chains read each block (else ideal converters)
        # the rig's parts (twin.parts; today's by default): its output stage and sensor chains come from them
        self.parts = parts or rig_parts(p)
        refuse_ideal_converters(p, self.ideal_sensors)
        self._motor_volts = self.parts.motor_volts_of(p)
        self._limits = self.parts.io_board.output_range(
            p
        )  # the board's output: the DAC's volts, a pulse's µs
        self._block_span_s = block_span_s(p.daq)
        self._angle: AngleSensorChain = self.parts.angle_sensor.chain(p)
        self._ball: BallSensorChain = self.parts.ball_sensor.chain(p, seed)
        self._ideal = IdealSensors(p)
        self.last_block: PhysicsBlock | None = None
        # An actuator stepped with the physics (ActuatorPart.step_law) on the MuJoCo plant: its law reads the drive
        # joint's own angle and speed from MjData (the rotor's: on a lever the horn's, not the beam's through the
        # linkage's soft closure; and still the rotor's once a lost ball freezes the law's state floats). The
        # reference plant runs the part's ramp and law itself (twin.reference: DriveLaw.ramp) on the tick's control.
        self.step_law: StepLaw | None = None
        self._rotor_at: tuple[int, int] | None = None
        if self.parts.actuator.step_law is not None and isinstance(self.physics, Plant):
            joint = self.physics.model.joint(drive_joint(p))
            self._rotor_at = (int(joint.qposadr[0]), int(joint.dofadr[0]))
        self.reset()

    # --- the Rig interface ----------------------------------------------------------------------------
    @property
    def period_s(self) -> float:
        return self.params.period_s

    def read(self) -> DaqSample:
        return self._read(None)

    def parameters(self) -> Parameters:
        return self.params

    def command_range(self) -> CommandRange:
        return self._limits

    def write(self, command_v: float) -> None:
        if not isinstance(command_v, (int, float, np.floating, np.integer)) or not math.isfinite(command_v):
            raise ValueError(f"command_v = {command_v!r}: the DAC command must be a finite number of volts")
        self.command_v = float(command_v)
        limits = self._limits
        if not limits.low <= self.command_v <= limits.high:  # the board clamps it: said once a run
            self.clamped_commands += 1
            if self.clamped_commands == 1:
                text = clamped_command_text(self.command_v, limits, self._ticks, self.time_s)
                warnings.warn(text, CommandClampedWarning, stacklevel=2)
        self._set_motor_volts(self._motor_volts_for(self.command_v))

    # --- simulation only ------------------------------------------------------------------------------
    def read_with_state_law(self, law_volts, law_period_s: float) -> DaqSample:
        """One tick in which the motor volts are recomputed every ``law_period_s`` from the plant's true
        state: ``law_volts(state) -> terminal volts`` (clamped to the amplifier's rails, no DAC). This is
        the chapter 4 designs' path (all four states measured): simulation only, never a ``Controller``."""
        self._refuse_step_law("a law on the state")
        return self._read((law_volts, whole_steps(law_period_s, self.params.physics.timestep_s, "period_s")))

    def read_with_firmware(self, firmware: FirmwareBoard) -> DaqSample:
        """One tick of a rig whose controller is firmware on a microcontroller (``twin.firmware.Firmware``): every
        physics step its pins see the sensor signals in time (the ball chain's RC output, the angle counter's
        DAC level: no card's block means) and the motor the mean terminal volts of the board's output over the
        step. The first tick after ``reset`` powers the board on (the core leaves reset as the first block
        begins: its first period reads the held rig, as the software's Start does). The block returned is
        what the PCI-1712 would read beside it (for the log). Simulation only; ``daq.output_latency_s`` does not
        apply (the firmware's own timing is its latency)."""
        self._refuse_step_law("firmware")
        schedule = self._schedule
        if self._ticks == 0:
            firmware.boot(self._step_time(schedule.next_start_step))
        plan = schedule.next_block()
        drive = _FirmwareDrive(self, firmware)
        if plan.free_steps:  # released before this block begins: the board runs on, the card does not read
            drive.physics(plan.free_steps)
        pieces: list[PhysicsBlock] = []
        t_start = self._step_time(plan.start_step) if plan.start_step < 0 else self.physics.time_s
        if plan.held_end_step is not None:
            pieces.append(drive.held(plan.start_step, plan.held_end_step))
        if plan.observed_steps:
            pieces.append(drive.physics(plan.observed_steps))
        block = self.last_block = _join(pieces)
        if self.ideal_sensors:
            ball_v, angle_v = self._ideal.read_v(float(block.x_m[-1]), float(block.theta_rad[-1]))
        else:
            angle_v = self._angle.read_block_v(block)
            ball_v = self._ball.reading_v
        self._ticks += 1
        self.command_v = firmware.command_v
        return DaqSample(time_s=t_start + self._block_span_s, ball_v=ball_v, angle_v=angle_v)

    def reset(
        self,
        x_m: float = 0.0,
        theta_rad: float = 0.0,
        xdot_m_s: float = 0.0,
        thetadot_rad_s: float = 0.0,
        *,
        seed: int | None = None,
    ) -> None:
        """Hold the rig in a state (released at t = 0); the DAC at 2.5 V (zero volts at the motor, as the
        Start button does)."""
        self.physics.reset(x_m, theta_rad, xdot_m_s, thetadot_rad_s)
        if seed is not None:
            self.seed = seed
        self._held = np.array([x_m, theta_rad, xdot_m_s, thetadot_rad_s], dtype=float)
        self._schedule.reset()
        self._ball.reset(x_m, self._step_time(self._schedule.chain_start_step), seed=self.seed)
        self._ticks = 0
        self.clamped_commands = 0  # commands written outside the DAC's range this run (the card clamped them)
        # a fresh write path each run: an actuator may hold state across ticks (a servo's dead band)
        self._motor_volts = self.parts.motor_volts_of(self.params)
        self.command_v = self.parts.actuator.rest_command(self.params)
        self._pending_motor_v = self._applied_motor_v = self._motor_volts_for(self.command_v)
        self.last_block = None
        if self._rotor_at is not None:  # a fresh law each run: its state (a stepper's ramp) starts anew
            assert self.parts.actuator.step_law is not None
            self.step_law = self.parts.actuator.step_law(self.params)

    def true_state(self) -> np.ndarray:
        """The true (x_m, θ_rad, ẋ_m_s, θ̇_rad_s): for validation and logs, never for a controller."""
        return self._held.copy() if self.held else self.physics.state()

    def true_state_row(self) -> np.ndarray | None:
        """The MuJoCo state row the true state is computed from (``Plant.state_row``: a view valid until the
        next tick), or ``None`` when ``true_state`` must be asked (held, ball lost, the reference model)."""
        if self.held or not isinstance(self.physics, Plant):
            return None
        return self.physics.state_row()

    def true_states_of_rows(self, rows: np.ndarray) -> np.ndarray:
        """``true_state`` for state rows ``true_state_row`` gave, one per row, bit for bit."""
        if not isinstance(self.physics, Plant):
            raise RigError("true_states_of_rows needs the MuJoCo plant")
        return self.physics.row_states(rows)

    @property
    def held(self) -> bool:
        """Whether the rig is still held at its initial state (the blocks read so far end before release)."""
        return self._schedule.held

    @property
    def time_s(self) -> float:
        """Simulated time since release (negative while the rig is held)."""
        if self.held:
            return self._step_time(self._schedule.next_start_step)
        return self.physics.time_s

    @property
    def ticks(self) -> int:
        return self._ticks

    @property
    def ball_lost(self) -> bool:
        return self.physics.ball_lost

    @property
    def ball_lost_time_s(self) -> float | None:
        return self.physics.ball_lost_time_s

    @property
    def motor_volts_v(self) -> float:
        """Volts across the motor now (after the DAC and the amplifier's ±12 V)."""
        return self._applied_motor_v

    @property
    def dropout_count(self) -> int:
        """Contact losses of the ball-position wire since the last reset (0 with ideal sensors)."""
        return 0 if self.ideal_sensors else self._ball.dropout_count

    @property
    def noise_enabled(self) -> bool:
        return self.params.ball_sensor.noise_enabled and not self.ideal_sensors

    def set_noise(self, enabled: bool) -> None:
        """Switch the ball sensor's contact noise on or off from now on."""
        self.params = self.params.with_overrides({"ball_sensor.noise_enabled": bool(enabled)})
        self._ball.set_params(self.params)

    def kick_ball(self, dv_m_s: float) -> None:
        """Give the ball a velocity kick along the beam (a flick with a finger), keeping it rolling."""
        if self.held:
            if not math.isfinite(dv_m_s):
                raise ValueError(f"dv_m_s = {dv_m_s!r} is not finite")
            self._held[2] += dv_m_s
            self.physics.reset(*self._held)
            return
        self.physics.kick_ball(dv_m_s)

    # --- internals --------------------------------------------------------------------------------------
    def _step_time(self, step: int) -> float:
        """Time of a physics step index relative to release: after release the physics clock itself."""
        return step * self.params.physics.timestep_s

    def _held_block(self, t0_s: float, t1_s: float) -> PhysicsBlock:
        """The held rig from ``t0_s`` to ``t1_s`` as a block (two knots: the state does not move)."""
        x, th = float(self._held[0]), float(self._held[1])
        return PhysicsBlock(
            time_s=np.array([t0_s, t1_s]),
            x_m=np.array([x, x]),
            theta_rad=np.array([th, th]),
            on_track=np.array([True, True]),
        )

    def _motor_volts_for(self, command_v: float) -> float:
        if self.ideal_sensors:
            return float(ideal_motor_volts(command_v, self.params))
        return self._motor_volts(command_v)

    def _set_motor_volts(self, volts: float) -> None:
        self._pending_motor_v = volts
        if self._schedule.command_written():
            self._applied_motor_v = volts

    def _step_volts(self, n: int) -> np.ndarray:
        """Terminal volts for the next ``n`` physics steps (the output latency switches within them)."""
        volts = np.full(n, self._applied_motor_v)
        k = self._schedule.switch_at(n)
        if k is not None:
            volts[k:] = self._pending_motor_v
            self._applied_motor_v = self._pending_motor_v
        return volts

    def _refuse_step_law(self, what: str) -> None:
        if self._rotor_at is not None:
            raise RigError(
                f"parts.actuator = {self.parts.actuator.name!r} computes its torque each physics step "
                f"(ActuatorPart.step_law): {what} cannot drive it; write its commands with write()"
            )

    def _advance(self, n: int) -> PhysicsBlock:
        """``n`` physics steps at the control the board's commands give (the output latency switching within
        them): the physics' own ``advance``, or with the actuator's per-step law (``_advance_step_law``)."""
        if self._rotor_at is None:
            return self.physics.advance(self._step_volts(n))
        return self._advance_step_law(self._step_volts(n))

    def _advance_step_law(self, controls: np.ndarray) -> PhysicsBlock:
        """One physics step per control (the drive's output for the board's command at that step): before each,
        the actuator's ``step_law`` turns the control and the drive joint's angle and speed into the motor's
        torque (``Plant.advance_with_law``, every step)."""
        assert isinstance(self.physics, Plant) and self._rotor_at is not None and self.step_law is not None
        law, (qpos_at, dof_at) = self.step_law, self._rotor_at
        data = self.physics.data
        qpos, qvel = data.qpos, data.qvel
        next_control = iter(controls.tolist()).__next__

        def torque(x_m: float, theta_rad: float, xdot_m_s: float, thetadot_rad_s: float) -> float:
            return law(next_control(), qpos.item(qpos_at), qvel.item(dof_at))

        block, _ = self.physics.advance_with_law(len(controls), torque, 1)
        return block

    def _advance_with_law(self, n: int, law, law_steps: int) -> PhysicsBlock:
        rail = self.params.amplifier.rail_v
        # A law that also takes the state as four Python floats (``of_floats``, as twin.engine's does) gets
        # it so: no state array per physics step.
        of_floats = getattr(law, "of_floats", None)

        def clamped_volts(x_m: float, theta_rad: float, xdot_m_s: float, thetadot_rad_s: float) -> float:
            if of_floats is None:
                volts = float(law(np.array([x_m, theta_rad, xdot_m_s, thetadot_rad_s])))
            else:
                volts = float(of_floats(x_m, theta_rad, xdot_m_s, thetadot_rad_s))
            if not math.isfinite(volts):
                raise FloatingPointError(
                    f"the state law returned {volts!r} volts at t = {self.physics.time_s:.3f} s"
                )
            # min(max(volts, −rail), rail), the same float, without the builtins' calls
            volts = -rail if volts < -rail else volts
            return rail if volts > rail else volts

        if isinstance(self.physics, Plant):  # MuJoCo steps one by one in the plant, the law between them
            block, volts = self.physics.advance_with_law(n, clamped_volts, law_steps)
            self._applied_motor_v = self._pending_motor_v = volts
            return block
        parts = []
        done = 0
        while done < n:
            m = min(law_steps, n - done)
            self._applied_motor_v = self._pending_motor_v = clamped_volts(*self.physics.state().tolist())
            parts.append(self.physics.advance(np.full(m, self._applied_motor_v)))
            done += m
        return _join(parts)

    def _read(self, law) -> DaqSample:
        schedule = self._schedule
        if law is None and self._chains and schedule.next_is_plain():
            # The common tick: one control period of physics at the volts the motor has, the full chains.
            t_start = self.physics.time_s
            if self._rotor_at is None:
                block = self.physics.advance_held(self._applied_motor_v, self._steps_per_tick)
            else:
                block = self._advance_step_law(np.full(self._steps_per_tick, self._applied_motor_v))
            self.last_block = block
            schedule.plain_block()
            self._ticks += 1
            angle_v = self._angle.read_block_v(block)
            return DaqSample(t_start + self._block_span_s, self._ball.advance_block(block), angle_v)
        plan = schedule.next_block()
        t_start = self._step_time(plan.start_step) if plan.start_step < 0 else self.physics.time_s
        if plan.free_steps:  # released before this block begins: run free up to it, unobserved
            pre = self._advance(plan.free_steps)
            t_start = self.physics.time_s
            if not self.ideal_sensors:
                self._ball.advance(pre.time_s, pre.x_m, pre.on_track)
        pieces: list[PhysicsBlock] = []
        if plan.held_end_step is not None:  # the held rig, until release at t = 0 (or the block's end)
            pieces.append(self._held_block(t_start, self._step_time(plan.held_end_step)))
        if plan.observed_steps:
            if law is None:
                pieces.append(self._advance(plan.observed_steps))
            else:
                pieces.append(self._advance_with_law(plan.observed_steps, *law))
        block = _join(pieces)
        self.last_block = block
        if self.ideal_sensors:
            ball_v, angle_v = self._ideal.read_v(float(block.x_m[-1]), float(block.theta_rad[-1]))
        else:
            angle_v = self._angle.read_block_v(block)
            ball_v = self._ball.advance_block(block)
        self._ticks += 1
        return DaqSample(time_s=t_start + self._block_span_s, ball_v=ball_v, angle_v=angle_v)


_CONTACT_2 = np.array([True, True])


class _FirmwareDrive:
    """A tick's physics steps with a firmware's board in the loop (``SimRig.read_with_firmware``): at each
    step's start the pins get the signals at that instant (held over the step), the board runs to the step's
    end, and the motor gets the mean of the amplifier's volts over the board's outputs in the step (the
    firmware cannot see the step's physics before its end: this is causal)."""

    def __init__(self, rig: SimRig, firmware: FirmwareBoard) -> None:
        self.rig, self.firmware = rig, firmware
        self.dt = rig.params.physics.timestep_s
        self.amplifier = rig.params.amplifier
        self.ideal = rig.ideal_sensors
        self.ball, self.angle = rig._ball, rig._angle
        self.t_s = 0.0
        self.x_m = 0.0

    def _ball_to(self, t_s: float, x_m: float) -> None:
        """The ball chain from its last point to (t, x), the wiper linear between."""
        if not self.ideal:
            x0 = self.x_m
            self.ball.advance_rig_block(
                np.array((self.t_s, t_s)),
                np.array((x0, x_m)),
                _CONTACT_2,
                True,
                (min(x0, x_m), max(x0, x_m)),
                True,
            )
        self.t_s, self.x_m = t_s, x_m

    def _volts(self, theta_rad: float) -> float:
        """The board for one step from (self.t_s, self.x_m, θ): the step's mean motor volts."""
        if self.ideal:
            ball_v, angle_v = self.rig._ideal.read_v(self.x_m, theta_rad)
        else:
            ball_v, angle_v = self.ball.filtered_v, self.angle.level_v(theta_rad)
        pieces = self.firmware.pins(self.t_s, ball_v, angle_v, self.t_s + self.dt)
        volts = 0.0
        for share, command_v in pieces:
            volts += share * float(amplifier_volts(command_v, self.amplifier))
        self.rig._applied_motor_v = self.rig._pending_motor_v = volts
        return volts

    def held(self, start_step: int, end_step: int) -> PhysicsBlock:
        """The held rig from ``start_step`` to ``end_step``, a step at a time (the board runs; the rig does not)."""
        rig = self.rig
        x, theta = float(rig._held[0]), float(rig._held[1])
        self.t_s, self.x_m = rig._step_time(start_step), x
        for step in range(start_step, end_step):
            self._volts(theta)
            self._ball_to(rig._step_time(step + 1), x)
        return rig._held_block(rig._step_time(start_step), rig._step_time(end_step))

    def physics(self, n: int) -> PhysicsBlock:
        """``n`` physics steps, the board in the loop at each."""
        physics = self.rig.physics
        self.t_s = physics.time_s
        self.x_m = float(physics.state()[0])
        first = [True]

        def volts(x_m: float, theta_rad: float, xdot_m_s: float, thetadot_rad_s: float) -> float:
            if first[0]:
                first[0] = False
            else:
                self._ball_to(self.t_s + self.dt, x_m)
            return self._volts(theta_rad)

        if isinstance(physics, Plant):
            block, _ = physics.advance_with_law(n, volts, 1)
        else:
            parts = []
            for _ in range(n):
                state = physics.state().tolist()
                parts.append(physics.advance(np.full(1, volts(*state))))
            block = _join(parts)
        # the last step's end: the chain to the block's end (its contact as the block says)
        if not self.ideal:
            x0 = self.x_m
            self.ball.advance_rig_block(
                np.array((self.t_s, float(block.time_s[-1]))),
                np.array((x0, float(block.x_m[-1]))),
                block.on_track[-2:],
                True,
            )
        return block


def _join(parts: list[PhysicsBlock]) -> PhysicsBlock:
    """Consecutive blocks as one (each part's first entry repeats the previous part's last)."""
    if len(parts) == 1:
        return parts[0]
    return PhysicsBlock(
        time_s=np.concatenate([parts[0].time_s] + [b.time_s[1:] for b in parts[1:]]),
        x_m=np.concatenate([parts[0].x_m] + [b.x_m[1:] for b in parts[1:]]),
        theta_rad=np.concatenate([parts[0].theta_rad] + [b.theta_rad[1:] for b in parts[1:]]),
        on_track=np.concatenate([parts[0].on_track] + [b.on_track[1:] for b in parts[1:]]),
    )


class TwinRig(SimRig):
    """The MuJoCo twin with the full I/O chain."""

    def __init__(self, params: Parameters | None = None, *, seed: int = 0, noise: bool | None = None) -> None:
        super().__init__(params, seed=seed, noise=noise, plant="twin", ideal_sensors=False)


class ReferenceRig(SimRig):
    """The analytic reference model with ideal converters."""

    def __init__(self, params: Parameters | None = None, *, seed: int = 0) -> None:
        super().__init__(params, seed=seed, plant="reference", ideal_sensors=True)


def make_rig(
    params: Parameters | None = None,
    *,
    plant: str = DEFAULT_PLANT,
    ideal_sensors: bool = False,
    seed: int = 0,
    noise: bool | None = None,
) -> SimRig:
    """The simulated rig asked for: ``plant`` a registered backend's name (``twin.rigs.backends``: 'twin', MuJoCo;
    'reference', the analytic model), with the full sensor chain or ideal converters."""
    return SimRig(params, seed=seed, noise=noise, plant=plant, ideal_sensors=ideal_sensors)


def run_closed_loop(
    controller: Controller | StateLaw | Firmware,
    *,
    x0_m: float,
    theta0_rad: float,
    duration_s: float = 10.0,
    seed: int = 0,
    noise: bool = True,
    params: Parameters | None = None,
    plant: str = "twin",
    ideal_sensors: bool = False,
    stop_when_lost: bool = True,
    criteria: Criteria | None = None,
    pacer: Pacer | None = None,
    controller_timeout_s: float | None = None,
    scenario: Scenario | None = None,
) -> RunResult:
    """Run ``controller`` on a fresh simulated rig from (x0, θ0) at rest for ``duration_s`` after release.

    The rig is held while the controller's ``start`` reads it, released at t = 0 and driven from
    t = ``start.free_run_s`` on (twin.rigs.sim). Initial velocities are zero; the controller's observer starts
    from zero velocity, as on the rig. ``stop_when_lost`` ends the run at the tick the ball is lost.
    ``controller_timeout_s``: the watchdog's budget per update (``ClosedLoop``). ``scenario``: a flick and a
    setpoint (``Scenario``)."""
    if not (isinstance(duration_s, (int, float)) and math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration_s = {duration_s!r} must be a positive number of seconds")
    p = params or Parameters()
    rig = make_rig(p, plant=plant, ideal_sensors=ideal_sensors, seed=seed, noise=noise)
    rig.reset(x0_m, theta0_rad)
    s = scenario or Scenario()
    if s.setpoint_m is not None:
        if not isinstance(controller, Setpoint):
            name = getattr(controller, "name", controller)
            raise ValueError(f"{name!r} has no ball setpoint (twin.interface.Setpoint)")
        check_on_track(p, "setpoint_m", s.setpoint_m)
        controller.setpoint_m = s.setpoint_m
    loop = ClosedLoop(rig, controller, controller_timeout_s=controller_timeout_s)
    try:
        ticks = update_ticks(duration_s, rig.params)
        first = s.flick_tick(rig.period_s)
        if first is None:
            ended = loop.run(ticks, pacer=pacer, stop_when_lost=stop_when_lost)
        else:
            first = min(first, ticks)
            ended = loop.run(first, pacer=pacer, stop_when_lost=stop_when_lost)
            if ended == ENDED_TICKS:
                if s.flick_speed_m_s != 0:
                    rig.kick_ball(s.flick_speed_m_s)  # between two ticks, as the live view's Flick
                ended = loop.run(ticks - first, pacer=pacer, stop_when_lost=stop_when_lost)
        result = loop.result(ended, x0_m, criteria)
        if s.setpoint_m is not None:
            result.verdict = loop.verdict(x0_m, criteria, x_ref_m=s.setpoint_m)
        return result
    finally:
        if loop.is_firmware:  # its core is a process of its own
            controller.close()  # type: ignore[union-attr]
