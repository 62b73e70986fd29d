"""The reference plant over N runs in one compiled kernel: ``twin.reference.ReferencePlant.advance`` for every
run at once, no Python per step.

The equations and the step are compiled from their homes, not written again: ``twin.reference``'s
``ball_beam_accelerations`` (eq 3.1.26/3.1.27), ``pivot_friction_nm``, ``rk4_step`` (classical RK4) and
``step_boundary`` (the stops: θ clamped, an outward θ̇ zeroed; the ball lost once |x| passes the track's end),
``twin.dcmotor.torque_nm`` (eq 3.3.1). What this module adds is the loop over runs and steps: each run's motor
volts held over a step through the amplifier's rails, a lost run's state frozen, as the reference plant does.
``tests/test_screen.py`` holds the kernel to the reference plant over random states and volts.

A beam driven otherwise (``twin.reference.DriveLaw``: the end lever's exact closure or the pivot, turned by a
hobby servo or the geared motor) is a row of another kind: the kernel branches once per run, and its driven
derivative and boundary call ``ReferencePlant``'s functions in ``ReferencePlant``'s order
(``twin.drive_equations``: ``lever_horn_closure_rad``, ``lever_ratio_slope``, ``lever_shaft_derivatives``;
``twin.drive_equations.servo_torque_nm``; ``twin.reference``: ``geared_shaft_torque_nm``, ``driven_beam_terms``,
``drive_stop_derivative``, ``drive_stop_boundary``). ``tests/test_screen_driven.py`` holds it to the reference
plant on those rigs, each run its own servo and linkage. A beam hinged off its track's centre (Open Ball & Beam,
BB01: ``ReferencePlant._hinged_off_centre_derivative``) is a driven row with ``twin.reference.hinged_beam_terms``
between the beam's terms and the accelerations (``tests/test_screen_hinged.py``). A stepper is a driven row whose
law is ``twin.drive_equations.stepper_shaft_torque_nm`` and whose control each step is its sketch's whole position
(``stepper_sketch_steps``), the ramp (s, v: per-run state, ``advance_plant``'s ``ramps``) stepped toward the
written target by ``stepper_ramp_step``, in ``ReferencePlant.advance``'s order (``tests/test_screen_stepper.py``).
A part without such a form is refused by its field (``kernel_refusal``).

Why numba: it compiles the core's own Python functions (one home per equation) with no build step and no
compiler on the user's machine; a C kernel would be a second copy of the equations.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np

from twin.dcmotor import torque_nm
from twin.drive_equations import (
    lever_horn_closure_rad,
    lever_ratio_slope,
    lever_shaft_derivatives,
    servo_torque_nm,
    stepper_magnet_torque_nm,
    stepper_pullout_nm,
    stepper_ramp_acceleration,
    stepper_ramp_step,
    stepper_shaft_torque_nm,
    stepper_sketch_steps,
)
from twin.jit import njit_cached
from twin.parameters import Parameters
from twin.physics import BatchBlock, BatchClock, check_initial_state
from twin.reference import (
    DriveLaw,
    EquationCoefficients,
    ball_beam_accelerations,
    drive_law,
    drive_stop_boundary,
    drive_stop_derivative,
    driven_beam_terms,
    geared_motor_numbers,
    geared_shaft_torque_nm,
    hinged_beam_terms,
    pivot_friction_nm,
    rk4_step,
    step_boundary,
)

__all__ = [
    "KERNEL_PARTS",
    "PlantRows",
    "ReferenceBatchPhysics",
    "advance_plant",
    "derivatives",
    "kernel_refusal",
    "plant_rows",
]

_accelerations = numba.njit(inline="always")(ball_beam_accelerations)
_torque = numba.njit(inline="always")(torque_nm)
_friction = numba.njit(inline="always")(pivot_friction_nm)
_rk4 = numba.njit(inline="always")(rk4_step)
_boundary = numba.njit(inline="always")(step_boundary)
_horn = numba.njit(inline="always")(lever_horn_closure_rad)
_ratio_slope = numba.njit(inline="always")(lever_ratio_slope)
_shaft_derivatives = numba.njit(inline="always")(lever_shaft_derivatives)
_servo = numba.njit(inline="always")(servo_torque_nm)
_stepper_pullout = numba.njit(inline="always")(stepper_pullout_nm)
_stepper_magnet = numba.njit(inline="always")(stepper_magnet_torque_nm)
_stepper = numba.njit(inline="always")(stepper_shaft_torque_nm)
_ramp_acceleration = numba.njit(inline="always")(stepper_ramp_acceleration)
_ramp_step = numba.njit(inline="always")(stepper_ramp_step)
_sketch_steps = numba.njit(inline="always")(stepper_sketch_steps)
_geared = numba.njit(inline="always")(geared_shaft_torque_nm)
_beam_terms = numba.njit(inline="always")(driven_beam_terms)
_stop_derivative = numba.njit(inline="always")(drive_stop_derivative)
_drive_stops = numba.njit(inline="always")(drive_stop_boundary)
_hinged = numba.njit(inline="always")(hinged_beam_terms)

# A run's row of constants: the 13 of EquationCoefficients.as_row, then the motor's and the rig's (the thesis's
# eq 3.1.27 as written reads these only) ...
K_TAU, K_B, RAIL, STOP, HALF = 13, 14, 15, 16, 17
# ... then, for a beam driven otherwise (``twin.reference.DriveLaw``): whether it is (KIND), the drive's and the
# actuator's kinds, the inertia turning with the shaft, the drive's stops, the ball's share of a stop's impulse,
# the drive's numbers (``lever_kernel_numbers``) and the actuator's (``servo_torque_numbers``,
# ``geared_motor_numbers``). A driven row's α₂ (column 5) has the drive's inertia on the beam added and no
# reflected rotor (the law brings it), its RAIL is infinite (the actuator's law bounds its ctrl), as
# ``ReferencePlant``'s.
KIND, DRIVE, ACTUATOR, SHAFT_INERTIA, LO, HI, COUPLING = 18, 19, 20, 21, 22, 23, 24
DRIVE_NUMBERS, ACTUATOR_NUMBERS = 25, 32  # 7 and 4 columns
# ... then, for a driven beam hinged off its track's centre (``beam.hinged_off_centre``): whether it is (HINGED),
# the track's centre's offset d from the pivot and the beam's weight moment M_B·g·x_g (``hinged_beam_terms``)
HINGED, OFFSET, WEIGHT = 36, 37, 38
# ... then a stepper's numbers (``twin.parts.stepper.stepper_kernel_numbers``: 9 columns), and whether the law has
# a sketch's ramp between the written control and it (RAMPED; ``DriveLaw.ramp``: v_max and a, 2 columns). A ramped
# run's ramp state (s, v) is per-run state beside (x, θ, ẋ, θ̇): ``advance_plant``'s ``ramps``.
STEPPER_NUMBERS = 39
RAMPED, RAMP = 48, 49
ROW = 51
THESIS, DRIVEN = 0.0, 1.0  # KIND
PIVOT, END_LEVER = 0.0, 1.0  # DRIVE
GEARED_MOTOR, HOBBY_SERVO, STEPPER = 0.0, 1.0, 2.0  # ACTUATOR

# The parts the kernel has a form for, by role: the plant's roles only (sensors and boards are the batch engine's
# chains). Another part in one of these roles (another track or ball) is refused (``kernel_refusal``): its
# equations are not compiled here, and the screening falls back to MuJoCo. The stepper runs the reference model's
# law and its sketch's ramp, as ``ReferencePlant`` does.
KERNEL_PARTS: dict[str, tuple[str, ...]] = {
    "ball": ("steel_ball",),
    "track": ("two_wires", "v_groove", "rod_and_strip", "tube"),  # they enter through r* and h* alone
    "beam_drive": ("pivot", "end_lever"),
    "actuator": ("escap_dc_motor", "hobby_servo", "stepper"),
}
_DRIVE_KINDS = {"pivot": PIVOT, "end_lever": END_LEVER}
_ACTUATOR_KINDS = {"escap_dc_motor": GEARED_MOTOR, "hobby_servo": HOBBY_SERVO, "stepper": STEPPER}


@dataclass(frozen=True)
class PlantRows:
    """Each run's constants as one (N, ROW) array (the kernel's input), and the common time step."""

    rows: np.ndarray
    timestep_s: float


def kernel_refusal(params: Parameters) -> str | None:
    """Why the kernel cannot run the rig ``params.parts`` names (the first part it has no form for, by its field),
    or None if it can."""
    for role, known in KERNEL_PARTS.items():
        name = getattr(params.parts, role)
        if name not in known:
            return (
                f"parts.{role} = {name!r}: the fast engine's compiled plant has no form for this part (it has "
                f"{', '.join(repr(k) for k in known)})"
            )
    return None


def plant_rows(params: Sequence[Parameters], *, motor_inertia: bool = True) -> PlantRows:
    """The kernel's constants of each run's parameters (one time step for all: refused otherwise; a rig with a
    part the kernel has no form for: ``ValueError`` naming it, ``kernel_refusal``). ``motor_inertia``: the
    thesis's eq 3.1.27 with the reflected rotor (a driven beam's law always brings its actuator's)."""
    steps = {p.physics.timestep_s for p in params}
    if len(steps) != 1:
        raise ValueError(f"the runs have different physics.timestep_s: {sorted(steps)}")
    rows = np.zeros((len(params), ROW))
    for i, p in enumerate(params):
        refusal = kernel_refusal(p)
        if refusal is not None:
            raise ValueError(f"run {i}: {refusal}")
        law = drive_law(p)
        q = EquationCoefficients.from_params(p, motor_inertia=motor_inertia and law is None)
        rows[i, :13] = q.as_row()
        rows[i, K_TAU] = p.motor.torque_per_volt_nm_per_v
        rows[i, K_B] = p.motor.backemf_at_beam_v_s_per_rad
        rows[i, RAIL] = p.amplifier.rail_v
        rows[i, STOP] = p.beam.stop_angle_rad
        rows[i, HALF] = p.track.half_length_m
        if law is not None:
            _driven_row(rows[i], p, q, law)
    return PlantRows(rows, steps.pop())


