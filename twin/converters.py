"""The unit conversions of the rig software (appendix A), in one place for every controller.

Both callbacks of appendix A (``d_cb_control_law`` and ``d_cb_state_feedback``) convert the raw ADC volts
and the computed control value with the same literal numbers. They are ported here operation by operation
(same constants, same order of floating-point operations), so a controller using them computes what the
MATLAB code computed. These are the *software's* numbers, deliberately not parameters: a recalibrated
controller passes its own numbers instead of editing these.

All functions take a float or a numpy array and return the same kind. NaN or infinite input raises
``ValueError`` naming the argument (MATLAB would silently propagate NaN to the motor).
"""

from __future__ import annotations

from typing import overload

import numpy as np

__all__ = [
    "AMPLIFIER_GAIN_V_PER_V",
    "ANGLE_GAIN_DEG_PER_V",
    "ANGLE_REFERENCE_MOTOR_DEG",
    "ANGLE_REFERENCE_V",
    "BALL_GAIN_M_PER_V",
    "BALL_OFFSET_M",
    "COMMAND_HIGH_V",
    "COMMAND_LOW_V",
    "GEAR_RATIO",
    "SOFTWARE_PI",
    "ZERO_COMMAND_V",
    "ball_position_m",
    "beam_angle_deg",
    "beam_angle_rad",
    "clip_command_v",
    "dac_command_v",
    "finite_values",
    "motor_volts_from_command",
]

# eq 6.3.1 / appendix A: x1 = (0.0693 * x1_temp) + 0.0018 (straight-line fit of Table 6.3).
BALL_GAIN_M_PER_V = 0.0693
BALL_OFFSET_M = 0.0018
# eq 6.2.9-6.2.10 / appendix A: x2_temp_2 = (143.22657649*(x2_temp - 5.002) + 718.59375) / 7.
# 143.22657649 = (360/256) / (5 kΩ·2.0108 mA/1024), i.e. the unrounded slope of eq 6.2.5, and 5.002 V is the
# measured DAC output at DI = 1023 (eq 6.2.4), where the motor angle is 718.59375° (§6.2).
ANGLE_GAIN_DEG_PER_V = 143.22657649
ANGLE_REFERENCE_V = 5.002
ANGLE_REFERENCE_MOTOR_DEG = 718.59375
GEAR_RATIO = 7  # the literal "/ 7" of appendix A (gearbox 1:7, §6.2)
SOFTWARE_PI = 3.141592654  # appendix A: x2 = x2_temp_2 * (3.141592654 / 180)
# §6.4 / appendix A: adat = (u/9.6) + 2.5; u = (adat-2.5)*9.6; limits 1.25…3.75 V (±12 V at the motor).
AMPLIFIER_GAIN_V_PER_V = 9.6
ZERO_COMMAND_V = 2.5
COMMAND_LOW_V = 1.25
COMMAND_HIGH_V = 3.75


def finite_values(value: float | np.ndarray, name: str) -> np.ndarray:
    """``value`` as a float64 array; raises ValueError naming ``name`` if it is not numeric or not finite."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} = {value!r} is not a number or an array of numbers") from None
    if not np.isfinite(arr).all():
        bad = arr[~np.isfinite(arr)][0] if arr.ndim else arr
        raise ValueError(f"{name} contains {float(bad)!r}: it must be finite")
    return arr


def _same_kind(result: np.ndarray, value: float | np.ndarray) -> float | np.ndarray:
    """A Python float for scalar input, an array otherwise."""
    return float(result) if np.ndim(value) == 0 else result


@overload
def ball_position_m(volts: float) -> float: ...
@overload
def ball_position_m(volts: np.ndarray) -> np.ndarray: ...
def ball_position_m(volts: float | np.ndarray) -> float | np.ndarray:
    """Ball position (m) from the ball channel's volts: 0.0693·V + 0.0018 (eq 6.3.1, appendix A)."""
    v = finite_values(volts, "volts")
    return _same_kind((BALL_GAIN_M_PER_V * v) + BALL_OFFSET_M, volts)


@overload
def beam_angle_deg(volts: float) -> float: ...
@overload
def beam_angle_deg(volts: np.ndarray) -> np.ndarray: ...
def beam_angle_deg(volts: float | np.ndarray) -> float | np.ndarray:
    """Beam angle in degrees from the angle channel's volts (eq 6.2.10; appendix A's ``x2_temp_2``)."""
    v = finite_values(volts, "volts")
    return _same_kind(
        (ANGLE_GAIN_DEG_PER_V * (v - ANGLE_REFERENCE_V) + ANGLE_REFERENCE_MOTOR_DEG) / GEAR_RATIO, volts
    )


@overload
def beam_angle_rad(volts: float) -> float: ...
@overload
def beam_angle_rad(volts: np.ndarray) -> np.ndarray: ...
def beam_angle_rad(volts: float | np.ndarray) -> float | np.ndarray:
    """Beam angle (rad) exactly as appendix A computes it: eq 6.2.10 in degrees, times 3.141592654/180."""
    v = finite_values(volts, "volts")
    deg = (ANGLE_GAIN_DEG_PER_V * (v - ANGLE_REFERENCE_V) + ANGLE_REFERENCE_MOTOR_DEG) / GEAR_RATIO
    return _same_kind(deg * (SOFTWARE_PI / 180), volts)


@overload
def dac_command_v(motor_volts: float) -> float: ...
@overload
def dac_command_v(motor_volts: np.ndarray) -> np.ndarray: ...
def dac_command_v(motor_volts: float | np.ndarray) -> float | np.ndarray:
    """DAC command from desired motor volts: V/9.6 + 2.5 (§6.4; appendix A ``adat``), not clipped."""
    v = finite_values(motor_volts, "motor_volts")
    return _same_kind((v / AMPLIFIER_GAIN_V_PER_V) + ZERO_COMMAND_V, motor_volts)


@overload
def motor_volts_from_command(command_v: float) -> float: ...
@overload
def motor_volts_from_command(command_v: np.ndarray) -> np.ndarray: ...
def motor_volts_from_command(command_v: float | np.ndarray) -> float | np.ndarray:
    """Motor volts the software assumes for a DAC command: (cmd − 2.5)·9.6 (appendix A ``u(k)``)."""
    c = finite_values(command_v, "command_v")
    return _same_kind((c - ZERO_COMMAND_V) * AMPLIFIER_GAIN_V_PER_V, command_v)


@overload
def clip_command_v(command_v: float, low: float = ..., high: float = ...) -> float: ...
@overload
def clip_command_v(command_v: np.ndarray, low: float = ..., high: float = ...) -> np.ndarray: ...
def clip_command_v(
    command_v: float | np.ndarray, low: float = COMMAND_LOW_V, high: float = COMMAND_HIGH_V
) -> float | np.ndarray:
    """The software's command limits (appendix A: 1.25…3.75 V; appendix B's first-run limits are 2…3 V)."""
    c = finite_values(command_v, "command_v")
    lo = float(finite_values(low, "low"))
    hi = float(finite_values(high, "high"))
    if not lo < hi:
        raise ValueError(f"low = {lo!r} V must be below high = {hi!r} V")
    return _same_kind(np.clip(c, lo, hi), command_v)
