"""An independent simulator of the open-ball-and-beam preset, for testing the part-built rig's calibration on a
log the twin did not make. Written from the physics on paper with numpy only (nothing from twin/ or calib/):

* geometry: the preset's numbers as literals (Open Ball & Beam: a 1.5 in ball on two 5 mm rods 16 mm apart,
  their axes 13 mm above the hinge bolt; the beam hinged at its back end and lifted 230 mm out by a 48 mm fork
  from a 20.76 mm horn). The ball touches each rod on the line from its centre to the rod's axis, r/(r + ρ) of
  the way: its centre stands √((r + ρ)² − (s/2)²) above the rods' plane and the line through its two contacts
  lies r* = r·√((r + ρ)² − (s/2)²)/(r + ρ) below its centre.
* ball: Lagrange's equation for its distance p from the hinge along the beam, the beam's angle θ(t) imposed
  (the servo is stiff: the beam goes where the horn puts it). The ball's centre sits at P = p·e₁ + h_c·e₂
  (e₁ = (cos θ, sin θ), e₂ = (−sin θ, cos θ)), so |Ṗ|² = (ṗ − h_c·θ̇)² + p²·θ̇²; rolling on the contact line
  turns it at ω = θ̇ − ṗ/r*. With I = 2/5·m·r², T = ½m|Ṗ|² + ½I·ω², V = m·g·(p·sin θ + h_c·cos θ) and a
  rolling resistance −c_r·m·ṗ:
      (m + I/r*²)·p̈ − (m·h_c + I/r*)·θ̈ − m·p·θ̇² + m·g·sin θ = −c_r·m·ṗ
  i.e. p̈ = (p·θ̇² − g·sin θ − c_r·ṗ + (h_c + (2/5)·r²/r*)·θ̈)/(1 + (2/5)·(r/r*)²).
* four-bar: the rod's end A(θ) = L·e₁ on the beam, the horn's pin C(φ) = S + c·(cos φ, sin φ), |A − C| = ℓ.
  For a horn angle φ, A lies on the circle of radius L about the hinge and on the circle of radius ℓ about C:
  with d = |C|, cos(θ − ∠C) = (L² + d² − ℓ²)/(2·L·d), the branch with the rod pushing up (θ = ∠C + arccos …).
  dθ/dφ and d²θ/dφ² by central differences of that closed form.
* servo: the horn follows its target (the pulse's angle, 2.12901 rad per 1000 µs from the 1500 µs centre, the
  preset's fit) as a first-order loop, φ̇ = (target − φ)/T_s, its speed limited to ±ω_max.
* sensor: a VL53L0X ranging back to back; each range is the mean distance from its face to the ball's near
  surface over its timing budget, ending ``latency_s`` before the board reads it, times a gain, less an offset,
  plus Gaussian noise of 1.2 mm + 1 % of the distance, rounded to the millimetre; one range in 200 is the
  out-of-range code 8190 (a return lost off the round ball).
* board: a 20 ms loop; a PD controller on the range in pulse µs (derivative low-passed), a ±10 mm square setpoint
  every 5 s and a ±``dither_us`` pseudo-random dither changing every 40 ms; whole µs within 1000…2000.
  It prints what a sketch would: ``time_ms,distance_mm,pulse_us`` (with a header line and a "ready" line).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

G = 9.80665
# the preset's geometry (twin/parts/presets/open-ball-and-beam.toml: parts_list.xlsx, rail_holder, fork.stp)
BALL_R = 0.01905
ROD_R = 0.0025
ROD_GAP = 0.016  # rod axes apart
ROD_AXIS_H = 0.013  # rod axes above the hinge bolt
TRACK_OFFSET = 0.115  # the exposed rods' middle from the hinge (the preset's x = 0)
HALF_LENGTH = 0.105
MOUNT_X = 0.107  # the sensor's face, in the preset's x
BEAM_ARM, ROD, CRANK = 0.23, 0.048, 0.0207587
SHAFT = (0.24882, -0.05065)
SERVO_RAD_PER_US = 2.12901 / 1000.0
PERIOD_S = 0.02
OUT_OF_RANGE_MM = 8190
_H = 1e-3  # the integration step


@dataclass(frozen=True)
class TrueRig:
    """The simulated rig's own values (the defaults are the preset's; a test moves them)."""

    horn_neutral_rad: float = 0.84469
    speed_limit_rad_s: float = 6.545
    time_constant_s: float = 0.0133  # the preset's servo: e_sat/ω₀ = 5°/6.545 rad/s
    sensor_offset_mm: float = 0.0  # subtracted from each range (a cover's crosstalk)
    sensor_gain: float = 1.0
    latency_s: float = 0.0  # from the range's end to the board's read
    budget_s: float = 0.02
    rolling_damping_1_s: float = 0.0
    dither_us: float = 40.0
    noise: bool = True

    def moved(self, **changes: float) -> TrueRig:
        return replace(self, **changes)


def _geometry() -> tuple[float, float, float]:
    """(h_c, r*, k) of the ball on the rods: its centre's height over the hinge, its rolling radius, (2/5)(r/r*)²."""
    rise = math.sqrt((BALL_R + ROD_R) ** 2 - (ROD_GAP / 2) ** 2)
    r_star = BALL_R * rise / (BALL_R + ROD_R)
    return ROD_AXIS_H + rise, r_star, 0.4 * (BALL_R / r_star) ** 2