def _driven_row(row: np.ndarray, p: Parameters, q: EquationCoefficients[float], law: DriveLaw) -> None:
    """A driven beam's columns, the numbers ``ReferencePlant`` takes from its ``DriveLaw``."""
    shaft_inertia_kgm2, limits = law.shaft_inertia_kgm2, law.theta_limits_rad
    row[KIND] = DRIVEN
    row[5] = q.alpha_thdd + law.beam_inertia_kgm2
    row[RAIL] = math.inf
    row[DRIVE] = _DRIVE_KINDS[p.parts.beam_drive]
    row[ACTUATOR] = _ACTUATOR_KINDS[p.parts.actuator]
    row[SHAFT_INERTIA] = shaft_inertia_kgm2
    row[LO], row[HI] = limits or (-math.inf, math.inf)
    row[COUPLING] = (q.k2 + q.c) / (1.0 + q.k1)
    # ReferencePlant._hinged_off_centre_derivative's d and M_B·g·x_g, computed as it computes them
    if p.beam.hinged_off_centre:
        row[HINGED] = 1.0
        row[OFFSET] = p.beam.track_offset_m
        row[WEIGHT] = p.beam.mass_kg * q.g * p.beam.cog_along_m
    if row[DRIVE] == END_LEVER:
        row[DRIVE_NUMBERS : DRIVE_NUMBERS + 7] = law.drive_numbers
    if row[ACTUATOR] == HOBBY_SERVO:
        row[ACTUATOR_NUMBERS : ACTUATOR_NUMBERS + 3] = law.actuator_numbers
    elif row[ACTUATOR] == STEPPER:
        row[STEPPER_NUMBERS : STEPPER_NUMBERS + 9] = law.actuator_numbers
    else:
        row[ACTUATOR_NUMBERS : ACTUATOR_NUMBERS + 4] = geared_motor_numbers(p)
    if law.ramp is not None:
        row[RAMPED] = 1.0
        row[RAMP : RAMP + 2] = law.ramp


