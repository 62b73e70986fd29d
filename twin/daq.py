"""The Advantech PCI-1712 I/O card as the thesis software used it (Table 6.4, §6.5, appendix A).

Quantization convention (both converters, straight binary, mid-tread, round half up):

    LSB     = (V_max − V_min) / 2**bits
    code    = clip(floor((V − V_min)/LSB + 0.5), 0, 2**bits − 1)
    reading = V_min + code·LSB

so the ADC (12 bit, −5…+5 V) reads −5 V … +4.99756 V in steps of 2.441 mV and saturates at both ends, and
the DAC (12 bit, 0…5 V) outputs 0 … 4.99878 V in steps of 1.221 mV. Code 2**bits − 1 is the top of the range
because a 12-bit code cannot represent V_max itself (the card's convention). The software's command values
1.25, 2.5 and 3.75 V are exact DAC codes (1024, 2048, 3072).

Block semantics (appendix A, ``TimerFcn`` every 20 ms): the card samples both input channels at 40 kHz;
each tick the software takes the next 800-sample block, uses the LAST sample of the ball channel
(``data(blocksize,1)``) and the MEAN of the angle channel (``mean(data(:,2))``), and logs the time of the
block's last sample (``time(blocksize)``). Block k covers (t0, t0 + T]; its samples are taken at
t0 + (i + 1)/f_s, i = 0 … 799: the first sample one sample period after the block starts and the last at
the block's end, so the time stamp of a block is exactly its end and the next block starts there.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from twin.converters import finite_input, finite_values
from twin.parameters import Daq

__all__ = [
    "ANGLE_CHANNEL",
    "BALL_CHANNEL",
    "BlockPlan",
    "TickSchedule",
    "adc_code",
    "adc_lsb_v",
    "adc_quantize_v",
    "adc_quantizer",
    "block_sample_times_s",
    "block_span_s",
    "block_time_s",
    "dac_code",
    "dac_lsb_v",
    "dac_quantize_v",
    "dac_quantizer",
    "software_block_reading_v",
]

# Channel order of a block, appendix A: addchannel(AI, 1:2); data(:,1) is the ball, data(:,2) the angle.
BALL_CHANNEL = 0
ANGLE_CHANNEL = 1


def adc_lsb_v(daq: Daq) -> float:
    """One ADC step: 10 V / 4096 = 2.441 mV with the thesis's settings."""
    return (daq.adc_max_v - daq.adc_min_v) / 2 ** int(daq.adc_bits)


def dac_lsb_v(daq: Daq) -> float:
    """One DAC step: 5 V / 4096 = 1.221 mV with the thesis's settings."""
    return (daq.dac_max_v - daq.dac_min_v) / 2 ** int(daq.dac_bits)


def _code(v: np.ndarray, v_min: float, lsb: float, bits: float) -> np.ndarray:
    return np.clip(np.floor((v - v_min) / lsb + 0.5), 0, 2 ** int(bits) - 1)


def _quantize_float(v_min: float, lsb: float, top: int, volts: float) -> float:
    """``_quantize`` of one Python float with ``top`` = 2**bits − 1: the same IEEE operations as numpy's path."""
    if not math.isfinite(volts):
        raise ValueError(f"volts = {volts!r}: it must be finite")
    return v_min + min(max(math.floor((volts - v_min) / lsb + 0.5), 0), top) * lsb


def _quantize(volts: float | np.ndarray, v_min: float, lsb: float, bits: float) -> float | np.ndarray:
    """v_min + code·LSB; a plain float takes a math-only path (same IEEE operations, 10x faster)."""
    if type(volts) is float:
        return _quantize_float(v_min, lsb, 2 ** int(bits) - 1, volts)
    v = finite_values(volts, "volts")
    out = v_min + _code(v, v_min, lsb, bits) * lsb
    return float(out) if np.ndim(volts) == 0 else out


def adc_code(volts: float | np.ndarray, daq: Daq) -> int | np.ndarray:
    """ADC output code(s) 0 … 4095 for input volts (saturating)."""
    v = finite_values(volts, "volts")
    code = _code(v, daq.adc_min_v, adc_lsb_v(daq), daq.adc_bits).astype(np.int64)
    return int(code) if np.ndim(volts) == 0 else code


def adc_quantize_v(volts: float | np.ndarray, daq: Daq) -> float | np.ndarray:
    """The volts the software reads for an analog input (12 bit over −5…+5 V, saturating)."""
    return _quantize(volts, daq.adc_min_v, adc_lsb_v(daq), daq.adc_bits)


def adc_quantizer(daq: Daq) -> Callable[[float], float]:
    """``adc_quantize_v`` of one Python float with the card's constants bound once (a per-tick reading)."""
    return functools.partial(_quantize_float, daq.adc_min_v, adc_lsb_v(daq), 2 ** int(daq.adc_bits) - 1)


def dac_quantizer(daq: Daq) -> Callable[[float], float]:
    """``dac_quantize_v`` of one Python float with the card's constants bound once (a per-tick command)."""
    return functools.partial(_quantize_float, daq.dac_min_v, dac_lsb_v(daq), 2 ** int(daq.dac_bits) - 1)


def dac_code(volts: float | np.ndarray, daq: Daq) -> int | np.ndarray:
    """DAC code(s) 0 … 4095 for commanded volts (clipped to the card's range)."""
    v = finite_values(volts, "volts")
    code = _code(v, daq.dac_min_v, dac_lsb_v(daq), daq.dac_bits).astype(np.int64)
    return int(code) if np.ndim(volts) == 0 else code


def dac_quantize_v(volts: float | np.ndarray, daq: Daq) -> float | np.ndarray:
    """The volts the card outputs for a commanded value (12 bit over 0…5 V, clipped to the range)."""
    return _quantize(volts, daq.dac_min_v, dac_lsb_v(daq), daq.dac_bits)


