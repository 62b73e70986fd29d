"""Quanser's Q8-USB data-acquisition card as the rig's I/O board (``quanser_q8_usb``), group ``quanser_q8``.

From Quanser's HIL SDK documentation (docs.quanser.com/hil_sdk/documentation/q8_usb.html): 8 analog inputs,
16-bit, ±10 V (or ±5 V), sampled simultaneously; 8 analog outputs, 16-bit, programmable range; encoder counters
(the SRV02's encoder is read by ``twin.parts.shaft_encoder`` in counts); a hardware timebase up to 1 kHz (8 kHz in
its fast mode). The Q2-USB, the smaller card many BB01 labs use, is commonly quoted as 2 analog inputs and 2
outputs of 12 bits at ±10 V: that is NOT confirmed from a stored data sheet; set ``adc_bits``/``dac_bits`` = 12
for it at your own risk.

What the board reads and writes, in its own unit (volts both ways, as the HIL API's ``hil_read_analog`` and
``hil_write_analog`` give them):

    the ADC   ``q8_quantize_v``: the pin's volts to the nearest of the 2^b codes of the bipolar range ±R
              (two's complement: codes −2^(b−1) … 2^(b−1) − 1, one LSB = 2R/2^b = 0.305 mV at 16 bits and ±10 V),
              clipped at the ends; the rounding to the nearest code is assumed (the documentation gives the
              resolution, not the converter's transfer)
    the DAC   the same quantizer on the command: the volts the amplifier sees (``dac_writer``); the guard holds a
              controller's command within ±R (``output_range``)

The loop's period is the user's (``quanser_q8.loop_period_s``, what the controller runs at on the card's
timebase): the simulated rig ticks at it (``Parameters.period_s``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from twin.converters import finite_input
from twin.interface import CommandRange
from twin.parameters import Parameters, check_group, param, register_group, register_loop_period
from twin.parts.contract import BatchForm, BatchWrite, IoBoardPart, MjcfFragment, register

__all__ = ["QUANSER_Q8_USB", "QuanserQ8", "q8_output_range", "q8_quantize_v"]

_HIL_DOC = "Quanser HIL SDK documentation, Q8-USB (docs.quanser.com/hil_sdk/documentation/q8_usb.html)"
_RANGE_WHY = "the Q8-USB's analog ranges are ±10 V at most (±5 V is its other input range)"


@dataclass(frozen=True)
class QuanserQ8:
    """The Q8-USB's converters (bits, bipolar range) and the control loop's period."""

    adc_bits: int = param(
        16,
        "bit",
        f"{_HIL_DOC}: analog inputs 16-bit",
        ge=8,
        le=24,
        integer=True,
        why="a converter of whole bits: 8 (the coarsest card worth modelling) to 24",
    )
    adc_range_v: float = param(
        10.0, "V", f"{_HIL_DOC}: analog inputs ±10 V (or ±5 V)", gt=0.0, le=10.0, why=_RANGE_WHY
    )
    dac_bits: int = param(
        16,
        "bit",
        f"{_HIL_DOC}: analog outputs 16-bit",
        ge=8,
        le=24,
        integer=True,
        why="a converter of whole bits: 8 (the coarsest card worth modelling) to 24",
    )
    dac_range_v: float = param(
        10.0,
        "V",
        f"{_HIL_DOC}: analog outputs of programmable range, ±10 V as Quanser's SRV02 labs use them (config_servo.m "
        "VMAX_DAC = 10)",
        gt=0.0,
        le=10.0,
        why=_RANGE_WHY,
    )
    loop_period_s: float = param(
        0.02,
        "s",
        "assumed: the controller's period on the card's timebase (the user's; the card's timebase runs up to "
        "1 kHz), 20 ms as the thesis's; the BB01 is slow enough (its ball's poles about 0.5 /s, the servo's 1/τ "
        "45 /s) for a 50 Hz loop, as rig-lqg shows. The simulated rig ticks at it, a whole number of physics "
        "steps",
        ge=1e-3,
        le=1.0,
        why="the card's timebase runs at most 1 kHz (1 ms); a loop slower than 1 s cannot hold an unstable rig",
    )

    def __post_init__(self) -> None:
        check_group(self, "quanser_q8")


register_group("quanser_q8", QuanserQ8)
register_loop_period("quanser_q8_usb", "quanser_q8.loop_period_s")


def q8_quantize_v(
    volts: float | np.ndarray, bits: float | np.ndarray, range_v: float | np.ndarray
) -> float | np.ndarray:
    """The volts a bipolar b-bit converter of range ±R gives for ``volts``: the nearest code
    ⌊V/LSB + ½⌋, LSB = 2R/2^b, clipped to −2^(b−1) … 2^(b−1) − 1, times the LSB. One float in, one float out;
    arrays elementwise, the same bits."""
    v = np.asarray(volts, dtype=float)
    if not np.isfinite(v).all():
        raise ValueError(f"volts = {volts!r}: a converter's input must be finite")
    half = np.exp2(np.asarray(bits, dtype=float) - 1.0)
    lsb = np.asarray(range_v, dtype=float) / half
    codes = np.clip(np.floor(v / lsb + 0.5), -half, half - 1.0)
    out = codes * lsb
    return float(out) if np.ndim(out) == 0 else out


def _adc(params: Parameters) -> Callable[[float], float]:
    g = params.of(QuanserQ8)
    return lambda volts: float(q8_quantize_v(float(volts), g.adc_bits, g.adc_range_v))


def _dac(params: Parameters) -> Callable[[float], float]:
    g = params.of(QuanserQ8)

    return lambda command_v: float(q8_quantize_v(float(command_v), g.dac_bits, g.dac_range_v))


def _columns(params: Sequence[Parameters], bits: str, range_v: str) -> tuple[np.ndarray, np.ndarray]:
    groups = [p.of(QuanserQ8) for p in params]
    return (
        np.array([getattr(g, bits) for g in groups], dtype=float),
        np.array([getattr(g, range_v) for g in groups], dtype=float),
    )


def _batch_adc(params: Sequence[Parameters]) -> BatchWrite:
    """The ADC of N runs (``q8_quantize_v`` on arrays, each run's card): ``_adc``'s bits."""
    bits, ranges = _columns(params, "adc_bits", "adc_range_v")

    def read(runs: np.ndarray, volts: np.ndarray) -> np.ndarray:
        return np.asarray(q8_quantize_v(np.asarray(volts, dtype=float), bits[runs], ranges[runs]))

    return read


def _batch_dac(params: Sequence[Parameters]) -> BatchWrite:
    """The DAC of N runs (``q8_quantize_v`` on the commands, each run's card): ``_dac``'s bits."""
    bits, ranges = _columns(params, "dac_bits", "dac_range_v")

    def write(runs: np.ndarray, command_v: np.ndarray) -> np.ndarray:
        c = finite_input(command_v, "command_v")
        return np.asarray(q8_quantize_v(np.asarray(c, dtype=float), bits[runs], ranges[runs]))

    return write


def q8_output_range(params: Parameters) -> CommandRange:
    """The board's output range (``IoBoardPart.output_range``): the DAC's ±R volts."""
    r = params.of(QuanserQ8).dac_range_v
    return CommandRange(-r, r, "V", "−quanser_q8.dac_range_v … quanser_q8.dac_range_v", "the DAC's range")


def _volts_of(params: Parameters) -> Callable[[float], float]:
    """The card reads volts: its reading is the volts."""
    return float


# --- the batch form: the ADC and the DAC over N cards at once ---------------------------------------------------
def _inputs(rng: np.random.Generator, n: int) -> tuple[list[Parameters], np.ndarray]:
    params = [
        Parameters().with_overrides(
            {
                "quanser_q8.adc_bits": int(a),
                "quanser_q8.dac_bits": int(d),
                "quanser_q8.adc_range_v": float(r),
            },
            origin="batch form",
        )
        for a, d, r in zip(
            rng.choice([12, 16], n).tolist(),
            rng.choice([12, 16], n).tolist(),
            rng.choice([5.0, 10.0], n).tolist(),
            strict=True,
        )
    ]
    return params, rng.uniform(-12.0, 12.0, (n, 2))  # past both ends of both converters


def _single(params: Parameters, row: np.ndarray) -> np.ndarray:
    """One card's per-tick reading and write (``adc``, ``dac_writer``)."""
    return np.array([_adc(params)(float(row[0])), _dac(params)(float(row[1]))])


def _batch(params: Sequence[Parameters], rows: np.ndarray) -> np.ndarray:
    """Every card at once (``batch_adc``, ``batch_dac``)."""
    runs = np.arange(len(rows))
    return np.column_stack([_batch_adc(params)(runs, rows[:, 0]), _batch_dac(params)(runs, rows[:, 1])])


QUANSER_Q8_USB = register(
    IoBoardPart(
        name="quanser_q8_usb",
        source=f"{_HIL_DOC}: 16-bit ±10 V analog inputs and outputs, encoder counters, timebase up to 1 kHz; the "
        "converters' rounding to the nearest code assumed. The Q2-USB's 12-bit figures are unconfirmed",
        groups={"quanser_q8": QuanserQ8},
        equations=(q8_quantize_v, q8_output_range),
        mjcf=MjcfFragment(),
        batch=BatchForm(_single, _batch, _inputs, "twin.parts.quanser_q8.q8_quantize_v"),
        dac_writer=_dac,
        adc=_adc,
        volts_of=_volts_of,
        output_range=q8_output_range,
        batch_dac=_batch_dac,
        batch_adc=_batch_adc,
    )
)