def beam_angle(phi: float) -> float:
    """θ for the horn at φ (the four-bar's closure, rod pushing up)."""
    cx, cz = SHAFT[0] + CRANK * math.cos(phi), SHAFT[1] + CRANK * math.sin(phi)
    d = math.hypot(cx, cz)
    return math.atan2(cz, cx) + math.acos((BEAM_ARM**2 + d * d - ROD**2) / (2 * BEAM_ARM * d))


def beam_angle_rates(phi: float, step: float = 1e-5) -> tuple[float, float, float]:
    """θ, dθ/dφ, d²θ/dφ² (central differences)."""
    a, b, c = beam_angle(phi - step), beam_angle(phi), beam_angle(phi + step)
    return b, (c - a) / (2 * step), (c - 2 * b + a) / step**2


def level_pulse_us(rig: TrueRig) -> float:
    """The pulse whose horn angle holds the beam level (bisection on θ(φ))."""
    lo, hi = rig.horn_neutral_rad - 0.8, rig.horn_neutral_rad + 0.8
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if beam_angle(mid) < 0.0 else (lo, mid)
    return 1500.0 + (0.5 * (lo + hi) - rig.horn_neutral_rad) / SERVO_RAD_PER_US


def _ball_acc(p: float, pd: float, th: float, thd: float, thdd: float, c_r: float) -> float:
    h_c, r_star, k = _geometry()
    return (p * thd * thd - G * math.sin(th) - c_r * pd + (h_c + 0.4 * BALL_R**2 / r_star) * thdd) / (1.0 + k)


