"""The verdict of a closed-loop run: one typed object computed once from the true state.

Every figure comes from the plant's true state at the 50 Hz ticks (and the per-step peaks of each tick), never
from what a controller measured or estimated. The criteria are data (``Criteria``) with the reason for
each default; ``evaluate`` is the only place they are applied and ``settling_time_s`` is the one home of the
settling metric.

    ball_lost, ball_lost_time_s      the ball left the track (and when)
    steady_x_m, steady_theta_rad     means over the final window
    limit_cycle_x_pp_m, _theta_pp_rad  peak-to-peak over the final window
    settling_time_s                  last time |x − steady_x| exceeded max(2 % |x0|, 1 mm), measured from
                                     release; None when that happens inside the final window
    held                             ball kept and the final window within the offset and limit-cycle bands
    peak_motor_voltage_v, saturated_fraction (share of ticks at the ±12 V rails), peak_theta_rad, hit_stops

A lost ball has no steady state: the window fields and the settling time are None and ``held`` is False.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

__all__ = ["Criteria", "Verdict", "evaluate", "settling_time_s"]


@dataclass(frozen=True)
class Criteria:
    """What ``held`` and the settling time mean (defaults and their reasons in the README)."""

    # ≥ 4 periods of the slowest limit cycle seen on the twin (0.73 s) and ≤ a fifth of a 15 s run.
    window_s: float = 3.0
    # The ball sensor's converter alone puts the balance point 3–4.5 mm off centre (Table 6.3 read through
    # eq 6.3.1); a centimetre is what a person watching the rig still calls "in the middle".
    offset_band_m: float = 0.010
    # Ten encoder counts (one count = 3.5 mrad): far beyond quantization, far below a visible tilt.
    offset_band_rad: float = 0.035
    # A ball wandering less than a centimetre is balanced; the quantization limit cycle is 1–3 mm.
    limit_cycle_band_m: float = 0.010
    # Peak-to-peak beam motion of a balanced rig: the limit cycle moves the beam by a few counts.
    limit_cycle_band_rad: float = 0.035
    # Settling: the usual 2 % of the initial offset, but never below 1 mm (a third of the converter's offset).
    settling_fraction: float = 0.02
    settling_floor_m: float = 1e-3
    # The beam counts as on its stops within 1 mrad of them (MuJoCo's stop is a soft constraint).
    stop_tolerance_rad: float = 1e-3

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"criterion {name} = {value!r} must be a finite number ≥ 0")


@dataclass(frozen=True)
class Verdict:
    held: bool
    reason: str
    ball_lost: bool
    ball_lost_time_s: float | None
    steady_x_m: float | None
    steady_theta_rad: float | None
    limit_cycle_x_pp_m: float | None
    limit_cycle_theta_pp_rad: float | None
    settling_time_s: float | None
    peak_motor_voltage_v: float
    saturated_fraction: float
    peak_theta_rad: float
    hit_stops: bool
    duration_s: float

    def to_json(self) -> dict[str, object]:
        """Plain JSON values rounded to their meaning: µm, µrad, ms, mV, 0.01 %."""
        digits = {
            "ball_lost_time_s": 3,
            "steady_x_m": 6,
            "steady_theta_rad": 6,
            "limit_cycle_x_pp_m": 6,
            "limit_cycle_theta_pp_rad": 6,
            "settling_time_s": 3,
            "peak_motor_voltage_v": 3,
            "saturated_fraction": 4,
            "peak_theta_rad": 6,
            "duration_s": 3,
        }
        out: dict[str, object] = {}
        for key, value in asdict(self).items():
            if key in digits and value is not None:
                value = round(float(value), digits[key])
            elif isinstance(value, (bool, np.bool_)):
                value = bool(value)
            out[key] = value
        return out


def settling_time_s(
    t_s: np.ndarray, x_m: np.ndarray, steady_x_m: float, x0_m: float, criteria: Criteria
) -> float | None:
    """The time after which |x − steady_x| stays within max(fraction·|x0|, floor): the time of the first
    sample after the last one outside. 0 if no sample is outside; None if the last one outside lies in
    the final window (the run did not settle in time to tell)."""
    band = max(criteria.settling_fraction * abs(x0_m), criteria.settling_floor_m)
    outside = np.flatnonzero(np.abs(np.asarray(x_m) - steady_x_m) > band)
    if not outside.size:
        return 0.0
    last = int(outside[-1])
    if last + 1 >= len(t_s) or t_s[last + 1] > t_s[-1] - criteria.window_s:
        return None
    return float(max(t_s[last + 1], 0.0))


def evaluate(
    t_s: np.ndarray,
    x_m: np.ndarray,
    theta_rad: np.ndarray,
    motor_volts_v: np.ndarray,
    peak_abs_theta_rad: np.ndarray,
    *,
    x0_m: float,
    ball_lost_time_s: float | None,
    rail_v: float,
    stop_angle_rad: float,
    criteria: Criteria | None = None,
) -> Verdict:
    """The verdict from the ticks of one run (times from release; the rows before release are the held rig).

    ``peak_abs_theta_rad`` is the largest |θ| over the physics steps of each tick while the ball was on the
    track; ``motor_volts_v`` the volts across the motor at each tick."""
    c = criteria or Criteria()
    t = np.asarray(t_s, dtype=float)
    released = t >= 0.0
    volts = np.abs(np.asarray(motor_volts_v, dtype=float)[released])
    peak_v = float(volts.max()) if volts.size else 0.0
    saturated = float(np.mean(volts >= rail_v - 1e-9)) if volts.size else 0.0
    peak_theta = float(np.max(peak_abs_theta_rad)) if len(peak_abs_theta_rad) else 0.0
    common = dict(
        ball_lost=ball_lost_time_s is not None,
        ball_lost_time_s=ball_lost_time_s,
        peak_motor_voltage_v=peak_v,
        saturated_fraction=saturated,
        peak_theta_rad=peak_theta,
        hit_stops=peak_theta >= stop_angle_rad - c.stop_tolerance_rad,
        duration_s=float(t[-1]),
    )
    none = dict(
        steady_x_m=None,
        steady_theta_rad=None,
        limit_cycle_x_pp_m=None,
        limit_cycle_theta_pp_rad=None,
        settling_time_s=None,
    )
    if ball_lost_time_s is not None:
        return Verdict(held=False, reason=f"ball lost at {ball_lost_time_s:.3f} s", **none, **common)  # type: ignore[arg-type]
    if t[-1] < c.window_s:
        return Verdict(
            held=False,
            reason=f"the run ({t[-1]:.3f} s) is shorter than the final window ({c.window_s:g} s)",
            **none,  # type: ignore[arg-type]
            **common,  # type: ignore[arg-type]
        )
    x = np.asarray(x_m, dtype=float)
    th = np.asarray(theta_rad, dtype=float)
    window = t >= t[-1] - c.window_s
    steady_x, steady_th = float(np.mean(x[window])), float(np.mean(th[window]))
    pp_x, pp_th = float(np.ptp(x[window])), float(np.ptp(th[window]))
    failures = []
    if abs(steady_x) > c.offset_band_m:
        failures.append(f"offset {steady_x * 1e3:+.1f} mm beyond ±{c.offset_band_m * 1e3:g} mm")
    if abs(steady_th) > c.offset_band_rad:
        failures.append(f"beam offset {steady_th * 1e3:+.1f} mrad beyond ±{c.offset_band_rad * 1e3:g} mrad")
    if pp_x > c.limit_cycle_band_m:
        failures.append(f"ball limit cycle {pp_x * 1e3:.1f} mm p-p beyond {c.limit_cycle_band_m * 1e3:g} mm")
    if pp_th > c.limit_cycle_band_rad:
        failures.append(
            f"beam limit cycle {pp_th * 1e3:.1f} mrad p-p beyond {c.limit_cycle_band_rad * 1e3:g} mrad"
        )
    return Verdict(
        held=not failures,
        reason="; ".join(failures) if failures else "held",
        steady_x_m=steady_x,
        steady_theta_rad=steady_th,
        limit_cycle_x_pp_m=pp_x,
        limit_cycle_theta_pp_rad=pp_th,
        settling_time_s=settling_time_s(t[released], x[released], steady_x, x0_m, c),
        **common,  # type: ignore[arg-type]
    )
