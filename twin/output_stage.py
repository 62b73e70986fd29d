"""The output side of the rig (§6.4): the I/O card's DAC, then the power amplifier, then the motor.

    command (software volts) → DAC: 12 bit, 0…5 V, clipped to the card's range (twin.daq)
                             → amplifier: V_motor = 9.6·(V_dac − 2.5), limited to ±12 V (§6.4)

The software's own command limits (1.25…3.75 V, appendix A; 2…3 V on a first run, appendix B) are the
controller's business (``twin.converters.clip_command_v``) and are not applied here: a controller that
forgets them still cannot drive the motor beyond the amplifier's ±12 V.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from twin.converters import finite_input, finite_values
from twin.daq import dac_quantize_v, dac_quantizer
from twin.interface import CommandRange
from twin.parameters import Amplifier, Parameters

__all__ = [
    "CommandClampedWarning",
    "amplifier_of",
    "amplifier_volts",
    "clamped_command_text",
    "motor_volts",
    "motor_volts_of",
]


class CommandClampedWarning(RuntimeWarning):
    """A command written to the DAC outside its range: the card outputs the nearest end of the range."""


def clamped_command_text(command: float, limits: CommandRange, tick: int, time_s: float) -> str:
    """Why a command outside the board's output range is worth a warning: the board clamps it, so the actuator
    gets the end of its range (the DC motor its amplifier's rail) whatever the command asked for, silently."""
    end = limits.high if command > limits.high else limits.low
    return (
        f"command_v = {command!r} {limits.unit} written at tick k = {tick} (t = {time_s:.3f} s) is outside "
        f"{limits.text()}: the board outputs {end!r} {limits.unit} (the actuator at the end of its range); "
        "warned once per run, the clamped commands are counted (clamped_commands)"
    )


def amplifier_volts(
    dac_output_v: float | np.ndarray, amplifier: Amplifier, gain_v_per_v: np.ndarray | None = None
) -> float | np.ndarray:
    """Motor volts for the DAC's actual output: 9.6·(V − 2.5) clipped to ±12 V (§6.4). ``gain_v_per_v``:
    each run's gain in place of ``amplifier``'s, for a batch of runs (element by element, the same bits)."""
    if type(dac_output_v) is float and math.isfinite(dac_output_v):  # one command per tick: no numpy
        v: float | np.ndarray = dac_output_v
    else:
        v = finite_values(dac_output_v, "dac_output_v")
    gain = amplifier.gain_v_per_v if gain_v_per_v is None else gain_v_per_v
    volts = gain * (v - amplifier.zero_command_v)
    if type(volts) is float:  # min/max is np.clip on a finite number, same bits
        return min(max(volts, -amplifier.rail_v), amplifier.rail_v)
    out = np.clip(volts, -amplifier.rail_v, amplifier.rail_v)
    return float(out) if np.ndim(dac_output_v) == 0 else out


def motor_volts(
    command_v: float | np.ndarray, params: Parameters, gain_v_per_v: np.ndarray | None = None
) -> float | np.ndarray:
    """Motor volts for a command written to the DAC: DAC quantization and range, then the amplifier
    (``gain_v_per_v``: as ``amplifier_volts``).

    NaN or infinite commands raise ValueError naming the value (the card cannot output them)."""
    c = finite_input(command_v, "command_v")
    out = amplifier_volts(dac_quantize_v(c, params.daq), params.amplifier, gain_v_per_v)
    if type(out) is float:
        return out
    return float(out) if np.ndim(command_v) == 0 else out


def ideal_motor_volts(
    command_v: float | np.ndarray, params: Parameters, gain_v_per_v: np.ndarray | None = None
) -> float | np.ndarray:
    """Motor volts for an exact DAC (the ideal converters): the card's range, no quantization, then the
    amplifier (``gain_v_per_v``: as ``amplifier_volts``); a float for a number, an array for an array (the
    batch)."""
    daq = params.daq
    if isinstance(command_v, (int, float)):
        return float(
            amplifier_volts(float(min(max(command_v, daq.dac_min_v), daq.dac_max_v)), params.amplifier)
        )
    clipped = np.clip(command_v, daq.dac_min_v, daq.dac_max_v)
    return np.asarray(amplifier_volts(clipped, params.amplifier, gain_v_per_v))


def amplifier_of(params: Parameters) -> Callable[[float], float]:
    """``amplifier_volts`` of one finite Python float with the amplifier bound once: the motor volts for the
    DAC's output (the actuator's half of the rig's per-tick write, ``twin.parts``)."""
    amplifier = params.amplifier
    return lambda dac_output_v: float(amplifier_volts(dac_output_v, amplifier))


def motor_volts_of(params: Parameters) -> Callable[[float], float]:
    """``motor_volts`` of one finite Python float with the DAC's constants bound once (the rig's per-tick
    write): the same two steps (``tests/test_output_stage.py`` checks it against ``motor_volts``)."""
    dac, amplifier = dac_quantizer(params.daq), amplifier_of(params)
    return lambda command_v: amplifier(dac(command_v))