def simulate(rig: TrueRig, duration_s: float, seed: int) -> list[str]:
    """The lines a sketch prints over ``duration_s`` of the loop (header first)."""
    rng = np.random.default_rng(seed)
    level = level_pulse_us(rig)
    dist_set = (MOUNT_X - BALL_R) * 1000.0  # the range of a ball at x = 0
    p, pd, phid = TRACK_OFFSET, 0.0, 0.0  # the ball at rest mid-track, the horn still
    phi = rig.horn_neutral_rad + (level - 1500.0) * SERVO_RAD_PER_US
    pulse = round(level)
    hist_t: list[float] = [0.0]
    hist_d: list[float] = [(MOUNT_X - BALL_R) - (p - TRACK_OFFSET)]
    lines = ["ready", "time_ms,distance_mm,pulse_us"]
    n_ticks = int(round(duration_s / PERIOD_S))
    deriv, last_mm, dither = 0.0, dist_set, 0.0
    t = 0.0
    for j in range(n_ticks):
        reading = _range_mm(rig, rng, t, hist_t, hist_d)
        if j % 2 == 0:
            dither = rig.dither_us * (1.0 if rng.random() < 0.5 else -1.0)
        target_mm = dist_set + (10.0 if (t // 5.0) % 2 else -10.0)
        if reading != OUT_OF_RANGE_MM:
            deriv += 0.25 * ((reading - last_mm) / PERIOD_S - deriv)  # a low-passed derivative
            last_mm = reading
        command = level - 2.0 * (last_mm - target_mm) - 1.5 * deriv + dither
        pulse = int(round(min(max(command, 1000.0), 2000.0)))
        lines.append(f"{int(round(t * 1000.0))},{reading},{pulse}")
        target = rig.horn_neutral_rad + (pulse - 1500.0) * SERVO_RAD_PER_US
        p, pd, phi, phid, path = _tick(rig, p, pd, phi, phid, target)
        for s_, p_ in path:
            hist_t.append(t + s_)
            hist_d.append((MOUNT_X - BALL_R) - (p_ - TRACK_OFFSET))
        t = (j + 1) * PERIOD_S
        if abs(p - TRACK_OFFSET) > HALF_LENGTH:
            raise RuntimeError(f"the simulated ball left the rods at t = {t:.2f} s")
    return lines


def _horn(rig: TrueRig, phi: float, target: float, s: float) -> tuple[float, float, float]:
    """The horn's angle, speed and acceleration s after a tick's start at φ: at the speed limit while the error
    exceeds ω_max·T_s (until s₁ = (|e| − ω_max·T_s)/ω_max), then the lag's exponential from there (exact)."""
    e0 = target - phi
    w, tc = rig.speed_limit_rad_s, rig.time_constant_s
    s1 = max(0.0, (abs(e0) - w * tc) / w)
    if s < s1:
        rate = math.copysign(w, e0)
        return phi + rate * s, rate, 0.0
    e1 = e0 if s1 == 0.0 else math.copysign(w * tc, e0)
    e = e1 * math.exp(-(s - s1) / tc)
    return target - e, e / tc, -e / tc**2


def _tick(
    rig: TrueRig, p: float, pd: float, phi: float, phid: float, target: float
) -> tuple[float, float, float, float, list[tuple[float, float]]]:
    """One tick with the target held: the horn's speed jumps to its new value at the tick's start (the ball
    takes its share of the beam's jump, integrating the θ̈ term: Δṗ = (h_c + (2/5)r²/r*)·Δθ̇/(1 + k)), then RK4
    steps of the ball with θ(t) from the horn's exact path."""
    h_c, r_star, k = _geometry()
    coupling = (h_c + 0.4 * BALL_R**2 / r_star) / (1.0 + k)
    _, speed0, _ = _horn(rig, phi, target, 0.0)
    pd += coupling * beam_angle_rates(phi)[1] * (speed0 - phid)

    def f(s: float, p_: float, pd_: float) -> tuple[float, float]:
        ph, phd, phdd = _horn(rig, phi, target, s)
        th, r1, r2 = beam_angle_rates(ph)
        return pd_, _ball_acc(p_, pd_, th, r1 * phd, r1 * phdd + r2 * phd * phd, rig.rolling_damping_1_s)

    s = 0.0
    path: list[tuple[float, float]] = []  # (time into the tick, p) after each step: the sensor's record
    for _ in range(int(round(PERIOD_S / _H))):
        k1 = f(s, p, pd)
        k2 = f(s + 0.5 * _H, p + 0.5 * _H * k1[0], pd + 0.5 * _H * k1[1])
        k3 = f(s + 0.5 * _H, p + 0.5 * _H * k2[0], pd + 0.5 * _H * k2[1])
        k4 = f(s + _H, p + _H * k3[0], pd + _H * k3[1])
        p += _H / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        pd += _H / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        s += _H
        path.append((s, p))
    end, speed, _ = _horn(rig, phi, target, PERIOD_S)
    return p, pd, end, speed, path


def _range_mm(
    rig: TrueRig, rng: np.random.Generator, t: float, hist_t: list[float], hist_d: list[float]
) -> int:
    """The range the board reads at t: the mean distance over the budget ending ``latency_s`` before t."""
    u, z = rng.random(), rng.standard_normal()
    end = t - rig.latency_s
    times = np.asarray(hist_t[-400:])
    dists = np.asarray(hist_d[-400:])
    grid = np.linspace(end - rig.budget_s, end, 41)
    mean_m = float(np.mean(np.interp(grid, times, dists)))  # before t = 0 the ball rested where it started
    if rig.noise and u < 0.005:
        return OUT_OF_RANGE_MM
    mm = rig.sensor_gain * mean_m * 1000.0 - rig.sensor_offset_mm
    if rig.noise:
        mm += (1.2 + 0.01 * mm) * z
    return int(max(round(mm), 0))


def write_log(path: str, rig: TrueRig, duration_s: float, seed: int) -> None:
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("\n".join(simulate(rig, duration_s, seed)) + "\n")
