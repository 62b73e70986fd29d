"""The reference plant over N runs in one compiled kernel: ``twin.reference.ReferencePlant.advance`` for every
run at once, no Python per step.

The equations and the step are compiled from their homes, not written again: ``twin.reference``'s
``ball_beam_accelerations`` (eq 3.1.26/3.1.27), ``pivot_friction_nm``, ``rk4_step`` (classical RK4) and
``step_boundary`` (the stops: θ clamped, an outward θ̇ zeroed; the ball lost once |x| passes the track's end),
``twin.dcmotor.torque_nm`` (eq 3.3.1). What this module adds is the loop over runs and steps: each run's motor
volts held over a step through the amplifier's rails, a lost run's state frozen, as the reference plant does.
``tests/test_screen.py`` holds the kernel to the reference plant over random states and volts.

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
from twin.physics import BatchBlock, BatchClock, check_initial_state
from twin.reference import (
    EquationCoefficients,
    ball_beam_accelerations,
    pivot_friction_nm,
    rk4_step,
    step_boundary,
)

__all__ = ["PlantRows", "ReferenceBatchPhysics", "advance_plant", "derivatives", "plant_rows"]

_accelerations = numba.njit(inline="always")(ball_beam_accelerations)
_torque = numba.njit(inline="always")(torque_nm)
_friction = numba.njit(inline="always")(pivot_friction_nm)
_rk4 = numba.njit(inline="always")(rk4_step)
_boundary = numba.njit(inline="always")(step_boundary)

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
                x, th, xd, thd = _rk4(_f_held, x, th, xd, thd, (r, v), h)
                th, thd, lost = _boundary(x, th, thd, r[STOP], r[HALF])
                if lost:
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
        super().__init__(self.n)

    def advance(self, runs: np.ndarray, volts: np.ndarray) -> BatchBlock:
        """``ReferencePlant.advance`` for runs ``runs``."""
        live, m, h = runs, volts.shape[1], self.plant.timestep_s
        t0 = self._time_s
        plant = self.plant if len(live) == self.n else PlantRows(self.plant.rows[live], h)
        states, lost_step = self.states[live], self.lost_step[live]
        recorded = advance_plant(plant, states, lost_step, volts, record=True)
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
        self.states[live], self.lost_step[live] = states, lost_step
        times = t0 + np.arange(m + 1) * h
        self._time_s = float(times[-1])
        return BatchBlock(times, along, theta, on)

    def true_state(self, runs: np.ndarray) -> np.ndarray:
        """The kernel's state (frozen once lost: where the ball left the track)."""
        return self.states[runs]
