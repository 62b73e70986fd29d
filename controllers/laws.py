"""Control laws of chapter 4–5 as plain functions of the state (x, θ, ẋ, θ̇), plus the Kalman state source.

Laws return u: volts for state feedback, N·m for control law partitioning and sliding mode. A reference
ball position (``ref_x_m``) shifts the regulated state where the law allows it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

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
# call counts: ``of_floats`` takes the state as four Python floats and does the elementwise arithmetic in
# Python (IEEE, so the bits numpy gives). Its matrix and vector products stay numpy's (BLAS fuses their
# multiply-adds, so written out they would differ in the last bit), on vectors and results each law reuses:
# scratch, so one law object is not for two threads at once. ``__call__`` on a state vector is ``of_floats``
# on its four floats.


class _Vector:
    """A float64 vector Python writes element by element (``set``, a memoryview: cheaper per element than
    ndarray item assignment) and numpy reads (``array``, the same memory). Scratch: pickled empty."""

    __slots__ = ("set", "array")

    def __init__(self, size: int) -> None:
        memory = bytearray(8 * size)
        self.set = memoryview(memory).cast("d")
        self.array = np.frombuffer(memory, dtype=np.float64)

    def __reduce__(self) -> tuple[type[_Vector], tuple[int]]:
        return _Vector, (len(self.set),)


def _buffer(size: int) -> _Vector:
    return field(default_factory=lambda: _Vector(size), init=False, repr=False, compare=False)


def _result(*shape: int) -> np.ndarray:
    """An array for a dot product's result (``a.dot(b, out)`` then ``out.item()``: cheaper than the float
    ``a.dot(b)`` returns). A (1×n) gain dotted with a vector is a dot of two vectors, as ``@`` takes it,
    into shape (1,); two vectors into shape ()."""
    return field(default_factory=lambda: np.empty(shape), init=False, repr=False, compare=False)


def _floats(x: np.ndarray) -> list[float]:
    return np.asarray(x, dtype=float).tolist()


@dataclass
class StateFeedbackLaw:
    """u = −K·(x − x_ref) (eq 4.2.1 with r = 0; x_ref = (ref, 0, 0, 0) for a setpoint)."""

    gain: np.ndarray  # (1×4)
    ref_x_m: float = 0.0
    _err: _Vector = _buffer(4)
    _u: np.ndarray = _result(1)

    def __call__(self, x: np.ndarray) -> float:
        return self.of_floats(*_floats(x))

    def of_floats(self, x_m: float, theta_rad: float, xdot_m_s: float, thetadot_rad_s: float) -> float:
        err, u = self._err, self._u
        e = err.set
        e[0], e[1], e[2], e[3] = x_m - self.ref_x_m, theta_rad, xdot_m_s, thetadot_rad_s
        self.gain.dot(err.array, u)
        return -u.item()


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
    _minus_zeta_err: _Vector = _buffer(2)
    _zeta_dot: _Vector = _buffer(2)
    _tau_bar: _Vector = _buffer(2)
    _alpha: _Vector = _buffer(2)
    _alpha_tau_bar: np.ndarray = _result()

    def __call__(self, x: np.ndarray) -> float:
        return self.of_floats(*_floats(x))

    def of_floats(self, x_m: float, theta_rad: float, xdot_m_s: float, thetadot_rad_s: float) -> float:
        terms, alpha, alpha_tau_bar = self.terms, self._alpha, self._alpha_tau_bar
        alpha.set[0], alpha.set[1] = terms.alpha_xdd, terms.alpha_theta(x_m)
        tau_bar = self._tau_bar_of(-(x_m - self.ref_x_m), -theta_rad, xdot_m_s, thetadot_rad_s)
        alpha.array.dot(tau_bar, alpha_tau_bar)
        return alpha_tau_bar.item() + terms.beta_of(x_m, theta_rad, xdot_m_s, thetadot_rad_s)

    def _tau_bar_of(self, e0: float, e1: float, v0: float, v1: float) -> np.ndarray:
        """τ̄ = kp @ (−ζ̃) − kv @ ζ̇ for −ζ̃ = (e0, e1), ζ̇ = (v0, v1): (−kp) @ ζ̃ as kp @ (−ζ̃), the same products.

        With diagonal gains (the thesis's and the designed ones) each row of a gain times a vector is its one
        nonzero product, whatever the BLAS: the zero products add exactly nothing to it. So when the four
        products are finite and nonzero they are taken in Python; otherwise (where a zero's sign would depend on
        the BLAS, or a NaN) numpy's gemv, as before."""
        (kp00, kp01), (kp10, kp11) = self.kp.tolist()
        (kv00, kv01), (kv10, kv11) = self.kv.tolist()
        if kp01 == kp10 == kv01 == kv10 == 0.0:
            a0, a1, b0, b1 = kp00 * e0, kp11 * e1, kv00 * v0, kv11 * v1
            if a0 and a1 and b0 and b1 and math.isfinite(a0 + a1 + b0 + b1):
                tau_bar = self._tau_bar
                tau_bar.set[0], tau_bar.set[1] = a0 - b0, a1 - b1
                return tau_bar.array
        minus_zeta_err, zeta_dot = self._minus_zeta_err, self._zeta_dot
        minus_zeta_err.set[0], minus_zeta_err.set[1] = e0, e1
        zeta_dot.set[0], zeta_dot.set[1] = v0, v1
        return self.kp.dot(minus_zeta_err.array) - self.kv.dot(zeta_dot.array)


@dataclass
class SlidingModeLaw:
    """Sliding mode (eq 4.4.28–4.4.30): u = −K_eq·x + Σ kᵢxᵢ − η·sgn(s), s = S̄·x,
    kᵢ = k⁻ where s·xᵢ > 0 and k⁺ where s·xᵢ < 0."""

    surface: np.ndarray  # S̄ (1×4)
    equivalent_gain: np.ndarray  # K_eq (1×4)
    k_minus: float
    k_plus: float
    eta: float
    _x: _Vector = _buffer(4)
    _k: _Vector = _buffer(4)
    _row_dot: np.ndarray = _result(1)
    _k_dot: np.ndarray = _result()

    def __call__(self, x: np.ndarray) -> float:
        return self.of_floats(*_floats(x))

    def of_floats(self, x_m: float, theta_rad: float, xdot_m_s: float, thetadot_rad_s: float) -> float:
        x, xs, ks, row_dot, k_dot = self._x.array, self._x.set, self._k.set, self._row_dot, self._k_dot
        k_minus, k_plus = self.k_minus, self.k_plus
        xs[0], xs[1], xs[2], xs[3] = x_m, theta_rad, xdot_m_s, thetadot_rad_s
        self.surface.dot(x, row_dot)  # S̄·x; then K_eq·x
        s = row_dot.item()
        ks[0], ks[1], ks[2], ks[3] = (
            k_minus if s * x_m > 0 else k_plus,
            k_minus if s * theta_rad > 0 else k_plus,
            k_minus if s * xdot_m_s > 0 else k_plus,
            k_minus if s * thetadot_rad_s > 0 else k_plus,
        )
        self.equivalent_gain.dot(x, row_dot)
        self._k.array.dot(x, k_dot)
        sign = 1.0 if s > 0 else -1.0 if s < 0 else s if s != s else 0.0  # np.sign: 0.0 for ±0, NaN for NaN
        return -row_dot.item() + k_dot.item() - self.eta * sign


class KalmanState:
    """Full-order steady-state Kalman filter in current-estimate form on (Φ, Γ), measuring (x, θ)."""

    def __init__(self, phi: np.ndarray, gamma: np.ndarray, gain: np.ndarray) -> None:
        self.phi, self.gamma, self.gain = phi, gamma, gain
        self.h = np.eye(2, 4)

    def start(self, xa: np.ndarray) -> np.ndarray:
        self._x = np.concatenate([xa, np.zeros(2)])
        return self._x.copy()

    def update(self, xa: np.ndarray, u_prev: float) -> np.ndarray:
        predicted = self.phi @ self._x + self.gamma[:, 0] * u_prev
        self._x = predicted + self.gain @ (xa - self.h @ predicted)
        return self._x.copy()


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

    def reset(self) -> None:
        self.integral_m_s = 0.0

    def __call__(self, x: np.ndarray) -> float:
        error = np.asarray(x, dtype=float) - np.array([self.ref_x_m, 0.0, 0.0, 0.0])
        u = -(self.gain @ error).item() - self.integral_gain * self.integral_m_s
        step_m_s = self.period_s * float(error[0])
        push_v = -self.integral_gain * step_m_s  # what this step of z adds to the next command
        if not ((u >= self.u_max_v and push_v > 0) or (u <= self.u_min_v and push_v < 0)):
            self.integral_m_s += step_m_s
        return u
