"""Controller and observer design (thesis chapters 4–5), separate from the code that runs at 50 Hz.

Every function takes the model matrices and the poles (or specification) it is asked for and returns gains;
nothing here reads a sensor. The designs are computed with python-control.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "DesignError",
    "state_feedback_gain",
    "ReducedObserver",
    "reduced_order_observer",
    "clp_gains",
    "clp_effective_gain",
    "SlidingSurface",
    "sliding_surface",
    "continuous_poles_to_discrete",
    "check_poles",
    "LqrDesign",
    "lqr_design",
    "LqiDesign",
    "lqi_design",
    "steady_state",
]


Poles = np.ndarray | Sequence[complex]  # a pole set: numbers (real poles may be floats)


def _control() -> Any:
    """python-control, imported when a design is computed: it takes over a second to import, and a
    controller built from fixed gains (the appendix's, a sweep's batch) needs none of it."""
    import control

    return control


class DesignError(ValueError):
    """A design that cannot be done as asked (uncontrollable pair, poles not placeable, …)."""


def check_poles(matrix: np.ndarray, poles: np.ndarray) -> float:
    """Largest distance between the eigenvalues of ``matrix`` and the requested ``poles`` (matched)."""
    eig = np.sort_complex(np.linalg.eigvals(matrix))
    want = np.sort_complex(np.asarray(poles, dtype=complex))
    remaining = list(want)
    worst = 0.0
    for e in eig:
        j = int(np.argmin([abs(e - w) for w in remaining]))
        worst = max(worst, abs(e - remaining.pop(j)))
    return worst


def state_feedback_gain(a: np.ndarray, b: np.ndarray, poles: Poles) -> np.ndarray:
    """K (1×n) with eig(A − B·K) = poles, for u = −K·x (continuous A, B or discrete Φ, Γ alike).

    Single input: Ackermann's formula, which also places repeated poles (the thesis's −7.5, −7.5)."""
    a, b = np.atleast_2d(a), np.atleast_2d(b)
    poles = np.asarray(poles, dtype=complex)
    control = _control()
    if np.linalg.matrix_rank(control.ctrb(a, b)) < a.shape[0]:
        raise DesignError("the pair (A, B) is not controllable: the poles cannot be placed")
    k = np.real(control.acker(a, b, poles)) if b.shape[1] == 1 else np.real(control.place(a, b, poles))
    k = np.atleast_2d(k)
    _check_characteristic_polynomial(a - b @ k, poles)
    return k


def _check_characteristic_polynomial(matrix: np.ndarray, poles: np.ndarray) -> None:
    """The closed loop's characteristic polynomial equals Π(s − pᵢ). Compared by coefficients because the
    eigenvalues of a repeated pole (the thesis's −7.5, −7.5 or 0.9608⁴) are themselves ill-conditioned."""
    got = np.real(np.poly(matrix))
    want = np.real(np.poly(poles))
    scale = np.maximum(np.abs(want), 1.0)
    worst = float(np.max(np.abs(got - want) / scale))
    if worst > 1e-8:
        raise DesignError(f"closed-loop characteristic polynomial is off by {worst:.3g} (relative)")


@dataclass(frozen=True)
class ReducedObserver:
    """Reduced-order prediction observer of eq 5.2.19 for x = (x_a, x_b), x_a measured.

        x̂_b[k] = F·x̂_b[k−1] + Ga·x_a[k−1] + G·x_a[k] + H·u[k−1]

    with F = Φ_bb − G·Φ_ab, Ga = Φ_ba − G·Φ_aa, H = Γ_b − G·Γ_a (eq 5.2.19 regrouped)."""

    gain: np.ndarray  # G (n_b × n_a)
    f: np.ndarray
    ga: np.ndarray
    h: np.ndarray

    @classmethod
    def from_gain(
        cls, phi: np.ndarray, gamma: np.ndarray, gain: np.ndarray, n_measured: int = 2
    ) -> ReducedObserver:
        na = n_measured
        paa, pab, pba, pbb = phi[:na, :na], phi[:na, na:], phi[na:, :na], phi[na:, na:]
        ga_, gb_ = gamma[:na], gamma[na:]
        g = np.asarray(gain, dtype=float)
        return cls(gain=g, f=pbb - g @ pab, ga=pba - g @ paa, h=gb_ - g @ ga_)

    def error_poles(self) -> np.ndarray:
        """Eigenvalues of Φ_bb − G·Φ_ab (eq 5.2.21): the estimation error's dynamics."""
        return np.linalg.eigvals(self.f)


def reduced_order_observer(
    phi: np.ndarray, gamma: np.ndarray, poles: Poles, n_measured: int = 2
) -> ReducedObserver:
    """G with eig(Φ_bb − G·Φ_ab) = poles (§5.2): pole placement on the dual pair (Φ_bbᵀ, Φ_abᵀ)."""
    na = n_measured
    pab, pbb = phi[:na, na:], phi[na:, na:]
    poles = np.asarray(poles, dtype=complex)
    control = _control()
    if np.linalg.matrix_rank(control.obsv(pbb, pab)) < pbb.shape[0]:
        raise DesignError("(Φ_bb, Φ_ab) is not observable: the observer poles cannot be placed")
    if pab.shape[0] == 1:
        g = np.real(control.acker(pbb.T, pab.T, poles)).T
    else:
        g = np.real(control.place(pbb.T, pab.T, poles)).T
    obs = ReducedObserver.from_gain(phi, gamma, g, na)
    _check_characteristic_polynomial(obs.f, poles)
    return obs


def clp_effective_gain(alpha0: np.ndarray, kp: np.ndarray, kv: np.ndarray) -> np.ndarray:
    """The state feedback the control-law-partitioning servo law is at the origin (eq 4.3.5–4.3.6):

    τ = α·(−kp·(x, θ) − kv·(ẋ, θ̇)) + β   ⇒   K = [α₁kp₁, α₂kp₂, α₁kv₁, α₂kv₂] (plus β's linear part)."""
    a1, a2 = np.asarray(alpha0, dtype=float).ravel()
    kp, kv = np.diag(kp), np.diag(kv)
    return np.array([[a1 * kp[0], a2 * kp[1], a1 * kv[0], a2 * kv[1]]])


def clp_gains(
    a: np.ndarray, b: np.ndarray, alpha0: np.ndarray, beta_lin: np.ndarray, poles: Poles
) -> tuple[np.ndarray, np.ndarray]:
    """Diagonal kp, kv such that the linearized loop τ = α₀·τ̄ + β_lin·x, τ̄ = −kp·ζ − kv·ζ̇ has the
    requested four poles (eq 4.3.5–4.3.10 applied to the torque-input model A, B).

    The servo law has exactly four gains for four poles, so the placement is a state feedback in disguise:
    K_total = α-weighted (kp, kv) − β_lin, solved for the diagonal entries."""
    k = state_feedback_gain(a + b @ np.atleast_2d(beta_lin), b, poles)[0]
    a1, a2 = np.asarray(alpha0, dtype=float).ravel()
    kp = np.diag([k[0] / a1, k[1] / a2])
    kv = np.diag([k[2] / a1, k[3] / a2])
    return kp, kv


@dataclass(frozen=True)
class SlidingSurface:
    """Sliding-mode design of §4.4 in original coordinates: s(x) = S·x, u_eq = −K_eq·x (eq 4.4.6)."""

    surface: np.ndarray  # S̄ (1×n)
    equivalent_gain: np.ndarray  # K_eq (1×n), u_eq = −K_eq·x
    transform: np.ndarray  # T_r of eq 4.4.11
    sliding_poles: np.ndarray  # eig(A11 − A12·M)


def sliding_surface(a: np.ndarray, b: np.ndarray, poles: Poles) -> SlidingSurface:
    """Regular form by QR of B (eq 4.4.11), M placing eig(A11 − A12·M) = poles (eq 4.4.19), S̄ scaled so
    that S̄·B = 1."""
    n = a.shape[0]
    q, _ = np.linalg.qr(b, mode="complete")
    tr = q.T[::-1]  # last row along B: T_r·B = [0; B₂]
    ar = tr @ a @ tr.T
    a11, a12 = ar[: n - 1, : n - 1], ar[: n - 1, n - 1 :]
    m = state_feedback_gain(a11, a12, poles)
    s_reg = np.hstack([m, np.ones((1, 1))])
    s = s_reg @ tr
    s = s / (s @ b)  # scale (S₂, free per §4.4) so that S̄·B = 1: ṡ = u_n on the surface, as eq 4.4.27 assumes
    k_eq = np.linalg.solve(s @ b, s @ a)
    return SlidingSurface(
        surface=s, equivalent_gain=k_eq, transform=tr, sliding_poles=np.linalg.eigvals(a11 - a12 @ m)
    )


def continuous_poles_to_discrete(poles: Poles, period_s: float) -> np.ndarray:
    """z = e^{sT} (§5.2.1)."""
    return np.exp(np.asarray(poles, dtype=complex) * period_s)


def _bryson_weights(state_scale: Sequence[float], input_scale_v: float) -> tuple[np.ndarray, np.ndarray]:
    """Bryson's rule: Q = diag(1/xᵢ²), R = 1/u² for the largest acceptable excursions xᵢ and input u."""
    return np.diag(1.0 / np.asarray(state_scale, dtype=float) ** 2), np.array([[1.0 / input_scale_v**2]])


def _kalman_current_gain(
    phi: np.ndarray, gamma: np.ndarray, input_noise_v: float, measurement_noise: Sequence[float]
) -> np.ndarray:
    """Steady-state Kalman gain (n×2) in current-estimator form for (x, θ) measured (``kalman_current_gain``)."""
    return kalman_current_gain(phi, gamma, np.eye(2, phi.shape[0]), input_noise_v, measurement_noise)


def lqr_gain(
    phi: np.ndarray, gamma: np.ndarray, state_scale: Sequence[float], input_scale: float
) -> np.ndarray:
    """Discrete LQR gain K (1×n) with Bryson weights (``state_scale`` per state, ``input_scale``)."""
    q, r = _bryson_weights(state_scale, input_scale)
    gain, _, _ = _control().dlqr(phi, gamma, q, r)
    return np.atleast_2d(gain)


def kalman_current_gain(
    phi: np.ndarray, gamma: np.ndarray, h: np.ndarray, input_noise: float, measurement_noise: Sequence[float]
) -> np.ndarray:
    """Steady-state Kalman gain (n×m) in current-estimator form for the measured rows ``h`` (m×n):
    L = P⁻Hᵀ(HP⁻Hᵀ + R)⁻¹, P⁻ the a-priori covariance, the input disturbance (SD ``input_noise``) entering
    through Γ, the measurements' SDs ``measurement_noise``."""
    qn = np.array([[input_noise**2]])
    # Each noise squared as given: numpy squares a float64, Python's ** calls pow (1 value in 1000 differs).
    rn = np.diag([s**2 for s in measurement_noise])
    _, p_prior, _ = _control().dlqe(phi, gamma, h, qn, rn)
    return p_prior @ h.T @ np.linalg.inv(h @ p_prior @ h.T + rn)


@dataclass(frozen=True)
class LqrDesign:
    """Discrete LQR on (Φ, Γ), u = −K·(x − x_ref), with a steady-state Kalman filter for the state."""

    gain: np.ndarray  # K (1×4)
    kalman_gain: np.ndarray  # L (4×2), current-estimator form


def lqr_design(
    phi: np.ndarray,
    gamma: np.ndarray,
    *,
    state_scale: Sequence[float],
    input_scale_v: float,
    input_noise_v: float,
    measurement_noise: Sequence[float],
) -> LqrDesign:
    """LQR with Bryson weights (``state_scale`` per state, ``input_scale_v``) and the Kalman gain for an input
    disturbance of ``input_noise_v`` (SD, V) and measurement noise ``measurement_noise`` (SD of x, θ)."""
    gain = lqr_gain(phi, gamma, state_scale, input_scale_v)
    return LqrDesign(gain, _kalman_current_gain(phi, gamma, input_noise_v, measurement_noise))


@dataclass(frozen=True)
class LqiDesign:
    """LQR with integral action on the ball position (LQI): u = −K·(x − x_ref) − k_i·z with
    z[k+1] = z[k] + T·(x[k] − x_ref), and the Kalman filter of the plain design for the state."""

    gain: np.ndarray  # K (1×4) on the state error
    integral_gain: float  # k_i, V per (m·s)
    kalman_gain: np.ndarray  # L (4×2), current-estimator form
    period_s: float  # T of the integrator


def lqi_design(
    phi: np.ndarray,
    gamma: np.ndarray,
    period_s: float,
    *,
    state_scale: Sequence[float],
    integral_scale_m_s: float,
    input_scale_v: float,
    input_noise_v: float,
    measurement_noise: Sequence[float],
) -> LqiDesign:
    """LQR on the model augmented with the integral z of the ball position error (Bryson weights, z's scale
    ``integral_scale_m_s``): Φₐ = [[Φ, 0], [T·e₁ᵀ, 1]], Γₐ = [Γ; 0]. The Kalman filter is the plain
    design's: the integrator is computed exactly by the controller, it needs no estimate."""
    n = phi.shape[0]
    phi_a = np.zeros((n + 1, n + 1))
    phi_a[:n, :n] = phi
    phi_a[n, 0] = period_s
    phi_a[n, n] = 1.0
    gamma_a = np.vstack([gamma, np.zeros((1, gamma.shape[1]))])
    q, r = _bryson_weights((*state_scale, integral_scale_m_s), input_scale_v)
    gain_a, _, _ = _control().dlqr(phi_a, gamma_a, q, r)
    gain_a = np.atleast_2d(gain_a)
    return LqiDesign(
        gain=gain_a[:, :n].copy(),
        integral_gain=float(gain_a[0, n]),
        kalman_gain=_kalman_current_gain(phi, gamma, input_noise_v, measurement_noise),
        period_s=period_s,
    )


def steady_state(phi: np.ndarray, gamma: np.ndarray, gain: np.ndarray, x_ref: np.ndarray) -> np.ndarray:
    """The equilibrium of the linear loop x[k+1] = Φx + Γu, u = −K·(x − x_ref): x = (I − Φ + ΓK)⁻¹ΓK·x_ref.

    For a pure state feedback its ball position is not x_ref: holding the ball off centre takes a steady
    motor torque (the ball's weight on the beam), which the law only produces from a steady error."""
    closed = np.eye(phi.shape[0]) - phi + gamma @ gain
    return np.linalg.solve(closed, gamma @ gain @ np.asarray(x_ref, dtype=float))
