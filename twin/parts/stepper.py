"""A NEMA 17 stepper on a TMC2209 STEP/DIR driver (``STEPPER``, role ``actuator``), its sketch's AccelStepper-style
speed ramp, and its parameter group ``stepper``.

Physics (each equation's one home; the numbers: ``Stepper``):

    magnetic torque   τ_m = −T_po(φ̇)·sin(p·(φ − φ_c)): the rotor pulled toward the commanded microstep angle φ_c,
                      p = full steps per turn / 4 pole pairs (50 for a 1.8° motor: one electrical cycle is 4 full
                      steps, 7.2°); at a quarter cycle of lag (one full step) the torque is the holding torque
                      (``stepper_torque_nm``)
    pull-out torque   T_po(ω) = T_hold·min(1, V_s/(I·√(R² + (p·ω·L)²))): the driver holds the phase current I while
                      its supply can push it through the winding's impedance at the electrical frequency p·ω; above
                      that corner the current, and the torque, fall (``pullout_torque_nm``; the back-EMF is left out,
                      so the curve is an upper bound on the real one)
    detent torque     τ_d = −T_det·sin(4p·(φ − φ₀)): the unpowered rotor's pull toward its full-step positions,
                      four per electrical cycle (the magnet's cogging, its 4th harmonic)
    rotor             J_rotor on the driven joint (the armature) and a viscous b·φ̇ (the joint's damping)
    microsteps        φ_c = φ₀ + μ·n, μ = 2π/(steps·microsteps) per microstep, n the sketch's whole position
                      (``commanded_angle_rad``); φ₀ the drive joint's angle with the beam level, where the sketch
                      counts from (it sets its position to 0 with the beam level: ``rest_command`` is 0 on any drive;
                      a rig reset off level starts with the count at 0, and a rotor more than two full steps
                      from φ₀ falls into another cycle: steps missed at power-up)
    speed ramp        the sketch's position s moves toward the target at most v_max and ±a (AccelStepper's moveTo
                      and run()): the speed heads for sign(D)·min(v_max, √(2a|D|)), D the distance to go, with
                      |dv/dt| ≤ a, reaching it within one physics step when it can (``ramp_acceleration``):
                      full speed, then the braking that stops it on the target
    missed steps      above the pull-out torque the rotor slips whole electrical cycles; the sketch's count no longer
                      matches the rotor (``missed_full_steps``: a multiple of 4 full steps)

Where the ramp lives: in the run's per-step law (``StepperLaw``, the part's ``ActuatorPart.step_law``), not in
the board's per-tick write. The sketch's run() steps the motor at up to kHz rates between two loop ticks; a ramp
evaluated once a tick would jump the commanded angle by v_max·T each tick (at 2000 microsteps/s and 20 ms, 40
microsteps: 2.5 full steps, past the quarter cycle where the sine law turns over). The law holds (s, v) and
advances them every physics step.

How MuJoCo runs it: the actuator ``motor`` (``apply_stepper``) is a plain torque motor on the drive's input joint
(gear 1, ctrl the torque, unclamped: the sine bounds it), with the rotor's inertia and damping on that joint. The
simulated rig (``twin.rigs.sim.SimRig``) steps the law through ``twin.plant.Plant.advance_with_law`` (every
physics step, a fresh law each run): before each ``mj_step`` the law turns the board's target and the drive
joint's angle and speed, read from MjData (the beam's hinge on the pivot, the horn's joint on a lever: the rotor's
own coordinate, where its torque and inertia act, not φ(θ) through the linkage's soft closure), into the ctrl. The
torque is held over the step, as MuJoCo's implicitfast evaluates any force once a step: the rig's trajectory has
the bits of the same law evaluated inside mj_step as a user actuator (measured). No global state. Why not a
position actuator (kp = p·T_hold, clamped at ±T_hold): it is the sine's tangent, 19 % strong at one radian of
electrical lag and never lets go, so the rotor cannot slip. The batch engine (``twin.rigs.batch``) cannot run a
per-step law inside its rollout and refuses the rig; a law on the state or firmware (``SimRig.read_with_state_law``,
``read_with_firmware``) is refused too. Cost (measured, CPU time, interleaved with the thesis's rig in one process,
1 s SimRig runs, a 2-CPU machine under load): the fastest of 40 runs 23 µs a physics step on the pivot and 26 µs on
the lever against the thesis's 16 µs (medians 35, 45 and 22 µs). Error: against scipy's integration of the same
ODE, first order in the step (the torque held over it): 5.2e-4 rad at the rig's 1 ms and 5.1e-5 rad at 0.1 ms on a
1.6e-2 rad step; against the same step written out by hand, 1e-17 rad. The reference model (``twin.reference``)
runs the same sine, detent and damping law (RK4, the law in each stage) with the sketch's whole position as the
commanded one, and the same ramp each physics step (``DriveLaw.ramp``: ``twin.drive_equations.stepper_ramp_step``);
its compiled form (``twin.screen.plant``) too. The float arithmetic of the law and the ramp lives in
``twin.drive_equations`` (one home for this part, the reference model and the kernel).

Defaults: MotionKing 17HS4401 (17HS series data sheet, the 17HS4401 row: 1.8°, 1.7 A, 1.5 Ω, 2.8 mH, holding
torque 40 N·cm, detent torque 2.2 N·cm, rotor inertia 54 g·cm²), 12 V supply, 16 microsteps (TMC2209 data sheet:
8, 16, 32 or 64 by its MS1/MS2 pins).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from twin import model as mdl
from twin.drive_equations import (
    stepper_magnet_torque_nm,
    stepper_pullout_nm,
    stepper_ramp_acceleration,
    stepper_ramp_step,
    stepper_shaft_torque_nm,
)
from twin.interface import CommandRange
from twin.parameters import ParameterError, Parameters, check_group, param, register_group
from twin.parts.arduino import register_step_dir_actuator
from twin.parts.contract import ActuatorPart, BatchForm, BatchWrite, MjcfFragment, register, vary
from twin.reference import ShaftTorque, register_actuator_law

__all__ = [
    "STEPPER",
    "Stepper",
    "StepperLaw",
    "apply_stepper",
    "commanded_angle_rad",
    "level_angle_rad",
    "missed_full_steps",
    "rotor_missed_full_steps",
    "pullout_torque_nm",
    "ramp_acceleration",
    "stepper_batch_drive",
    "stepper_drive",
    "stepper_kernel_numbers",
    "stepper_range",
    "stepper_rest_steps",
    "stepper_torque_nm",
]

_MOTOR_DATA = "MotionKing 17HS series hybrid stepping motor data sheet, the 17HS4401 row"
_FULL_STEPS_PER_CYCLE = 4  # a two-phase motor: four full steps per electrical cycle


@dataclass(frozen=True)
class Stepper:
    """A two-phase hybrid stepper, its driver's current, supply and microsteps, and the sketch's ramp."""

    holding_torque_nm: float = param(
        0.40,
        "N·m",
        f"{_MOTOR_DATA}: holding torque 40 N·cm at the rated 1.7 A (vendors' listings of the same part say 40 to "
        "45 N·cm)",
        gt=0.0,
        le=20.0,
        why="NEMA 8 to NEMA 34 steppers hold 0.02 to about 12 N·m",
    )
    full_steps_per_rev: int = param(
        200,
        "steps/rev",
        f"{_MOTOR_DATA}: step angle 1.8° (200 full steps a turn, 50 pole pairs)",
        ge=4,
        le=1000,
        integer=True,
        why="hybrid steppers have 0.36° to 90° full steps (4 to 1000 a turn)",
    )
    microsteps: int = param(
        16,
        "microsteps/step",
        "assumed: 16 (TMC2209 data sheet: 8, 16, 32 or 64 microsteps by the MS1/MS2 pins, 1 to 256 over UART); "
        "read your driver's jumpers",
        ge=1,
        le=256,
        integer=True,
        why="the TMC2209's microstep resolutions are 1 to 256",
    )
    rotor_inertia_kgm2: float = param(
        54e-7,
        "kg·m²",
        f"{_MOTOR_DATA}: rotor inertia 54 g·cm²",
        gt=0.0,
        le=1e-2,
        why="NEMA 8 to NEMA 34 rotors have 2 to 4000 g·cm² (4e-4 kg·m²); 1e-2 leaves room for a coupling",
    )
    detent_torque_nm: float = param(
        0.022,
        "N·m",
        f"{_MOTOR_DATA}: detent torque 2.2 N·cm",
        ge=0.0,
        le=1.0,
        why="detent torque is a few percent of the holding torque",
    )
    damping_nm_s_per_rad: float = param(
        1e-3,
        "N·m·s/rad",
        "assumed: the rotor's bearings, iron losses and the driver's current loop as one viscous term (no data sheet "
        "gives it); fit from a log of the beam ringing after a step",
        ge=0.0,
        le=1.0,
        why="a NEMA 17's viscous losses are well under 0.1 N·m at 100 rad/s",
    )
    phase_resistance_ohm: float = param(
        1.5,
        "Ω",
        f"{_MOTOR_DATA}: 1.5 Ω per phase",
        gt=0.0,
        le=100.0,
        why="stepper windings have 0.1 to a few tens of ohms",
    )
    phase_inductance_h: float = param(
        2.8e-3,
        "H",
        f"{_MOTOR_DATA}: 2.8 mH per phase",
        gt=0.0,
        le=0.2,
        why="stepper windings have 0.1 to about 100 mH",
    )
    current_a: float = param(
        1.7,
        "A",
        f"{_MOTOR_DATA}: rated current 1.7 A per phase, the current the holding torque is given at; assumed the "
        "TMC2209's set current (its Vref)",
        gt=0.0,
        le=2.8,
        why="the TMC2209 drives at most 2.8 A peak",
    )
    supply_v: float = param(
        12.0,
        "V",
        "a 12 V supply of at least 2 A, as the documented Arduino + CNC shield + TMC2209 + NEMA 17 ball-and-beam "
        "build uses",
        ge=4.75,
        le=29.0,
        why="the TMC2209 runs from 4.75 to 29 V (its data sheet)",
    )
    max_speed_steps_s: float = param(
        2000.0,
        "microsteps/s",
        "assumed: the sketch's setMaxSpeed (AccelStepper; 2000 microsteps/s at 16 microsteps is 225°/s); read "
        "your sketch",
        gt=0.0,
        le=1e5,
        why="AccelStepper on a 16 MHz AVR steps at most about 4000 steps/s; a timer-driven sketch some 1e4",
    )
    acceleration_steps_s2: float = param(
        20000.0,
        "microsteps/s²",
        "assumed: the sketch's setAcceleration (AccelStepper); read your sketch",
        gt=0.0,
        le=1e7,
        why="a ramp faster than 1e7 steps/s² reaches any speed within a step: no ramp",
    )
    target_limit_steps: int = param(
        3200,
        "microsteps",
        "assumed: the sketch clamps moveTo's target to one turn either way of level (3200 microsteps at 16); "
        "the board's output range",
        ge=1,
        le=2**31 - 1,
        integer=True,
        why="AccelStepper's positions are C longs (32 bits)",
    )

    def __post_init__(self) -> None:
        check_group(self, "stepper")
        if self.full_steps_per_rev % _FULL_STEPS_PER_CYCLE:
            raise ParameterError(
                f"stepper.full_steps_per_rev = {self.full_steps_per_rev!r} is impossible: a two-phase stepper has "
                "4 full steps per pole pair (200 for 1.8°, 400 for 0.9°)"
            )

    @property
    def pole_pairs(self) -> int:
        """p: the rotor's pole pairs, full steps per turn / 4 (50 for a 1.8° motor)."""
        return self.full_steps_per_rev // _FULL_STEPS_PER_CYCLE

    @property
    def microstep_rad(self) -> float:
        """μ = 2π/(full steps · microsteps): one microstep's angle (1.8°/16 = 0.1125° by default)."""
        return 2.0 * math.pi / (self.full_steps_per_rev * self.microsteps)

    @property
    def supply_impedance_ohm(self) -> float:
        """V_s/I: the largest winding impedance the supply can hold the set current through."""
        return self.supply_v / self.current_a


