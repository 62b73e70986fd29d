"""A hobby servo commanded by its pulse width (``HOBBY_SERVO``, role ``actuator``): the pulse-to-angle map, its
internal position loop with the DC motor's torque-speed line, the dead band, and its parameter group ``servo``.

Physics (the equations' one home: ``servo_angle_rad``, ``servo_torque_nm``; the numbers: ``Servo``):

    target    the servo's angle for a pulse: linear between (pulse_min, angle_at_min) and (pulse_max,
              angle_at_max), held at the ends of its travel (``servo_angle_rad``)
    drive     the position loop's drive is proportional to the angle error and saturates at full voltage:
              τ_drive = clip(k_p·(target − angle), −τ_s, τ_s), k_p = τ_s/e_sat, e_sat the error at which it
              saturates (an analog servo's proportional band)
    motor     a DC motor through its gears: at full voltage its torque falls linearly with speed,
              τ = τ_s·(1 − ω/ω₀), i.e. τ_s − b·ω with b = τ_s/ω₀ (the back-EMF's damping, K_t·K_b/R reflected
              through the gears), present at any drive: τ = τ_drive − b·ω (``servo_torque_nm``)
    supply    τ_s and ω₀ both scale with the supply's volts (stall current V/R, no-load speed V/K_b): the
              data sheet's values at its rated volts times V_supply/V_rated; b = τ_s/ω₀ does not change
    inertia   the rotor's and the gears' inertia reflected to the horn (N²·J_rotor), on the driven joint

The MuJoCo actuator ``motor`` (``apply_hobby_servo``) is this law: a position actuator on the beam drive's input
joint (``twin.model.drive_joint``) with kp = τ_s/e_sat, forcerange ±τ_s, and the actuator's damping b and armature
on the joint (damping outside the force range's clamp, as the motor's back-EMF is). ``servo_drive(params)`` turns
the board's output, a pulse width in µs, into the actuator's ctrl, the target angle in rad, with the dead band as
hysteresis on the pulse it accepts: a new pulse moves the target only if it differs from the accepted one by more
than the dead band (state held in the closure: a fresh one each call).

Defaults: the TowerPro SG90 data sheet (specifications: stall torque 1.8 kgf·cm at 4.8 V, operating speed
0.1 s/60°, dead band width 10 µs; position "−90" at ~1 ms, "0" at 1.5 ms, "90" at ~2 ms). An MG996R (TowerPro
MG996R data sheet: stall torque 9.4 kgf·cm at 4.8 V and 11 kgf·cm at 6 V, operating speed 0.17 s/60° at 4.8 V and
0.14 s/60° at 6 V, dead band width 5 µs, travel about 120°: 60° each way) is ``MG996R``, a set of overrides a rig
description can apply.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType

import mujoco
import numpy as np

from twin import model as mdl
from twin.drive_equations import servo_angle_rad, servo_pulse_us, servo_torque_nm
from twin.parameters import ParameterError, Parameters, check_group, param, register_group
from twin.parts.contract import ActuatorPart, BatchForm, BatchWrite, MjcfFragment, register, vary
from twin.reference import ShaftTorque, register_actuator_law

__all__ = [
    "HOBBY_SERVO",
    "KGF_CM_NM",
    "MG996R",
    "Servo",
    "apply_hobby_servo",
    "servo_angle_rad",
    "servo_batch_drive",
    "servo_drive",
    "servo_pulse_us",
    "servo_rest_pulse_us",
    "servo_torque_nm",
    "servo_torque_numbers",
]

KGF_CM_NM = 9.80665e-2  # 1 kgf·cm = 9.80665 N × 0.01 m (the data sheets' torque unit)
_SIXTY_DEG_RAD = math.pi / 3.0  # the data sheets' speed: seconds per 60°


@dataclass(frozen=True)
class Servo:
    """A hobby servo: its pulse-to-angle map, motor, position loop, dead band and reflected inertia."""

    pulse_min_us: float = param(
        1000.0,
        "µs",
        'TowerPro SG90 data sheet: position "−90" at a ~1 ms pulse (the travel\'s one end)',
        ge=400.0,
        le=2600.0,
        why="hobby servos take 0.5 to 2.5 ms pulses (the Servo library's default limits: 544…2400 µs)",
    )
    pulse_max_us: float = param(
        2000.0,
        "µs",
        'TowerPro SG90 data sheet: position "90" at a ~2 ms pulse (the travel\'s other end)',
        ge=400.0,
        le=2600.0,
        why="hobby servos take 0.5 to 2.5 ms pulses (the Servo library's default limits: 544…2400 µs)",
    )
    angle_at_min_rad: float = param(
        -math.pi / 2,
        "rad",
        'TowerPro SG90 data sheet: "−90" (°) at the short pulse; a mirrored mount swaps the signs',
        ge=-math.pi,
        le=math.pi,
        why="a hobby servo turns less than half a turn each way",
    )
    angle_at_max_rad: float = param(
        math.pi / 2,
        "rad",
        'TowerPro SG90 data sheet: "90" (°) at the long pulse; a mirrored mount swaps the signs',
        ge=-math.pi,
        le=math.pi,
        why="a hobby servo turns less than half a turn each way",
    )
    stall_torque_nm: float = param(
        1.8 * KGF_CM_NM,
        "N·m",
        "TowerPro SG90 data sheet: stall torque 1.8 kgf·cm at 4.8 V (servo.rated_voltage_v) = 0.1765 N·m; "
        "MG996R: 9.4 kgf·cm at 4.8 V",
        gt=0.0,
        le=10.0,
        why="hobby servos stall at 0.1 to a few N·m (60 kgf·cm is 5.9 N·m)",
    )
    no_load_speed_rad_s: float = param(
        _SIXTY_DEG_RAD / 0.1,
        "rad/s",
        "TowerPro SG90 data sheet: operating speed 0.1 s/60° at 4.8 V (no load) = 10.47 rad/s; MG996R: 0.17 s/60°",
        gt=0.0,
        le=100.0,
        why="the fastest hobby servos turn 60° in about 0.02 s (52 rad/s)",
    )
    rated_voltage_v: float = param(
        4.8,
        "V",
        "TowerPro SG90 data sheet: its torque and speed are given at 4.8 V (four NiCd/NiMH cells)",
        gt=0.0,
        le=9.0,
        why="hobby servos are rated at 4.8 to 8.4 V",
    )
    supply_v: float = param(
        5.0,
        "V",
        "assumed: the servo fed from an Arduino's 5 V rail (stall torque and no-load speed scale with it); "
        "measure it under load",
        gt=0.0,
        le=9.0,
        why="hobby servos are fed 4.8 to 8.4 V; past 9 V they burn",
    )
    saturation_error_rad: float = param(
        math.radians(5.0),
        "rad",
        "assumed: the position loop's drive saturates 5° from its target (an analog servo's proportional band "
        "is a few degrees); fit from a log",
        gt=0.0,
        le=math.pi / 2,
        why="a loop that saturates only a quarter turn off its target is no position servo",
    )
    deadband_us: float = param(
        10.0,
        "µs",
        "TowerPro SG90 data sheet: dead band width 10 µs (MG996R: 5 µs)",
        ge=0.0,
        le=100.0,
        why="data sheets give 1 to 20 µs; 100 µs would be 18° of an SG90's travel",
    )
    armature_kgm2: float = param(
        1.5e-4,
        "kg·m²",
        "assumed: a micro motor's rotor (~1e-8 kg·m²) through the gear train's ~1:120 (~1300 rad/s at the motor "
        "over 10.5 rad/s at the horn), N²·J ≈ 1.5e-4 kg·m²: a mechanical time constant J/b ≈ 9 ms; fit from a log",
        gt=0.0,
        le=0.1,
        why="a hobby servo's reflected rotor inertia is well under 0.1 kg·m²",
    )

    def __post_init__(self) -> None:
        check_group(self, "servo")
        if not self.pulse_max_us > self.pulse_min_us:
            raise ParameterError(
                f"servo.pulse_min_us = {self.pulse_min_us!r} µs and servo.pulse_max_us = {self.pulse_max_us!r} µs "
                "are impossible together: the travel's long pulse must be longer than its short one"
            )
        if self.angle_at_max_rad == self.angle_at_min_rad:
            raise ParameterError(
                f"servo.angle_at_min_rad = servo.angle_at_max_rad = {self.angle_at_min_rad!r} rad is impossible: "
                "the servo's travel ends at two different angles"
            )

    @property
    def stall_torque_at_supply_nm(self) -> float:
        """τ_s at the supply's volts: the rated stall torque × V_supply/V_rated (stall current V/R)."""
        return self.stall_torque_nm * self.supply_v / self.rated_voltage_v

    @property
    def no_load_speed_at_supply_rad_s(self) -> float:
        """ω₀ at the supply's volts: the rated no-load speed × V_supply/V_rated (back-EMF balances V)."""
        return self.no_load_speed_rad_s * self.supply_v / self.rated_voltage_v

    @property
    def damping_nm_s_per_rad(self) -> float:
        """b = τ_s/ω₀: the torque-speed line's slope (K_t·K_b/R through the gears), the same at any supply."""
        return self.stall_torque_nm / self.no_load_speed_rad_s

    @property
    def kp_nm_per_rad(self) -> float:
        """k_p = τ_s/e_sat: the position loop's gain, the drive saturating at the error e_sat."""
        return self.stall_torque_at_supply_nm / self.saturation_error_rad


