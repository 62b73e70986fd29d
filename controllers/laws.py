"""Control laws of chapter 4–5 as plain functions of the state (x, θ, ẋ, θ̇), plus the Kalman state source.

Laws return u: volts for state feedback, N·m for control law partitioning and sliding mode. A reference
ball position (``ref_x_m``) shifts the regulated state where the law allows it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twin.parameters import Parameters
from twin.reference import EquationCoefficients

__all__ = ["StateFeedbackLaw", "ClpTerms", "ClpLaw", "SlidingModeLaw", "KalmanState"]


@dataclass
class StateFeedbackLaw:
    """u = −K·(x − x_ref) (eq 4.2.1 with r = 0; x_ref = (ref, 0, 0, 0) for a setpoint)."""

    gain: np.ndarray  # (1×4)
    ref_x_m: float = 0.0

    def __call__(self, x: np.ndarray) -> float:
        err = x - np.array([self.ref_x_m, 0.0, 0.0, 0.0])
        return float(-(self.gain @ err)[0])


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
        return np.array([self.alpha_xdd, self.alpha_thdd + self.alpha_thdd_x2 * x_m**2])

    def beta_value(self, x: np.ndarray) -> float:
        b1, b2, b3, b4 = self.beta
        xm, th, xd, thd = x
        return (
            b1 * math.sin(th)
            + b2 * xm * math.cos(th)
            + b3 * xm * xd * thd
            + b4 * xm * thd**2
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

    def __call__(self, x: np.ndarray) -> float:
        zeta_err = np.array([x[0] - self.ref_x_m, x[1]])
        tau_bar = -self.kp @ zeta_err - self.kv @ x[2:]
        return float(self.terms.alpha(x[0]) @ tau_bar + self.terms.beta_value(x))


@dataclass
class SlidingModeLaw:
    """Sliding mode (eq 4.4.28–4.4.30): u = −K_eq·x + Σ kᵢxᵢ − η·sgn(s), s = S̄·x,
    kᵢ = k⁻ where s·xᵢ > 0 and k⁺ where s·xᵢ < 0."""

    surface: np.ndarray  # S̄ (1×4)
    equivalent_gain: np.ndarray  # K_eq (1×4)
    k_minus: float
    k_plus: float
    eta: float

    def __call__(self, x: np.ndarray) -> float:
        s = float((self.surface @ x)[0])
        k = np.where(s * x > 0, self.k_minus, self.k_plus)
        return float(-(self.equivalent_gain @ x)[0] + k @ x - self.eta * np.sign(s))


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
