"""The ``open-ball-and-beam`` and ``arduino-stepper-ultrasonic`` presets linearized: the reference model's (A, B)
about the control that holds the level beam (``twin.linearize.linearize_reference`` at ``hold_control`` from the
actuator's rest, as ``controllers.rig_lqg._design`` calls them) against the linear model written here by hand
from rigid-body mechanics and the presets' numbers (typed here from the preset files' sources, not read from
them), within 1 % on every entry of the dynamic rows and on the eigenvalues.

The hand model is Lagrange's, in q = (x, θ) (x the ball from the track's centre, θ the beam), not the thesis's
eq 3.1.26/3.1.27 form the twin uses: the ball's centre sits at (x + d, c) in the beam's frame (d the track's
centre out from the pivot, c = h* + r* its height), so

    T = ½m·((ẋ − c·θ̇)² + (x + d)²·θ̇²) + ½J·(ẋ/r* − θ̇)² + ½(J_B + J_drive(θ))·θ̇²,   J = 2/5·m·r²
    V = m·g·((x + d)·sin θ + c·cos θ) + M·g·(x_g·sin θ + h·cos θ) + V_drive(θ)

(rolling without slip about the line through the ball's two contacts, r* below its centre). Linearized about
the level beam and the ball at the track's centre, held still by the actuator:

    m(1 + k₁)·ẍ − m(c + k₂)·θ̈ = −m·g·θ                                         (k₁ = J/(m·r*²), k₂ = J/(m·r*))
    −m(c + k₂)·ẍ + (J_B + J + m(c² + d²) + J_drive)·θ̈ = −m·g·x + (m·g·c + M·g·h − V″_drive)·θ + Q_θ

with Q_θ the actuator's generalized force linearized (each preset's below). The thesis's form follows from
this one by adding c times the ball's equation to the beam's; the two are the same model, written differently.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import twin.parts  # noqa: F401  (registers the parts)
from twin.linearize import hold_control, linearize_reference
from twin.parameters import Parameters
from twin.parts import rig_parts
from twin.parts.description import preset
from twin.parts.stepper import StepperLaw
from twin.reference import drive_law

G = 9.81  # m/s², the twin's physics.gravity_m_s2 (both presets keep it)


def _rest_and_hold(params: Parameters) -> tuple[float, float]:
    """The actuator's control at rest and the one that holds the level beam, as rig-lqg's design takes them."""
    actuator = rig_parts(params).actuator
    assert actuator.control_of is not None
    rest = actuator.control_of(params)(actuator.rest_command(params))
    return rest, hold_control(params, rest)


def _state_space(
    mass: np.ndarray, stiffness: np.ndarray, damping: np.ndarray, gain: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(A, B) of mass·q̈ = stiffness·q + damping·q̇ + gain·u, q = (x, θ)."""
    a = np.zeros((4, 4))
    a[0, 2] = a[1, 3] = 1.0
    a[2:, :2] = np.linalg.solve(mass, stiffness)
    a[2:, 2:] = np.linalg.solve(mass, damping)
    b = np.zeros(4)
    b[2:] = np.linalg.solve(mass, gain)
    return a, b


def _ball_rows(m: float, r: float, r_star: float, c: float) -> tuple[float, float, float]:
    """The ball's rolling: (m(1 + k₁), m(c + k₂), J), J = 2/5·m·r² about its centre."""
    j_ball = 0.4 * m * r * r
    return m + j_ball / r_star**2, m * c + j_ball / r_star, j_ball


def _relative(measured: np.ndarray, expected: np.ndarray) -> float:
    """The largest error of the hand model's non-zero entries, relative to each entry."""
    mask = np.abs(expected) > 1e-9
    return float(np.max(np.abs(measured[mask] - expected[mask]) / np.abs(expected[mask])))


