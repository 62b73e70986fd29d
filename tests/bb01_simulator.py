"""An independent simulator of the quanser-bb01 preset, for testing the part-built rig's calibration on a log the
twin did not make. Written from the physics on paper with numpy only (nothing from twin/ or calib/):

* geometry: the preset's numbers as literals (Quanser config_bb.m: L = 0.42545 m from the hinge to the link's
  coupling, a 1 in arm on the SRV02's load shaft; the link 100 mm, vertical at level, the arm horizontal). The
  beam's angle θ and the arm's θ_l are tied by the four-bar |A − C| = ℓ, A = L·(cos θ, sin θ), C = S + r_arm·(cos
  θ_l, sin θ_l): solved for θ_l(θ) about the shaft, θ_l = ∠(A − S) − arccos((r_arm² + e² − ℓ²)/(2·r_arm·e)),
  e = |A − S|; dθ_l/dθ and d²θ_l/dθ² by central differences.
* ball on the rod and strip (the preset's rod_and_strip defaults: a 1/4 in rod, axis 20 mm above the hinge, the
  strip's edge 12.7 mm across at 23.175 mm): the centre touches the rod (r + ρ from its axis) and the edge (r
  from it), the upper intersection of the two circles; it rolls about the line through its two contacts, r* =
  √(r² − s²/4) from the centre (s: the contacts' distance), the line's small tilt left out (cos 1.5° = 0.99965).
* Lagrange in (p, θ), p the ball's distance from the hinge along the beam: the ball's centre at P = p·e₁ + h_c·e₂,
  |Ṗ|² = (ṗ − h_c·θ̇)² + p²·θ̇², its spin θ̇ − ṗ/r*; the beam J_B about the hinge, the link as two point masses
  (half at the coupling, half at the arm's pin), the arm a rod about its shaft, the SRV02's J_eq at the load,
  all turning at θ̇_l = θ_l′·θ̇; gravity on the ball and the beam (its centre L/2 out, 10 mm up; the link's 10 g
  weight is left out, as the preset's model does). With J_s = J_eq + J_arm + m_l/2·r_arm²:
      (m + I/r*²)·p̈ − (m·h_c + I/r*)·θ̈ = m·p·θ̇² − m·g·sin θ − c_r·m·ṗ
      −(m·h_c + I/r*)·p̈ + M_θθ·θ̈ = θ_l′·τ_l − 2m·p·ṗ·θ̇ − J_s·θ_l′·θ_l″·θ̇² − m·g·(p·cos θ − h_c·sin θ)
                                    − M·g·(x_g·cos θ − h_g·sin θ)
  with M_θθ = m·(h_c² + p²) + I + J_B + m_l/2·L² + J_s·θ_l′².
* the SRV02 (config_servo.m, high gear): τ_l = η_g·K_g·η_m·k_t·(V − K_g·k_m·θ̇_l)/R_m − B_eq·θ̇_l, the VoltPAQ at
  gain 1 (±24 V), the Q8-USB's DAC 16-bit ±10 V.
* sensors: the strip's volts V₀ + x/K_BS (x = p − L/2, ±5 V) with Gaussian noise, through the Q8's 16-bit ±10 V
  ADC; the encoder ⌊θ_l·4096/2π + ½⌋ plus the counter's zero (where it was reset).
* board: a 20 ms loop; a cascade PD as Quanser's lab has it (the ball's position → the arm's angle → volts) from
  the nominal K_BS and the counts, a ±50 mm square setpoint every 5 s and a ±``dither_v`` pseudo-random dither
  changing every 40 ms. It prints ``time_ms,ball_v,counts,dac_v`` (a header line first).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

G = 9.81  # config_bb.m g
# the preset's geometry and masses (twin/parts/presets/quanser-bb01.toml)
L = 0.42545
R_ARM = 0.0254
LINK = 0.1
SHAFT = (L - R_ARM, -LINK)
BALL_M, BALL_R = 0.064, 0.0127
ROD_RHO, ROD_AXIS_Z = 3.175e-3, 0.02
EDGE_Y, EDGE_Z = 0.0127, 0.023175
BEAM_M, BEAM_XG, BEAM_HG = 0.3, L / 2, 0.01
LINK_M, ARM_M = 0.01, 0.01
# the SRV02 (config_servo.m): R_m, k_t, k_m, K_g, η_g, η_m, J_eq (no load), and the DAC's and ADC's 16 bits at ±10 V
K_T, K_M, K_G, ETA_G, ETA_M = 0.007683, 0.007678, 70.0, 0.90, 0.69
J_EQ = 1.77276e-3
AMP_RAIL = 24.0
COUNTS_PER_REV = 4096
STRIP_SUPPLY = 5.0
PERIOD_S = 0.02
_H = 1e-3  # the integration step


@dataclass(frozen=True)
class TrueRig:
    """The simulated rig's own values (the defaults are the preset's; a test moves them)."""

    resistance_ohm: float = 2.6  # R_m
    load_damping_nm_s: float = 15e-3  # B_eq at the load
    beam_inertia_kgm2: float = 0.0181  # J_B about the hinge
    strip_gain_m_per_v: float = -L / 10.0  # K_BS
    strip_offset_v: float = 0.0
    strip_noise_v: float = 0.005
    encoder_zero_counts: int = 0  # the count with the arm at its level pose
    rolling_damping_1_s: float = 0.0
    dither_v: float = 0.5
    noise: bool = True

    def moved(self, **changes: float) -> TrueRig:
        return replace(self, **changes)


def ball_geometry() -> tuple[float, float]:
    """(h_c, r*): the ball's centre's height over the hinge and its rolling radius on the rod and the edge."""
    ay, az, ey, ez = 0.0, ROD_AXIS_Z, EDGE_Y, EDGE_Z
    d = math.hypot(ey - ay, ez - az)
    ux, uz = (ey - ay) / d, (ez - az) / d
    big, small = BALL_R + ROD_RHO, BALL_R
    along = (big * big - small * small + d * d) / (2 * d)
    up = math.sqrt(big * big - along * along)
    cy, cz = ay + along * ux - up * uz, az + along * uz + up * ux  # the upper intersection
    if cz < az:
        cy, cz = ay + along * ux + up * uz, az + along * uz - up * ux
    p1y, p1z = ay + ROD_RHO * (cy - ay) / big, az + ROD_RHO * (cz - az) / big
    s = math.hypot(ey - p1y, ez - p1z)
    return cz, math.sqrt(BALL_R * BALL_R - s * s / 4.0)


def arm_angle(theta: float) -> float:
    """θ_l for the beam at θ (the four-bar solved about the SRV02's shaft)."""
    ax, az = L * math.cos(theta) - SHAFT[0], L * math.sin(theta) - SHAFT[1]
    e = math.hypot(ax, az)
    return math.atan2(az, ax) - math.acos((R_ARM * R_ARM + e * e - LINK * LINK) / (2 * R_ARM * e))


def arm_rates(theta: float, step: float = 1e-5) -> tuple[float, float, float]:
    """θ_l, dθ_l/dθ, d²θ_l/dθ² (central differences)."""
    a, b, c = arm_angle(theta - step), arm_angle(theta), arm_angle(theta + step)
    return b, (c - a) / (2 * step), (c - 2 * b + a) / step**2


def _load_torque(rig: TrueRig, volts: float, arm_speed: float) -> float:
    v = min(max(volts, -AMP_RAIL), AMP_RAIL)
    return ETA_G * K_G * ETA_M * K_T * (v - K_G * K_M * arm_speed) / rig.resistance_ohm - (
        rig.load_damping_nm_s * arm_speed
    )


def derivative(rig: TrueRig, state: np.ndarray, volts: float) -> np.ndarray:
    """(ṗ, θ̇, p̈, θ̈) from the two Lagrange equations (module docstring) solved as a 2×2 system."""
    p, th, pd, thd = state
    h_c, r_star = ball_geometry()
    inertia = 0.4 * BALL_M * BALL_R**2
    j_s = J_EQ + ARM_M * R_ARM**2 / 3.0 + 0.5 * LINK_M * R_ARM**2
    _, d1, d2 = arm_rates(th)
    m_pp = BALL_M + inertia / r_star**2
    m_pt = -(BALL_M * h_c + inertia / r_star)
    m_tt = BALL_M * (h_c**2 + p * p) + inertia + rig.beam_inertia_kgm2 + 0.5 * LINK_M * L * L + j_s * d1 * d1
    s, c = math.sin(th), math.cos(th)
    f_p = BALL_M * p * thd * thd - BALL_M * G * s - rig.rolling_damping_1_s * BALL_M * pd
    f_t = (
        d1 * _load_torque(rig, volts, d1 * thd)
        - 2 * BALL_M * p * pd * thd
        - j_s * d1 * d2 * thd * thd
        - BALL_M * G * (p * c - h_c * s)
        - BEAM_M * G * (BEAM_XG * c - BEAM_HG * s)
    )
    det = m_pp * m_tt - m_pt * m_pt
    return np.array([pd, thd, (m_tt * f_p - m_pt * f_t) / det, (m_pp * f_t - m_pt * f_p) / det])


def advance(rig: TrueRig, state: np.ndarray, volts: float, duration_s: float) -> np.ndarray:
    """RK4 at ``_H`` with the volts held."""
    y = np.array(state, dtype=float)
    for _ in range(int(round(duration_s / _H))):
        k1 = derivative(rig, y, volts)
        k2 = derivative(rig, y + 0.5 * _H * k1, volts)
        k3 = derivative(rig, y + 0.5 * _H * k2, volts)
        k4 = derivative(rig, y + _H * k3, volts)
        y = y + _H / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return y


def quantize(volts: float) -> float:
    """The Q8-USB's 16-bit ±10 V converter: the nearest code, clipped."""
    lsb = 20.0 / 65536.0
    return min(max(math.floor(volts / lsb + 0.5), -32768), 32767) * lsb


def simulate(rig: TrueRig, duration_s: float, seed: int) -> list[str]:
    """The lines the lab's model logs over ``duration_s`` of the loop (header first)."""
    rng = np.random.default_rng(seed)
    state = np.array([L / 2, 0.0, 0.0, 0.0])  # the ball at rest mid-beam, the beam level
    lines = ["time_ms,ball_v,counts,dac_v"]
    k_bs = -L / 10.0  # the lab's nominal calibration, not the rig's own
    step = 2 * math.pi / COUNTS_PER_REV
    x_f, xd_f, dither = 0.0, 0.0, 0.0
    for j in range(int(round(duration_s / PERIOD_S))):
        t = j * PERIOD_S
        x = state[0] - L / 2
        volts = rig.strip_offset_v + x / rig.strip_gain_m_per_v
        if rig.noise:
            volts += rig.strip_noise_v * rng.standard_normal()
        ball_v = quantize(min(max(volts, -STRIP_SUPPLY), STRIP_SUPPLY))
        counts = math.floor(arm_angle(state[1]) / step + 0.5) + rig.encoder_zero_counts
        # the controller: the ball from the nominal K_BS, its speed low-passed; the arm's angle from the counts
        x_meas = k_bs * ball_v
        xd_f += 0.3 * ((x_meas - x_f) / PERIOD_S - xd_f) if j else 0.0
        x_f = x_meas
        x_set = 0.05 if (t // 5.0) % 2 else -0.05
        arm_set = min(max(5.8 * (x_meas - x_set) + 5.4 * xd_f, -0.6), 0.6)
        if j % 2 == 0:
            dither = rig.dither_v * (1.0 if rng.random() < 0.5 else -1.0)
        command = min(max(4.0 * (arm_set - counts * step) + 0.3 + dither, -10.0), 10.0)
        lines.append(f"{int(round(t * 1000.0))},{ball_v:.6f},{counts},{command:.5f}")
        state = advance(rig, state, quantize(command), PERIOD_S)
        if abs(state[0] - L / 2) > 0.2 or abs(arm_angle(state[1])) > math.radians(56.0):
            raise RuntimeError(f"the simulated rig left its range at t = {t:.2f} s: {state}")
    return lines


def write_log(path: str, rig: TrueRig, duration_s: float, seed: int) -> None:
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("\n".join(simulate(rig, duration_s, seed)) + "\n")
