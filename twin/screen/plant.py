"""The reference plant over N runs in one compiled kernel: ``twin.reference.ReferencePlant.advance`` for every
run at once, no Python per step.

The equations are compiled from their homes (``twin.reference.ball_beam_accelerations``, eq 3.1.26/3.1.27;
``twin.dcmotor.torque_nm``, eq 3.3.1), not written again; what this module adds is the loop: classical RK4 at
``physics.timestep_s`` with each run's motor volts held over a step through the amplifier's rails, the stops
(θ clamped, an outward θ̇ zeroed) and the ball lost once |x| passes the track's end (its state then frozen), as
the reference plant does at its step boundary. ``tests/test_screen.py`` holds the kernel to the reference
plant to 1e-12 over random states and volts.

Why numba: it compiles the core's own Python functions (one home per equation) with no build step and no
compiler on the user's machine; a C kernel would be a second copy of the equations.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numba
import numpy as np

from twin.dcmotor import torque_nm
from twin.jit import njit_cached
from twin.parameters import Parameters
from twin.reference import COULOMB_REGULARIZATION_RAD_S, EquationCoefficients, ball_beam_accelerations

__all__ = ["PlantRows", "advance_plant", "derivatives", "plant_rows"]

_accelerations = numba.njit(inline="always")(ball_beam_accelerations)
_torque = numba.njit(inline="always")(torque_nm)
_EPS = COULOMB_REGULARIZATION_RAD_S

# A run's row of constants: the 13 of EquationCoefficients.as_row, then the motor's and the rig's.
K_TAU, K_B, RAIL, STOP, HALF = 13, 14, 15, 16, 17
ROW = 18


@dataclass(frozen=True)
class PlantRows:
    """Each run's constants as one (N, ROW) array (the kernel's input), and the common time step."""

    rows: np.ndarray
    timestep_s: float


def plant_rows(params: Sequence[Parameters], *, motor_inertia: bool = True) -> PlantRows:
    """The kernel's constants of each run's parameters (one time step for all: refused otherwise)."""
    steps = {p.physics.timestep_s for p in params}
    if len(steps) != 1:
        raise ValueError(f"the runs have different physics.timestep_s: {sorted(steps)}")
    rows = np.empty((len(params), ROW))
    for i, p in enumerate(params):
        q = EquationCoefficients.from_params(p, motor_inertia=motor_inertia)
        rows[i, :13] = q.as_row()
        rows[i, K_TAU] = p.motor.torque_per_volt_nm_per_v
        rows[i, K_B] = p.motor.backemf_at_beam_v_s_per_rad
        rows[i, RAIL] = p.amplifier.rail_v
        rows[i, STOP] = p.beam.stop_angle_rad
        rows[i, HALF] = p.track.half_length_m
    return PlantRows(rows, steps.pop())


@numba.njit(inline="always")
def _f(
    r: np.ndarray, x: float, th: float, xd: float, thd: float, v: float
) -> tuple[float, float, float, float]:
    friction = r[12] * max(-1.0, min(1.0, thd / _EPS))
    tau = _torque(v, thd, r[K_TAU], r[K_B])
    xdd, thdd = _accelerations(
        r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8], r[9], r[10], r[11],
        x, xd, thd, math.sin(th), math.cos(th), friction, tau,
    )  # fmt: skip
    return xd, thd, xdd, thdd


@njit_cached
def _derivatives(rows: np.ndarray, states: np.ndarray, volts: np.ndarray) -> np.ndarray:
    out = np.empty_like(states)
    for i in range(states.shape[0]):
        d = _f(rows[i], states[i, 0], states[i, 1], states[i, 2], states[i, 3], volts[i])
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
) -> None:
    n, m = volts.shape
    record = xs.shape[1] == m + 1
    for i in range(n):
        r = rows[i]
        x, th, xd, thd = states[i, 0], states[i, 1], states[i, 2], states[i, 3]
        if record:
            xs[i, 0], thetas[i, 0] = x, th
        for k in range(m):
            if lost_step[i] < 0:
                v = min(max(volts[i, k], -r[RAIL]), r[RAIL])
                a1 = _f(r, x, th, xd, thd, v)
                a2 = _f(
                    r,
                    x + 0.5 * h * a1[0],
                    th + 0.5 * h * a1[1],
                    xd + 0.5 * h * a1[2],
                    thd + 0.5 * h * a1[3],
                    v,
                )
                a3 = _f(
                    r,
                    x + 0.5 * h * a2[0],
                    th + 0.5 * h * a2[1],
                    xd + 0.5 * h * a2[2],
                    thd + 0.5 * h * a2[3],
                    v,
                )
                a4 = _f(r, x + h * a3[0], th + h * a3[1], xd + h * a3[2], thd + h * a3[3], v)
                x = x + h / 6.0 * (a1[0] + 2 * a2[0] + 2 * a3[0] + a4[0])
                th = th + h / 6.0 * (a1[1] + 2 * a2[1] + 2 * a3[1] + a4[1])
                xd = xd + h / 6.0 * (a1[2] + 2 * a2[2] + 2 * a3[2] + a4[2])
                thd = thd + h / 6.0 * (a1[3] + 2 * a2[3] + 2 * a3[3] + a4[3])
                if abs(th) > r[STOP]:
                    th = math.copysign(r[STOP], th)
                    if thd * th > 0:
                        thd = 0.0
                if abs(x) > r[HALF]:
                    lost_step[i] = step0 + k + 1
            elif not record:
                break
            if record:  # a lost run's state stays where it was
                xs[i, k + 1], thetas[i, k + 1] = x, th
        states[i, 0], states[i, 1], states[i, 2], states[i, 3] = x, th, xd, thd


_NO_RECORD = np.empty((0, 0))


def advance_plant(
    plant: PlantRows,
    states: np.ndarray,
    lost_step: np.ndarray,
    volts: np.ndarray,
    step0: int = 0,
    *,
    record: bool = False,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Advance every run's state (N, 4; in place) over its motor volts (N, M: one per physics step), as
    ``ReferencePlant.advance``; ``lost_step`` (N, int, −1: on the track) gets the step (counted from ``step0``)
    after which a run's ball passed the track's end, and that run stops there. ``record``: return each run's
    x and θ before and after every step, (N, M + 1) each, as ``ReferencePlant.advance``'s block."""
    if states.dtype != np.float64 or not states.flags.c_contiguous:
        raise ValueError("states: a C-contiguous float64 (N, 4) array (advanced in place)")
    volts = np.ascontiguousarray(volts, dtype=float)
    if not record:
        _advance(plant.rows, plant.timestep_s, states, lost_step, volts, step0, _NO_RECORD, _NO_RECORD)
        return None
    xs = np.empty((volts.shape[0], volts.shape[1] + 1))
    thetas = np.empty_like(xs)
    _advance(plant.rows, plant.timestep_s, states, lost_step, volts, step0, xs, thetas)
    return xs, thetas