def _zeros_stay_zero(measured: np.ndarray, expected: np.ndarray) -> bool:
    """Where the hand model has 0 (∂/∂ẋ: nothing acts on the ball's speed at rest), the twin's entry is below a
    millionth of its row's largest."""
    for row_m, row_e in zip(measured, expected, strict=True):
        zero = np.abs(row_e) <= 1e-9
        if np.any(np.abs(row_m[zero]) > 1e-6 * np.max(np.abs(row_e))):
            return False
    return True


def _eigen_errors(a: np.ndarray, a_hand: np.ndarray) -> tuple[float, float]:
    """(the largest |Δλ|/|λ|, the largest |ΔRe λ|/|Re λ|) over the eigenvalues paired by sorting: a lightly damped
    pair's real part (the damping) is checked on its own, not lost under its imaginary part."""
    twin_eig = np.sort_complex(np.linalg.eigvals(a))
    hand_eig = np.sort_complex(np.linalg.eigvals(a_hand))
    whole = np.abs(twin_eig - hand_eig) / np.abs(hand_eig)
    real = np.abs(twin_eig.real - hand_eig.real) / np.abs(hand_eig.real)
    return float(np.max(whole)), float(np.max(real))


# --- open-ball-and-beam: two rods, a beam hinged at its back end, a DS3218MG servo through a horn and a fork ------
# The preset's numbers (twin/parts/presets/open-ball-and-beam.toml, from TSummersLab/open-ball-beam's files)
OBB_M, OBB_R = 0.039, 0.01905  # the Delrin ball (parts_list.xlsx)
OBB_ROD_R, OBB_ROD_SPACING, OBB_ROD_AXES = 0.0025, 0.016, 0.013  # 5 mm rods 16 mm apart, axes 13 mm up
OBB_BEAM_M, OBB_BEAM_J, OBB_BEAM_H = 0.1, 0.0021, 0.013  # assumed in the preset
OBB_D = OBB_XG = 0.115  # the exposed rods' middle and the beam's centre of gravity out from the pivot bolt
OBB_L, OBB_ROD, OBB_CRANK = 0.23, 0.048, 0.0207587  # pivot→tip bolt, the fork's holes, the horn (fitted)
OBB_SHAFT = (0.24882, -0.05065)  # the servo's shaft from the pivot (fitted)
OBB_NEUTRAL, OBB_TRAVEL = 0.84469, 0.98  # the horn's angle at 1500 µs, its travel either way
OBB_FORK_M, OBB_HORN_M = 0.003, 0.005  # assumed
OBB_STALL, OBB_NO_LOAD = 1.8633, 6.545  # DS3218MG: 19 kgf·cm, 60°/0.16 s at 5 V (its supply: rated = supply)
OBB_ARMATURE = 5e-4  # assumed
# servo.saturation_error_rad: the part's default (assumed there; the preset does not set it)
SATURATION_RAD = math.radians(5.0)


def _obb_rolling() -> tuple[float, float]:
    """The ball on two rods (radius ρ, axes s = 8 mm either side of the middle, 13 mm above the pivot): its centre
    is r + ρ from each axis, √((r + ρ)² − s²) above them; each contact lies ρ from its axis toward the centre, so
    the line through the two is ρ·√((r + ρ)² − s²)/(r + ρ) above the axes and r*, the centre above it, is
    r·√((r + ρ)² − s²)/(r + ρ): 17.689 mm. (r*, c = the centre's height above the pivot: 33.011 mm)."""
    reach, half = OBB_R + OBB_ROD_R, OBB_ROD_SPACING / 2
    rise = math.sqrt(reach**2 - half**2)
    return OBB_R * rise / reach, OBB_ROD_AXES + rise