# --- the equations: pure functions of numbers (floats, or arrays: each run its own motor) -----------------------
def commanded_angle_rad(position_steps: Any, level_rad: Any, microstep_rad: Any) -> Any:
    """φ_c = φ₀ + μ·n: the angle the driver's currents point the rotor to, n the sketch's position rounded to a
    whole microstep (the step pulses it has sent: floor(s + ½)), counted from the level beam's φ₀."""
    if isinstance(position_steps, float):
        return level_rad + microstep_rad * math.floor(position_steps + 0.5)
    return level_rad + microstep_rad * np.floor(np.asarray(position_steps) + 0.5)


def pullout_torque_nm(
    speed_rad_s: Any,
    holding_nm: Any,
    pole_pairs: Any,
    resistance_ohm: Any,
    inductance_h: Any,
    supply_impedance_ohm: Any,
) -> Any:
    """T_po(ω) = T_hold·min(1, (V_s/I)/√(R² + (p·ω·L)²)): the torque the rotor can pull with at speed ω. The
    driver holds the set current I while the supply V_s can drive it through the winding's impedance at the
    electrical frequency p·ω; past that corner the current, and with it the torque, fall as 1/|Z| (back-EMF left
    out: an upper bound). At 12 V, 1.7 A, 1.5 Ω, 2.8 mH and p = 50 the corner is √(7.06² − 1.5²)/(50·2.8e-3) =
    49.3 rad/s (470 rpm)."""
    if isinstance(speed_rad_s, float) and isinstance(holding_nm, float):  # one run's floats (per-step law)
        return stepper_pullout_nm(
            speed_rad_s, holding_nm, pole_pairs, resistance_ohm, inductance_h, supply_impedance_ohm
        )
    reactance = pole_pairs * np.abs(speed_rad_s) * inductance_h
    impedance = np.sqrt(resistance_ohm * resistance_ohm + reactance * reactance)
    return holding_nm * np.minimum(1.0, supply_impedance_ohm / impedance)


