"""The geared DC motor's torque law at the beam (thesis eq 3.3.1), the same law MuJoCo's dcmotor applies."""

from __future__ import annotations

import numpy as np

from twin.parameters import Amplifier, Motor

__all__ = ["beam_torque_nm"]


def beam_torque_nm(
    motor: Motor, amplifier: Amplifier, volts: float | np.ndarray, beam_rate_rad_s: float | np.ndarray
) -> float | np.ndarray:
    """τ = (K_t/R)·N·(V − K_b·N·θ̇) (eq 3.3.1) with V clamped to the amplifier's ±rail.

    With the thesis's values this is 0.016383·(V − 0.154·θ̇) N·m. The motor's own viscous damping and
    rotor inertia are not part of this law (they act on the joint, see ``twin.reference``)."""
    v = np.clip(volts, -amplifier.rail_v, amplifier.rail_v)
    return motor.torque_per_volt_nm_per_v * (
        v - motor.backemf_at_beam_v_s_per_rad * np.asarray(beam_rate_rad_s)
    )