def _obb_horn(theta: float) -> float:
    """The horn's angle φ (from +x toward +z, at the shaft S) that closes the four-bar with the beam at θ: the root
    of F = |A − C|² − r² (A = L·(cos θ, sin θ), C = S + c·(cos φ, sin φ)) by bisection over the horn's travel,
    where F is monotonic (no dead point: F's φ-derivative is −2(A − C)·C′, zero only with the rod along the horn)."""

    def f(phi: float) -> float:
        ux = OBB_L * math.cos(theta) - OBB_SHAFT[0] - OBB_CRANK * math.cos(phi)
        uz = OBB_L * math.sin(theta) - OBB_SHAFT[1] - OBB_CRANK * math.sin(phi)
        return ux * ux + uz * uz - OBB_ROD**2

    lo, hi = OBB_NEUTRAL - OBB_TRAVEL, OBB_NEUTRAL + OBB_TRAVEL
    f_lo = f(lo)
    assert f_lo * f(hi) < 0.0  # one crossing over the travel
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        if f(mid) * f_lo > 0.0:
            lo, f_lo = mid, f(mid)
        else:
            hi = mid
    return 0.5 * (lo + hi)


def _obb_lever() -> tuple[float, float, float]:
    """(φ, φ′ = dφ/dθ, φ″) at the level beam: the closure F(θ, φ) = 0 differentiated implicitly,
    φ′ = −F_θ/F_φ, φ″ = −(F_θθ + 2F_θφ·φ′ + F_φφ·φ′²)/F_φ, with u = A − C:
    F_θ = 2u·A′, F_φ = −2u·C′, F_θθ = 2(|A′|² + u·A″), F_φφ = 2(|C′|² − u·C″), F_θφ = −2A′·C′."""
    phi = _obb_horn(0.0)
    a, a1, a2 = np.array([OBB_L, 0.0]), np.array([0.0, OBB_L]), np.array([-OBB_L, 0.0])
    c1 = OBB_CRANK * np.array([-math.sin(phi), math.cos(phi)])
    c2 = -OBB_CRANK * np.array([math.cos(phi), math.sin(phi)])
    u = a - (np.array(OBB_SHAFT) + OBB_CRANK * np.array([math.cos(phi), math.sin(phi)]))
    f_t, f_p = 2 * u @ a1, -2 * u @ c1
    f_tt, f_pp, f_tp = 2 * (a1 @ a1 + u @ a2), 2 * (c1 @ c1 - u @ c2), -2 * a1 @ c1
    d1 = -f_t / f_p
    d2 = -(f_tt + 2 * f_tp * d1 + f_pp * d1 * d1) / f_p
    return phi, float(d1), float(d2)


