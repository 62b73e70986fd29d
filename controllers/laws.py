"""Control laws of chapter 4–5 as plain functions of the state (x, θ, ẋ, θ̇), plus the Kalman state source.

Laws return u: volts for state feedback, N·m for control law partitioning and sliding mode. A reference
ball position (``ref_x_m``) shifts the regulated state where the law allows it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from twin import fixedorder as fo
from twin.parameters import Parameters
from twin.reference import EquationCoefficients

__all__ = [
    "StateFeedbackLaw",
    "ClpTerms",
    "ClpLaw",
    "SlidingModeLaw",
    "KalmanState",
    "IntegralStateFeedbackLaw",
]

# The laws run every physics step on the true state (1 kHz, controllers.loop.TrueStateLaw), where each numpy
# call counts: ``of_floats`` takes the state as four Python floats and does the arithmetic in Python, its
# sums of products left to right (twin.fixedorder: the bits do not depend on the BLAS kernel, and the batch's
# elementwise numpy gives the same). ``__call__`` on a state vector is ``of_floats`` on its four floats.


class _Rows:
    """A matrix's rows as Python floats for ``twin.fixedorder``, read again when the matrix is replaced."""

    __slots__ = ("source", "rows")

    def __init__(self) -> None:
        self.source: np.ndarray | None = None
        self.rows: list[list[float]] = []

    def of(self, matrix: np.ndarray) -> list[list[float]]:
        if matrix is not self.source:
            self.rows = np.atleast_2d(np.asarray(matrix, dtype=float)).tolist()
            self.source = matrix
        return self.rows


def _rows() -> _Rows:
    return field(default_factory=_Rows, init=False, repr=False, compare=False)


def _floats(x: np.ndarray) -> list[float]:
    return np.asarray(x, dtype=float).tolist()


@dataclass
class StateFeedbackLaw:
    """u = −K·(x − x_ref) (eq 4.2.1 with r = 0; x_ref = (ref, 0, 0, 0) for a setpoint)."""

    gain: np.ndarray  # (1×4)
    ref_x_m: float = 0.0
    _gain: _Rows = _rows()

    def __call__(self, x: np.ndarray) -> float:
        return self.of_floats(*_floats(x))

    def of_floats(self, x_m: float, theta_rad: float, xdot_m_s: float, thetadot_rad_s: float) -> float:
        k = self._gain.of(self.gain)[0]
        return -fo.dot(k, (x_m - self.ref_x_m, theta_rad, xdot_m_s, thetadot_rad_s))


@dataclass(frozen=True)
class ClpTerms:
    """α and β of eq 3.1.27 / 4.3.1: τ = [α₁, α₂ + α₃·x²]·[ẍ, θ̈] + β₁ sin θ + β₂ x cos θ + β₃ x ẋ θ̇ + β₄ x θ̇²
    (+ β₅ θ̇ for the motor's viscous damping, which the thesis neglects)."""

    alpha_xdd: float
    alpha_thdd: float
    alpha_thdd_x2: float
    beta: tuple[float, float, float, float]
    beta_thetadot: float = 0.0

    def alpha(self, x_m: float) -> np.ndarray:
        return np.array([self.alpha_xdd, self.alpha_theta(x_m)])

    def alpha_theta(self, x_m: float) -> float:
        """α₂ + α₃·x². x² as numpy's float64 scalar power takes it: libm's pow (which differs from x·x in the
        last bit for some x), inf where it overflows (where Python's ``**`` raises)."""
        try:
            x2 = x_m**2
        except OverflowError:
            x2 = math.inf
        return self.alpha_thdd + self.alpha_thdd_x2 * x2

    def beta_of(self, xm: float, th: float, xd: float, thd: float) -> float:
        b1, b2, b3, b4 = self.beta
        try:  # θ̇² as ``alpha_theta`` takes x²
            thd2 = thd**2
        except OverflowError:
            thd2 = math.inf
        return (
            b1 * math.sin(th)
            + b2 * xm * math.cos(th)
            + b3 * xm * xd * thd
            + b4 * xm * thd2
            + self.beta_thetadot * thd
        )

    def beta_linear(self) -> np.ndarray:
        """∂β/∂x at the origin (1×4)."""
        return np.array([[self.beta[1], self.beta[0], 0.0, self.beta_thetadot]])

    @classmethod
    def from_params(cls, params: Parameters) -> ClpTerms:
        """Recomputed from the rig's parameters: eq 3.1.27 with θ̇² (twin.reference.EquationCoefficients),
        including the motor's reflected inertia and damping, which act on the beam like J_BP and a viscous
        term."""
        q = EquationCoefficients.from_params(params)
        return cls(
            alpha_xdd=q.alpha_xdd,
            alpha_thdd=q.alpha_thdd,
            alpha_thdd_x2=q.alpha_thdd_x2,
            beta=q.beta,
            beta_thetadot=q.beta_thetadot,
        )