def stepper_torque_nm(
    commanded_rad: Any,
    angle_rad: Any,
    speed_rad_s: Any,
    level_rad: Any,
    holding_nm: Any,
    pole_pairs: Any,
    detent_nm: Any,
    resistance_ohm: Any,
    inductance_h: Any,
    supply_impedance_ohm: Any,
) -> Any:
    """The rotor's torque without its viscous term: −T_po(φ̇)·sin(p·(φ − φ_c)) − T_det·sin(4p·(φ − φ₀)). The
    magnetic torque pulls the rotor toward φ_c within half an electrical cycle of it, hardest (T_po) at a quarter
    cycle, one full step; the detent torque toward its full-step positions, zero on them and a full step off."""
    if isinstance(speed_rad_s, (int, float)) and isinstance(angle_rad, (int, float)):  # one run's floats
        return stepper_magnet_torque_nm(
            stepper_pullout_nm, commanded_rad, angle_rad, speed_rad_s, level_rad, holding_nm, pole_pairs,
            detent_nm, resistance_ohm, inductance_h, supply_impedance_ohm,
        )  # fmt: skip
    pull = pullout_torque_nm(
        speed_rad_s, holding_nm, pole_pairs, resistance_ohm, inductance_h, supply_impedance_ohm
    )
    detent = detent_nm * np.sin(_FULL_STEPS_PER_CYCLE * pole_pairs * (angle_rad - level_rad))
    return -pull * np.sin(pole_pairs * (angle_rad - commanded_rad)) - detent