def _obb_analytic(
    *, link_weights: bool = True, two_point_fork: bool = False
) -> tuple[np.ndarray, np.ndarray, float]:
    """The open-ball-and-beam's linear model at its hold, by hand; (A, B, the servo's torque at the hold).

    The servo (twin/parts/servo.py, twin/drive_equations.py ``servo_torque_nm``): τ_s = clip(k_p·(u − φ_s), ±τ_s)
    − b·φ̇_s at its shaft, φ_s = φ − neutral its own angle, u its target; k_p = τ_s/e_sat (the stall torque over
    the error at which its drive saturates: a stiffness), b = τ_s/ω₀ (the torque-speed line: a damping). Within its
    band it is linear: at the beam, through φ(θ), Q_θ = φ′(θ)·τ_s, so
        Q_θ ≈ Q₀ + (φ″·τ₀ − k_p·φ′²)·θ − b·φ′²·θ̇ + k_p·φ′·δu       (τ₀ = τ_s at the hold, Q₀ = φ′·τ₀)
    and the shaft's inertia (the armature, the horn m_h·c²/3) appears at the beam as J_s·φ′². The fork, a bar with
    its ends at the pin C and the attachment A: ½·(m/3)·(|v_C|² + v_C·v_A + |v_A|²) (exact for a uniform bar;
    ``two_point_fork``: half its mass at each end, ½·(m/2)·(|v_C|² + |v_A|²), the reference model's, which is
    (m/12)·|v_C − v_A|² more: the bar turning about its middle as m·ℓ²/4, not m·ℓ²/12). The links' weights (the
    horn's at c/2, the fork's at its middle) enter V_drive; the reference model leaves them out
    (``link_weights=False`` does too). The hold: the servo carries the ball's m·g·d, the beam's M·g·x_g and the
    links' V′_drive, Q₀ = φ′·τ₀."""
    r_star, c = _obb_rolling()
    ball_xx, ball_xt, j_ball = _ball_rows(OBB_M, OBB_R, r_star, c)
    phi, d1, d2 = _obb_lever()
    kp = OBB_STALL / SATURATION_RAD
    damping = OBB_STALL / OBB_NO_LOAD
    horn_vel = OBB_CRANK * np.array([-math.sin(phi), math.cos(phi)]) * d1  # v_C per θ̇
    tip_vel = np.array([0.0, OBB_L])  # v_A per θ̇
    j_fork = OBB_FORK_M / 3 * (horn_vel @ horn_vel + horn_vel @ tip_vel + tip_vel @ tip_vel)
    if two_point_fork:
        j_fork = OBB_FORK_M / 2 * (horn_vel @ horn_vel + tip_vel @ tip_vel)
    j_shaft = OBB_ARMATURE + OBB_HORN_M * OBB_CRANK**2 / 3
    j_total = OBB_BEAM_J + j_ball + OBB_M * (c**2 + OBB_D**2) + j_shaft * d1**2 + j_fork
    # the links' potential m·g·z: the horn's centre at c/2, the fork's at the middle of C and A
    w = (OBB_HORN_M / 2 + OBB_FORK_M / 2) * G * OBB_CRANK if link_weights else 0.0
    v1 = w * math.cos(phi) * d1 + (OBB_FORK_M / 2 * G * OBB_L if link_weights else 0.0)
    v2 = w * (math.cos(phi) * d2 - math.sin(phi) * d1**2)
    tau0 = (OBB_M * G * OBB_D + OBB_BEAM_M * G * OBB_XG + v1) / d1
    mass = np.array([[ball_xx, -ball_xt], [-ball_xt, j_total]])
    stiffness = np.array(
        [
            [0.0, -OBB_M * G],
            [-OBB_M * G, OBB_M * G * c + OBB_BEAM_M * G * OBB_BEAM_H - v2 + d2 * tau0 - kp * d1**2],
        ]
    )
    damping_matrix = np.array([[0.0, 0.0], [0.0, -damping * d1**2]])
    a, b = _state_space(mass, stiffness, damping_matrix, np.array([0.0, kp * d1]))
    return a, b, tau0


OBB = preset("open-ball-and-beam")


@pytest.mark.quick
def test_open_ball_and_beam_preset_carries_the_numbers_typed_here() -> None:
    """The hand model's numbers are the preset's (a changed preset shows here first, not as a model error); its
    two-wire contacts are the rods' geometry rounded to 10 µm (d = 16·r/(r + ρ) = 14.144 mm, h* = 15.321 mm)."""
    p = OBB
    link, servo = p.group("linkage"), p.group("servo")
    assert (p.ball.mass_kg, p.ball.radius_m) == (OBB_M, OBB_R)
    assert (p.beam.mass_kg, p.beam.inertia_pivot_kgm2, p.beam.cog_height_m) == (
        OBB_BEAM_M,
        OBB_BEAM_J,
        OBB_BEAM_H,
    )
    assert (p.beam.track_offset_m, p.beam.cog_along_m) == (OBB_D, OBB_XG)
    assert (link.beam_arm_m, link.rod_m, link.crank_m) == (OBB_L, OBB_ROD, OBB_CRANK)
    assert (link.shaft_x_m, link.shaft_z_m, link.horn_neutral_rad) == (*OBB_SHAFT, OBB_NEUTRAL)
    assert (link.rod_mass_kg, link.horn_mass_kg, link.horn_travel_rad) == (OBB_FORK_M, OBB_HORN_M, OBB_TRAVEL)
    assert (servo.stall_torque_nm, servo.no_load_speed_rad_s, servo.armature_kgm2) == (
        OBB_STALL,
        OBB_NO_LOAD,
        OBB_ARMATURE,
    )
    assert servo.supply_v == servo.rated_voltage_v and servo.saturation_error_rad == SATURATION_RAD
    assert p.physics.gravity_m_s2 == G and p.beam.pivot_damping_nm_s_per_rad == 0.0
    r_star, c = _obb_rolling()
    assert p.rolling_radius_m == pytest.approx(r_star, rel=1e-4)  # measured 4.4e-5
    assert p.ball_centre_height_m == pytest.approx(c, rel=5e-5)  # measured 1.8e-5


