"""The unit conversions of the rig software (appendix A), in one place for every controller.

Both callbacks of appendix A (``d_cb_control_law`` and ``d_cb_state_feedback``) convert the raw ADC volts
and the computed control value with the same literal numbers. Those numbers are the parameter group
``software`` (``twin.parameters.SoftwareCalibration``): a controller receives them, it does not import them.
With the default values the functions here compute what the MATLAB lines computed, operation for
operation (same constants, same order of floating-point operations).

The inverse conversions (``ball_volts_v``, ``angle_volts_v``) give the volts that the software turns back
into a given position or angle: the ideal sensors of the twin (``twin.sensors.IdealSensors``) use them.

All functions take a float or a numpy array and return the same kind. NaN or infinite input raises
``ValueError`` naming the argument (MATLAB would silently propagate NaN to the motor). A controller calls
them every tick on single readings: a finite Python float is checked and converted inline (the same IEEE
operations as on a 0-d array, without numpy's or a helper's cost per call).
"""

from __future__ import annotations

import math
from typing import overload

import numpy as np

from twin.parameters import SoftwareCalibration

__all__ = [
    "angle_volts_v",
    "ball_position_m",
    "ball_volts_v",
    "beam_angle_deg",
    "beam_angle_rad",
    "clip_command_v",
    "dac_command_v",
    "finite_input",
    "finite_values",
    "motor_volts_from_command",
]


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


def finite_input(value: float | np.ndarray, name: str) -> float | np.ndarray:
    """A finite Python float as it is, anything else through ``finite_values``.

    The conversions run once per tick on single readings: on a Python float they are the same IEEE
    operations as on a 0-d array (same bits) without numpy's cost per call, which dominates there."""
    if type(value) is float and math.isfinite(value):
        return value
    return finite_values(value, name)


def _same_kind(result: float | np.ndarray, value: float | np.ndarray) -> float | np.ndarray:
    """A Python float for scalar input, an array otherwise."""
    if type(result) is float:
        return result
    return float(result) if np.ndim(value) == 0 else result


@overload
def ball_position_m(volts: float, sw: SoftwareCalibration) -> float: ...
@overload
def ball_position_m(volts: np.ndarray, sw: SoftwareCalibration) -> np.ndarray: ...
def ball_position_m(volts: float | np.ndarray, sw: SoftwareCalibration) -> float | np.ndarray:
    """Ball position (m) from the ball channel's volts: 0.0693·V + 0.0018 (eq 6.3.1, appendix A)."""
    v = volts if type(volts) is float and math.isfinite(volts) else finite_values(volts, "volts")
    out = (sw.ball_gain_m_per_v * v) + sw.ball_offset_m
    return out if type(out) is float else _same_kind(out, volts)


@overload
def ball_volts_v(x_m: float, sw: SoftwareCalibration) -> float: ...
@overload
def ball_volts_v(x_m: np.ndarray, sw: SoftwareCalibration) -> np.ndarray: ...
def ball_volts_v(x_m: float | np.ndarray, sw: SoftwareCalibration) -> float | np.ndarray:
    """The ball channel's volts that eq 6.3.1 reads as ``x_m`` (its inverse)."""
    x = finite_input(x_m, "x_m")
    return _same_kind((x - sw.ball_offset_m) / sw.ball_gain_m_per_v, x_m)


def _angle_deg(v: float | np.ndarray, sw: SoftwareCalibration) -> float | np.ndarray:
    # x2_temp_2 = ((143.22657649*(x2_temp - 5.002) + 718.59375) / 7)
    return (
        sw.angle_gain_deg_per_v * (v - sw.angle_reference_v) + sw.angle_reference_motor_deg
    ) / sw.angle_gear_ratio


@overload
def beam_angle_deg(volts: float, sw: SoftwareCalibration) -> float: ...
@overload
def beam_angle_deg(volts: np.ndarray, sw: SoftwareCalibration) -> np.ndarray: ...
def beam_angle_deg(volts: float | np.ndarray, sw: SoftwareCalibration) -> float | np.ndarray:
    """Beam angle in degrees from the angle channel's volts (eq 6.2.10; appendix A's ``x2_temp_2``)."""
    return _same_kind(_angle_deg(finite_input(volts, "volts"), sw), volts)


