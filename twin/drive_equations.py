"""The equations of the drives and actuators beyond the thesis's that the compiled screening kernel runs too
(``twin.screen``), in one home below it: the end lever's exact four-bar closure (its part: ``twin.parts.linkage``,
where the geometry, the MJCF fragment and the refusals live), the hobby servo's pulse map and torque law (its
part: ``twin.parts.servo``) and the stepper's torque law and its sketch's speed ramp on one run's floats (its part:
``twin.parts.stepper``, which holds their array forms). Arithmetic on floats or numpy arrays alike (the
stepper's: floats), numba compiles them as they are.

The lever (``twin.parts.linkage``'s docstring draws it): the beam's pivot P at the origin, the attachment A at L
along the beam at θ, the servo's shaft S at (S_x, S_z), its horn's pin C at c from S at φ, the push-rod of length r
between C and A.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = [
    "lever_horn_closure_rad",
    "lever_horn_rad",
    "lever_ratio",
    "lever_ratio_slope",
    "lever_shaft_angles",
    "lever_shaft_derivatives",
    "lever_theta_rad",
    "servo_angle_rad",
    "servo_pulse_us",
    "servo_torque_nm",
    "stepper_magnet_torque_nm",
    "stepper_pullout_nm",
    "stepper_ramp_acceleration",
    "stepper_ramp_step",
    "stepper_sketch_steps",
    "stepper_shaft_torque_nm",
]


def lever_theta_rad(
    phi_rad: Any, beam_arm_m: Any, rod_m: Any, crank_m: Any, shaft_x_m: Any, shaft_z_m: Any
) -> Any:
    """The beam's angle θ for the horn's angle φ: the exact closure of the four-bar P–A–C–S (module docstring),
    θ = ∠C + arccos((L² + d² − r²)/(2·L·d)), C = S + c·(cos φ, sin φ), d = |C|; the branch with the rod not
    crossed (the attachment counter-clockwise of the pin, seen from the pivot). NaN where the linkage cannot
    close (d outside [|L − r|, L + r])."""
    pin_x = shaft_x_m + crank_m * np.cos(phi_rad)
    pin_z = shaft_z_m + crank_m * np.sin(phi_rad)
    d = np.hypot(pin_x, pin_z)
    cos_apex = (beam_arm_m * beam_arm_m + d * d - rod_m * rod_m) / (2.0 * beam_arm_m * d)
    with np.errstate(invalid="ignore"):
        return np.arctan2(pin_z, pin_x) + np.arccos(cos_apex)


def lever_horn_rad(
    theta_rad: Any,
    beam_arm_m: Any,
    rod_m: Any,
    crank_m: Any,
    shaft_x_m: Any,
    shaft_z_m: Any,
    sense: Any = 1.0,
    near_rad: Any = 0.0,
) -> Any:
    """The horn's angle φ that holds the beam at θ (the inverse of ``lever_theta_rad``): the closure solved about
    the shaft, φ = ∠(A − S) − sense·arccos((c² + e² − r²)/(2·c·e)), A = L·(cos θ, sin θ), e = |A − S|. The two
    solutions mirror each other about the line S→A; ``sense`` = sign(dθ/dφ) picks the one of the linkage's
    working range (+1: the horn lifts the beam as φ grows, a servo on the pivot's side of the attachment; −1: it
    lowers it, a horn reaching back toward the pivot). The angle is given within ±π of ``near_rad`` (the horn's
    neutral). NaN where the rod cannot reach."""
    with np.errstate(invalid="ignore"):
        return lever_horn_closure_rad(
            theta_rad, beam_arm_m, rod_m, crank_m, shaft_x_m, shaft_z_m, sense, near_rad
        )


def lever_horn_closure_rad(
    theta_rad: Any,
    beam_arm_m: Any,
    rod_m: Any,
    crank_m: Any,
    shaft_x_m: Any,
    shaft_z_m: Any,
    sense: Any,
    near_rad: Any,
) -> Any:
    """``lever_horn_rad``'s arithmetic, numpy functions only (no error state), so that the compiled screening
    kernel (twin.screen, numba) computes it from this one home."""
    dx = beam_arm_m * np.cos(theta_rad) - shaft_x_m
    dz = beam_arm_m * np.sin(theta_rad) - shaft_z_m
    e = np.hypot(dx, dz)
    cos_shaft = (crank_m * crank_m + e * e - rod_m * rod_m) / (2.0 * crank_m * e)
    phi = np.arctan2(dz, dx) - sense * np.arccos(cos_shaft)
    return near_rad + np.mod(phi - near_rad + np.pi, 2.0 * np.pi) - np.pi


def lever_ratio(
    phi_rad: Any, beam_arm_m: Any, rod_m: Any, crank_m: Any, shaft_x_m: Any, shaft_z_m: Any
) -> Any:
    """dθ/dφ at the horn angle φ: the closure |A − C|² = r² differentiated, (A − C)·(A′·dθ − C′·dφ) = 0, so
    dθ/dφ = ((A − C)·C′)/((A − C)·A′), A′ = L·(−sin θ, cos θ), C′ = c·(−sin φ, cos φ): the pin's and the
    attachment's velocities along the rod are equal (a rigid rod). Zero where the rod lines up with the horn,
    infinite where it lies along the beam's radius."""
    theta = lever_theta_rad(phi_rad, beam_arm_m, rod_m, crank_m, shaft_x_m, shaft_z_m)
    with np.errstate(divide="ignore", invalid="ignore"):
        return lever_ratio_slope(theta, phi_rad, beam_arm_m, crank_m, shaft_x_m, shaft_z_m)[0]


