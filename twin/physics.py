"""What the simulated rig needs from a physics backend, free of MuJoCo.

Two backends implement ``PhysicsBackend``: the MuJoCo twin (``twin.plant.Plant``) and the analytic reference
model (``twin.reference.ReferencePlant``). The simulated rig (``twin.rigs.sim.SimRig``) drives either with the motor
volts of each physics step of one control period and reads back a ``PhysicsBlock``: the ball position, the
beam angle and the ball's contact with the track at every step, which the sensor chains turn into the
block the I/O card delivers.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Protocol

import numpy as np

from twin.parameters import Parameters

__all__ = ["PhysicsBackend", "PhysicsBlock", "check_initial_state", "check_on_track"]


class PhysicsBlock(NamedTuple):
    """One stretch of simulated time, at the physics steps: index 0 is the state before the first step.

    A backend that has the block's extremes at hand passes them on (the sensor chains' and the log's
    per-tick tests read them instead of scanning the arrays again); ``None`` means "not given"."""

    time_s: np.ndarray  # (n + 1,)
    x_m: np.ndarray  # ball centre along the beam (m)
    theta_rad: np.ndarray  # beam angle (rad)
    on_track: np.ndarray  # (n + 1,) bool: the ball sits on both wires within the track
    x_range_m: tuple[float, float] | None = None  # (min, max) of x_m
    theta_range_rad: tuple[float, float] | None = None  # (min, max) of theta_rad
    all_on_track: bool | None = None  # on_track.all()
    equal_steps: bool = (
        False  # the times are equally spaced (one physics step apart, up to the clock's rounding)
    )


class PhysicsBackend(Protocol):
    """A physics backend of the simulated rig (not ``twin.parameters.Physics``, the physics parameter group)."""

    params: Parameters

    @property
    def time_s(self) -> float: ...

    @property
    def timestep_s(self) -> float: ...

    @property
    def ball_lost(self) -> bool: ...

    @property
    def ball_lost_time_s(self) -> float | None: ...

    def reset(
        self, x_m: float, theta_rad: float, xdot_m_s: float = 0.0, thetadot_rad_s: float = 0.0
    ) -> None: ...

    def advance(self, motor_volts: np.ndarray) -> PhysicsBlock:
        """One physics step per entry of ``motor_volts`` (terminal volts, held over the step)."""
        ...

    def advance_held(self, motor_volts: float, n_steps: int) -> PhysicsBlock:
        """``advance`` with the same terminal volts for ``n_steps`` steps."""
        ...

    def state(self) -> np.ndarray:
        """(x_m, θ_rad, ẋ_m_s, θ̇_rad_s) now, in the thesis's coordinates (eq 3.1.28)."""
        ...

    def kick_ball(self, dv_m_s: float) -> None:
        """Add ``dv_m_s`` to the ball's speed along the beam, keeping it rolling without slipping."""
        ...


def check_initial_state(
    params: Parameters, x_m: float, theta_rad: float, xdot_m_s: float, thetadot_rad_s: float
) -> None:
    """Refuse an initial state that is not finite, off the track or beyond the stops (ValueError naming it)."""
    for name, value in (
        ("x_m", x_m),
        ("theta_rad", theta_rad),
        ("xdot_m_s", xdot_m_s),
        ("thetadot_rad_s", thetadot_rad_s),
    ):
        if not isinstance(value, (int, float, np.floating, np.integer)) or not math.isfinite(value):
            raise ValueError(f"initial state {name} = {value!r} is not a finite number")
    check_on_track(params, "initial x_m", x_m)
    if abs(theta_rad) > params.beam.stop_angle_rad:
        raise ValueError(
            f"initial theta_rad = {theta_rad!r} is beyond the stops (|θ| ≤ {params.beam.stop_angle_rad:.4f} rad)"
        )


def check_on_track(params: Parameters, name: str, x_m: object) -> float:
    """A ball position given by the user — a start, a setpoint (``run``, ``judge``, the environment's options)
    — as a float; refused unless it is a finite number on the track, |x| ≤ ``track.half_length_m``
    (ValueError naming ``name`` and the value; a name ending in ``_m`` carries its unit, others are given m)."""
    unit = "" if name.endswith("_m") else " m"
    if isinstance(x_m, (bool, np.bool_)) or not isinstance(x_m, (int, float, np.floating, np.integer)):
        raise ValueError(f"{name} = {x_m!r}: a number of metres along the track")
    x = float(x_m)
    if not math.isfinite(x):
        raise ValueError(f"{name} = {x_m!r}{unit} is not a finite number")
    half = params.track.half_length_m
    if abs(x) > half:
        raise ValueError(f"{name} = {x_m!r}{unit} is off the track (|x| ≤ {half:g} m)")
    return x
