"""The geared DC motor's law at the beam (thesis eq 3.3.1) and its inverse: the one home of both.

    τ = k_τ·(V − k_b·θ̇),   k_τ = N·K_t/R,  k_b = N·K_b          (eq 3.3.1; 0.016383·(V − 0.154·θ̇))
    V = τ/k_τ + k_b·θ̇                                            (the inverse a torque law uses)

MuJoCo's ``dcmotor`` applies the same law in the twin; the reference model and the controllers that turn a
torque into volts call these functions (the thesis's designs with its printed, rounded k_τ = 0.0164).
"""

from __future__ import annotations

import numpy as np

from twin.parameters import Amplifier, Motor

__all__ = ["beam_torque_nm", "torque_nm", "volts_for_torque_v"]


def torque_nm(
    volts: float | np.ndarray,
    rate_rad_s: float | np.ndarray,
    torque_per_volt: float | np.ndarray,
    backemf_v_s_per_rad: float | np.ndarray,
) -> float | np.ndarray:
    """τ = k_τ·(V − k_b·θ̇) (eq 3.3.1) with the constants given (arrays broadcast: the fit's batch of
    parameter values)."""
    return torque_per_volt * (volts - backemf_v_s_per_rad * rate_rad_s)


def volts_for_torque_v(
    torque: float | np.ndarray,
    rate_rad_s: float | np.ndarray,
    torque_per_volt: float | np.ndarray,
    backemf_v_s_per_rad: float | np.ndarray,
) -> float | np.ndarray:
    """V = τ/k_τ + k_b·θ̇: the terminal volts that give torque τ at the beam at rate θ̇ (eq 3.3.1 inverted;
    arrays broadcast: a batch of runs, each with its design's constants)."""
    return torque / torque_per_volt + backemf_v_s_per_rad * rate_rad_s


def beam_torque_nm(
    motor: Motor, amplifier: Amplifier, volts: float | np.ndarray, beam_rate_rad_s: float | np.ndarray
) -> float | np.ndarray:
    """τ = (K_t/R)·N·(V − K_b·N·θ̇) (eq 3.3.1) with V clamped to the amplifier's ±rail.

    With the thesis's values this is 0.016383·(V − 0.154·θ̇) N·m. The motor's own viscous damping and
    rotor inertia are not part of this law (they act on the joint, see ``twin.reference``)."""
    v = np.clip(volts, -amplifier.rail_v, amplifier.rail_v)
    return torque_nm(
        v, np.asarray(beam_rate_rad_s), motor.torque_per_volt_nm_per_v, motor.backemf_at_beam_v_s_per_rad
    )