# An MG996R in place of the SG90 (TowerPro MG996R data sheet, its 4.8 V column: 9.4 kgf·cm, 0.17 s/60°, dead
# band 5 µs; "approximately 120 degrees (60 in each direction)"). The sheet gives the travel, not the pulses that
# reach its ends: assumed the SG90's 1…2 ms (measure yours with a sweep).
MG996R: Mapping[str, float] = MappingProxyType(
    {
        "servo.stall_torque_nm": 9.4 * KGF_CM_NM,
        "servo.no_load_speed_rad_s": _SIXTY_DEG_RAD / 0.17,
        "servo.rated_voltage_v": 4.8,
        "servo.deadband_us": 5.0,
        "servo.angle_at_min_rad": -math.pi / 3,
        "servo.angle_at_max_rad": math.pi / 3,
    }
)


# --- the equations: pure functions of numbers (floats, or arrays: each run its own servo) ------------------------
def servo_rest_pulse_us(params: Parameters) -> float:
    """The pulse that holds the beam level (the rig's command before the controller's first): the one whose
    target is the drive's input joint's value in the model's reference pose, which every drive builds with the
    beam level (0 on the thesis's pivot; the servo's angle at the level beam on a lever, ``servo_shaft``'s
    reference)."""
    s = params.of(Servo)
    model = mdl.build_model(params)
    level = float(model.qpos0[model.joint(mdl.drive_joint(params)).qposadr[0]])
    return float(
        servo_pulse_us(level, s.pulse_min_us, s.pulse_max_us, s.angle_at_min_rad, s.angle_at_max_rad)
    )