def ramp_acceleration(
    target_steps: Any, position_steps: Any, speed_steps_s: Any, max_speed: Any, acceleration: Any, step_s: Any
) -> Any:
    """dv/dt of the sketch's ramp (AccelStepper's moveTo and run(), in continuous time): the speed heads for
    sign(D)·min(v_max, √(2a|D|)), D = target − position, the fastest speed that can still stop on the target at
    the deceleration a, and no faster than reaches it within one physics step ``step_s`` (|D|/h: it lands on the
    target instead of hunting around it), changing at most a (reaching it within one step when it can). So it
    accelerates at a to v_max, cruises, and brakes at a onto the target; moving away, it brakes and turns."""
    if isinstance(target_steps, float) and isinstance(position_steps, float):  # one run's floats
        return stepper_ramp_acceleration(
            target_steps, position_steps, speed_steps_s, max_speed, acceleration, step_s
        )
    distance = np.asarray(target_steps) - position_steps
    reach = np.minimum(np.sqrt(2.0 * acceleration * np.abs(distance)), np.abs(distance) / step_s)
    wanted = np.sign(distance) * np.minimum(max_speed, reach)
    return np.clip((wanted - speed_steps_s) / step_s, -acceleration, acceleration)


def missed_full_steps(
    position_steps: Any, angle_rad: Any, level_rad: Any, pole_pairs: Any, microsteps: Any
) -> Any:
    """The full steps the rotor has lost against the sketch's count: the whole electrical cycles between where the
    currents point it (φ_c) and where it is, times 4 (a rotor that slipped one cycle forward reads −4). Within
    half a cycle of φ_c it is 0."""
    microstep = 2.0 * np.pi / (_FULL_STEPS_PER_CYCLE * pole_pairs * microsteps)
    lag = commanded_angle_rad(position_steps, level_rad, microstep) - angle_rad
    return _FULL_STEPS_PER_CYCLE * np.round(lag * pole_pairs / (2.0 * np.pi))