@numba.njit(inline="always")
def _f(
    r: np.ndarray, x: float, th: float, xd: float, thd: float, v: float
) -> tuple[float, float, float, float]:
    friction = _friction(r[12], thd)
    tau = _torque(v, thd, r[K_TAU], r[K_B])
    xdd, thdd = _accelerations(
        r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8], r[9], r[10], r[11],
        x, xd, thd, math.sin(th), math.cos(th), friction, tau,
    )  # fmt: skip
    return xd, thd, xdd, thdd


@numba.njit(inline="always")
def _f_held(
    x: float, th: float, xd: float, thd: float, held: tuple[np.ndarray, float]
) -> tuple[float, float, float, float]:
    """``_f`` as ``rk4_step`` calls it: the run's row and its held volts passed through as one input."""
    r, v = held
    return _f(r, x, th, xd, thd, v)


@numba.njit(inline="always")
def _lever(
    th: float, arm: float, rod: float, crank: float, sx: float, sz: float, sense: float, neutral: float
) -> tuple[float, float, float]:
    """``twin.drive_equations.lever_shaft_angles``: the same functions called in the same order."""
    phi = _horn(th, arm, rod, crank, sx, sz, sense, neutral)
    ratio, slope = _ratio_slope(th, phi, arm, crank, sx, sz)
    dphi, ddphi = _shaft_derivatives(ratio, slope)
    return phi - neutral, dphi, ddphi


