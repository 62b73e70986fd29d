"""Linearize the MuJoCo model at the origin and reduce it to the thesis's four states.

The contact model has 7 degrees of freedom (beam hinge + free ball) and so a 14-state linearization. The
ball's orientation does not enter the dynamics (a sphere) and is dropped; of the remaining 11 modes, 7 are
the fast contact modes (the wires' normal and friction constraints, time constants of a few ms) and 4 are
the slow rigid-body modes of the rolling ball on the beam. The slow modal subspace, expressed in
(x, θ, ẋ, θ̇), is the reduced model.
"""

from __future__ import annotations

import mujoco
import numpy as np

from twin import model as mdl
from twin.parameters import Parameters
from twin.plant import Plant
from twin.reference import InputKind, ReferencePlant

__all__ = ["hold_control", "linearize_mujoco", "linearize_reference", "LinearizationError"]

# The slow and fast modes must be well separated for the reduction to be meaningful.
MIN_MODE_SEPARATION = 20.0
# With a drive's linkage stiffened for the linearization, its modes lie above the slow four by at least this.
MIN_LINKAGE_SEPARATION = 10.0


class LinearizationError(RuntimeError):
    pass


def _continuous_jacobians(plant: Plant, eps: float) -> tuple[np.ndarray, np.ndarray]:
    """Continuous-time (A, B) in MuJoCo's tangent coordinates (dq, v) from a semi-implicit Euler step.

    With Euler, v' = v + h·a(q, v, u) exactly, so the v-rows of the transition Jacobian divided by h give
    ∂a/∂q, ∂a/∂v, ∂a/∂u; and dq/dt = v in tangent coordinates."""
    m, d = plant.model, plant.data
    nv, nu = m.nv, m.nu
    h = m.opt.timestep
    a_d = np.zeros((2 * nv + m.na, 2 * nv + m.na))
    b_d = np.zeros((2 * nv + m.na, nu))
    mujoco.mjd_transitionFD(m, d, eps, True, a_d, b_d, None, None)
    a = np.zeros((2 * nv, 2 * nv))
    a[:nv, nv:] = np.eye(nv)
    a[nv:, :nv] = a_d[nv : 2 * nv, :nv] / h
    a[nv:, nv:] = (a_d[nv : 2 * nv, nv : 2 * nv] - np.eye(nv)) / h
    b = np.zeros((2 * nv, nu))
    b[nv:] = b_d[nv : 2 * nv] / h
    return a, b


def _output_map(plant: Plant, eps: float) -> np.ndarray:
    """∂(x, θ, ẋ, θ̇)/∂(dq, v) by central differences around the current state."""
    m, d = plant.model, plant.data
    nv = m.nv
    qpos0, qvel0 = d.qpos.copy(), d.qvel.copy()
    c = np.zeros((4, 2 * nv))
    for i in range(2 * nv):
        outs = []
        for sign in (1.0, -1.0):
            d.qpos[:] = qpos0
            d.qvel[:] = qvel0
            if i < nv:
                dq = np.zeros(nv)
                dq[i] = sign * eps
                mujoco.mj_integratePos(m, d.qpos, dq, 1.0)
            else:
                d.qvel[i - nv] += sign * eps
            mujoco.mj_kinematics(m, d)
            outs.append(plant.state())
        c[:, i] = (outs[0] - outs[1]) / (2 * eps)
    d.qpos[:] = qpos0
    d.qvel[:] = qvel0
    mujoco.mj_forward(m, d)
    return c