def lever_ratio_slope(
    theta_rad: Any, phi_rad: Any, beam_arm_m: Any, crank_m: Any, shaft_x_m: Any, shaft_z_m: Any
) -> tuple[Any, Any]:
    """(ρ, dρ/dφ) at a closed pose (θ, φ), ρ = dθ/dφ (``lever_ratio``), in closed form. With u = A − C (the rod),
    ρ = N/D, N = u·C′, D = u·A′; along the closure u′ = ρ·A′ − C′ (d/dφ), so
    N′ = ρ·A′·C′ − c² + u·C″ and D′ = ρ·L² − A′·C′ + ρ·u·A″ (C″ = −c·(cos φ, sin φ), A″ = −L·(cos θ, sin θ)),
    and dρ/dφ = (N′ − ρ·D′)/D. Numpy functions only: floats, arrays and the compiled kernel (twin.screen)."""
    cos_phi, sin_phi = np.cos(phi_rad), np.sin(phi_rad)
    cos_th, sin_th = np.cos(theta_rad), np.sin(theta_rad)
    rod_x = beam_arm_m * cos_th - (shaft_x_m + crank_m * cos_phi)
    rod_z = beam_arm_m * sin_th - (shaft_z_m + crank_m * sin_phi)
    pin_along = crank_m * (rod_z * cos_phi - rod_x * sin_phi)
    beam_along = beam_arm_m * (rod_z * cos_th - rod_x * sin_th)
    ratio = pin_along / beam_along
    across = beam_arm_m * crank_m * (cos_th * cos_phi + sin_th * sin_phi)  # A′·C′
    d_pin = ratio * across - crank_m * crank_m - crank_m * (rod_x * cos_phi + rod_z * sin_phi)
    d_beam = ratio * beam_arm_m * beam_arm_m - across - ratio * beam_arm_m * (rod_x * cos_th + rod_z * sin_th)
    return ratio, (d_pin - ratio * d_beam) / beam_along


