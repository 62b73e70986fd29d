"""The MuJoCo plant: set and read the rig's state in the thesis's coordinates, step it, detect a lost ball.

State (eq 3.1.28): x = (x, θ, ẋ, θ̇) with x the ball centre along the beam from the pivot's normal (m),
θ the beam angle (rad, > 0 lifts the +x end), ẋ the ball's speed relative to the beam.

``advance`` runs a whole control period in one C call (``mujoco.rollout``, one thread) and computes the
ball's position, the beam angle and the lost-ball test for every step in numpy from the returned states:
no Python per physics step. The state is carried from call to call with MuJoCo's solver warm start, so the
trajectory is bit-identical to stepping ``mj_step`` one step at a time.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import mujoco
import numpy as np
from mujoco import rollout

from twin import fixedorder as fo
from twin import model as mdl
from twin.parameters import ParameterError, Parameters
from twin.physics import PhysicsBlock, check_initial_state

__all__ = [
    "FULL_STATE",
    "BallKinematics",
    "NumericalError",
    "Plant",
    "beyond_stops",
    "failure_time_s",
    "numerical_failure",
    "STOP_YIELD_RAD",
    "stop_overshoot_bound_rad",
    "through_stops",
    "warning_text",
]

FULL_STATE = mujoco.mjtState.mjSTATE_FULLPHYSICS  # a run's whole state: what a batch row carries
_CTRL = mujoco.mjtState.mjSTATE_CTRL

# MuJoCo's warnings, each a sign that the simulation (not the rig) failed: its step reset the state (BADQ*),
# its buffers overflowed (contacts, constraints) or the model is not physical. They are counted in MjData
# and reported per run as a NumericalError; MuJoCo's default handler would also print each one to stderr.
_WARNING_TEXT = {
    mujoco.mjtWarning.mjWARN_INERTIA: "a body inertia that is not physical (INERTIA)",
    mujoco.mjtWarning.mjWARN_CONTACTFULL: "a full contact buffer (CONTACTFULL)",
    mujoco.mjtWarning.mjWARN_CNSTRFULL: "a full constraint buffer (CNSTRFULL)",
    mujoco.mjtWarning.mjWARN_BADQPOS: "an unstable simulation (BADQPOS: a NaN, infinite or huge position)",
    mujoco.mjtWarning.mjWARN_BADQVEL: "an unstable simulation (BADQVEL: a NaN, infinite or huge velocity)",
    mujoco.mjtWarning.mjWARN_BADQACC: "an unstable simulation (BADQACC: a NaN, infinite or huge acceleration)",
    mujoco.mjtWarning.mjWARN_BADCTRL: "a bad actuator input (BADCTRL)",
}
mujoco.set_mju_user_warning(lambda message: None)


class NumericalError(FloatingPointError):
    """The simulation failed, not the rig: MuJoCo warned (an unstable step, a full buffer, …), its state is
    not finite, or the beam went past its stops by more than they can yield. A run that raises it has no
    physical verdict; the message names the time, what happened and the parameters that differ from the
    defaults."""


def numerical_failure(params: Parameters, what: str, t_s: float) -> NumericalError:
    """``numerical failure: {what} at t = … s — the parameters differ from the defaults in …; the physics
    step is … ms``."""
    changed = changed_text(params)
    which = (
        f"the parameters differ from the defaults in {changed}"
        if changed
        else "the parameters are the defaults"
    )
    return NumericalError(
        f"numerical failure: {what} at t = {t_s:.3f} s — {which}; the physics step is "
        f"{params.physics.timestep_s * 1e3:g} ms"
    )


def changed_text(params: Parameters, most: int = 6) -> str:
    """The parameters that differ from the defaults, ``motor.resistance_ohm = 1e-09, …`` ('' for none)."""
    changed = params.changed()
    shown = ", ".join(f"{name} = {value!r}" for name, value in list(changed.items())[:most])
    return shown + (f" and {len(changed) - most} more" if len(changed) > most else "")


def warning_text(counts: Mapping[int, int]) -> str:
    """What MuJoCo reported, from its warning counters (mjtWarning index → count)."""
    return "MuJoCo reported " + " and ".join(
        _WARNING_TEXT[mujoco.mjtWarning(i)] for i, n in counts.items() if n
    )


def failure_time_s(times_s: np.ndarray) -> float:
    """When a block that MuJoCo warned in went wrong: its clock stops advancing there (a BADQ* warning resets
    the state and the time; a batch's simulation stops stepping), else its end."""
    bad = np.flatnonzero(~(np.diff(times_s) > 0))
    return float(times_s[bad[0]]) if bad.size else float(times_s[-1])


def beyond_stops(params: Parameters, theta_abs_rad: float, t_s: float) -> NumericalError:
    """The failure of a beam at |θ| = ``theta_abs_rad``, past its stops further than they can yield."""
    stop, bound = params.beam.stop_angle_rad, stop_overshoot_bound_rad(params)
    return numerical_failure(
        params,
        f"the beam at {theta_abs_rad:.4g} rad, past its stops ({stop:.4g} rad) by more than they can yield "
        f"({bound:.3g} rad)",
        t_s,
    )


def stop_overshoot_bound_rad(params: Parameters) -> float:
    """How far past its stops the beam can physically go in the twin: the stops are soft constraints (time
    constant ``physics.contact_timeconst_s``) that act from the step after the beam reaches them, so at the
    motor's no-load speed at the rails, rail_v / (N·K_b), it yields at most that speed times one step plus
    the time constant. Further out is a numerical failure, not a physical state. (Over its stroke the beam
    reaches about 11 rad/s at the rails; an amplifier gain of 1000 slams it into its stops at up to 7 rad/s
    and they yield up to 4.2 mrad: the stops' softness, inside this bound of 0.23 rad, and hit_stops says
    so.)"""
    omega_max = params.amplifier.rail_v / params.motor.backemf_at_beam_v_s_per_rad
    return omega_max * (params.physics.timestep_s + params.physics.contact_timeconst_s)


# How far a stop's contact yields before the beam counts as gone through it: an amplifier gain of 1000 slams
# the beam into its stops at up to 7 rad/s and they yield 4.2 mrad (``stop_overshoot_bound_rad``); a rig's
# steel stop yields less. Beyond this the motor overpowered the stops' soft contact.
STOP_YIELD_RAD = 0.01


def through_stops(peak_theta_rad: float, params: Parameters) -> str:
    """What to tell of a run whose beam went past its stops further than they yield (``STOP_YIELD_RAD``):
    "" when it did not."""
    past = peak_theta_rad - params.beam.stop_angle_rad
    if past <= STOP_YIELD_RAD:
        return ""
    return (
        f"the beam went {past:.3f} rad past its ±{math.degrees(params.beam.stop_angle_rad):.1f}° stops "
        f"(peak θ {peak_theta_rad:.3f} rad): the motor (rail ±{params.amplifier.rail_v:g} V) overpowered the "
        f"stops' contact, which yields {1e3 * STOP_YIELD_RAD:.0f} mrad at most on the rig — what followed is "
        "not what the rig would do"
    )


# The ball counts as lost once its centre has dropped this far below (or risen above) its seat on the wires.
# 2 mm is 40x the largest transient lift seen in fast combined rolling and tilting (measured: µm).
LOST_HEIGHT_TOLERANCE_M = 2e-3


def _all_finite(values: np.ndarray) -> bool:
    """Whether every value is finite: a NaN or an infinity makes the sum of squares non-finite (one BLAS
    call); only when it is not (or it overflowed) are the values looked at one by one."""
    return math.isfinite(values.dot(values)) or bool(np.isfinite(values).all())


@dataclass(frozen=True)
class BallKinematics:
    """The ball relative to the beam, in the beam frame."""

    position_m: np.ndarray  # (along the beam, lateral, height above P)
    velocity_m_s: np.ndarray  # relative to the beam, beam frame
    spin_rad_s: float  # ball angular velocity relative to the beam, about the hinge axis


class _StepBuffers:
    """Arrays reused by every ``advance`` of ``n`` steps (the per-tick cost is allocation, not arithmetic).

    ``rows`` holds the state before the first step and after each step; ``initial_state`` and ``states``
    are views of it in the shapes ``mujoco.rollout`` takes, so the rollout writes straight into it."""

    def __init__(self, n: int, nu: int, nstate: int, timestep_s: float) -> None:
        self.control = np.zeros((1, n, nu))
        self.rows = np.empty((n + 1, nstate))
        self.initial_state = self.rows[None, 0]  # (1, nstate)
        self.states = self.rows[None, 1:]  # (1, n, nstate), C-contiguous
        self.step_offsets_s = np.arange(n + 1) * timestep_s  # time of each row after the first


class Plant:
    """MuJoCo model + data of the rig, with the thesis's state coordinates.

    ``hold_beam_rad`` builds the rig with the beam rigidly held at that angle (no motor)."""

    def __init__(self, params: Parameters | None = None, *, hold_beam_rad: float | None = None) -> None:
        self.params = params or Parameters()
        self.held_angle_rad = hold_beam_rad
        try:
            self.model = mdl.build_model(self.params, hold_beam_rad=hold_beam_rad)
        except ValueError as exc:  # MuJoCo's compiler refused the model (its message: "Error: …")
            changed = changed_text(self.params) or "none"
            reason = str(exc).removeprefix("Error: ").strip().replace("\n", " ")
            raise ParameterError(
                f"MuJoCo cannot build the model from these parameters: {reason} (parameters that differ from "
                f"the defaults: {changed})"
            ) from None
        self.data = mujoco.MjData(self.model)
        m = self.model
        self._beam = m.body(mdl.BEAM_BODY).id
        self._ball = m.body(mdl.BALL_BODY).id
        ball_joint = m.joint(mdl.BALL_JOINT)
        self._ball_qpos = int(ball_joint.qposadr[0])
        self._ball_dof = int(ball_joint.dofadr[0])
        if hold_beam_rad is None:
            hinge = m.joint(mdl.HINGE)
            self._hinge_qpos: int | None = int(hinge.qposadr[0])
            self._hinge_dof: int | None = int(hinge.dofadr[0])
        else:
            self._hinge_qpos = self._hinge_dof = None
        self.ball_lost = False
        self.ball_lost_time_s: float | None = None
        mujoco.mj_kinematics(self.model, self.data)
        self._pivot = tuple(float(v) for v in self.data.xpos[self._beam])  # the beam body's origin is P
        # A beam hinged at one end: P is its hinge's anchor, and x is along from the track's centre, d out from P
        # (``beam.track_offset_m``; x − 0.0 is x bit for bit, so the thesis's rig subtracts nothing)
        self._track_offset_m = self.params.beam.track_offset_m
        if self.params.beam.hinged_off_centre and hold_beam_rad is None:
            self._pivot = tuple(float(v) for v in self.data.xanchor[m.joint(mdl.HINGE).id])
        self._pivot_0d = tuple(np.array(v) for v in self._pivot)
        self._nstate = mujoco.mj_stateSize(m, FULL_STATE)
        self._warmstart = np.empty((1, m.nv))
        self._rollout = rollout.Rollout(nthread=0)
        self._models, self._datas = [m], [self.data]  # rollout's arguments, built once
        self._buffers: dict[int, _StepBuffers] = {}
        # Indices into a state row (time, qpos, qvel) and the track's limits, for the per-step reads.
        self._row_ball, self._row_ball_v = 1 + self._ball_qpos, 1 + m.nq + self._ball_dof
        self._row_theta = 1 + (self._hinge_qpos or 0)
        self._row_thetadot = 1 + m.nq + (self._hinge_dof or 0)
        p = self.params
        track = p.track_geometry  # the track the rig names (the two wires: past their ends by r, beside one)
        self._along_limit_m = track.end_limit_m
        self._lateral_limit_m = track.lateral_limit_m
        self._seat_height_m = p.ball_centre_height_m
        self._all_on_cache: dict[int, np.ndarray] = {}
        # MuJoCo's warning counters (live views into MjData, read once a block) and the beam's furthest
        # physical angle: past either, the block is a numerical failure (NumericalError).
        self._warning_stats = [self.data.warning[int(w)] for w in _WARNING_TEXT]
        self._theta_limit_rad = p.beam.stop_angle_rad + stop_overshoot_bound_rad(p)
        self.reset()

    # --- state ------------------------------------------------------------------------------------
    @property
    def time_s(self) -> float:
        return float(self.data.time)

    def reset(
        self,
        x_m: float = 0.0,
        theta_rad: float = 0.0,
        xdot_m_s: float = 0.0,
        thetadot_rad_s: float = 0.0,
        *,
        keep_time: bool = False,
    ) -> None:
        """Put the ball on the wires at x, rolling without slipping at ẋ, and the beam at θ, θ̇.

        ``keep_time`` keeps the simulation clock running (a disturbance mid-run rather than a new run)."""
        p = self.params
        if self.held_angle_rad is not None:
            theta_rad, thetadot_rad_s = self.held_angle_rad, 0.0
        check_initial_state(p, x_m, theta_rad, xdot_m_s, thetadot_rad_s)
        m, d = self.model, self.data
        time_s = d.time
        mujoco.mj_resetData(m, d)
        if keep_time:
            d.time = time_s
        if self._hinge_qpos is not None:
            d.qpos[self._hinge_qpos] = theta_rad
            d.qvel[self._hinge_dof] = thetadot_rad_s
            for name, (qpos, qvel) in mdl.drive_pose(p, theta_rad, thetadot_rad_s).items():
                joint = m.joint(name)  # a lever's horn and push-rod, closed with the beam at θ
                d.qpos[joint.qposadr[0]] = qpos
                d.qvel[joint.dofadr[0]] = qvel
        mujoco.mj_kinematics(m, d)
        rot = d.xmat[self._beam].reshape(3, 3).tolist()  # products in a fixed order (twin.fixedorder)
        pivot = d.xpos[self._beam].copy()
        axis = np.array(fo.matvec(rot, mdl.HINGE_AXIS_BEAM.tolist()))
        omega_beam = thetadot_rad_s * axis
        offset = np.array(fo.matvec(rot, [x_m, 0.0, p.ball_centre_height_m]))
        q = self._ball_qpos
        d.qpos[q : q + 3] = pivot + offset
        d.qpos[q + 3 : q + 7] = [1.0, 0.0, 0.0, 0.0]
        v = self._ball_dof
        # the beam turns about its hinge: the ball's velocity is ω × (its position from the pivot), the track's
        # centre d out from it on a beam hinged at one end
        lever = offset
        if p.beam.hinged_off_centre:
            lever = np.array(fo.matvec(rot, [x_m + p.beam.track_offset_m, 0.0, p.ball_centre_height_m]))
        d.qvel[v : v + 3] = np.array(fo.matvec(rot, [xdot_m_s, 0.0, 0.0])) + np.cross(omega_beam, lever)
        # Rolling without slipping (eq 3.1.13): spin relative to the beam about the hinge axis = -ẋ/r*.
        d.qvel[v + 3 : v + 6] = omega_beam + (-xdot_m_s / p.rolling_radius_m) * axis
        d.ctrl[:] = 0.0
        mujoco.mj_forward(m, d)
        self.ball_lost = False
        self.ball_lost_time_s = None
        self.lost_state: np.ndarray | None = None
        self._end_row: np.ndarray | None = None  # the last advance's final state row (MjData's state now)

    def _beam_axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The beam frame's unit vectors in world coordinates: a rotation by θ about (0, −1, 0).

        Computed from qpos, not from MjData.xmat, which mj_step leaves one step behind."""
        c, s = math.cos(self._theta()), math.sin(self._theta())
        return np.array([c, 0.0, s]), np.array([0.0, 1.0, 0.0]), np.array([-s, 0.0, c])

    def ball_kinematics(self) -> BallKinematics:
        d = self.data
        ex, ey, ez = self._beam_axes()
        axis = -ey  # the hinge axis, world frame
        omega_beam = self._theta_dot() * axis
        q, v = self._ball_qpos, self._ball_dof
        offset = d.qpos[q : q + 3] - np.asarray(self._pivot)
        v_rel = d.qvel[v : v + 3] - np.cross(omega_beam, offset)
        omega_ball = np.zeros(3)
        mujoco.mju_rotVecQuat(omega_ball, d.qvel[v + 3 : v + 6], d.qpos[q + 3 : q + 7])  # body → world
        o, w = offset.tolist(), v_rel.tolist()
        axes = [ex.tolist(), ey.tolist(), ez.tolist()]
        return BallKinematics(
            position_m=np.array(fo.matvec(axes, o)) - np.array([self._track_offset_m, 0.0, 0.0]),
            velocity_m_s=np.array(fo.matvec(axes, w)),
            spin_rad_s=fo.dot((omega_ball - omega_beam).tolist(), axis.tolist()),
        )

    def _theta(self) -> float:
        if self._hinge_qpos is None:
            assert self.held_angle_rad is not None
            return float(self.held_angle_rad)
        return float(self.data.qpos[self._hinge_qpos])

    def _theta_dot(self) -> float:
        if self._hinge_dof is None:
            return 0.0
        return float(self.data.qvel[self._hinge_dof])

    def state(self) -> np.ndarray:
        """(x_m, θ_rad, ẋ_m_s, θ̇_rad_s) in the thesis's coordinates (eq 3.1.28). Once the ball is lost, the
        state at the step it left the track: what falls afterwards is no longer the rig's state."""
        if self.lost_state is not None:
            return self.lost_state.copy()
        if self._hinge_qpos is None:
            return self._held_state()
        d = self.data
        # A state row (time, qpos, qvel) as Python floats: ``_state_of_row``'s operations are the ones
        # ``row_states`` takes, so the same bits.
        return self._state_of_row([0.0, *d.qpos.tolist(), *d.qvel.tolist()])

    def state_row(self) -> np.ndarray | None:
        """The full-physics state row (time, qpos, qvel, …) ``state`` reads now — a view, valid until the plant
        steps again — or ``None`` when ``state`` is not that row's (ball lost, beam held, MjData set since
        the last advance): ``row_states`` of the row is ``state``, bit for bit, so a log can defer it."""
        row = self._end_row
        if row is None or self.lost_state is not None or self._hinge_qpos is None or row[0] != self.data.time:
            return None
        return row

    def _held_state(self) -> np.ndarray:
        """``state`` of a rig built with the beam held (no hinge joint): ``_state_floats``'s operations."""
        d = self.data
        theta = self._theta()
        q, v = self._ball_qpos, self._ball_dof
        ox, oz = float(d.qpos[q]) - self._pivot[0], float(d.qpos[q + 2]) - self._pivot[2]
        thetadot = 0.0  # the velocity relative to the beam, as ``state`` takes it: v − ω×offset
        vx, vz = float(d.qvel[v]) + thetadot * oz, float(d.qvel[v + 2]) - thetadot * ox
        c, s = math.cos(theta), math.sin(theta)
        return np.array([ox * c + oz * s - self._track_offset_m, theta, vx * c + vz * s, thetadot])

    def row_states(self, rows: np.ndarray) -> np.ndarray:
        """(x, θ, ẋ, θ̇) for each full-physics state row (time, qpos, qvel), shape (n, 4): what ``state``
        computes from MjData, with the same elementwise operations in the same order (``_state_floats``),
        so a run in a batch (``twin.rigs.batch``) or a deferred log row has the bits of ``state`` alone."""
        if self._hinge_qpos is None or self._hinge_dof is None:
            raise ValueError("row_states needs the beam's hinge (a rig built with hold_beam_rad has none)")
        nq = self.model.nq
        theta, thetadot = rows[:, 1 + self._hinge_qpos], rows[:, 1 + nq + self._hinge_dof]
        q, v = 1 + self._ball_qpos, 1 + nq + self._ball_dof
        px, _, pz = self._pivot_0d
        ox, oz = rows[:, q] - px, rows[:, q + 2] - pz
        vx, vz = rows[:, v] + thetadot * oz, rows[:, v + 2] - thetadot * ox
        c, s = np.cos(theta), np.sin(theta)
        return np.stack([ox * c + oz * s - self._track_offset_m, theta, vx * c + vz * s, thetadot], axis=1)

    # --- stepping ---------------------------------------------------------------------------------
    @property
    def timestep_s(self) -> float:
        return float(self.model.opt.timestep)

    def step(self, motor_volts: float, n_steps: int = 1) -> None:
        """Advance ``n_steps`` physics steps with the motor's terminal volts held (the dcmotor clamps them to
        the amplifier's rails), updating the latched ``ball_lost`` flag."""
        self.advance_held(motor_volts, n_steps)

    def advance_held(self, motor_volts: float, n_steps: int) -> PhysicsBlock:
        """``advance`` with the same terminal volts for all ``n_steps`` steps (a control period's usual case:
        the volts are filled into the rollout's control buffer, not built as an array and checked)."""
        if not isinstance(motor_volts, (int, float)) or not math.isfinite(motor_volts):
            raise ValueError(f"motor_volts = {motor_volts!r} is not finite")
        buf = self._buffers.get(n_steps) or self._step_buffers(n_steps)
        buf.control.fill(motor_volts)
        return self._roll(buf, n_steps)

    def advance(self, motor_volts: np.ndarray) -> PhysicsBlock:
        """One physics step per entry of ``motor_volts`` in one C call; the ball and beam at every step.

        The ``ball_lost`` flag latches at the first step after which the ball no longer sits on both wires
        within the track (see ``track_coordinates``)."""
        volts = np.asarray(motor_volts, dtype=np.float64)
        n = volts.size
        if not _all_finite(volts):
            raise ValueError(f"motor_volts contains {volts[~np.isfinite(volts)][0]!r}: it must be finite")
        buf = self._step_buffers(n)
        if n and self.model.nu:
            buf.control[0, :, 0] = volts
        return self._roll(buf, n)

    def _roll(self, buf: _StepBuffers, n: int) -> PhysicsBlock:
        """Roll out ``n`` steps with the control in ``buf``, from MjData's state (or the row the last advance
        left it in, which is that state: no read-back), into ``buf.rows``; the block."""
        m, d = self.model, self.data
        rows = buf.rows  # (n + 1, nstate): time, qpos, qvel; row 0 the state before the first step
        t0 = float(d.time)
        carried = self._end_row
        if carried is not None and carried[0] == t0:  # MjData is in the state the last advance left
            rows[0] = carried
        else:
            mujoco.mj_getState(m, d, rows[0], FULL_STATE)
        if n:
            self._warmstart[0] = d.qacc_warmstart
            self._rollout.rollout(
                self._models,
                self._datas,
                buf.initial_state,
                buf.control,
                control_spec=_CTRL.value,
                skip_checks=True,
                nstep=n,
                initial_warmstart=self._warmstart,
                state=buf.states,
                sensordata=None,
                chunk_size=None,
            )
        if not _all_finite(rows[-1]):
            raise numerical_failure(self.params, "the MuJoCo state is not finite", float(rows[-1, 0]))
        return self._block(rows, t0 + buf.step_offsets_s)

    def advance_with_law(
        self, n: int, volts_for_state: Callable[[float, float, float, float], float], law_steps: int
    ) -> tuple[PhysicsBlock, float]:
        """``n`` physics steps with the motor's terminal volts recomputed every ``law_steps`` steps by
        ``volts_for_state(x_m, θ_rad, ẋ_m_s, θ̇_rad_s)`` (the state as ``state`` gives it then, as four Python
        floats): the block and the last volts.

        The same trajectory, block and lost-ball latch as ``advance`` called once per law period, at a
        fraction of the cost: ``mj_step`` on the plant's own MjData (a one-step rollout call costs about
        7 µs more than the step) and the state read from the step's row as Python floats, and handed on
        so: a law run every step pays for each array made per step."""
        if self._hinge_qpos is None or n < 1 or law_steps < 1:
            raise ValueError("advance_with_law needs the beam's hinge, n ≥ 1 and law_steps ≥ 1")
        m, d = self.model, self.data
        buf = self._step_buffers(n)
        rows = buf.rows
        mujoco.mj_getState(m, d, rows[0], FULL_STATE)
        ctrl = d.ctrl
        step, get_state, cos, sin = mujoco.mj_step, mujoco.mj_getState, math.cos, math.sin
        full = FULL_STATE.value  # the spec as an int: pybind converts it faster than the enum
        row_theta, q = self._row_theta, self._row_ball
        px, py, pz = self._pivot
        along_limit, lateral_limit = self._along_limit_m, self._lateral_limit_m
        offset = self._track_offset_m
        seat, tolerance = self._seat_height_m, LOST_HEIGHT_TOLERANCE_M
        lost_state = self.lost_state
        state: tuple[float, ...]
        if lost_state is None:
            row = rows[0].tolist()
            theta = row[row_theta]
            state = self._state_floats(row, cos(theta), sin(theta))
        else:
            state = tuple(lost_state.tolist())
        volts = math.nan
        for k in range(1, n + 1):  # k: the row after the step
            if (k - 1) % law_steps == 0:
                volts = volts_for_state(*state)
                ctrl[0] = volts
            step(m, d)
            dest = rows[k]
            get_state(m, d, dest, full)
            row = dest.tolist()
            law_reads = k % law_steps == 0  # the law reads this row's state (the next call's, for the last)
            if lost_state is None:
                theta = row[row_theta]
                c, s = cos(theta), sin(theta)
                # ``on_track``'s test on ``beam_frame``'s coordinates, in Python floats: the same operations,
                # so the same answer (numpy's cos and sin equal math's); inline, as a call costs as much.
                dx, dy, dz = row[q] - px, row[q + 1] - py, row[q + 2] - pz
                if not (
                    abs(c * dx + s * dz - offset) <= along_limit
                    and abs(dy) < lateral_limit
                    and abs(c * dz - s * dx - seat) < tolerance
                ):
                    lost_state = self._row_state(dest)
                    state = tuple(lost_state.tolist())
                elif law_reads and k < n:
                    state = self._state_floats(row, c, s)
            if (law_reads or k == n) and not math.isfinite(sum(row)):  # where advance checks, once a period
                raise numerical_failure(self.params, "the MuJoCo state is not finite", row[0])
        # Times as advance makes them: each law period's start time plus whole steps.
        starts = rows[0:n:law_steps, 0]
        times = np.empty(n + 1)
        times[0] = rows[0, 0]
        times[1:] = (starts[:, None] + buf.step_offsets_s[None, 1 : law_steps + 1]).ravel()[:n]
        return self._block(rows, times), volts

    def _block(self, rows: np.ndarray, times: np.ndarray) -> PhysicsBlock:
        """The block of these state rows (row 0 the state before the first step), latching ``ball_lost`` at
        the first row off the track. The common block (on the track throughout) is told from the extremes
        of the ball's beam-frame coordinates, which the sensor chains then reuse."""
        n = len(rows) - 1
        self._end_row = rows[-1]
        if self._hinge_qpos is None:
            theta = np.full(n + 1, self._theta())
        else:
            theta = rows[:, self._row_theta].copy()
        q = self._row_ball
        along, lateral, height = self.beam_frame(theta, rows[:, q : q + 3])
        al, th, lat, hgt = along.tolist(), theta.tolist(), lateral.tolist(), height.tolist()
        x_range, theta_range = (min(al), max(al)), (min(th), max(th))
        self._check_numerics(rows, theta_range)
        # ``on_track(...).all()`` from the extremes: |·| below a bound everywhere ⇔ at both extremes, and
        # subtracting the seat height is monotonic in float arithmetic, so the same answer.
        seat, tol, lat_limit = self._seat_height_m, LOST_HEIGHT_TOLERANCE_M, self._lateral_limit_m
        if self.ball_lost:
            on = np.zeros(n + 1, dtype=bool)
        elif (
            -self._along_limit_m <= x_range[0]
            and x_range[1] <= self._along_limit_m
            and -lat_limit < min(lat)
            and max(lat) < lat_limit
            and -tol < min(hgt) - seat
            and max(hgt) - seat < tol
        ):
            return PhysicsBlock(times, along, theta, self._all_on(n + 1), x_range, theta_range, True, True)
        else:
            on = self.on_track(along, lateral, height)
            on[0] = True
            if not on.all():  # latched from the first step off the track
                first_off = int(np.flatnonzero(~on)[0])
                self.ball_lost = True
                self.ball_lost_time_s = float(rows[first_off, 0])
                self.lost_state = self._row_state(rows[first_off])
                on[first_off:] = False
        return PhysicsBlock(times, along, theta, on, x_range, theta_range, bool(on.all()), True)

    def _check_numerics(self, rows: np.ndarray, theta_range: tuple[float, float]) -> None:
        """Raise NumericalError when MuJoCo warned during these rows' steps, or the beam went past its stops
        further than they can yield (``stop_overshoot_bound_rad``)."""
        if any(w.number for w in self._warning_stats):
            counts = {int(w): self._warning_stats[j].number for j, w in enumerate(_WARNING_TEXT)}
            raise numerical_failure(self.params, warning_text(counts), failure_time_s(rows[:, 0]))
        if max(-theta_range[0], theta_range[1]) > self._theta_limit_rad:
            theta = np.abs(rows[:, self._row_theta])
            k = int(np.flatnonzero(theta > self._theta_limit_rad)[0])
            raise beyond_stops(self.params, float(theta[k]), float(rows[k, 0]))

    def _all_on(self, size: int) -> np.ndarray:
        """A read-only all-True ``on_track`` of this size (shared: the common block's flags)."""
        on = self._all_on_cache.get(size)
        if on is None:
            on = self._all_on_cache[size] = np.ones(size, dtype=bool)
            on.flags.writeable = False
        return on

    def _step_buffers(self, n: int) -> _StepBuffers:
        buf = self._buffers.get(n)
        if buf is None:
            m = self.model
            buf = self._buffers[n] = _StepBuffers(n, m.nu, self._nstate, m.opt.timestep)
        return buf

    def _state_of_row(self, r: list[float]) -> np.ndarray:
        """``state`` from one state row as Python floats (time, qpos, qvel) (see ``_state_floats``)."""
        theta = r[self._row_theta]
        return np.array(self._state_floats(r, math.cos(theta), math.sin(theta)))

    def _state_floats(self, r: list[float], c: float, s: float) -> tuple[float, float, float, float]:
        """(x, θ, ẋ, θ̇) of one state row as Python floats (time, qpos, qvel), given c = cos θ and s = sin θ.

        x and ẋ are the ball's offset from P and its velocity relative to the beam (v − ω×offset, ω = θ̇
        about (0, −1, 0)) dotted with the beam's axis (cos θ, 0, sin θ): two products added in this order
        (the zero term adds nothing), the same in ``row_states`` and ``beam_frame`` (no BLAS: its kernel
        would decide the order and the fused multiply-adds, twin.fixedorder)."""
        thetadot = r[self._row_thetadot]
        q, v = self._row_ball, self._row_ball_v
        px, _, pz = self._pivot
        ox, oz = r[q] - px, r[q + 2] - pz
        vx, vz = r[v] + thetadot * oz, r[v + 2] - thetadot * ox
        return ox * c + oz * s - self._track_offset_m, r[self._row_theta], vx * c + vz * s, thetadot

    def _row_state(self, row: np.ndarray) -> np.ndarray:
        """(x, θ, ẋ, θ̇) from one row of (time, qpos, qvel): the ball relative to the beam, as ``state``."""
        nq = self.model.nq
        theta, thetadot = (
            (float(self.held_angle_rad or 0.0), 0.0)
            if self._hinge_qpos is None or self._hinge_dof is None
            else (float(row[1 + self._hinge_qpos]), float(row[1 + nq + self._hinge_dof]))
        )
        q, v = 1 + self._ball_qpos, 1 + nq + self._ball_dof
        ox, oz = row[q] - self._pivot[0], row[q + 2] - self._pivot[2]
        # Velocity relative to the rotating beam: v − ω×offset with ω = θ̇ about (0, −1, 0).
        vx, vz = row[v] + thetadot * oz, row[v + 2] - thetadot * ox
        c, s = math.cos(theta), math.sin(theta)
        return np.array([ox * c + oz * s - self._track_offset_m, theta, vx * c + vz * s, thetadot])

    def beam_frame(
        self, theta_rad: np.ndarray, ball_xyz: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The ball centre's coordinates in the beam frame (along, lateral, height above P) from the beam
        angle and the ball centre's world position (``ball_xyz[..., 0:3]``) at each step: elementwise, so
        the rows of a batch of runs (``twin.rigs.batch``) give the same bits as a run alone."""
        c, s = np.cos(theta_rad), np.sin(theta_rad)
        px, py, pz = self._pivot_0d  # 0-d arrays: numpy converts a Python float operand on every call
        dx, dz = ball_xyz[..., 0] - px, ball_xyz[..., 2] - pz
        return dx * c + dz * s - self._track_offset_m, ball_xyz[..., 1] - py, dz * c - dx * s

    def on_track(self, along: np.ndarray, lateral: np.ndarray, height: np.ndarray) -> np.ndarray:
        """Whether the ball sits on both wires within the track, from its beam-frame coordinates."""
        return (
            (np.abs(along) <= self._along_limit_m)
            & (np.abs(lateral) < self._lateral_limit_m)
            & (np.abs(height - self._seat_height_m) < LOST_HEIGHT_TOLERANCE_M)
        )

    @property
    def frame_key(self) -> tuple:
        """All that ``beam_frame``, ``on_track`` and ``row_states`` read of this plant: plants equal in it give
        the same bits there (a batch calls them once for the rows of all such plants: a spread's rigs differ
        in masses, motor and friction, not in where their track lies)."""
        return (
            self._pivot,
            self._track_offset_m,
            self._along_limit_m,
            self._lateral_limit_m,
            self._seat_height_m,
            self._hinge_qpos,
            self._hinge_dof,
            self._ball_qpos,
            self._ball_dof,
            self.model.nq,
        )

    def track_coordinates(self, theta_rad: np.ndarray, ball_xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The ball's position along the beam and whether it sits on the track at each step (see
        ``beam_frame``)."""
        along, lateral, height = self.beam_frame(theta_rad, ball_xyz)
        return along, self.on_track(along, lateral, height)

    def kick_ball(self, dv_m_s: float) -> None:
        """Give the ball a velocity kick along the beam (a flick with a finger), keeping it rolling."""
        if not math.isfinite(dv_m_s):
            raise ValueError(f"dv_m_s = {dv_m_s!r} is not finite")
        if self.ball_lost:
            return
        x, theta, xdot, thetadot = self.state()
        self.reset(x, theta, xdot + dv_m_s, thetadot, keep_time=True)

    def motor_torque_nm(self) -> float:
        """Joint torque the motor applies to the beam now (N·m): gear × motor torque, eq 3.3.1."""
        if self._hinge_dof is None:
            return 0.0
        return float(self.data.qfrc_actuator[self._hinge_dof])

    def warnings(self) -> dict[str, int]:
        """MuJoCo warnings raised so far (name -> count), empty when there were none."""
        return {mujoco.mjtWarning(i).name: int(w.number) for i, w in enumerate(self.data.warning) if w.number}
