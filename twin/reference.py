"""Analytic reference model of the rig (thesis §3.1–3.4): the independent check on the MuJoCo model, the model
controllers are designed on, and the plant of the reference rig (``ReferencePlant``).

Equations of motion, q = (x, θ), in the thesis's own form (the one home of their coefficients):

    (1 + k₁)·ẍ − (k₂ + c)·θ̈ = x·θ̇² − g·sin θ                                                  (eq 3.1.26)
    τ = α₁·ẍ + (α₂ + α₃·x²)·θ̈ + β₁·sin θ + β₂·x·cos θ + β₃·x·ẋ·θ̇ + β₄·x·θ̇² + β₅·θ̇ + τ_f(θ̇)     (eq 3.1.27)

with k₁ = 2r²/(5r*²), k₂ = 2r²/(5r*), c = h* + r*, α₁ = k₁·m·h*, α₂ = J_BP + J_a − k₂·m·h*, α₃ = m,
β₁ = −M_B·g·h, β₂ = m·g, β₃ = 2m, β₄ = −m·c (eq 3.1.27's printed "x·ẋ²" read as x·θ̇², as the Newton
derivation 3.1.16/3.1.24 gives), β₅ = B_a + B_p. J_a = J_m·N² and B_a = B_m·N² are the motor's reflected
rotor inertia and viscous damping (Table 3.2), which the thesis neglects (§3.3; ``motor_inertia=False``
drops them); B_p and τ_f are the pivot bearing's viscous and Coulomb friction (parameters, default 0).
τ_f = F·sat(θ̇/ω_f) with ω_f = ``COULOMB_REGULARIZATION_RAD_S``: MuJoCo's ``frictionloss`` is a soft
constraint too, and a fixed-step integrator cannot follow an exact sign function.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields
from typing import Any, Generic, Literal, TypeVar

import numpy as np

from twin.dcmotor import beam_torque_nm, torque_nm
from twin.drive_equations import stepper_ramp_acceleration, stepper_ramp_step, stepper_sketch_steps
from twin.parameters import Parameters
from twin.physics import PhysicsBlock, check_initial_state

__all__ = [
    "COULOMB_REGULARIZATION_RAD_S",
    "DriveKinematics",
    "DriveLaw",
    "ShaftMap",
    "ShaftTorque",
    "drive_law",
    "register_actuator_law",
    "register_shaft_map",
    "STATE_NAMES",
    "EquationCoefficients",
    "ReferenceModel",
    "ReferencePlant",
    "discretize_zoh",
    "drive_stop_boundary",
    "drive_stop_derivative",
    "driven_beam_terms",
    "geared_motor_numbers",
    "geared_shaft_torque_nm",
    "hinged_beam_terms",
    "pivot_friction_nm",
    "rk4_step",
    "step_boundary",
]

STATE_NAMES = ("x", "theta", "xdot", "thetadot")
InputKind = Literal["torque", "voltage"]

# Below this beam rate the pivot's dry friction falls linearly to zero (0.01 rad/s = 0.57°/s).
COULOMB_REGULARIZATION_RAD_S = 0.01


# A coefficient: one parameter set's float, or a (B, 1) column of B parameter sets' values.
C = TypeVar("C", float, np.ndarray)


@dataclass(frozen=True)
class EquationCoefficients(Generic[C]):
    """The coefficients of eq 3.1.26 and eq 3.1.27 for a parameter set (see the module docstring): floats
    (``from_params``), or (B, 1) columns over B parameter sets (``stack``) for ``accelerations`` on a batch."""

    k1: C  # 2r²/(5r*²)
    k2: C  # 2r²/(5r*)  (m)
    c: C  # h* + r*  (m)
    g: C  # m/s²
    alpha_xdd: C  # α₁ (kg·m)
    alpha_thdd: C  # α₂ (kg·m²)
    alpha_thdd_x2: C  # α₃ (kg)
    beta: tuple[C, C, C, C]  # β₁ sin θ, β₂ x cos θ, β₃ x ẋ θ̇, β₄ x θ̇²
    beta_thetadot: C  # β₅: viscous damping at the beam (N·m·s/rad)
    coulomb_nm: C  # F: the pivot's dry friction (N·m)

    @staticmethod
    def stack(rows: Sequence[EquationCoefficients[float]]) -> EquationCoefficients[np.ndarray]:
        """Row b of every coefficient column is ``rows[b]``'s (each field, and each of ``beta``, a (B, 1)
        float array), so that ``accelerations`` computes every parameter set's at once."""

        def column(values: Sequence[float]) -> np.ndarray:
            return np.array(values, dtype=float)[:, None]

        columns: dict[str, Any] = {}
        for f in fields(EquationCoefficients):
            values = [getattr(row, f.name) for row in rows]
            columns[f.name] = (
                tuple(column(each) for each in zip(*values, strict=True))
                if isinstance(values[0], tuple)
                else column(values)
            )
        return EquationCoefficients(**columns)

    @staticmethod
    def from_params(params: Parameters, *, motor_inertia: bool = True) -> EquationCoefficients[float]:
        p = params
        m, r, rs, hs = p.ball.mass_kg, p.ball.radius_m, p.rolling_radius_m, p.rolling_axis_height_m
        g = p.physics.gravity_m_s2
        gear2 = p.motor.gear_ratio**2
        j_a = p.motor.rotor_inertia_kgm2 * gear2 if motor_inertia else 0.0
        b_a = p.motor.viscous_damping_nm_s_per_rad * gear2 if motor_inertia else 0.0
        k1 = 2 * r**2 / (5 * rs**2)
        k2 = 2 * r**2 / (5 * rs)
        c = p.ball_centre_height_m
        return EquationCoefficients(
            k1=k1,
            k2=k2,
            c=c,
            g=g,
            alpha_xdd=k1 * m * hs,
            alpha_thdd=p.beam.inertia_pivot_kgm2 + j_a - k2 * m * hs,
            alpha_thdd_x2=m,
            beta=(-p.beam.mass_kg * g * p.beam.cog_height_m, m * g, 2 * m, -m * c),
            beta_thetadot=b_a + p.beam.pivot_damping_nm_s_per_rad,
            coulomb_nm=p.beam.pivot_friction_nm,
        )

    def accelerations(self, x: Any, th: Any, xd: Any, thd: Any, torque_nm: Any) -> tuple[Any, Any]:
        """(ẍ, θ̈) from eq 3.1.26 and 3.1.27 for a motor torque at the beam: floats, or numpy arrays of
        states (a batch, e.g. identification windows) with the same arithmetic (``ball_beam_accelerations``)."""
        if isinstance(th, float):
            s, co = math.sin(th), math.cos(th)
        else:
            s, co = np.sin(th), np.cos(th)
        friction = pivot_friction_nm(self.coulomb_nm, thd)
        b1, b2, b3, b4 = self.beta
        return ball_beam_accelerations(
            self.k1, self.k2, self.c, self.g, self.alpha_xdd, self.alpha_thdd, self.alpha_thdd_x2,
            b1, b2, b3, b4, self.beta_thetadot, x, xd, thd, s, co, friction, torque_nm,
        )  # fmt: skip

    def as_row(self) -> tuple[float, ...]:
        """The coefficients in ``ball_beam_accelerations``'s order, then the dry friction (a compiled kernel's
        row: twin.screen)."""
        b1, b2, b3, b4 = self.beta
        return (
            float(self.k1), float(self.k2), float(self.c), float(self.g), float(self.alpha_xdd),
            float(self.alpha_thdd), float(self.alpha_thdd_x2), float(b1), float(b2), float(b3), float(b4),
            float(self.beta_thetadot), float(self.coulomb_nm),
        )  # fmt: skip