def lever_shaft_angles(
    theta_rad: Any,
    beam_arm_m: Any,
    rod_m: Any,
    crank_m: Any,
    shaft_x_m: Any,
    shaft_z_m: Any,
    sense: Any,
    neutral_rad: Any,
) -> tuple[Any, Any, Any]:
    """The reference model's shaft map of the lever (``twin.reference.DriveKinematics``): the servo's own angle
    φ − neutral for the beam at θ (``lever_horn_closure_rad``), φ′ and φ″ (``lever_shaft_derivatives`` of
    ``lever_ratio_slope``). The compiled kernel (twin.screen.plant ``_lever``) calls the same three functions in
    this order."""
    phi = lever_horn_closure_rad(
        theta_rad, beam_arm_m, rod_m, crank_m, shaft_x_m, shaft_z_m, sense, neutral_rad
    )
    ratio, slope = lever_ratio_slope(theta_rad, phi, beam_arm_m, crank_m, shaft_x_m, shaft_z_m)
    dphi, ddphi = lever_shaft_derivatives(ratio, slope)
    return phi - neutral_rad, dphi, ddphi


def lever_shaft_derivatives(ratio: Any, slope: Any) -> tuple[Any, Any]:
    """φ′ = dφ/dθ = 1/ρ and φ″ = d²φ/dθ² = −(dρ/dφ)/ρ³ from ρ = dθ/dφ and dρ/dφ (φ″ = d(1/ρ)/dφ · dφ/dθ)."""
    return 1.0 / ratio, -slope / (ratio * ratio * ratio)


def servo_angle_rad(
    pulse_us: Any, pulse_min_us: Any, pulse_max_us: Any, angle_at_min_rad: Any, angle_at_max_rad: Any
) -> Any:
    """The servo's target angle for a pulse width: linear from (pulse_min, angle_at_min) to (pulse_max,
    angle_at_max), the pulse held within [pulse_min, pulse_max] (the travel's ends)."""
    held = np.minimum(np.maximum(pulse_us, pulse_min_us), pulse_max_us)
    return angle_at_min_rad + (held - pulse_min_us) * (angle_at_max_rad - angle_at_min_rad) / (
        pulse_max_us - pulse_min_us
    )


def servo_torque_nm(
    target_rad: Any,
    angle_rad: Any,
    speed_rad_s: Any,
    kp_nm_per_rad: Any,
    stall_nm: Any,
    damping_nm_s_per_rad: Any,
) -> Any:
    """The torque at the horn: the position loop's drive clip(k_p·(target − angle), ±τ_s) less the motor's
    back-EMF damping b·ω. Saturated, it is the DC motor's line τ_s·(1 − ω/ω₀) (b = τ_s/ω₀): τ_s at stall, 0 at
    the no-load speed, τ_s/2 at half of it."""
    drive = np.minimum(np.maximum(kp_nm_per_rad * (target_rad - angle_rad), -stall_nm), stall_nm)
    return drive - damping_nm_s_per_rad * speed_rad_s


def servo_pulse_us(
    angle_rad: Any, pulse_min_us: Any, pulse_max_us: Any, angle_at_min_rad: Any, angle_at_max_rad: Any
) -> Any:
    """The pulse width whose target is ``angle_rad`` (the inverse of ``servo_angle_rad``), held within the
    travel's pulses."""
    pulse = pulse_min_us + (angle_rad - angle_at_min_rad) * (pulse_max_us - pulse_min_us) / (
        angle_at_max_rad - angle_at_min_rad
    )
    return np.minimum(np.maximum(pulse, pulse_min_us), pulse_max_us)


# --- the stepper on one run's floats (twin.parts.stepper: the physics, the numbers and the array form) ----------
def stepper_pullout_nm(
    speed_rad_s: float,
    holding_nm: float,
    pole_pairs: float,
    resistance_ohm: float,
    inductance_h: float,
    supply_impedance_ohm: float,
) -> float:
    """T_po(ω) = T_hold·min(1, (V_s/I)/√(R² + (p·ω·L)²)) on floats (``twin.parts.stepper.pullout_torque_nm``)."""
    x = pole_pairs * abs(speed_rad_s) * inductance_h
    return holding_nm * min(1.0, supply_impedance_ohm / math.sqrt(resistance_ohm * resistance_ohm + x * x))