def servo_drive(params: Parameters) -> Callable[[float], float]:
    """The actuator's ctrl (the target angle, rad) for the board's output (a pulse width, µs): the pulse map
    (``servo_angle_rad``) of the last accepted pulse, a new pulse accepted only if it differs from it by more
    than the dead band (hysteresis). The first pulse is accepted; the state lives in this closure (a fresh one
    each call: a new run calls it again)."""
    s = params.of(Servo)
    accepted: float | None = None

    def target_rad(pulse_us: float) -> float:
        nonlocal accepted
        if accepted is None or abs(pulse_us - accepted) > s.deadband_us:
            accepted = float(pulse_us)
        return float(
            servo_angle_rad(accepted, s.pulse_min_us, s.pulse_max_us, s.angle_at_min_rad, s.angle_at_max_rad)
        )

    return target_rad


def servo_batch_drive(params: Sequence[Parameters]) -> BatchWrite:
    """``servo_drive`` of N runs (``twin.parts.contract.ActuatorPart.batch_drive``): each run's last accepted
    pulse (its dead band's state, none at first) and pulse map, on arrays; run i's targets are its own
    ``servo_drive``'s bit for bit."""
    servos = [p.of(Servo) for p in params]

    def column(name: str) -> np.ndarray:
        return np.array([getattr(s, name) for s in servos], dtype=float)

    deadband = column("deadband_us")
    pulse_min, pulse_max = column("pulse_min_us"), column("pulse_max_us")
    angle_min, angle_max = column("angle_at_min_rad"), column("angle_at_max_rad")
    accepted = np.full(len(servos), np.nan)  # no pulse accepted yet

    def target_rad(runs: np.ndarray, pulse_us: np.ndarray) -> np.ndarray:
        pulse = np.asarray(pulse_us, dtype=float)
        last = accepted[runs]
        accepted[runs] = np.where(np.isnan(last) | (np.abs(pulse - last) > deadband[runs]), pulse, last)
        return np.asarray(
            servo_angle_rad(
                accepted[runs], pulse_min[runs], pulse_max[runs], angle_min[runs], angle_max[runs]
            )
        )

    return target_rad