@numba.njit  # not inlined at numba's IR: four inlined copies per RK4 step took 10 s more to compile, cold
def _f_driven(
    r: np.ndarray, x: float, th: float, xd: float, thd: float, ctrl: float
) -> tuple[float, float, float, float]:
    """``ReferencePlant._driven_derivative``'s derivative (a hinged row: ``_hinged_off_centre_derivative``'s): the
    same functions called in the same order."""
    if r[DRIVE] == END_LEVER:
        phi, dphi, ddphi = _lever(
            th, r[DRIVE_NUMBERS], r[DRIVE_NUMBERS + 1], r[DRIVE_NUMBERS + 2], r[DRIVE_NUMBERS + 3],
            r[DRIVE_NUMBERS + 4], r[DRIVE_NUMBERS + 5], r[DRIVE_NUMBERS + 6],
        )  # fmt: skip
    else:  # at the pivot: φ = θ
        phi, dphi, ddphi = th, 1.0, 0.0
    a = ACTUATOR_NUMBERS
    if r[ACTUATOR] == HOBBY_SERVO:
        tau = _servo(ctrl, phi, dphi * thd, r[a], r[a + 1], r[a + 2])
    elif r[ACTUATOR] == STEPPER:
        b = STEPPER_NUMBERS
        tau = _stepper(
            _stepper_magnet, _stepper_pullout, ctrl, phi, dphi * thd, r[b], r[b + 1], r[b + 2], r[b + 3],
            r[b + 4], r[b + 5], r[b + 6], r[b + 7], r[b + 8],
        )  # fmt: skip
    else:
        tau = _geared(_torque, ctrl, dphi * thd, r[a], r[a + 1], r[a + 2], r[a + 3])
    a2, torque = _beam_terms(r[5], r[SHAFT_INERTIA], dphi, ddphi, thd, tau)
    s, co = math.sin(th), math.cos(th)
    # the ball's distance from the pivot: x itself under the track's centre (x + 0.0 would turn −0.0 into +0.0)
    along = x
    if r[HINGED] != 0.0:
        along, torque = _hinged(x, co, torque, r[OFFSET], r[WEIGHT])
    xdd, thdd = _accelerations(
        r[0], r[1], r[2], r[3], r[4], a2, r[6], r[7], r[8], r[9], r[10], r[11],
        along, xd, thd, s, co, _friction(r[12], thd), torque,
    )  # fmt: skip
    return _stop_derivative(r[0], r[3], along, th, xd, thd, s, xdd, thdd, r[LO], r[HI])


@numba.njit(inline="always")
def _f_driven_held(
    x: float, th: float, xd: float, thd: float, held: tuple[np.ndarray, float]
) -> tuple[float, float, float, float]:
    r, v = held
    return _f_driven(r, x, th, xd, thd, v)


@numba.njit(inline="always")
def _thesis_boundary(
    r: np.ndarray, x: float, th: float, xd: float, thd: float
) -> tuple[float, float, float, bool]:
    th, thd, lost = _boundary(x, th, thd, r[STOP], r[HALF])
    return th, xd, thd, lost


@numba.njit(inline="always")
def _driven_boundary(
    r: np.ndarray, x: float, th: float, xd: float, thd: float
) -> tuple[float, float, float, bool]:
    """``ReferencePlant._driven_boundary``: the beam's stops, then the drive's with the ball's share. On a hinged
    row too: x is from the track's centre, whose ends are ±HALF; the ball's share is the same (d is constant, so
    x + d and x change alike across the stop's impulse)."""
    before = thd
    th, thd, lost = _boundary(x, th, thd, r[STOP], r[HALF])
    th, xd, thd = _drive_stops(th, xd, thd, before, r[LO], r[HI], r[COUPLING])
    return th, xd, thd, lost