def stepper_magnet_torque_nm(
    pullout: Callable[[float, float, float, float, float, float], float],
    commanded_rad: float,
    angle_rad: float,
    speed_rad_s: float,
    level_rad: float,
    holding_nm: float,
    pole_pairs: float,
    detent_nm: float,
    resistance_ohm: float,
    inductance_h: float,
    supply_impedance_ohm: float,
) -> float:
    """−T_po(φ̇)·sin(p·(φ − φ_c)) − T_det·sin(4p·(φ − φ₀)) on floats (``twin.parts.stepper.stepper_torque_nm``;
    ``pullout``: ``stepper_pullout_nm``, or its compiled form in the kernel; 4 full steps per electrical cycle)."""
    pull = pullout(speed_rad_s, holding_nm, pole_pairs, resistance_ohm, inductance_h, supply_impedance_ohm)
    detent = detent_nm * math.sin(4 * pole_pairs * (angle_rad - level_rad))
    return -pull * math.sin(pole_pairs * (angle_rad - commanded_rad)) - detent


def stepper_shaft_torque_nm(
    magnet: Callable[..., float],
    pullout: Callable[[float, float, float, float, float, float], float],
    target_steps: float,
    angle_rad: float,
    speed_rad_s: float,
    level_rad: float,
    microstep_rad: float,
    holding_nm: float,
    pole_pairs: float,
    detent_nm: float,
    resistance_ohm: float,
    inductance_h: float,
    supply_impedance_ohm: float,
    damping_nm_s_per_rad: float,
) -> float:
    """The reference model's stepper at its shaft (``twin.parts.stepper``'s law for ``twin.reference.DriveLaw``,
    stateless): the control as the commanded position, φ_c = φ₀ + μ·n, the magnet's torque
    (``magnet``: ``stepper_magnet_torque_nm``) less the viscous b·φ̇. The reference plant and the compiled
    kernel (twin.screen.plant) alike."""
    commanded = level_rad + microstep_rad * target_steps
    law = magnet(
        pullout, commanded, angle_rad, speed_rad_s, level_rad, holding_nm, pole_pairs, detent_nm,
        resistance_ohm, inductance_h, supply_impedance_ohm,
    )  # fmt: skip
    return law - damping_nm_s_per_rad * speed_rad_s


def stepper_ramp_acceleration(
    target_steps: float,
    position_steps: float,
    speed_steps_s: float,
    max_speed: float,
    acceleration: float,
    step_s: float,
) -> float:
    """dv/dt of the sketch's ramp on floats (``twin.parts.stepper.ramp_acceleration``): the speed heads for
    sign(D)·min(v_max, √(2a|D|), |D|/h), D = target − position, changing at most a."""
    d = target_steps - position_steps
    w = math.copysign(min(max_speed, math.sqrt(2.0 * acceleration * abs(d)), abs(d) / step_s), d)
    return min(max((w - speed_steps_s) / step_s, -acceleration), acceleration)


def stepper_ramp_step(
    ramp_acceleration: Callable[[float, float, float, float, float, float], float],
    target_steps: float,
    position_steps: float,
    speed_steps_s: float,
    max_speed: float,
    acceleration: float,
    step_s: float,
) -> tuple[float, float]:
    """One physics step h of the sketch's ramp toward ``target_steps`` (``ramp_acceleration``:
    ``stepper_ramp_acceleration``, or its compiled form): v ← v + h·dv/dt, s ← s + h·v (semi-implicit Euler: a
    speed of D/h lands on the target). (s, v) after the step; ``twin.parts.stepper.StepperLaw``, the reference
    model and the compiled kernel alike."""
    speed = speed_steps_s + step_s * ramp_acceleration(
        target_steps, position_steps, speed_steps_s, max_speed, acceleration, step_s
    )
    return position_steps + step_s * speed, speed


def stepper_sketch_steps(position_steps: float) -> float:
    """n = floor(s + ½): the sketch's whole position (the step pulses it has sent) for the ramp's position s."""
    return float(math.floor(position_steps + 0.5))