# --- the MJCF fragment --------------------------------------------------------------------------------------
def apply_hobby_servo(spec: mujoco.MjSpec, p: Parameters) -> None:
    """The actuator ``motor`` as the servo (``servo``) on the beam drive's input joint (``drive_joint``): a
    position actuator, kp = τ_s/e_sat, its force clamped to ±τ_s (at the supply's volts), the torque-speed line's
    damping b = τ_s/ω₀ and the reflected inertia on the joint, its ctrl (the target angle) within the travel."""
    s = p.of(Servo)
    motor = spec.actuator(mdl.MOTOR)
    if motor is None:
        raise mdl.ModelError(f"{mdl.model_path()}: no actuator named '{mdl.MOTOR}'")
    motor.trntype = mujoco.mjtTrn.mjTRN_JOINT
    motor.target = mdl.drive_joint(p)
    motor.set_to_position(kp=s.kp_nm_per_rad)
    motor.gear = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    motor.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
    motor.forcerange = [-s.stall_torque_at_supply_nm, s.stall_torque_at_supply_nm]
    motor.damping = [s.damping_nm_s_per_rad, 0.0, 0.0]
    motor.armature = s.armature_kgm2
    motor.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
    motor.ctrlrange = sorted([s.angle_at_min_rad, s.angle_at_max_rad])


# --- the batch form: the drive (pulse map) and the torque law over N servos at once -----------------------------
_VARIED = (
    "servo.stall_torque_nm",
    "servo.no_load_speed_rad_s",
    "servo.supply_v",
    "servo.saturation_error_rad",
    "servo.pulse_min_us",
)


def _inputs(rng: np.random.Generator, n: int) -> tuple[list[Parameters], np.ndarray]:
    params = vary(Parameters(), _VARIED, rng, n)  # each run its own values, ±5 %
    # pulses past both ends of the travel, angles and speeds of a fast swing both ways
    rows = np.column_stack(
        [rng.uniform(800.0, 2200.0, n), rng.uniform(-1.6, 1.6, n), rng.uniform(-12.0, 12.0, n)]
    )
    return params, rows


