"""The two TimerFcn callbacks of appendix A, ported line by line: the code that ran on the rig.

``d_cb_state_feedback`` and ``d_cb_control_law`` (file "d_cb_computed_torque.m") in their ``control == 5``
(Drive Motor) branch, with their numbers, conversions, clipping and the signal each feeds its observer:
state feedback feeds back the clipped motor volts (u(k) = (adat − 2.5)·9.6), control-law partitioning the
computed torque T. The ``control == 1``/``4`` branches (Start, Clear Buffer) only set x1(1), x2(1), which is
``start``. These numbers differ from chapters 4–5 in places (e.g. β's 0.17 vs 0.1849, kp 40/38 vs
29.77/37.94, the observer's G = [[4, 8], [−15, 12]] vs the printed [[4, −8], [−15, 12]]); they are kept
exactly as printed because they are what stabilised the real rig.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from twin.converters import (
    ball_position_m,
    beam_angle_rad,
    clip_command_v,
    dac_command_v,
    motor_volts_from_command,
)
from twin.interface import Controller, DaqSample, Telemetry
from twin.parameters import SoftwareCalibration

__all__ = ["AppendixStateFeedback", "AppendixControlLaw"]


class _AppendixCallback(Controller):
    """Shared bookkeeping of the callbacks: tick index k (1 at start) and the MATLAB values at k − 1
    (x1(k−1) … x4(k−1), u(k−1)), the only ones the callbacks read back. The conversions are the software
    calibration's (``params.software``; the defaults are the literals of the MATLAB lines)."""

    def __init__(self, software: SoftwareCalibration | None = None) -> None:
        super().__init__()
        self.software = software or SoftwareCalibration()

    def start(self, sample: DaqSample) -> None:
        # control == 1 / 4: x1(1), x2(1) from the measurements; x3(1) = x4(1) = u(1) = 0 (zeros(...)).
        self.k = 1
        sw = self.software
        x1, x2 = ball_position_m(sample.ball_v, sw), beam_angle_rad(sample.angle_v, sw)
        self.prev = (x1, x2, 0.0, 0.0, 0.0)
        self.telemetry = Telemetry(np.array([x1, x2, 0.0, 0.0]), 0.0, 0.0)

    def _measure(self, sample: DaqSample) -> tuple[float, float]:
        # x1(k) = (0.0693 * x1_temp) + 0.0018; x2(k) = ((143.22657649*(x2_temp - 5.002) + 718.59375)/7)
        # * (3.141592654/180): the converters are these lines, operation for operation.
        self.k += 1
        return ball_position_m(sample.ball_v, self.software), beam_angle_rad(sample.angle_v, self.software)

    def _command(self, value_v: float) -> float:
        # adat = (value/9.6) + 2.5, then clipped to 1.25…3.75 V.
        return clip_command_v(dac_command_v(value_v, self.software), self.software)


def state_feedback_step(prev: tuple[Any, ...], x1_k: Any, x2_k: Any) -> tuple[Any, Any, Any]:
    """``d_cb_state_feedback``'s observer and law, as printed: (x3(k), x4(k), u_temp) from the values at
    k − 1 ``prev`` = (x1, x2, x3, x4, u) and the measured x1(k), x2(k). Floats or arrays over a batch (the
    same operations in the same order give the same bits)."""
    x1, x2, x3, x4, u = prev
    x3_k = 0.9207 * x3 - 0.1601 * x4 - 3.9409 * x1 - 8.0826 * x2 - 0.0055 * u + 4 * x1_k + 8 * x2_k
    x4_k = 0.2927 * x3 + 0.7494 * x4 + 14.257 * x1 - 11.945 * x2 + 0.0717 * u - 15 * x1_k + 12 * x2_k
    u_temp = -1 * (-36.3437 * x1_k + 24.5992 * x2_k - 15.9593 * x3_k + 3.9815 * x4_k)
    return x3_k, x4_k, u_temp


def control_law_step(
    prev: tuple[Any, ...], x1_k: Any, x2_k: Any, sin: Callable, cos: Callable, power: Callable
) -> tuple[Any, Any, Any, Any]:
    """``d_cb_control_law``'s observer, β, F′, torque and voltage, as printed: (x3(k), x4(k), torque,
    v_temp). ``sin``, ``cos`` and ``power`` are ``math.sin``, ``math.cos``, ``pow`` for floats and
    ``np.sin``, ``np.cos``, ``np.float_power`` over a batch: MATLAB's x^2 is libm's pow, which differs
    from x·x in the last bit now and then."""
    x1, x2, x3, x4, u = prev
    # REDUCED ORDER OBSERVER
    x3_k = (
        (u * 0.066)
        + ((x1 * -40.011) + (x2 * 0.1797))
        + ((x3 * 0.2) + (x4 * 0.0036))
        + ((x1_k * 39.9998) + (x2_k * -0.227))
    )
    x4_k = (
        (u * 3.0244)
        + ((x1 * -0.462) + (x2 * -39.563))
        + ((x3 * -0.0036) + (x4 * 0.2))
        + ((x1_k * -0.0452) + (x2_k * 39.608))
    )
    # FIND_BETA
    beta = (
        (-0.0137 * sin(x2_k))
        + (0.17 * x1_k * cos(x2_k))
        + (0.0346 * x1_k * x3_k * x4_k)
        + (-0.000373 * x1_k * power(x4_k, 2))
    )
    # FIND_FPRIME: D = -[-40 0; 0 38]*[x1; x2]; E = -[-23.5604 0; 0 5.1736]*[x3; x4]
    d = (40.0 * x1_k, -38.0 * x2_k)  # negating the literals is exact: same bits as MATLAB
    e = (23.5604 * x3_k, -5.1736 * x4_k)
    b = (d[0] + e[0], d[1] + e[1])
    c = (power(x1_k, 2) * 0.01732) + 0.004
    f_prime = 0.003833 * b[0] + c * b[1]
    # FIND_TORQUE, then voltage
    t = beta + f_prime
    v_temp = ((t * 9.4) / (0.022 * 7)) + (x4_k * 0.022 * 7)
    return x3_k, x4_k, t, v_temp


class AppendixStateFeedback(_AppendixCallback):
    """``d_cb_state_feedback`` (appendix A)."""

    name = "appendix-sf"

    def update(self, sample: DaqSample) -> float:
        x1_k, x2_k = self._measure(sample)
        x3_k, x4_k, u_temp = state_feedback_step(self.prev, x1_k, x2_k)
        adat = self._command(u_temp)
        u_k = motor_volts_from_command(adat, self.software)  # u(k) = (adat-2.5)*9.6
        self.prev = (x1_k, x2_k, x3_k, x4_k, u_k)
        self.telemetry = Telemetry(np.array([x1_k, x2_k, x3_k, x4_k]), u_k, u_temp)
        return adat


class AppendixControlLaw(_AppendixCallback):
    """``d_cb_control_law`` (appendix A, file "d_cb_computed_torque.m")."""

    name = "appendix-clp"

    def update(self, sample: DaqSample) -> float:
        x1_k, x2_k = self._measure(sample)
        x3_k, x4_k, t, v_temp = control_law_step(self.prev, x1_k, x2_k, math.sin, math.cos, pow)
        adat = self._command(v_temp)
        self.prev = (x1_k, x2_k, x3_k, x4_k, t)
        self.telemetry = Telemetry(np.array([x1_k, x2_k, x3_k, x4_k]), t, v_temp)
        return adat