@overload
def beam_angle_rad(volts: float, sw: SoftwareCalibration) -> float: ...
@overload
def beam_angle_rad(volts: np.ndarray, sw: SoftwareCalibration) -> np.ndarray: ...
def beam_angle_rad(volts: float | np.ndarray, sw: SoftwareCalibration) -> float | np.ndarray:
    """Beam angle (rad) exactly as appendix A computes it: eq 6.2.10 in degrees, times 3.141592654/180."""
    v = volts if type(volts) is float and math.isfinite(volts) else finite_values(volts, "volts")
    out = _angle_deg(v, sw) * (sw.software_pi / 180)
    return out if type(out) is float else _same_kind(out, volts)


@overload
def angle_volts_v(theta_rad: float, sw: SoftwareCalibration) -> float: ...
@overload
def angle_volts_v(theta_rad: np.ndarray, sw: SoftwareCalibration) -> np.ndarray: ...
def angle_volts_v(theta_rad: float | np.ndarray, sw: SoftwareCalibration) -> float | np.ndarray:
    """The angle channel's volts that eq 6.2.10 reads as ``theta_rad`` (its inverse)."""
    th = finite_input(theta_rad, "theta_rad")
    motor_deg = th / (sw.software_pi / 180) * sw.angle_gear_ratio
    return _same_kind(
        (motor_deg - sw.angle_reference_motor_deg) / sw.angle_gain_deg_per_v + sw.angle_reference_v, theta_rad
    )


@overload
def dac_command_v(motor_volts: float, sw: SoftwareCalibration) -> float: ...
@overload
def dac_command_v(motor_volts: np.ndarray, sw: SoftwareCalibration) -> np.ndarray: ...
def dac_command_v(motor_volts: float | np.ndarray, sw: SoftwareCalibration) -> float | np.ndarray:
    """DAC command from desired motor volts: V/9.6 + 2.5 (§6.4; appendix A ``adat``), not clipped."""
    v = (
        motor_volts
        if type(motor_volts) is float and math.isfinite(motor_volts)
        else finite_values(motor_volts, "motor_volts")
    )
    out = (v / sw.command_gain_v_per_v) + sw.command_zero_v
    return out if type(out) is float else _same_kind(out, motor_volts)


@overload
def motor_volts_from_command(command_v: float, sw: SoftwareCalibration) -> float: ...
@overload
def motor_volts_from_command(command_v: np.ndarray, sw: SoftwareCalibration) -> np.ndarray: ...
def motor_volts_from_command(command_v: float | np.ndarray, sw: SoftwareCalibration) -> float | np.ndarray:
    """Motor volts the software assumes for a DAC command: (cmd − 2.5)·9.6 (appendix A ``u(k)``)."""
    c = (
        command_v
        if type(command_v) is float and math.isfinite(command_v)
        else finite_values(command_v, "command_v")
    )
    out = (c - sw.command_zero_v) * sw.command_gain_v_per_v
    return out if type(out) is float else _same_kind(out, command_v)


@overload
def clip_command_v(
    command_v: float, sw: SoftwareCalibration, low: float | None = ..., high: float | None = ...
) -> float: ...
@overload
def clip_command_v(
    command_v: np.ndarray, sw: SoftwareCalibration, low: float | None = ..., high: float | None = ...
) -> np.ndarray: ...
def clip_command_v(
    command_v: float | np.ndarray,
    sw: SoftwareCalibration,
    low: float | None = None,
    high: float | None = None,
) -> float | np.ndarray:
    """The software's command limits (appendix A: 1.25…3.75 V; appendix B's first-run limits are 2…3 V).

    ``low``/``high`` default to the software calibration's ``command_low_v``/``command_high_v``."""
    c = (
        command_v
        if type(command_v) is float and math.isfinite(command_v)
        else finite_values(command_v, "command_v")
    )
    lo = float(sw.command_low_v) if low is None else float(finite_input(low, "low"))
    hi = float(sw.command_high_v) if high is None else float(finite_input(high, "high"))
    if not lo < hi:
        raise ValueError(f"low = {lo!r} V must be below high = {hi!r} V")
    if type(c) is float:  # min/max is np.clip on a finite number
        return min(max(c, lo), hi)
    return _same_kind(np.clip(c, lo, hi), command_v)