@dataclass
class ClpLaw:
    """Control law partitioning (eq 4.3.5–4.3.6): τ = α·τ̄ + β, τ̄ = −kv·(ζ̇ − ζ̇_d) − kp·(ζ − ζ_d),
    with ζ = (x, θ), ζ_d = (ref, 0) and ζ̈_d = ζ̇_d = 0."""

    terms: ClpTerms
    kp: np.ndarray  # diag (2×2)
    kv: np.ndarray
    ref_x_m: float = 0.0
    _kp: _Rows = _rows()
    _kv: _Rows = _rows()

    def __call__(self, x: np.ndarray) -> float:
        return self.of_floats(*_floats(x))

    def of_floats(self, x_m: float, theta_rad: float, xdot_m_s: float, thetadot_rad_s: float) -> float:
        terms = self.terms
        tau_bar = self._tau_bar_of(-(x_m - self.ref_x_m), -theta_rad, xdot_m_s, thetadot_rad_s)
        alpha = (terms.alpha_xdd, terms.alpha_theta(x_m))
        return fo.dot(alpha, tau_bar) + terms.beta_of(x_m, theta_rad, xdot_m_s, thetadot_rad_s)

    def _tau_bar_of(self, e0: float, e1: float, v0: float, v1: float) -> list[float]:
        """τ̄ = kp @ (−ζ̃) − kv @ ζ̇ for −ζ̃ = (e0, e1), ζ̇ = (v0, v1): (−kp) @ ζ̃ as kp @ (−ζ̃), the same products."""
        a = fo.matvec(self._kp.of(self.kp), (e0, e1))
        b = fo.matvec(self._kv.of(self.kv), (v0, v1))
        return [a[0] - b[0], a[1] - b[1]]


@dataclass
class SlidingModeLaw:
    """Sliding mode (eq 4.4.28–4.4.30): u = −K_eq·x + Σ kᵢxᵢ − η·sgn(s), s = S̄·x,
    kᵢ = k⁻ where s·xᵢ > 0 and k⁺ where s·xᵢ < 0."""

    surface: np.ndarray  # S̄ (1×4)
    equivalent_gain: np.ndarray  # K_eq (1×4)
    k_minus: float
    k_plus: float
    eta: float
    _surface: _Rows = _rows()
    _equivalent_gain: _Rows = _rows()

    def __call__(self, x: np.ndarray) -> float:
        return self.of_floats(*_floats(x))

    def of_floats(self, x_m: float, theta_rad: float, xdot_m_s: float, thetadot_rad_s: float) -> float:
        x = (x_m, theta_rad, xdot_m_s, thetadot_rad_s)
        k_minus, k_plus = self.k_minus, self.k_plus
        s = fo.dot(self._surface.of(self.surface)[0], x)  # S̄·x
        k = (
            k_minus if s * x_m > 0 else k_plus,
            k_minus if s * theta_rad > 0 else k_plus,
            k_minus if s * xdot_m_s > 0 else k_plus,
            k_minus if s * thetadot_rad_s > 0 else k_plus,
        )
        equivalent = fo.dot(self._equivalent_gain.of(self.equivalent_gain)[0], x)  # K_eq·x
        sign = 1.0 if s > 0 else -1.0 if s < 0 else s if s != s else 0.0  # np.sign: 0.0 for ±0, NaN for NaN
        return -equivalent + fo.dot(k, x) - self.eta * sign


class KalmanState:
    """Full-order steady-state Kalman filter in current-estimate form on (Φ, Γ), measuring (x, θ)."""

    def __init__(self, phi: np.ndarray, gamma: np.ndarray, gain: np.ndarray) -> None:
        self.phi, self.gamma, self.gain = phi, gamma, gain
        self.h = np.eye(2, 4)
        # The products in a fixed order (twin.fixedorder), on the matrices' rows as floats.
        self._phi, self._gain, self._h = phi.tolist(), gain.tolist(), self.h.tolist()
        self._gamma0 = gamma[:, 0].tolist()

    def start(self, xa: np.ndarray) -> np.ndarray:
        self._x = [*np.asarray(xa, dtype=float).tolist(), 0.0, 0.0]
        return np.array(self._x)

    def update(self, xa: np.ndarray, u_prev: float) -> np.ndarray:
        predicted = [p + g * u_prev for p, g in zip(fo.matvec(self._phi, self._x), self._gamma0, strict=True)]
        innovation = [a - b for a, b in zip(xa.tolist(), fo.matvec(self._h, predicted), strict=True)]
        correction = fo.matvec(self._gain, innovation)
        self._x = [p + c for p, c in zip(predicted, correction, strict=True)]
        return np.array(self._x)


@dataclass
class IntegralStateFeedbackLaw:
    """LQI: u = −K·(x − x_ref) − k_i·z with z[k+1] = z[k] + T·(x[k] − ref), one call per tick (z is state:
    ``reset`` before a run). Anti-windup by conditional integration: z is held while u is at or beyond a
    command limit (``u_min_v``/``u_max_v``, the motor volts the software's limits allow) and this tick's
    error would push it further out."""

    gain: np.ndarray  # K (1×4)
    integral_gain: float  # k_i, V per (m·s)
    period_s: float
    u_min_v: float
    u_max_v: float
    ref_x_m: float = 0.0
    integral_m_s: float = 0.0
    _gain: _Rows = _rows()

    def reset(self) -> None:
        self.integral_m_s = 0.0

    def __call__(self, x: np.ndarray) -> float:
        x_m, theta_rad, xdot_m_s, thetadot_rad_s = np.asarray(x, dtype=float).tolist()
        error = [x_m - self.ref_x_m, theta_rad, xdot_m_s, thetadot_rad_s]
        u = -fo.dot(self._gain.of(self.gain)[0], error) - self.integral_gain * self.integral_m_s
        step_m_s = self.period_s * error[0]
        push_v = -self.integral_gain * step_m_s  # what this step of z adds to the next command
        if not ((u >= self.u_max_v and push_v > 0) or (u <= self.u_min_v and push_v < 0)):
            self.integral_m_s += step_m_s
        return u