# --- the runtime: the sketch's target, the rest command, the board's range, the counts ---------------------------
def stepper_drive(params: Parameters) -> Callable[[float], float]:
    """The actuator's ctrl for the board's output: the sketch's target position in microsteps (what moveTo
    takes), as it is; the actuator's ramp moves the sketch's position toward it."""
    del params  # the target is the law's input; the ramp's limits are the law's (StepperLaw)

    def target_steps(steps: float) -> float:
        return float(steps)

    return target_steps


def stepper_batch_drive(params: Sequence[Parameters]) -> BatchWrite:
    """``stepper_drive`` of N runs (``ActuatorPart.batch_drive``): each run's target as it is (no state)."""
    del params

    def target_steps(runs: np.ndarray, steps: np.ndarray) -> np.ndarray:
        return np.array(steps, dtype=float)

    return target_steps


def stepper_rest_steps(params: Parameters) -> float:
    """The target that holds the beam level: 0 microsteps on any drive (the sketch counts from the level beam,
    where the actuator's φ₀ is the drive joint's angle)."""
    del params
    return 0.0


def stepper_range(params: Parameters) -> CommandRange:
    """What the board's STEP/DIR output takes: a target within ±``stepper.target_limit_steps`` microsteps."""
    limit = float(params.of(Stepper).target_limit_steps)
    return CommandRange(
        -limit, limit, "microsteps", "±stepper.target_limit_steps", "the stepper's target position"
    )


def _level_rad(model: mujoco.MjModel, joint: str) -> float:
    return float(model.qpos0[model.joint(joint).qposadr[0]])