@njit_cached
def _derivatives(rows: np.ndarray, states: np.ndarray, volts: np.ndarray) -> np.ndarray:
    out = np.empty_like(states)
    for i in range(states.shape[0]):
        r = rows[i]
        if r[KIND] == THESIS:
            d = _f(r, states[i, 0], states[i, 1], states[i, 2], states[i, 3], volts[i])
        else:
            d = _f_driven(r, states[i, 0], states[i, 1], states[i, 2], states[i, 3], volts[i])
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = d
    return out


def derivatives(plant: PlantRows, states: np.ndarray, volts: np.ndarray) -> np.ndarray:
    """(ẋ, θ̇, ẍ, θ̈) of each run's state (N, 4) under its motor volts (N,), compiled."""
    return _derivatives(plant.rows, np.ascontiguousarray(states, dtype=float), np.asarray(volts, dtype=float))


@njit_cached
def _advance(
    rows: np.ndarray,
    h: float,
    states: np.ndarray,
    lost_step: np.ndarray,
    volts: np.ndarray,
    step0: int,
    xs: np.ndarray,
    thetas: np.ndarray,
    ramps: np.ndarray,
) -> None:
    for i in range(volts.shape[0]):
        # the kind is a run's constant: one branch per run, each kind's step loop compiled on its own
        if rows[i, KIND] == THESIS:
            _advance_run(
                _f_held, _thesis_boundary, rows[i], h, i, states, lost_step, volts, step0, xs, thetas, ramps,
                False,
            )  # fmt: skip
        elif rows[i, RAMPED] == 0.0:
            _advance_run(
                _f_driven_held, _driven_boundary, rows[i], h, i, states, lost_step, volts, step0, xs, thetas,
                ramps, False,
            )  # fmt: skip
        else:
            _advance_run(
                _f_driven_held, _driven_boundary, rows[i], h, i, states, lost_step, volts, step0, xs, thetas,
                ramps, True,
            )  # fmt: skip


@numba.njit(inline="always")
def _advance_run(
    f: Any,
    boundary: Any,
    r: np.ndarray,
    h: float,
    i: int,
    states: np.ndarray,
    lost_step: np.ndarray,
    volts: np.ndarray,
    step0: int,
    xs: np.ndarray,
    thetas: np.ndarray,
    ramps: np.ndarray,
    ramped: bool,
) -> None:
    """Run i over its volts: RK4 of ``f`` with each step's volts held through the rails, then ``boundary``.
    ``ramped`` (a stepper's sketch, ``ReferencePlant.advance``'s order): the step's control is the ramp's whole
    position, then the ramp (``ramps[i]``: s, v) moves one step toward the written control."""
    m = volts.shape[1]
    record = xs.shape[1] == m + 1
    x, th, xd, thd = states[i, 0], states[i, 1], states[i, 2], states[i, 3]
    position, speed = 0.0, 0.0
    if ramped:
        position, speed = ramps[i, 0], ramps[i, 1]
    if record:
        xs[i, 0], thetas[i, 0] = x, th
    for k in range(m):
        if lost_step[i] < 0:
            v = min(max(volts[i, k], -r[RAIL]), r[RAIL])
            if ramped:
                target, v = v, _sketch_steps(position)
                position, speed = _ramp_step(
                    _ramp_acceleration, target, position, speed, r[RAMP], r[RAMP + 1], h
                )
            x, th, xd, thd = _rk4(f, x, th, xd, thd, (r, v), h)
            th, xd, thd, lost = boundary(r, x, th, xd, thd)
            if lost:
                lost_step[i] = step0 + k + 1
        elif not record:
            break
        if record:  # a lost run's state stays where it was
            xs[i, k + 1], thetas[i, k + 1] = x, th
    states[i, 0], states[i, 1], states[i, 2], states[i, 3] = x, th, xd, thd
    if ramped:
        ramps[i, 0], ramps[i, 1] = position, speed


_NO_RECORD = np.empty((0, 0))