def _single(params: Parameters, row: np.ndarray) -> np.ndarray:
    """One run: the rig's per-tick drive (``servo_drive``, its first pulse) and the torque law on floats."""
    s = params.of(Servo)
    pulse, angle, speed = row.tolist()
    target = servo_drive(params)(pulse)
    torque = servo_torque_nm(
        target, angle, speed, s.kp_nm_per_rad, s.stall_torque_at_supply_nm, s.damping_nm_s_per_rad
    )
    return np.array([target, float(torque)])


def _batch(params: Sequence[Parameters], rows: np.ndarray) -> np.ndarray:
    """Every run at once: the pulse map and the torque law on arrays, each run's servo a column."""
    servos = [p.of(Servo) for p in params]

    def column(name: str) -> np.ndarray:
        return np.array([getattr(s, name) for s in servos])

    target = servo_angle_rad(
        rows[:, 0],
        column("pulse_min_us"),
        column("pulse_max_us"),
        column("angle_at_min_rad"),
        column("angle_at_max_rad"),
    )
    torque = servo_torque_nm(
        target,
        rows[:, 1],
        rows[:, 2],
        column("kp_nm_per_rad"),
        column("stall_torque_at_supply_nm"),
        column("damping_nm_s_per_rad"),
    )
    return np.column_stack([target, torque])


def _reference_law(params: Parameters) -> tuple[ShaftTorque, float]:
    """The servo for the reference model (``twin.reference.DriveLaw``): its torque law at the shaft and its
    reflected inertia (the armature)."""
    s = params.of(Servo)
    kp, stall, damping = servo_torque_numbers(s)

    def torque(target_rad: float, angle_rad: float, speed_rad_s: float) -> float:
        return float(servo_torque_nm(target_rad, angle_rad, speed_rad_s, kp, stall, damping))

    return torque, s.armature_kgm2


def servo_torque_numbers(servo: Servo) -> tuple[float, float, float]:
    """``servo_torque_nm``'s numbers after the speed (k_p, τ_s at the supply, b), as the reference model and the
    compiled kernel's row (twin.screen.plant) pass them."""
    return servo.kp_nm_per_rad, servo.stall_torque_at_supply_nm, servo.damping_nm_s_per_rad


register_group("servo", Servo)
register_actuator_law("hobby_servo", _reference_law, lambda params: servo_torque_numbers(params.of(Servo)))


def servo_command_of(params: Parameters) -> Callable[[float], float]:
    """The software's conversion: a target angle → its pulse (``servo_pulse_us``)."""
    s = params.of(Servo)
    return lambda target_rad: float(
        servo_pulse_us(target_rad, s.pulse_min_us, s.pulse_max_us, s.angle_at_min_rad, s.angle_at_max_rad)
    )


def servo_control_of(params: Parameters) -> Callable[[float], float]:
    """The target a pulse asks for, nominally (``servo_angle_rad``, no dead band)."""
    s = params.of(Servo)
    return lambda pulse_us: float(
        servo_angle_rad(pulse_us, s.pulse_min_us, s.pulse_max_us, s.angle_at_min_rad, s.angle_at_max_rad)
    )


HOBBY_SERVO = register(
    ActuatorPart(
        name="hobby_servo",
        source="TowerPro SG90 data sheet (specifications: 1.8 kgf·cm, 0.1 s/60° at 4.8 V, dead band 10 µs, "
        "±90° at 1…2 ms); MG996R data sheet for MG996R; position loop and reflected inertia assumed (fit from a log)",
        groups={"servo": Servo},
        equations=(servo_angle_rad, servo_pulse_us, servo_torque_nm, servo_drive, servo_rest_pulse_us),
        mjcf=MjcfFragment((("actuator", mdl.MOTOR),), apply_hobby_servo),
        batch=BatchForm(_single, _batch, _inputs, "twin.parts.servo.servo_torque_nm"),
        drive=servo_drive,
        rest_command=servo_rest_pulse_us,
        batch_drive=servo_batch_drive,
        command_of=servo_command_of,
        control_of=servo_control_of,
        control_unit="rad",  # servo_drive's target angle
    )
)