@functools.lru_cache(maxsize=64)
def _cached_level_rad(params: Parameters) -> float:
    return _level_rad(mdl.build_model(params), mdl.drive_joint(params))


def level_angle_rad(params: Parameters) -> float:
    """φ₀: the drive joint's angle with the beam level (its reference in the rig's model), where the sketch
    counts from (computed once per parameters: a law is made each run)."""
    try:
        return _cached_level_rad(params)
    except TypeError:  # parameters that cannot be a cache key: build the model
        return _level_rad(mdl.build_model(params), mdl.drive_joint(params))


# --- the per-step law: the ramp's state and the torque, once a physics step ---------------------------------------
class StepperLaw:
    """One run's stepper, a physics step at a time (the part's ``step_law``, ``twin.parts.contract.StepLaw``):
    the simulated rig (``twin.rigs.sim.SimRig``) calls it before each physics step with the sketch's target (the
    board's command, microsteps), the drive joint's angle and speed (the rotor's: the beam's hinge on the pivot,
    the horn's joint on a lever), and puts the torque it returns on that joint as the ``motor``'s ctrl. It holds
    the sketch's ramp (AccelStepper's position s and speed v, microsteps), from 0 at rest: the sketch set its
    count to 0 with the beam level. A fresh law per run."""

    __slots__ = ("_level", "_microstep", "_ramp", "_torque", "joint", "position_steps", "speed_steps_s")

    def __init__(self, params: Parameters) -> None:
        s = params.of(Stepper)
        self.joint = mdl.drive_joint(params)
        self._level = level_angle_rad(params)
        self._microstep = s.microstep_rad
        self._torque = (
            self._level,
            s.holding_torque_nm,
            s.pole_pairs,
            s.detent_torque_nm,
            s.phase_resistance_ohm,
            s.phase_inductance_h,
            s.supply_impedance_ohm,
        )
        self._ramp = (s.max_speed_steps_s, s.acceleration_steps_s2, params.physics.timestep_s)
        self.position_steps = 0.0  # s, microsteps (a float: the ramp's continuous position)
        self.speed_steps_s = 0.0  # v, microsteps/s

    def __call__(self, target_steps: float, angle_rad: float, speed_rad_s: float) -> float:
        """The torque (N·m) on the drive joint over the next physics step (``stepper_torque_nm``, φ_c from the
        sketch's position now: ``commanded_angle_rad``); then the ramp moves one step h toward ``target_steps``:
        v ← v + h·``ramp_acceleration``, s ← s + h·v (the speed the step ends with, semi-implicit Euler: a
        speed of D/h lands on the target). Floats in, a float out."""
        position, speed = self.position_steps, self.speed_steps_s
        level, hold, pairs, detent, resistance, inductance, impedance = self._torque
        commanded = commanded_angle_rad(position, level, self._microstep)
        torque: float = stepper_torque_nm(
            commanded, angle_rad, speed_rad_s, level, hold, pairs, detent, resistance, inductance, impedance
        )
        self.position_steps, self.speed_steps_s = stepper_ramp_step(
            stepper_ramp_acceleration, target_steps, position, speed, *self._ramp
        )
        return torque

    @property
    def sketch_position_steps(self) -> float:
        """The sketch's position now (AccelStepper's currentPosition): the ramp's, rounded to whole microsteps."""
        return float(math.floor(self.position_steps + 0.5))

    def missed_full_steps(self, angle_rad: float) -> int:
        """``missed_full_steps`` of this run now, the rotor at ``angle_rad`` (the drive joint's angle)."""
        _, _, pairs, *_ = self._torque
        microsteps = round(2.0 * math.pi / (_FULL_STEPS_PER_CYCLE * pairs * self._microstep))
        return int(missed_full_steps(self.position_steps, angle_rad, self._level, pairs, microsteps))