@pytest.mark.quick
def test_open_ball_and_beam_rest_and_hold_are_the_lever_and_the_weights() -> None:
    """The servo's rest target is its own angle at the level beam (the closure, solved here by bisection); its
    hold adds the error whose k_p·e carries the ball's and the beam's weights about the hinge through the lever
    (the reference model's links weigh nothing)."""
    rest, hold = _rest_and_hold(OBB)
    phi, d1, _ = _obb_lever()
    assert rest == pytest.approx(phi - OBB_NEUTRAL, abs=1e-9)  # −3.588 mrad: the horn 48.19° up at level
    _, _, tau0 = _obb_analytic(link_weights=False)
    assert (hold - rest) * OBB_STALL / SATURATION_RAD == pytest.approx(
        tau0, rel=1e-6
    )  # 19.2 mN·m at the horn
    assert d1 == pytest.approx(8.1549, abs=1e-4)  # dφ/dθ at level: 8.2, not L/c = 11.1 (the rod leans)


@pytest.mark.quick
def test_open_ball_and_beam_linearization_is_the_analytic_model_within_1_percent() -> None:
    _, hold = _rest_and_hold(OBB)
    a, b = linearize_reference(OBB, hold)
    a_hand, b_hand, _ = _obb_analytic()
    assert _relative(a[2:], a_hand[2:]) < 0.01  # measured 4.1e-4
    assert _relative(b.ravel()[2:], b_hand[2:]) < 0.01  # measured 4.1e-4
    assert _zeros_stay_zero(a[2:], a_hand[2:])
    whole, real = _eigen_errors(a, a_hand)
    # the servo's −434.8 and −90.57 /s, the ball's ±0.0425 /s: measured 5.3e-4 (the servo's fast pole)
    assert whole < 0.01 and real < 0.01
    # where the 4.1e-4 comes from: the reference model's fork (twin.parts.linkage.lever_shaft_map: half its mass
    # at each pin) carries 1.48e-5 kg·m² more at the beam than the bar (0.122e-3 against 0.108e-3 kg·m²: 4.1e-4
    # of the beam equation's 0.0361 kg·m²); with its two-point fork and weightless links the hand model agrees
    # to the preset's contacts rounded to 10 µm (measured 4.9e-6 on A and B); the links' weights are 4.1e-5
    a_twin_way, b_twin_way, _ = _obb_analytic(link_weights=False, two_point_fork=True)
    assert _relative(a[2:], a_twin_way[2:]) < 2e-5
    assert _relative(b.ravel()[2:], b_twin_way[2:]) < 2e-5
    a_free, _, _ = _obb_analytic(link_weights=False)
    assert _relative(a_free[2:], a_hand[2:]) < 1e-4


# --- arduino-stepper-ultrasonic: a V-groove, a beam turned at its middle, a 17HS4401 on a TMC2209 --------------
# The preset's numbers (twin/parts/presets/arduino-stepper-ultrasonic.toml; the stepper's: the part's defaults,
# MotionKing 17HS series data sheet, the 17HS4401 row; TMC2209 data sheet for the 16 microsteps)
ST_M, ST_R = 0.039, 0.01905  # the acetal ball (assumed)
ST_ALPHA, ST_VERTEX = math.pi / 4, 0.012  # a 90° angle laid as a V, its corner 12 mm above the shaft
ST_BEAM_M, ST_BEAM_J, ST_BEAM_H = 0.15, 0.0032, 0.01  # assumed
ST_HOLD, ST_DETENT, ST_ROTOR = 0.40, 0.022, 54e-7  # 40 N·cm, 2.2 N·cm, 54 g·cm²
ST_PAIRS, ST_MICROSTEPS = 50, 16  # 1.8°: 200 full steps, 4 per electrical cycle; 16 microsteps
ST_DAMPING = 1e-3  # assumed: the rotor's viscous losses


