"""What the simulated rig needs from a physics backend, free of MuJoCo.

Two backends implement ``PhysicsBackend``: the MuJoCo twin (``twin.plant.Plant``) and the analytic reference
model (``twin.reference.ReferencePlant``). The simulated rig (``twin.rigs.sim.SimRig``) drives either with the motor
volts of each physics step of one control period and reads back a ``PhysicsBlock``: the ball position, the
beam angle and the ball's contact with the track at every step, which the sensor chains turn into the
block the I/O card delivers.

``BatchPhysics`` is the same for N runs stepped together (the batch engine, ``twin.rigs.batch.BatchRig``):
start the runs from their parameters and initial states, advance the live ones by a block of volts per step,
and report the true state, the track contact, when each ball was lost and the clock. Its signatures carry
numpy arrays only. ``twin.rigs.backends`` names each backend's single-run and batch implementations.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import NamedTuple, Protocol

import numpy as np

from twin.interface import RigError
from twin.parameters import Parameters

__all__ = [
    "BatchBlock",
    "BatchClock",
    "BatchFactory",
    "BatchPhysics",
    "PhysicsBackend",
    "PhysicsBlock",
    "SingleFactory",
    "check_initial_state",
    "check_on_track",
    "whole_steps",
]


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


class BatchBlock(NamedTuple):
    """One stretch of simulated time of the live runs of a batch, at the physics steps (index 0: the state
    before the first step). The runs are in step: one clock for all."""

    time_s: np.ndarray  # (m + 1,)
    x_m: np.ndarray  # (live, m + 1) ball centre along the beam (m)
    theta_rad: np.ndarray  # (live, m + 1) beam angle (rad)
    on_track: np.ndarray  # (live, m + 1) bool: false from the first step off the track on (a lost run: all)


class BatchClock:
    """The bookkeeping every ``BatchPhysics`` shares: the runs' clock and which runs are lost, and when (a
    backend subclasses it and moves ``_time_s``, ``_lost`` and ``_lost_time_s`` as its runs advance)."""

    def __init__(self, n: int, time_s: float = 0.0) -> None:
        self._time_s = time_s
        self._lost = np.zeros(n, dtype=bool)
        self._lost_time_s: list[float | None] = [None] * n

    @property
    def time_s(self) -> float:
        return self._time_s

    @property
    def lost(self) -> np.ndarray:
        return self._lost

    @property
    def lost_time_s(self) -> list[float | None]:
        return self._lost_time_s


class BatchPhysics(Protocol):
    """N runs of one physics backend stepped together, each run its single-run backend bit for bit (an
    exact backend) or its screening stand-in. Built by a ``BatchFactory`` from each run's parameters and
    initial state (x, θ at rest, checked as ``check_initial_state``), with the clock at 0. ``runs`` are
    indices of the runs still going, ascending; the others are not advanced."""

    @property
    def time_s(self) -> float:
        """The runs' clock after the last block."""
        ...

    @property
    def lost(self) -> np.ndarray:
        """(N,) bool: the run's ball has left the track (latched)."""
        ...

    @property
    def lost_time_s(self) -> list[float | None]:
        """Per run: the time of the last state on the track before its ball was lost, None while on it."""
        ...

    def advance(self, runs: np.ndarray, volts: np.ndarray) -> BatchBlock:
        """Advance runs ``runs`` by one physics step per column of ``volts`` (len(runs), m): terminal volts,
        each held over its step."""
        ...

    def true_state(self, runs: np.ndarray) -> np.ndarray:
        """(len(runs), 4): (x_m, θ_rad, ẋ_m_s, θ̇_rad_s) now; a lost run's where its ball left the track."""
        ...


# A backend's makers: one run from its parameters; N runs from theirs, their starts and the threads to use.
SingleFactory = Callable[[Parameters], PhysicsBackend]
BatchFactory = Callable[[Sequence[Parameters], np.ndarray, np.ndarray, int], BatchPhysics]


# A beam drive whose linkage reaches less than the beam's stops (a lever's horn at its travel's ends): the beam's
# travel (θ_low, θ_high) it allows, by the drive's name (``twin.parts.linkage`` registers the end lever's).
_DRIVE_REACH: dict[str, Callable[[Parameters], tuple[float, float]]] = {}


def register_drive_reach(drive: str, reach: Callable[[Parameters], tuple[float, float]]) -> None:
    """The beam's travel the drive ``drive`` allows, ``reach(params)`` (its module calls this once)."""
    _DRIVE_REACH[drive] = reach


def beam_travel_rad(params: Parameters) -> tuple[float, float]:
    """How far the beam can turn: its stops (±``beam.stop_angle_rad``), narrowed to its drive's reach."""
    stop = params.beam.stop_angle_rad
    reach = _DRIVE_REACH.get(params.parts.beam_drive)
    if reach is None:
        return -stop, stop
    low, high = reach(params)
    return max(-stop, low), min(stop, high)


def check_initial_state(
    params: Parameters, x_m: float, theta_rad: float, xdot_m_s: float, thetadot_rad_s: float
) -> None:
    """Refuse an initial state that is not finite, off the track or beyond the beam's travel (its stops, or its
    drive's reach: ValueError naming it)."""
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
    low, high = beam_travel_rad(params)
    if not low <= theta_rad <= high:
        raise ValueError(
            f"initial theta_rad = {theta_rad!r} is beyond what parts.beam_drive = {params.parts.beam_drive!r} "
            f"reaches ({low:.4f} … {high:.4f} rad)"
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


# A period or latency within this share of a whole number of physics steps is that whole number (clock rounding).
_STEP_TOLERANCE = 1e-9


def whole_steps(duration_s: float, step_s: float, name: str) -> int:
    """``duration_s`` in physics steps; ``RigError`` naming ``name`` unless it is a whole number of them."""
    n = duration_s / step_s
    steps = int(round(n))
    if abs(n - steps) > _STEP_TOLERANCE * max(1.0, n):
        raise RigError(
            f"{name} = {duration_s!r} s is not a whole number of physics steps ({step_s!r} s): it would be "
            f"{n:.6f} steps"
        )
    return steps