def block_sample_times_s(block_start_s: float, daq: Daq) -> np.ndarray:
    """The 800 sample times of the block covering (t0, t0 + T]: t0 + (i + 1)/f_s, i = 0 … 799."""
    t0 = float(finite_values(block_start_s, "block_start_s"))
    return t0 + np.arange(1, daq.block_size + 1) / daq.sample_rate_hz


def block_span_s(daq: Daq) -> float:
    """From a block's start to its last sample: 800/f_s."""
    return daq.block_size / daq.sample_rate_hz


def block_time_s(block_start_s: float, daq: Daq) -> float:
    """Time stamp of the block (appendix A ``time(blocksize)``): its last sample, t0 + 800/f_s."""
    t0 = float(finite_input(block_start_s, "block_start_s"))
    return t0 + block_span_s(daq)


def software_block_reading_v(data_v: np.ndarray, daq: Daq) -> tuple[float, float]:
    """(ball volts, angle volts) as appendix A reduces a block: ``data(blocksize,1)``, ``mean(data(:,2))``.

    ``data_v`` is the block as ``getdata`` returns it: shape (800, 2), column 0 the ball channel, column 1
    the angle channel (already ADC-quantized)."""
    data = finite_values(data_v, "data_v")
    if data.shape != (daq.block_size, 2):
        raise ValueError(
            f"data_v has shape {data.shape}: a block is ({daq.block_size}, 2) (samples, channels)"
        )
    return float(data[-1, BALL_CHANNEL]), float(np.mean(data[:, ANGLE_CHANNEL]))


@dataclass(frozen=True)
class BlockPlan:
    """One block's physics, in this order: ``free_steps`` unobserved steps (the rig released before the
    block begins), the held rig from ``start_step`` to ``held_end_step`` (a block that begins before release),
    then ``observed_steps`` physics steps up to the block's end. Steps count from release (t = 0)."""

    start_step: int
    end_step: int
    free_steps: int
    held_end_step: int | None
    observed_steps: int


class TickSchedule:
    """When the DAQ's blocks end and when a command reaches the motor, in physics steps from release: the one
    home of the start timing (held rig, free run, release) and the output latency, which the single rig
    (``twin.rigs.sim.SimRig``) and the batch (``twin.rigs.batch``) both follow.

    After ``reset`` the rig is held; block k = −1 (the one ``Controller.start`` reads) ends at
    free_run − T, block k at free_run + k·T; the rig is released at step 0. A command written takes effect
    ``latency_steps`` physics steps later (at once without latency); the latency runs on while the rig is
    held."""

    def __init__(self, steps_per_tick: int, latency_steps: int, free_run_steps: int) -> None:
        self.steps_per_tick = steps_per_tick
        self.latency_steps = latency_steps
        self.free_run_steps = free_run_steps
        self.reset()

    def reset(self) -> None:
        # The next block (the one Controller.start reads) ends one period before the first command.
        self.next_end_step = self.free_run_steps - self.steps_per_tick
        # The ball chain starts at the start block's beginning, or at release if the rig runs free before it
        # (a free run longer than one period).
        self.chain_start_step = min(self.next_end_step - self.steps_per_tick, 0)
        self.steps_done = 0  # physics steps since release
        self.switch_in_steps: int | None = None  # steps until the pending command takes effect

    @property
    def next_start_step(self) -> int:
        return self.next_end_step - self.steps_per_tick

    @property
    def held(self) -> bool:
        """Whether the rig is still held (the blocks read so far end before release)."""
        return self.next_end_step - self.steps_per_tick < 0

    def next_is_plain(self) -> bool:
        """Whether the next block is one control period from where the physics stands, after release, with no
        command on its way (the common tick: ``plain_block`` then, not ``next_block``)."""
        return (
            self.next_end_step - self.steps_per_tick == self.steps_done >= 0 and self.switch_in_steps is None
        )

    def next_is_observed(self) -> bool:
        """Whether the next block is one control period of physics from where it stands, after release (a
        command may switch within it): ``next_block`` then plans no free run and no held part."""
        return self.next_end_step - self.steps_per_tick == self.steps_done >= 0

    def plain_block(self) -> None:
        """Move past a plain block (see ``next_is_plain``)."""
        self.steps_done = self.next_end_step
        self.next_end_step += self.steps_per_tick

    def next_block(self) -> BlockPlan:
        """The next block's plan; the schedule moves past it (the latency's countdown over a held stretch
        included: run the plan's free and observed steps with ``switch_at``)."""
        end = self.next_end_step
        start = end - self.steps_per_tick
        free = start - self.steps_done if start > self.steps_done else 0
        held_end = min(end, 0) if start < 0 else None
        if held_end is not None and self.switch_in_steps is not None:  # the latency runs on while held
            self.switch_in_steps = max(0, self.switch_in_steps - (held_end - start))
        observed = end - max(start, 0) if end > 0 else 0
        self.steps_done = max(self.steps_done, start) + observed
        self.next_end_step = end + self.steps_per_tick
        return BlockPlan(start, end, free, held_end, observed)

    def command_written(self) -> bool:
        """A command was written: whether it acts at once (no latency; else after ``latency_steps``)."""
        if self.latency_steps == 0:
            self.switch_in_steps = None
            return True
        self.switch_in_steps = self.latency_steps
        return False

    def switch_at(self, n: int) -> int | None:
        """For the next ``n`` physics steps: the step (0 … n − 1) from which the pending command acts, or
        None (no command pending, or it acts later)."""
        k = self.switch_in_steps
        if k is None:
            return None
        if k < n:
            self.switch_in_steps = None
            return k
        self.switch_in_steps = k - n
        return None