def _groove_rolling() -> tuple[float, float]:
    """The ball in a V of half-angle α (each wall α from the vertical): its centre is r from each wall, so
    r/sin α above the vertex; each contact is r from the centre along the wall's normal (cos α across, sin α
    down): the line through the two lies r·sin α below the centre, r* = r·sin α = 13.470 mm (the two wires'
    √(r² − d²/4) with d = 2r·cos α). (r*, c = the centre's height above the shaft: 38.941 mm)."""
    return ST_R * math.sin(ST_ALPHA), ST_VERTEX + ST_R / math.sin(ST_ALPHA)


def _stepper_analytic() -> tuple[np.ndarray, np.ndarray]:
    """The stepper preset's linear model at rest (the beam balanced on the motor's shaft: its rest holds it), by
    hand; the control in microsteps of the commanded position.

    The stepper (twin/parts/stepper.py, ``stepper_torque_nm``; twin/drive_equations.py): on the shaft, directly
    (φ = θ), τ = −T_po(φ̇)·sin(p·(φ − φ_c)) − T_det·sin(4p·(φ − φ₀)) − b·φ̇, φ_c = φ₀ + μ·n. At rest T_po = T_hold
    (below the corner speed, 49 rad/s, the driver holds its current: flat, and multiplied by sin 0 anyway), so
        τ ≈ −p·(T_hold + 4·T_det)·θ − b·θ̇ + p·T_hold·μ·n      (μ = 2π/(200·16) per microstep)
    The rotor's inertia adds to the beam's (φ′ = 1).

    What is linearized: the reference model's law, stateless, with the control n as the commanded position and not
    rounded. The rig's actuator is not differentiable at rest: the sketch's position moves toward the target
    through AccelStepper's speed ramp (a state, rate- and acceleration-limited) and the driver points the rotor at
    whole microsteps (floor(s + ½)), so a target of ±0.4 microstep moves nothing. This model is the one the
    reference model (and rig-lqg's design) linearizes: the ramp taken as instant and the steps as continuous; one
    microstep is p·μ = 0.098 rad electrical, where the sine is linear within 0.16 %."""
    r_star, c = _groove_rolling()
    ball_xx, ball_xt, j_ball = _ball_rows(ST_M, ST_R, r_star, c)
    microstep = 2 * math.pi / (4 * ST_PAIRS * ST_MICROSTEPS)
    stiffness_motor = ST_PAIRS * (ST_HOLD + 4 * ST_DETENT)
    j_total = ST_BEAM_J + ST_ROTOR + j_ball + ST_M * c**2
    mass = np.array([[ball_xx, -ball_xt], [-ball_xt, j_total]])
    stiffness = np.array(
        [[0.0, -ST_M * G], [-ST_M * G, ST_M * G * c + ST_BEAM_M * G * ST_BEAM_H - stiffness_motor]]
    )
    damping = np.array([[0.0, 0.0], [0.0, -ST_DAMPING]])
    return _state_space(mass, stiffness, damping, np.array([0.0, ST_PAIRS * ST_HOLD * microstep]))


STEPPER_RIG = preset("arduino-stepper-ultrasonic")