def pivot_friction_nm(coulomb_nm: Any, thetadot_rad_s: Any) -> Any:
    """τ_f = F·sat(θ̇/ω_f), the pivot's dry friction (ω_f = ``COULOMB_REGULARIZATION_RAD_S``): floats, numpy
    arrays, and the compiled kernel (twin.screen, numba) from this one home."""
    z = thetadot_rad_s / COULOMB_REGULARIZATION_RAD_S
    if isinstance(z, float):  # a float, or a float in the compiled kernel
        return coulomb_nm * max(-1.0, min(1.0, z))
    return coulomb_nm * np.clip(z, -1.0, 1.0)


def step_boundary(
    x: float, th: float, thd: float, stop_rad: float, half_m: float
) -> tuple[float, float, bool]:
    """What the equations leave out, at a step's end: the beam meets its stops inelastically (θ clamped to
    ±``stop_rad``, an outward θ̇ set to zero), and the ball is lost once |x| passes the track's end
    (``half_m``). (θ, θ̇, lost) after the step; the reference plant and the compiled kernel alike."""
    if abs(th) > stop_rad:
        th = math.copysign(stop_rad, th)
        if thd * th > 0:
            thd = 0.0
    return th, thd, abs(x) > half_m


def ball_beam_accelerations(
    k1: Any, k2: Any, c: Any, g: Any, alpha_xdd: Any, alpha_thdd: Any, alpha_thdd_x2: Any,
    b1: Any, b2: Any, b3: Any, b4: Any, beta_thetadot: Any,
    x: Any, xd: Any, thd: Any, s: Any, co: Any, friction: Any, torque_nm: Any,
) -> tuple[Any, Any]:  # fmt: skip
    """(ẍ, θ̈) of eq 3.1.26 and 3.1.27 (the coefficients: ``EquationCoefficients``) given sin θ, cos θ and the
    pivot's dry friction: arithmetic only, so that floats, numpy arrays and the compiled screening kernel
    (twin.screen, numba) compute it from this one home."""
    rhs_ball = x * thd * thd - g * s
    rhs_beam = (
        torque_nm
        - b1 * s
        - b2 * x * co
        - b3 * x * xd * thd
        - b4 * x * thd * thd
        - beta_thetadot * thd
        - friction
    )
    # [[1 + k1, −(k2 + c)], [α₁, α₂ + α₃x²]]·(ẍ, θ̈) = (rhs_ball, rhs_beam), solved by Cramer's rule.
    m11, m12 = 1.0 + k1, -(k2 + c)
    m21, m22 = alpha_xdd, alpha_thdd + alpha_thdd_x2 * x * x
    det = m11 * m22 - m12 * m21
    return (rhs_ball * m22 - m12 * rhs_beam) / det, (m11 * rhs_beam - m21 * rhs_ball) / det