def advance_plant(
    plant: PlantRows,
    states: np.ndarray,
    lost_step: np.ndarray,
    volts: np.ndarray,
    step0: int = 0,
    *,
    record: bool = False,
    ramps: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Advance every run's state (N, 4; in place) over its motor volts (N, M: one per physics step), as
    ``ReferencePlant.advance``; ``lost_step`` (N, int, −1: on the track) gets the step (counted from ``step0``)
    after which a run's ball passed the track's end, and that run stops there. ``record``: return each run's
    x and θ before and after every step, (N, M + 1) each, as ``ReferencePlant.advance``'s block. ``ramps``: each
    run's stepper ramp (N, 2: s in microsteps, v in microsteps/s; advanced in place, as ``ReferencePlant``'s
    across its ``advance`` calls); None: every ramped run's ramp from rest at 0 (a run from its start)."""
    if states.dtype != np.float64 or not states.flags.c_contiguous:
        raise ValueError("states: a C-contiguous float64 (N, 4) array (advanced in place)")
    if ramps is None:
        ramps = np.zeros((states.shape[0], 2))
    elif ramps.dtype != np.float64 or not ramps.flags.c_contiguous or ramps.shape != (states.shape[0], 2):
        raise ValueError("ramps: a C-contiguous float64 (N, 2) array (advanced in place)")
    volts = np.ascontiguousarray(volts, dtype=float)
    if not record:
        _advance(plant.rows, plant.timestep_s, states, lost_step, volts, step0, _NO_RECORD, _NO_RECORD, ramps)
        return None
    xs = np.empty((volts.shape[0], volts.shape[1] + 1))
    thetas = np.empty_like(xs)
    _advance(plant.rows, plant.timestep_s, states, lost_step, volts, step0, xs, thetas, ramps)
    return xs, thetas


class ReferenceBatchPhysics(BatchClock):
    """The reference plant over N runs in the kernel (``twin.physics.BatchPhysics``): each run is
    ``ReferencePlant`` from the same start under the same volts (tests/test_screen.py). A lost run's state
    stays where its ball left the track, as the reference plant's."""

    def __init__(
        self, params: Sequence[Parameters], x0: np.ndarray, theta0: np.ndarray, nthread: int
    ) -> None:
        """As ``ReferencePlant.reset``: each start checked, at rest, the clock at 0 (``nthread``: unused, the
        kernel runs on the caller's thread)."""
        for i, q in enumerate(params):
            check_initial_state(q, float(x0[i]), float(theta0[i]), 0.0, 0.0)
        self.n = len(params)
        self.plant = plant_rows(params)
        self.states = np.zeros((self.n, 4))
        self.states[:, 0], self.states[:, 1] = x0, theta0
        self.lost_step = np.full(self.n, -1, dtype=np.int64)  # ≥ 0 once lost: the kernel skips the run
        self.ramps = np.zeros((self.n, 2))  # a stepper's ramp (s, v), from rest as ReferencePlant.reset's
        super().__init__(self.n)

    def advance(self, runs: np.ndarray, volts: np.ndarray) -> BatchBlock:
        """``ReferencePlant.advance`` for runs ``runs``."""
        live, m, h = runs, volts.shape[1], self.plant.timestep_s
        t0 = self._time_s
        plant = self.plant if len(live) == self.n else PlantRows(self.plant.rows[live], h)
        states, lost_step, ramps = self.states[live], self.lost_step[live], self.ramps[live]
        recorded = advance_plant(plant, states, lost_step, volts, record=True, ramps=ramps)
        assert recorded is not None
        along, theta = recorded
        if not np.isfinite(states).all():
            j = int(np.flatnonzero(~np.isfinite(states).all(axis=1))[0])
            raise FloatingPointError(
                f"run {int(live[j])}: reference model state is not finite by t = {t0 + m * h:.3f} s"
            )
        on = np.ones(along.shape, dtype=bool)
        was_lost = self._lost[live]
        on[was_lost] = False
        for j in np.flatnonzero(~was_lost & (lost_step >= 0)).tolist():
            i, k = int(live[j]), int(lost_step[j])
            self._lost[i] = True
            self._lost_time_s[i] = t0 + k * h  # ReferencePlant's: its clock plus the step's offset
            on[j, k:] = False
        self.states[live], self.lost_step[live], self.ramps[live] = states, lost_step, ramps
        times = t0 + np.arange(m + 1) * h
        self._time_s = float(times[-1])
        return BatchBlock(times, along, theta, on)

    def true_state(self, runs: np.ndarray) -> np.ndarray:
        """The kernel's state (frozen once lost: where the ball left the track)."""
        return self.states[runs]