def linearize_mujoco(
    params: Parameters | None = None, input: InputKind = "torque", eps: float = 1e-6
) -> tuple[np.ndarray, np.ndarray]:
    """Continuous-time (A, B) of the MuJoCo model at the origin in (x, θ, ẋ, θ̇).

    ``input='torque'`` differentiates with respect to the hinge torque, ``'voltage'`` with respect to the
    actuator's control: the motor's terminal volts (the dcmotor's back-EMF then appears in A), a servo's target
    angle (rad) on a rig of other parts, about its rest (its control 0: the servo at its centre)."""
    plant = Plant(params)
    m, d = plant.model, plant.data
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_EULERDAMP  # keep damping explicit: exact ∂a/∂v
    separation = MIN_MODE_SEPARATION
    if m.neq:
        # A drive's linkage (a lever's push-rod, an equality connect) is as stiff in simulation as MuJoCo lets a
        # 1 ms step be (time constant 2·timestep): compliant enough to shift the servo's mode by 2.5 %. The
        # linearization is of the rigid linkage: its constraints 10× stiffer (nothing steps with them), whose
        # modes then lie ≥ 10× above the slow four (measured 11.3× for the default lever and SG90).
        m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_REFSAFE
        m.eq_solref[:, 0] = m.opt.timestep / 5.0
        separation = MIN_LINKAGE_SEPARATION
    plant.reset()
    # Let the contacts settle into their rest state at the (symmetric, hence exact) equilibrium.
    for _ in range(300):
        mujoco.mj_step(m, d)
    plant.reset()  # back to the exact origin, contacts now warm-started
    d.qvel[:] = 0.0
    mujoco.mj_forward(m, d)

    if input == "torque":
        # Differentiate with respect to the torque at the hinge: make the motor a plain torque source
        # (gain 1/N through gear N) so back-EMF does not enter while the rotor inertia and viscous damping,
        # which MuJoCo reflects through the gear, stay.
        m.actuator_gainprm[0, :] = 0.0
        m.actuator_biasprm[0, :] = 0.0
        m.actuator_gaintype[0] = mujoco.mjtGain.mjGAIN_FIXED
        m.actuator_biastype[0] = mujoco.mjtBias.mjBIAS_NONE
        m.actuator_dyntype[0] = mujoco.mjtDyn.mjDYN_NONE
        m.actuator_gainprm[0, 0] = 1.0 / m.actuator_gear[0, 0]
        m.actuator_ctrlrange[0] = [-1e6, 1e6]
    elif input != "voltage":
        raise ValueError(f"input = {input!r}: expected 'torque' or 'voltage'")

    a_full, b_full = _continuous_jacobians(plant, eps)
    c_full = _output_map(plant, eps)

    # Drop the ball's orientation (tangent dofs 3..5 of its free joint): nothing depends on it.
    ball_dof = int(m.joint(mdl.BALL_JOINT).dofadr[0])
    drop = set(range(ball_dof + 3, ball_dof + 6))
    keep = [i for i in range(a_full.shape[0]) if i not in drop]
    a, b, c = a_full[np.ix_(keep, keep)], b_full[keep], c_full[:, keep]

    eigvals, right = np.linalg.eig(a)

    order = np.argsort(np.abs(eigvals))
    slow, fast = order[:4], order[4:]
    ratio = np.abs(eigvals[fast[0]]) / np.abs(eigvals[slow[-1]])
    if ratio < separation:
        raise LinearizationError(
            f"slow and fast modes are not separated (|λ5|/|λ4| = {ratio:.1f}); cannot reduce"
        )
    left = np.linalg.inv(right)
    # Reduced model in output coordinates: z = C V_s η, η' = Λ η + W_s B u.
    cv = c @ right[:, slow]
    a_red = cv @ np.diag(eigvals[slow]) @ np.linalg.inv(cv)
    b_red = cv @ (left[slow] @ b)
    return np.real_if_close(a_red, tol=1e6).real, np.real_if_close(b_red, tol=1e6).real


def hold_control(params: Parameters, rest_control: float, eps: float = 1e-6) -> float:
    """The actuator's control that holds the beam level with the ball still at the track's centre: the root of
    θ̈(0, 0, 0, 0, u) of ``ReferencePlant.derivative`` by Newton's method from ``rest_control``. A beam balanced
    on its pivot (the thesis's) is held by its rest control itself, returned as it is; one hinged at its end
    needs the torque that carries its weight and the ball's (a motor's volts, a servo's target a little past
    level). A control with no effect on θ̈ there (a dead band) leaves ``rest_control``."""
    f = ReferencePlant(params).derivative
    u = rest_control
    for _ in range(20):
        thdd = f(0.0, 0.0, 0.0, 0.0, u)[3]
        if thdd == 0.0:
            break
        slope = (f(0.0, 0.0, 0.0, 0.0, u + eps)[3] - f(0.0, 0.0, 0.0, 0.0, u - eps)[3]) / (2.0 * eps)
        if slope == 0.0 or not np.isfinite(slope):
            break
        step = thdd / slope
        u -= step
        if abs(step) <= 1e-12 * max(1.0, abs(u)):
            break
    return u


def linearize_reference(
    params: Parameters, rest_control: float, eps: float = 1e-6
) -> tuple[np.ndarray, np.ndarray]:
    """Continuous-time (A, B) of the reference model of the rig ``params`` describes (its ``DriveLaw`` for a
    rig of other parts) in (x, θ, ẋ, θ̇) and the actuator's control, at the level beam with the ball still at the
    track's centre and the control at ``rest_control`` (the actuator's control at rest: 0 V for the thesis's
    motor, a servo's target at the level beam): central differences of ``ReferencePlant.derivative``."""
    f = ReferencePlant(params).derivative
    a = np.zeros((4, 4))
    for i in range(4):
        step = np.zeros(4)
        step[i] = eps
        up = f(float(step[0]), float(step[1]), float(step[2]), float(step[3]), rest_control)
        down = f(-float(step[0]), -float(step[1]), -float(step[2]), -float(step[3]), rest_control)
        a[:, i] = (np.array(up) - np.array(down)) / (2 * eps)
    b = np.array(f(0.0, 0.0, 0.0, 0.0, rest_control + eps)) - np.array(
        f(0.0, 0.0, 0.0, 0.0, rest_control - eps)
    )
    return a, (b / (2 * eps))[:, None]