def discretize_zoh(a: np.ndarray, b: np.ndarray, period_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Φ = e^{AT}, Γ = ∫₀ᵀ e^{Aη} dη B (eq 3.4.6): zero-order hold, no delay."""
    n, m = a.shape[0], b.shape[1]
    block = np.zeros((n + m, n + m))
    block[:n, :n] = a
    block[:n, n:] = b
    import scipy.linalg  # lazily: a run that never discretizes does not pay for scipy's import

    e = scipy.linalg.expm(block * period_s)
    return e[:n, :n], e[:n, n:]


@dataclass(frozen=True)
class ReferenceModel:
    params: Parameters
    motor_inertia: bool = True

    @property
    def coefficients(self) -> EquationCoefficients[float]:
        return EquationCoefficients.from_params(self.params, motor_inertia=self.motor_inertia)

    # --- nonlinear dynamics -------------------------------------------------------------------------
    def accelerations(self, state: np.ndarray, torque_nm: float) -> np.ndarray:
        """(ẍ, θ̈) for state (x, θ, ẋ, θ̇) and motor torque at the beam."""
        x, th, xd, thd = (float(v) for v in state)
        return np.array(self.coefficients.accelerations(x, th, xd, thd, torque_nm))

    def torque_from_voltage(self, volts: float, thetadot_rad_s: float) -> float:
        return float(beam_torque_nm(self.params.motor, self.params.amplifier, volts, thetadot_rad_s))

    def derivative(self, state: np.ndarray, u: float, input: InputKind = "voltage") -> np.ndarray:
        torque = self.torque_from_voltage(u, state[3]) if input == "voltage" else u
        acc = self.accelerations(state, torque)
        return np.array([state[2], state[3], acc[0], acc[1]])

    # --- linear models ------------------------------------------------------------------------------
    def linearize(self, input: InputKind = "torque") -> tuple[np.ndarray, np.ndarray]:
        """Continuous-time (A, B) at the origin (eq 3.2.8/3.2.9 for torque, 3.3.5/3.3.6 for voltage).

        The pivot's dry friction has no derivative at θ̇ = 0 and is left out."""
        q = self.coefficients
        b1, b2, _, _ = q.beta
        mass = np.array([[1.0 + q.k1, -(q.k2 + q.c)], [q.alpha_xdd, q.alpha_thdd]])
        stiffness = np.array([[0.0, -q.g], [-b2, -b1]])
        damping = np.array([[0.0, 0.0], [0.0, -q.beta_thetadot]])
        minv = np.linalg.inv(mass)
        a = np.zeros((4, 4))
        a[0, 2] = a[1, 3] = 1.0
        a[2:, :2] = minv @ stiffness
        a[2:, 2:] = minv @ damping
        b = np.zeros((4, 1))
        b[2:, 0] = minv[:, 1]
        if input == "voltage":
            k_v = self.params.motor.torque_per_volt_nm_per_v
            a[:, 3] -= k_v * self.params.motor.backemf_at_beam_v_s_per_rad * b[:, 0]
            b = k_v * b
        elif input != "torque":
            raise ValueError(f"input = {input!r}: expected 'torque' or 'voltage'")
        return a, b

    def discretize(
        self, input: InputKind = "torque", period_s: float = 0.02
    ) -> tuple[np.ndarray, np.ndarray]:
        """(Φ, Γ) at ``period_s`` (eq 3.4.8/3.4.9 and 3.4.13/3.4.14 at T = 20 ms)."""
        return discretize_zoh(*self.linearize(input), period_s)

    # --- simulation ---------------------------------------------------------------------------------
    def simulate(
        self,
        x0: np.ndarray,
        inputs: np.ndarray,
        hold_s: float,
        input: InputKind = "voltage",
        samples_per_hold: int = 20,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Integrate the nonlinear model with ``inputs`` held for ``hold_s`` each (zero-order hold).

        Returns times (s) and states (rows), sampled ``samples_per_hold`` times per hold interval."""
        state = np.asarray(x0, dtype=float)
        times, states = [0.0], [state.copy()]
        t = 0.0
        for u in np.asarray(inputs, dtype=float):

            def fun(_t: float, s: np.ndarray, u: float = float(u)) -> np.ndarray:
                return self.derivative(s, u, input)

            t_eval = t + hold_s * np.arange(1, samples_per_hold + 1) / samples_per_hold
            import scipy.integrate  # lazily: only the reference plant integrates (0.16 s of import)

            sol = scipy.integrate.solve_ivp(
                fun, (t, t + hold_s), state, method="DOP853", rtol=1e-10, atol=1e-12, t_eval=t_eval
            )
            if not sol.success:
                raise RuntimeError(f"reference integration failed at t = {t:.3f} s: {sol.message}")
            times.extend(sol.t)
            states.extend(sol.y.T)
            state = sol.y[:, -1]
            t += hold_s
        return np.array(times), np.array(states)


def rk4_step(f: Any, x: Any, th: Any, xd: Any, thd: Any, u: Any, h: float) -> tuple[Any, Any, Any, Any]:
    """One classical Runge-Kutta step of (x, θ, ẋ, θ̇) with the input ``u`` held; ``f(x, θ, ẋ, θ̇, u)`` returns
    the four derivatives. Floats or numpy arrays alike (the reference plant; the identification's batch), and
    the compiled kernel (twin.screen, numba: ``u`` may be any value ``f`` takes, passed through)."""
    a1 = f(x, th, xd, thd, u)
    a2 = f(x + 0.5 * h * a1[0], th + 0.5 * h * a1[1], xd + 0.5 * h * a1[2], thd + 0.5 * h * a1[3], u)
    a3 = f(x + 0.5 * h * a2[0], th + 0.5 * h * a2[1], xd + 0.5 * h * a2[2], thd + 0.5 * h * a2[3], u)
    a4 = f(x + h * a3[0], th + h * a3[1], xd + h * a3[2], thd + h * a3[3], u)
    return (
        x + h / 6.0 * (a1[0] + 2 * a2[0] + 2 * a3[0] + a4[0]),
        th + h / 6.0 * (a1[1] + 2 * a2[1] + 2 * a3[1] + a4[1]),
        xd + h / 6.0 * (a1[2] + 2 * a2[2] + 2 * a3[2] + a4[2]),
        thd + h / 6.0 * (a1[3] + 2 * a2[3] + 2 * a3[3] + a4[3]),
    )


# --- a beam driven otherwise than the thesis's geared motor at its pivot -------------------------------------
# θ → (φ, dφ/dθ, d²φ/dθ²): the actuator's shaft angle for the beam's angle and its first two derivatives.
ShaftMap = Callable[[float], tuple[float, float, float]]
# (ctrl, φ, φ̇) → the actuator's torque at its shaft (N·m), its own damping included.
ShaftTorque = Callable[[float, float, float], float]


@dataclass(frozen=True)
class DriveKinematics:
    """What a beam drive gives the reference model (``register_shaft_map``): θ → (φ, φ′, φ″) (``shaft``), the
    inertia its own links add at the shaft and on the beam, and the beam's travel its linkage allows (a horn's
    stops; None: the beam's own stops only)."""

    shaft: ShaftMap
    shaft_inertia_kgm2: float = 0.0
    beam_inertia_kgm2: float = 0.0
    theta_limits_rad: tuple[float, float] | None = None
    numbers: tuple[float, ...] = ()  # what the compiled kernel's row takes of the drive (twin.screen.plant)


@dataclass(frozen=True)
class DriveLaw:
    """How the beam is driven, for the reference model, when it is not the thesis's motor at the pivot (``drive_law``):
    the drive's kinematics ``shaft`` (the shaft angle φ(θ), a lever's exact closure), the actuator's ``torque`` at
    its shaft, the inertia turning with the shaft (``shaft_inertia_kgm2``: the actuator's reflected rotor, a horn,
    a push-rod's share) and what the drive adds to the beam's own about the pivot (``beam_inertia_kgm2``).

    The beam's equation (eq 3.1.27) then holds with α₂ + J_s·φ′² + J_b in place of α₂ and, as the torque at the
    beam, φ′·τ_s − J_s·φ′·φ″·θ̇² (Lagrange: the shaft's kinetic energy ½·J_s·φ′²·θ̇², its torque's virtual work
    τ_s·δφ = τ_s·φ′·δθ)."""

    shaft: ShaftMap
    torque: ShaftTorque
    shaft_inertia_kgm2: float
    beam_inertia_kgm2: float = 0.0
    theta_limits_rad: tuple[float, float] | None = None
    # the drive's and the actuator's numbers as the compiled kernel's row takes them (twin.screen.plant)
    drive_numbers: tuple[float, ...] = ()
    actuator_numbers: tuple[float, ...] = ()
    # a stepper's sketch ramp (v_max, a: microsteps/s, /s²), or None: the law's control each step is then the
    # ramp's whole position, the ramp heading for the written control (twin.drive_equations.stepper_ramp_step)
    ramp: tuple[float, float] | None = None


# Registered by the parts (twin.parts): a drive's kinematics and extra inertia (shaft, beam), and an actuator's
# torque law and inertia at its shaft, each from a rig's parameters.
_SHAFT_MAPS: dict[str, Callable[[Parameters], DriveKinematics]] = {}
_ACTUATOR_LAWS: dict[str, Callable[[Parameters], tuple[ShaftTorque, float]]] = {}
_ACTUATOR_NUMBERS: dict[str, Callable[[Parameters], tuple[float, ...]]] = {}
_ACTUATOR_RAMPS: dict[str, Callable[[Parameters], tuple[float, float]]] = {}
THESIS_DRIVE = ("pivot", "escap_dc_motor")  # eq 3.1.27 as the thesis writes it: no ``DriveLaw``


def _pivot(theta_rad: float) -> tuple[float, float, float]:
    return theta_rad, 1.0, 0.0


def _geared_motor(params: Parameters) -> tuple[ShaftTorque, float]:
    """The geared DC motor (eq 3.3.1) at its output shaft: its volts within the amplifier's rails, the reflected
    rotor inertia and viscous damping (Table 3.2, reflected by N²)."""
    rail, k_tau, k_b, b_a = geared_motor_numbers(params)

    def torque(volts: float, phi: float, phidot: float) -> float:
        return float(geared_shaft_torque_nm(torque_nm, volts, phidot, rail, k_tau, k_b, b_a))

    return torque, params.motor.rotor_inertia_kgm2 * params.motor.gear_ratio**2


def geared_motor_numbers(params: Parameters) -> tuple[float, float, float, float]:
    """``geared_shaft_torque_nm``'s numbers after φ̇ (rail, k_τ, k_b, B_m·N²), as ``_geared_motor`` and the compiled
    kernel's row (twin.screen.plant) take them."""
    p = params
    return (
        p.amplifier.rail_v,
        p.motor.torque_per_volt_nm_per_v,
        p.motor.backemf_at_beam_v_s_per_rad,
        p.motor.viscous_damping_nm_s_per_rad * p.motor.gear_ratio**2,
    )


def geared_shaft_torque_nm(
    motor_torque: Any, volts: Any, phidot: Any, rail_v: Any, k_tau: Any, k_b: Any, damping: Any
) -> Any:
    """The geared DC motor's torque at its output shaft driving a beam through a drive: eq 3.3.1
    (``motor_torque``: ``twin.dcmotor.torque_nm``, or its compiled form in the kernel) at the volts within the
    amplifier's rails, less the reflected viscous damping B_m·N²·φ̇."""
    return motor_torque(min(max(volts, -rail_v), rail_v), phidot, k_tau, k_b) - damping * phidot


def driven_beam_terms(
    alpha_thdd: Any, shaft_inertia: Any, dphi: Any, ddphi: Any, thd: Any, shaft_torque_nm: Any
) -> tuple[Any, Any]:
    """A driven beam's α₂ and torque in eq 3.1.27 (``DriveLaw``): α₂ + J_s·φ′² and φ′·τ_s − J_s·φ′·φ″·θ̇²
    (``alpha_thdd``: α₂ with the drive's own inertia on the beam J_b added). Arithmetic only: the reference
    plant and the compiled kernel (twin.screen) alike."""
    return (
        alpha_thdd + shaft_inertia * dphi * dphi,
        dphi * shaft_torque_nm - shaft_inertia * dphi * ddphi * thd * thd,
    )


def hinged_beam_terms(x: Any, co: Any, torque_nm: Any, offset_m: Any, weight_nm: Any) -> tuple[Any, Any]:
    """A beam hinged elsewhere than under its track's centre (``beam.track_offset_m`` = d, ``beam.cog_along_m`` =
    x_g): eq 3.1.26/3.1.27 hold in the ball's distance from the pivot, x + d (x stays measured from the track's
    centre), and the beam's weight x_g out along it loads the drive, τ − M_B·g·x_g·cos θ (``weight_nm`` =
    M_B·g·x_g, ``co`` = cos θ). (x + d, τ − M_B·g·x_g·cos θ); arithmetic only: the reference plant and the compiled
    kernel (twin.screen) alike."""
    return x + offset_m, torque_nm - weight_nm * co


def drive_stop_derivative(
    k1: Any, g: Any, x: Any, th: Any, xd: Any, thd: Any, s: Any, xdd: Any, thdd: Any, lo: Any, hi: Any
) -> tuple[Any, Any, Any, Any]:
    """The derivative (ẋ, θ̇, ẍ, θ̈) of a driven beam at its drive's stop (θ ∉ (lo, hi)) and pushed into it: the
    stop holds the beam, the ball rolls on a still beam (eq 3.1.26 with θ̈ = 0), as MuJoCo's joint limit holds
    it, not a step's spurious θ̈; elsewhere the equations' own. Arithmetic only (``s`` = sin θ)."""
    if (th >= hi and thdd > 0.0) or (th <= lo and thdd < 0.0):
        return xd, 0.0, (x * thd * thd - g * s) / (1.0 + k1), 0.0
    return xd, thd, xdd, thdd


def drive_stop_boundary(
    th: float, xd: float, thd: float, before_rad_s: float, lo: float, hi: float, coupling: float
) -> tuple[float, float, float]:
    """After ``step_boundary`` (θ̇ was ``before_rad_s`` ahead of it): the drive's own stops (a horn at its
    travel's ends, θ within [lo, hi]) and the ball's share of a stop's impulse: the stop acts on the beam
    alone, so across it eq 3.1.26 gives (1 + k₁)·Δẋ = (k₂ + c)·Δθ̇ (``coupling`` = (k₂ + c)/(1 + k₁)). (θ, ẋ, θ̇);
    the reference plant and the compiled kernel alike."""
    if th > hi:
        th, thd = hi, min(thd, 0.0)
    elif th < lo:
        th, thd = lo, max(thd, 0.0)
    if thd != before_rad_s:
        xd += coupling * (thd - before_rad_s)
    return th, xd, thd


def register_shaft_map(drive: str, factory: Callable[[Parameters], DriveKinematics]) -> None:
    """A beam drive's kinematics for the reference model, ``factory(params)`` (``twin.parts`` registers its
    drives' own)."""
    _SHAFT_MAPS[drive] = factory


def register_actuator_law(
    actuator: str,
    factory: Callable[[Parameters], tuple[ShaftTorque, float]],
    numbers: Callable[[Parameters], tuple[float, ...]] | None = None,
    ramp: Callable[[Parameters], tuple[float, float]] | None = None,
) -> None:
    """An actuator's torque law and inertia at its shaft for the reference model (``twin.parts`` registers its
    actuators' own); ``ramp``: a stepper's sketch ramp between the written control and the law (``DriveLaw``)."""
    _ACTUATOR_LAWS[actuator] = factory
    if numbers is not None:  # its law's numbers, for the compiled kernel's row
        _ACTUATOR_NUMBERS[actuator] = numbers
    if ramp is not None:
        _ACTUATOR_RAMPS[actuator] = ramp


def drive_law(params: Parameters) -> DriveLaw | None:
    """The reference model's law for the drive and actuator ``params.parts`` names: None for the thesis's (eq
    3.1.27 as written, the beam turned under its track's centre), else the registered kinematics and torque law
    (``ValueError`` naming the part if none is registered: its module under twin.parts was not imported, or it
    has no reference form)."""
    names = (params.parts.beam_drive, params.parts.actuator)
    if names == THESIS_DRIVE and not params.beam.hinged_off_centre:
        return None
    if names[0] != "pivot" and names[0] not in _SHAFT_MAPS:
        raise ValueError(f"parts.beam_drive = {names[0]!r}: the reference model has no kinematics for it")
    if names[1] != "escap_dc_motor" and names[1] not in _ACTUATOR_LAWS:
        raise ValueError(f"parts.actuator = {names[1]!r}: the reference model has no torque law for it")
    kin = DriveKinematics(_pivot) if names[0] == "pivot" else _SHAFT_MAPS[names[0]](params)
    torque, inertia = (_geared_motor if names[1] == "escap_dc_motor" else _ACTUATOR_LAWS[names[1]])(params)
    numbers = _ACTUATOR_NUMBERS.get(names[1])
    ramp = _ACTUATOR_RAMPS.get(names[1])
    return DriveLaw(
        kin.shaft,
        torque,
        inertia + kin.shaft_inertia_kgm2,
        kin.beam_inertia_kgm2,
        kin.theta_limits_rad,
        kin.numbers,
        numbers(params) if numbers is not None else (),
        ramp(params) if ramp is not None else None,
    )


class ReferencePlant:
    """The reference model as a physics backend (``twin.physics.PhysicsBackend``): fixed-step RK4 at
    ``physics.timestep_s`` with the motor volts held over each step (eq 3.3.1 through the amplifier's rails).

    What the equations leave out is handled at the step boundary: the beam meets its stops inelastically
    (θ clamped, an outward θ̇ set to zero), and the ball is lost once |x| passes the track's end; the
    state then stays where it was (the reference model cannot fall off a beam)."""

    def __init__(self, params: Parameters | None = None, *, motor_inertia: bool = True) -> None:
        self.params = params or Parameters()
        # another drive than the thesis's brings its actuator's inertia through its law, not eq 3.1.27's J_a
        self._law = drive_law(self.params)
        self.model = ReferenceModel(self.params, motor_inertia=motor_inertia and self._law is None)
        self._q = self.model.coefficients
        self.reset(0.0, 0.0)

    @property
    def time_s(self) -> float:
        return self._time_s

    @property
    def timestep_s(self) -> float:
        return self.params.physics.timestep_s

    @property
    def ball_lost(self) -> bool:
        return self._lost_time_s is not None

    @property
    def ball_lost_time_s(self) -> float | None:
        return self._lost_time_s

    def reset(self, x_m: float, theta_rad: float, xdot_m_s: float = 0.0, thetadot_rad_s: float = 0.0) -> None:
        check_initial_state(self.params, x_m, theta_rad, xdot_m_s, thetadot_rad_s)
        self._s = (float(x_m), float(theta_rad), float(xdot_m_s), float(thetadot_rad_s))
        self._time_s = 0.0
        self._lost_time_s: float | None = None
        self._ramp_state = (0.0, 0.0)  # a stepper's sketch (DriveLaw.ramp): s, v from 0 at every start

    def state(self) -> np.ndarray:
        return np.array(self._s)

    def kick_ball(self, dv_m_s: float) -> None:
        if not math.isfinite(dv_m_s):
            raise ValueError(f"dv_m_s = {dv_m_s!r} is not finite")
        if not self.ball_lost:
            x, th, xd, thd = self._s
            self._s = (x, th, xd + dv_m_s, thd)

    def advance_held(self, motor_volts: float, n_steps: int) -> PhysicsBlock:
        if not isinstance(motor_volts, (int, float)) or not math.isfinite(motor_volts):
            raise ValueError(f"motor_volts = {motor_volts!r} is not finite")
        return self.advance(np.full(n_steps, float(motor_volts)))

    def derivative(
        self, x: float, th: float, xd: float, thd: float, ctrl: float
    ) -> tuple[float, float, float, float]:
        """(ẋ, θ̇, ẍ, θ̈) of the state with the actuator's control ``ctrl`` held (the motor's volts within the
        amplifier's rails on the thesis's rig; a driven beam's ``DriveLaw``): what ``advance`` integrates, for a
        linearization (``twin.linearize.linearize_reference``)."""
        if self._law is None:
            p = self.params
            volts = min(max(ctrl, -p.amplifier.rail_v), p.amplifier.rail_v)
            torque = float(
                torque_nm(volts, thd, p.motor.torque_per_volt_nm_per_v, p.motor.backemf_at_beam_v_s_per_rad)
            )
            xdd, thdd = self._q.accelerations(x, th, xd, thd, torque)
            return xd, thd, xdd, thdd
        return self._driven_derivative(self._law)(x, th, xd, thd, ctrl)

    def advance(self, motor_volts: np.ndarray) -> PhysicsBlock:
        p = self.params
        h = p.physics.timestep_s
        rail, stop, half = p.amplifier.rail_v, p.beam.stop_angle_rad, p.track.half_length_m
        k_tau, k_b = p.motor.torque_per_volt_nm_per_v, p.motor.backemf_at_beam_v_s_per_rad
        acc = self._q.accelerations
        volts = np.asarray(motor_volts, dtype=np.float64)
        n = volts.size
        t0 = self._time_s
        times = np.empty(n + 1)
        xs = np.empty(n + 1)
        thetas = np.empty(n + 1)
        on = np.empty(n + 1, dtype=bool)
        x, th, xd, thd = self._s
        times[0], xs[0], thetas[0], on[0] = t0, x, th, not self.ball_lost

        def f(x: float, th: float, xd: float, thd: float, v: float) -> tuple[float, float, float, float]:
            xdd, thdd = acc(x, th, xd, thd, float(torque_nm(v, thd, k_tau, k_b)))
            return xd, thd, xdd, thdd

        law = self._law
        ramp = None if law is None else law.ramp
        position, speed = self._ramp_state
        lo, hi = -math.inf, math.inf
        if law is not None:
            f = self._driven_derivative(law)
            rail = math.inf  # the ctrl is a servo's target angle, say: the actuator's law bounds it
            lo, hi = law.theta_limits_rad or (lo, hi)
        for i in range(n):
            if self._lost_time_s is None:
                v = min(max(float(volts[i]), -rail), rail)
                if ramp is not None:  # the law's control: the sketch's whole position, its ramp heading for v
                    target, v = v, stepper_sketch_steps(position)
                    position, speed = stepper_ramp_step(
                        stepper_ramp_acceleration, target, position, speed, ramp[0], ramp[1], h
                    )
                x, th, xd, thd = rk4_step(f, x, th, xd, thd, v, h)
                if law is None:
                    th, thd, lost = step_boundary(x, th, thd, stop, half)
                else:
                    th, xd, thd, lost = self._driven_boundary(x, th, xd, thd, (lo, hi))
                if not all(math.isfinite(v_) for v_ in (x, th, xd, thd)):
                    raise FloatingPointError(
                        f"reference model state is not finite at t = {t0 + (i + 1) * h:.3f} s"
                    )
                if lost:
                    self._lost_time_s = t0 + (i + 1) * h
            times[i + 1] = t0 + (i + 1) * h
            xs[i + 1], thetas[i + 1], on[i + 1] = x, th, self._lost_time_s is None
        self._s = (x, th, xd, thd)
        self._ramp_state = (position, speed)
        self._time_s = float(times[-1])
        return PhysicsBlock(time_s=times, x_m=xs, theta_rad=thetas, on_track=on)

    def _driven_boundary(
        self, x: float, th: float, xd: float, thd: float, limits: tuple[float, float]
    ) -> tuple[float, float, float, bool]:
        """``step_boundary`` for a driven beam, with the drive's own stops (a horn at its travel's ends) and the
        ball's share of a stop's impulse: the stop acts on the beam alone, so across it eq 3.1.26 gives
        (1 + k₁)·Δẋ = (k₂ + c)·Δθ̇ (a beam stopped while the ball rolls on keeps the ball's momentum consistent
        with the coupling, as MuJoCo's joint limit does). (θ, ẋ, θ̇, lost)."""
        p, q = self.params, self._q
        before = thd
        th, thd, lost = step_boundary(x, th, thd, p.beam.stop_angle_rad, p.track.half_length_m)
        th, xd, thd = drive_stop_boundary(th, xd, thd, before, *limits, (q.k2 + q.c) / (1.0 + q.k1))
        return th, xd, thd, lost

    def _driven_derivative(self, law: DriveLaw) -> Callable[..., tuple[float, float, float, float]]:
        """The state's derivative with the beam driven through ``law`` (see ``DriveLaw``)."""
        q = self._q
        b1, b2, b3, b4 = q.beta
        alpha, j_s = q.alpha_thdd + law.beam_inertia_kgm2, law.shaft_inertia_kgm2
        shaft, shaft_torque = law.shaft, law.torque
        lo, hi = law.theta_limits_rad or (-math.inf, math.inf)
        if self.params.beam.hinged_off_centre:
            return self._hinged_off_centre_derivative(law)

        def f(x: float, th: float, xd: float, thd: float, ctrl: float) -> tuple[float, float, float, float]:
            # the compiled kernel's driven derivative (twin.screen.plant) is these calls in this order
            phi, dphi, ddphi = shaft(th)
            a2, torque = driven_beam_terms(alpha, j_s, dphi, ddphi, thd, shaft_torque(ctrl, phi, dphi * thd))
            s, co = math.sin(th), math.cos(th)
            xdd, thdd = ball_beam_accelerations(
                q.k1, q.k2, q.c, q.g, q.alpha_xdd, a2, q.alpha_thdd_x2,
                b1, b2, b3, b4, q.beta_thetadot, x, xd, thd, s, co, pivot_friction_nm(q.coulomb_nm, thd), torque,
            )  # fmt: skip
            return drive_stop_derivative(q.k1, q.g, x, th, xd, thd, s, xdd, thdd, lo, hi)

        return f

    def _hinged_off_centre_derivative(
        self, law: DriveLaw
    ) -> Callable[..., tuple[float, float, float, float]]:
        """``_driven_derivative`` of a beam hinged elsewhere than under its track's centre: the equations hold in
        the ball's distance from the pivot, x + d (``beam.track_offset_m``), and the beam's weight, x_g out along
        it (``beam.cog_along_m``), loads the drive with −M_B·g·x_g·cos θ."""
        q = self._q
        b1, b2, b3, b4 = q.beta
        alpha, j_s = q.alpha_thdd + law.beam_inertia_kgm2, law.shaft_inertia_kgm2
        shaft, shaft_torque = law.shaft, law.torque
        lo, hi = law.theta_limits_rad or (-math.inf, math.inf)
        d = self.params.beam.track_offset_m
        weight_nm = self.params.beam.mass_kg * q.g * self.params.beam.cog_along_m

        def f(x: float, th: float, xd: float, thd: float, ctrl: float) -> tuple[float, float, float, float]:
            # the compiled kernel's hinged rows (twin.screen.plant ``_f_driven``) are these calls in this order
            phi, dphi, ddphi = shaft(th)
            a2, torque = driven_beam_terms(alpha, j_s, dphi, ddphi, thd, shaft_torque(ctrl, phi, dphi * thd))
            s, co = math.sin(th), math.cos(th)
            xp, torque = hinged_beam_terms(x, co, torque, d, weight_nm)
            xdd, thdd = ball_beam_accelerations(
                q.k1, q.k2, q.c, q.g, q.alpha_xdd, a2, q.alpha_thdd_x2,
                b1, b2, b3, b4, q.beta_thetadot, xp, xd, thd, s, co, pivot_friction_nm(q.coulomb_nm, thd), torque,
            )  # fmt: skip
            return drive_stop_derivative(q.k1, q.g, xp, th, xd, thd, s, xdd, thdd, lo, hi)

        return f
