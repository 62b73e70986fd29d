"""Analytic reference model of the rig (thesis §3.1–3.4): the independent check on the MuJoCo model and the
model controllers are designed on.

Equations of motion (Lagrange; identical to the thesis's Newton derivation 3.1.16–3.1.25), q = (x, θ):

    (m + J/r*²)·ẍ − (m·c + J/r*)·θ̈ = m·x·θ̇² − m·g·sin θ                                    (3.1.26 × m)
    −(m·c + J/r*)·ẍ + (J_BP + J_a + J + m·c² + m·x²)·θ̈
        = τ − B_a·θ̇ − 2·m·x·ẋ·θ̇ − m·g·x·cos θ + m·g·c·sin θ + M_B·g·h·sin θ

with c = h* + r*, J = 2/5·m·r². Eliminating ẍ with 3.1.26 turns the second line into the thesis's eq 3.1.27
with its printed "x·ẋ²" read as x·θ̇² (design.md). J_a = J_m·N² and B_a = B_m·N² are the motor's reflected
rotor inertia and viscous damping (Table 3.2), which the thesis neglects (§3.3); ``motor_inertia=False``
drops them to give the thesis's model.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.integrate
import scipy.linalg

from twin.dcmotor import beam_torque_nm
from twin.parameters import Parameters

__all__ = ["ReferenceModel", "discretize_zoh", "STATE_NAMES"]

STATE_NAMES = ("x", "theta", "xdot", "thetadot")
InputKind = Literal["torque", "voltage"]


def discretize_zoh(a: np.ndarray, b: np.ndarray, period_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Φ = e^{AT}, Γ = ∫₀ᵀ e^{Aη} dη B (eq 3.4.6): zero-order hold, no delay."""
    n, m = a.shape[0], b.shape[1]
    block = np.zeros((n + m, n + m))
    block[:n, :n] = a
    block[:n, n:] = b
    e = scipy.linalg.expm(block * period_s)
    return e[:n, :n], e[:n, n:]


@dataclass(frozen=True)
class ReferenceModel:
    params: Parameters
    motor_inertia: bool = True

    # --- constants ----------------------------------------------------------------------------------
    @property
    def _c(self) -> float:
        return self.params.ball_centre_height_m

    @property
    def reflected_inertia_kgm2(self) -> float:
        mo = self.params.motor
        return mo.rotor_inertia_kgm2 * mo.gear_ratio**2 if self.motor_inertia else 0.0

    @property
    def reflected_damping_nm_s_per_rad(self) -> float:
        mo = self.params.motor
        return mo.viscous_damping_nm_s_per_rad * mo.gear_ratio**2 if self.motor_inertia else 0.0

    def mass_matrix(self, x_m: float) -> np.ndarray:
        p = self.params
        m, j, rs, c = p.ball.mass_kg, p.ball.inertia_kgm2, p.rolling_radius_m, self._c
        coupling = -(m * c + j / rs)
        return np.array(
            [
                [m + j / rs**2, coupling],
                [
                    coupling,
                    p.beam.inertia_pivot_kgm2 + self.reflected_inertia_kgm2 + j + m * c**2 + m * x_m**2,
                ],
            ]
        )

    # --- nonlinear dynamics -------------------------------------------------------------------------
    def accelerations(self, state: np.ndarray, torque_nm: float) -> np.ndarray:
        """(ẍ, θ̈) for state (x, θ, ẋ, θ̇) and motor torque at the beam."""
        p = self.params
        x, th, xd, thd = state
        m, g, c = p.ball.mass_kg, p.physics.gravity_m_s2, self._c
        s, co = math.sin(th), math.cos(th)
        rhs = np.array(
            [
                m * x * thd**2 - m * g * s,
                torque_nm
                - self.reflected_damping_nm_s_per_rad * thd
                - 2.0 * m * x * xd * thd
                - m * g * x * co
                + m * g * c * s
                + p.beam.mass_kg * g * p.beam.cog_height_m * s,
            ]
        )
        return np.linalg.solve(self.mass_matrix(x), rhs)

    def torque_from_voltage(self, volts: float, thetadot_rad_s: float) -> float:
        return float(beam_torque_nm(self.params.motor, self.params.amplifier, volts, thetadot_rad_s))

    def derivative(self, state: np.ndarray, u: float, input: InputKind = "voltage") -> np.ndarray:
        torque = self.torque_from_voltage(u, state[3]) if input == "voltage" else u
        acc = self.accelerations(state, torque)
        return np.array([state[2], state[3], acc[0], acc[1]])

    # --- linear models ------------------------------------------------------------------------------
    def linearize(self, input: InputKind = "torque") -> tuple[np.ndarray, np.ndarray]:
        """Continuous-time (A, B) at the origin (eq 3.2.8/3.2.9 for torque, 3.3.5/3.3.6 for voltage)."""
        p = self.params
        m, g, c = p.ball.mass_kg, p.physics.gravity_m_s2, self._c
        minv = np.linalg.inv(self.mass_matrix(0.0))
        stiffness = np.array([[0.0, -m * g], [-m * g, m * g * c + p.beam.mass_kg * g * p.beam.cog_height_m]])
        damping = np.array([[0.0, 0.0], [0.0, -self.reflected_damping_nm_s_per_rad]])
        a = np.zeros((4, 4))
        a[0, 2] = a[1, 3] = 1.0
        a[2:, :2] = minv @ stiffness
        a[2:, 2:] = minv @ damping
        b = np.zeros((4, 1))
        b[2:, 0] = minv[:, 1]
        if input == "voltage":
            k_v = p.motor.torque_per_volt_nm_per_v
            a[:, 3] -= k_v * p.motor.backemf_at_beam_v_s_per_rad * b[:, 0]
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
            fun: Callable[[float, np.ndarray], np.ndarray] = lambda _t, s, u=u: self.derivative(s, u, input)
            t_eval = t + hold_s * np.arange(1, samples_per_hold + 1) / samples_per_hold
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