def rotor_missed_full_steps(law: StepperLaw, model: mujoco.MjModel, data: mujoco.MjData) -> int:
    """``missed_full_steps`` of a stepper rig now: the sketch's count (the run's ``law``) against its rotor (the
    drive joint's angle in ``data``)."""
    return law.missed_full_steps(float(data.qpos[model.joint(law.joint).qposadr[0]]))


# --- the MuJoCo actuator: a plain torque motor, the torque from the law --------------------------------------
def apply_stepper(spec: mujoco.MjSpec, p: Parameters) -> None:
    """The actuator ``motor`` as the stepper on the beam drive's input joint: a plain torque motor (gear 1, ctrl
    the torque in N·m, no clamp: the law's sine bounds it by T_hold + T_det) whose ctrl the law sets each
    physics step (``StepperLaw``), the rotor's inertia (armature) and damping on the joint."""
    s = p.of(Stepper)
    motor = spec.actuator(mdl.MOTOR)
    if motor is None:
        raise mdl.ModelError(f"{mdl.model_path()}: no actuator named '{mdl.MOTOR}'")
    motor.set_to_motor()
    motor.trntype = mujoco.mjtTrn.mjTRN_JOINT
    motor.target = mdl.drive_joint(p)
    motor.gear = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    motor.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
    motor.forcelimited = mujoco.mjtLimited.mjLIMITED_FALSE
    motor.actlimited = mujoco.mjtLimited.mjLIMITED_FALSE
    motor.damping = [s.damping_nm_s_per_rad, 0.0, 0.0]
    motor.armature = s.rotor_inertia_kgm2


# --- the batch form: the torque law and the ramp over N motors at once ------------------------------------------
_VARIED = (
    "stepper.holding_torque_nm",
    "stepper.detent_torque_nm",
    "stepper.phase_inductance_h",
    "stepper.supply_v",
    "stepper.max_speed_steps_s",
    "stepper.acceleration_steps_s2",
)


def _inputs(rng: np.random.Generator, n: int) -> tuple[list[Parameters], np.ndarray]:
    params = vary(Parameters(), _VARIED, rng, n)  # each run its own values, ±5 %
    # targets and positions over a turn, angles over a few cycles, speeds past the corner both ways
    rows = np.column_stack(
        [
            rng.uniform(-3200.0, 3200.0, n),
            rng.uniform(-3200.0, 3200.0, n),
            rng.uniform(-3000.0, 3000.0, n),
            rng.uniform(-0.5, 0.5, n),
            rng.uniform(-150.0, 150.0, n),
        ]
    )
    return params, rows


def _single(params: Parameters, row: np.ndarray) -> np.ndarray:
    """One run: the drive's ctrl, the commanded angle, the torque law and the ramp on floats."""
    s = params.of(Stepper)
    target, position, speed, angle, rate = row.tolist()
    ctrl = stepper_drive(params)(target)
    commanded = float(commanded_angle_rad(position, 0.0, s.microstep_rad))
    torque = float(
        stepper_torque_nm(
            commanded,
            angle,
            rate,
            0.0,
            s.holding_torque_nm,
            s.pole_pairs,
            s.detent_torque_nm,
            s.phase_resistance_ohm,
            s.phase_inductance_h,
            s.supply_impedance_ohm,
        )
    )
    accel = float(
        ramp_acceleration(
            ctrl, position, speed, s.max_speed_steps_s, s.acceleration_steps_s2, params.physics.timestep_s
        )
    )
    return np.array([commanded, torque, accel])


def _batch(params: Sequence[Parameters], rows: np.ndarray) -> np.ndarray:
    """Every run at once: the same functions on arrays, each run's constants a column."""
    groups = [p.of(Stepper) for p in params]

    def column(name: str) -> np.ndarray:
        return np.array([getattr(g, name) for g in groups], dtype=float)

    target, position, speed, angle, rate = rows.T
    commanded = commanded_angle_rad(position, 0.0, column("microstep_rad"))
    torque = stepper_torque_nm(
        commanded,
        angle,
        rate,
        0.0,
        column("holding_torque_nm"),
        column("pole_pairs"),
        column("detent_torque_nm"),
        column("phase_resistance_ohm"),
        column("phase_inductance_h"),
        column("supply_impedance_ohm"),
    )
    steps = np.array([p.physics.timestep_s for p in params])
    accel = ramp_acceleration(
        target, position, speed, column("max_speed_steps_s"), column("acceleration_steps_s2"), steps
    )
    return np.column_stack([commanded, torque, accel])