@pytest.mark.quick
def test_stepper_preset_carries_the_numbers_typed_here() -> None:
    p = STEPPER_RIG
    groove, motor = p.group("v_groove"), p.group("stepper")
    assert (p.ball.mass_kg, p.ball.radius_m) == (ST_M, ST_R)
    assert (groove.half_angle_rad, groove.vertex_height_m) == (ST_ALPHA, ST_VERTEX)
    assert (p.beam.mass_kg, p.beam.inertia_pivot_kgm2, p.beam.cog_height_m) == (
        ST_BEAM_M,
        ST_BEAM_J,
        ST_BEAM_H,
    )
    assert not p.beam.hinged_off_centre and p.beam.pivot_damping_nm_s_per_rad == 0.0
    assert (motor.holding_torque_nm, motor.detent_torque_nm, motor.rotor_inertia_kgm2) == (
        ST_HOLD,
        ST_DETENT,
        ST_ROTOR,
    )
    assert (motor.full_steps_per_rev, motor.microsteps, motor.damping_nm_s_per_rad) == (200, 16, ST_DAMPING)
    # the driver holds its current at rest: V_s/I = 7.06 Ω > R = 1.5 Ω
    assert motor.supply_v / motor.current_a > motor.phase_resistance_ohm
    assert p.physics.gravity_m_s2 == G
    r_star, c = _groove_rolling()
    assert p.rolling_radius_m == pytest.approx(r_star, rel=1e-12)
    assert p.ball_centre_height_m == pytest.approx(c, rel=1e-12)


@pytest.mark.quick
def test_stepper_linearization_is_the_analytic_model_within_1_percent() -> None:
    rest, hold = _rest_and_hold(STEPPER_RIG)
    assert rest == hold == 0.0  # the sketch counts from the level beam, balanced on the shaft: 0 holds it
    a, b = linearize_reference(STEPPER_RIG, hold)
    a_hand, b_hand = _stepper_analytic()
    assert _relative(a[2:], a_hand[2:]) < 0.01  # measured 1.5e-9
    assert _relative(b.ravel()[2:], b_hand[2:]) < 0.01  # measured 1.6e-15
    assert _zeros_stay_zero(a[2:], a_hand[2:])
    whole, real = _eigen_errors(a, a_hand)
    # the rotor on its magnetic spring: −0.155 ± 87.08j /s (b/2J its damping); the ball: ±0.2924 /s
    assert whole < 0.01 and real < 0.01  # measured 7.7e-10 on both


@pytest.mark.quick
def test_the_stepper_law_the_linear_model_takes_the_slope_of() -> None:
    """What the linear model stands for: the reference model's law is the sine itself, T_hold·sin(p·μ·n) at the
    level beam for a commanded n microsteps (the linear p·T_hold·μ·n is 0.16 % above it at one microstep); the
    rig's own law (the sketch's ramp, then whole microsteps) is flat about rest: a target under half a microstep
    never reaches the coils, however long it is held."""
    microstep = 2 * math.pi / (4 * ST_PAIRS * ST_MICROSTEPS)
    law = drive_law(STEPPER_RIG)
    assert law is not None
    for n in (1.0, -3.0, 16.0):
        assert law.torque(n, 0.0, 0.0) == pytest.approx(
            ST_HOLD * math.sin(ST_PAIRS * microstep * n), rel=1e-12
        )
    linear = ST_PAIRS * ST_HOLD * microstep
    assert linear / law.torque(1.0, 0.0, 0.0) - 1.0 == pytest.approx(0.0016, abs=1e-4)
    rig_law = StepperLaw(STEPPER_RIG)
    torques = [rig_law(0.4, 0.0, 0.0) for _ in range(2000)]  # 2 s of physics steps, the rotor held level
    assert rig_law.position_steps == pytest.approx(0.4, abs=1e-9)  # the ramp got there
    assert max(abs(t) for t in torques) == 0.0  # but its whole microstep is still 0
    for _ in range(2000):  # past half a microstep the coils take the whole one: the sine at one microstep
        last = rig_law(0.6, 0.0, 0.0)
    assert last == pytest.approx(law.torque(1.0, 0.0, 0.0), rel=1e-12)
