"""A rig of other parts linearized: the MuJoCo twin of the lever and hobby servo (its linkage stiffened for the
linearization, twin.linearize) against the analytic linear model written here by hand, and against the reference
model's driven beam (twin.reference.DriveLaw) differentiated numerically."""

from __future__ import annotations

import numpy as np
import pytest

import twin.parts  # noqa: F401  (registers the parts)
from twin.linearize import linearize_mujoco
from twin.parameters import Parameters
from twin.parts.linkage import Linkage
from twin.parts.servo import Servo
from twin.reference import ReferencePlant

SERVO_RIG = Parameters().with_overrides(
    {"parts.beam_drive": "end_lever", "parts.actuator": "hobby_servo", "parts.io_board": "arduino_uno"}
)


def _analytic(p: Parameters) -> tuple[np.ndarray, np.ndarray]:
    """The linear model at the level beam, ball at the pivot, servo at its centre, by hand.

    With the default geometry the horn is horizontal and the rod vertical at level, so the pin and the attachment
    move vertically together: c·φ̇ = L·θ̇, φ′ = dφ/dθ = L/c, and φ ≈ φ′·θ. The servo's torque at its shaft is
    k_p·(u − φ) − b·φ̇ (within its saturation), at the beam φ′ times that (virtual work). The shaft's inertia
    J_s (rotor and gears reflected, the horn as a bar m_h·c²/3, half the rod at the pin) appears at the beam as
    J_s·φ′²; the rod's other half rides on the beam at L. Eq 3.1.26/3.1.27 linearized (sin θ ≈ θ, cos θ ≈ 1, no
    θ̇² terms) with the thesis's ball, track and beam and no motor inertia:

        (1 + k₁)·ẍ − (k₂ + c)·θ̈ = −g·θ
        α₁·ẍ + (α₂ + J_b + J_s·φ′²)·θ̈ = φ′·k_p·u − (k_p·φ′² + β₁)·θ − β₂·x − b·φ′²·θ̇"""
    link, servo = p.of(Linkage), p.of(Servo)
    m, r, g = p.ball.mass_kg, p.ball.radius_m, p.physics.gravity_m_s2
    h_star, d = p.track.contact_height_m, p.track.contact_spacing_m
    r_star = np.sqrt(r * r - d * d / 4)
    k1, k2, c = 2 * r * r / (5 * r_star * r_star), 2 * r * r / (5 * r_star), h_star + r_star
    alpha1, alpha2 = k1 * m * h_star, p.beam.inertia_pivot_kgm2 - k2 * m * h_star
    beta1, beta2 = -p.beam.mass_kg * g * p.beam.cog_height_m, m * g
    dphi = link.beam_arm_m / link.crank_m
    j_s = (
        servo.armature_kgm2 + link.horn_mass_kg * link.crank_m**2 / 3 + link.rod_mass_kg / 2 * link.crank_m**2
    )
    j_b = link.rod_mass_kg / 2 * link.beam_arm_m**2
    kp = servo.stall_torque_nm * servo.supply_v / servo.rated_voltage_v / servo.saturation_error_rad
    b = servo.stall_torque_nm / servo.no_load_speed_rad_s
    mass = np.array([[1 + k1, -(k2 + c)], [alpha1, alpha2 + j_b + j_s * dphi**2]])
    forces = np.array([[0.0, -g, 0.0, 0.0], [-beta2, -(kp * dphi**2 + beta1), 0.0, -b * dphi**2]])
    a = np.zeros((4, 4))
    a[0, 2] = a[1, 3] = 1.0
    a[2:] = np.linalg.solve(mass, forces)
    bu = np.zeros(4)
    bu[2:] = np.linalg.solve(mass, [0.0, dphi * kp])
    return a, bu


def _relative(measured: np.ndarray, expected: np.ndarray) -> float:
    """The largest error of the model's non-trivial entries, relative to each entry."""
    mask = np.abs(expected) > 1e-9
    return float(np.max(np.abs(measured[mask] - expected[mask]) / np.abs(expected[mask])))


@pytest.mark.quick
def test_the_servo_rigs_mujoco_linearization_is_the_analytic_model_within_1_percent() -> None:
    a_hand, b_hand = _analytic(SERVO_RIG)
    a_mj, b_mj = linearize_mujoco(SERVO_RIG, "voltage")
    assert _relative(a_mj[2:], a_hand[2:]) < 0.01  # measured 0.14 %
    assert _relative(b_mj.ravel()[2:], b_hand[2:]) < 0.01  # measured 0.02 %
    # the ball's pair (±0.103 /s: the servo holds the beam, the ball's weight barely tilts it) and the servo's
    # mode (−32 ± 84j /s), both from the hand model
    assert np.allclose(
        np.sort_complex(np.linalg.eigvals(a_mj)), np.sort_complex(np.linalg.eigvals(a_hand)), rtol=0.01
    )


@pytest.mark.quick
def test_the_reference_driven_beam_linearizes_to_the_analytic_model() -> None:
    a_hand, b_hand = _analytic(SERVO_RIG)
    plant = ReferencePlant(SERVO_RIG)
    f = plant._driven_derivative(plant._law)  # noqa: SLF001  (the derivative the reference integrates)
    h = 1e-6
    a = np.zeros((4, 4))
    for i in range(4):
        e = np.zeros(4)
        e[i] = h
        a[:, i] = (np.array(f(*e, 0.0)) - np.array(f(*(-e), 0.0))) / (2 * h)
    b = (np.array(f(0.0, 0.0, 0.0, 0.0, h)) - np.array(f(0.0, 0.0, 0.0, 0.0, -h))) / (2 * h)
    assert _relative(a[2:], a_hand[2:]) < 1e-5
    assert _relative(b[2:], b_hand[2:]) < 1e-5