def _reference_law(params: Parameters) -> tuple[ShaftTorque, float]:
    """The stepper for the reference model (``twin.reference.DriveLaw``): the torque law at the shaft with the
    ctrl as the commanded position in microsteps, its damping, and the rotor's inertia. φ₀ is the drive joint's
    angle with the beam level (its reference in the model). ``ReferencePlant.advance`` hands it the sketch's
    whole position (its ramp, ``DriveLaw.ramp``, heading for the target); the law does not round, so that a
    linearization (``twin.linearize.linearize_reference``, ctrl straight in) sees its slope, not a step
    function's."""
    s = params.of(Stepper)
    numbers = stepper_kernel_numbers(params)

    def torque(target_steps: float, angle_rad: float, speed_rad_s: float) -> float:
        return stepper_shaft_torque_nm(
            stepper_magnet_torque_nm, stepper_pullout_nm, target_steps, angle_rad, speed_rad_s, *numbers
        )

    return torque, s.rotor_inertia_kgm2


def stepper_kernel_numbers(params: Parameters) -> tuple[float, ...]:
    """``twin.drive_equations.stepper_shaft_torque_nm``'s numbers after φ̇ (φ₀, μ, T_hold, p, T_det, R, L, V_s/I,
    b), as the reference model's law and the compiled kernel's row (twin.screen.plant) take them."""
    s = params.of(Stepper)
    return (
        level_angle_rad(params),
        s.microstep_rad,
        s.holding_torque_nm,
        float(s.pole_pairs),
        s.detent_torque_nm,
        s.phase_resistance_ohm,
        s.phase_inductance_h,
        s.supply_impedance_ohm,
        s.damping_nm_s_per_rad,
    )


register_group("stepper", Stepper)
register_actuator_law(
    "stepper",
    _reference_law,
    stepper_kernel_numbers,
    lambda params: (params.of(Stepper).max_speed_steps_s, params.of(Stepper).acceleration_steps_s2),
)
register_step_dir_actuator("stepper", stepper_range)


def _steps(params: Parameters) -> Callable[[float], float]:
    """The software's conversions: the reference model's control is the target in microsteps, the board's
    command itself (its ramp is the driver's, not the model's)."""
    return float


STEPPER = register(
    ActuatorPart(
        name="stepper",
        source=f"{_MOTOR_DATA} (1.8°, 40 N·cm, 2.2 N·cm detent, 54 g·cm², 1.5 Ω, 2.8 mH, 1.7 A); TMC2209 data sheet "
        "(STEP/DIR, 8/16/32/64 microsteps by pins); AccelStepper's moveTo/run ramp; ramp limits and damping "
        "assumed (fit from a log)",
        groups={"stepper": Stepper},
        equations=(
            commanded_angle_rad,
            pullout_torque_nm,
            stepper_torque_nm,
            ramp_acceleration,
            missed_full_steps,
            stepper_drive,
            stepper_rest_steps,
            stepper_range,
        ),
        mjcf=MjcfFragment((("actuator", mdl.MOTOR),), apply_stepper),
        batch=BatchForm(_single, _batch, _inputs, "twin.parts.stepper.stepper_torque_nm"),
        drive=stepper_drive,
        rest_command=stepper_rest_steps,
        batch_drive=stepper_batch_drive,
        step_law=StepperLaw,
        command_of=_steps,
        control_of=_steps,
        control_unit="microsteps",  # stepper_drive's target
    )
)
