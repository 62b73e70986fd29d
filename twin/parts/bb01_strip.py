"""Quanser BB01's ball sensor (``bb01_strip``), group ``bb01_strip``: "a steel rod in parallel with a
nickel-chromium wire-wound resistor forming the track"; the ball is the wiper, and the voltage is read at the rod
(BB01 User Manual, Quanser Doc. No. 709 Rev 2.1, §2.2.1). The strip is fed ±5 V at its ends, so the rod's voltage
is linear in the ball's position and FALLS as x rises: Quanser's calibration K_BS = −L/10 m/V (``config_bb.m``:
±5 V over the beam's L = 0.42545 m).

    V = V₀ + x/K_BS, clipped to ±V_s     ``strip_volts``: x (m) from the track's centre (the beam's middle, +x
                                         toward the lifted end), V₀ an offset (0: the lab's software assumes
                                         none), V_s the strip's ±5 V ends

The board reads V at each block's end through its ADC (``IoBoardPart.adc``: the Q8-USB's 16-bit ±10 V), with the
wiper's contact noise added: one Gaussian draw of ``noise_v`` per reading from the run's seeded generator
(``ball_sensor.noise_enabled`` off: the draw is made and dropped, as the other ball sensors do). A ball off the
track (lost) reads where the plant last had it, clipped to the strip's ends. ``filtered_v`` is the noiseless rod
voltage now (no filter on the BB01's signal).

The software's conversion (``position_of``) is the lab's x = K_BS·V (config_bb.m), from the board's volts.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from twin.parameters import ParameterError, Parameters, check_group, param, register_group
from twin.parts.contract import (
    BallSensorPart,
    BatchForm,
    MjcfFragment,
    board_batch_adc,
    board_volts_of,
    register,
)
from twin.parts.ranging import SampledChain, form_batch, form_inputs, form_single, make_rng

__all__ = ["BB01_STRIP", "Bb01Strip", "Bb01StripBatch", "Bb01StripChain", "strip_position_of", "strip_volts"]

_CONTINUITY_S = 1e-9  # a block's first time and the chain's may differ by the clock's rounding


@dataclass(frozen=True)
class Bb01Strip:
    """The strip's calibration (K_BS, offset), its supply and its contact noise."""

    gain_m_per_v: float = param(
        -0.042545,
        "m/V",
        "Quanser config_bb.m K_BS = −L/10 = −0.042545 m/V (±5 V over L = 0.42545 m; x rising, V falling)",
        ge=-1.0,
        le=1.0,
        why="a strip on a bench beam under 2 m long fed at most ±10 V: |K| ≤ 1 m/V (0 is refused: no reading)",
    )
    offset_v: float = param(
        0.0,
        "V",
        "assumed: the rod at 0 V with the ball at the beam's middle, as the lab's x = K_BS·V takes it; fit from a "
        "log",
        ge=-5.0,
        le=5.0,
        why="an offset within the strip's ±5 V",
    )
    supply_v: float = param(
        5.0,
        "V",
        "Quanser config_bb.m: the sensor spans ±5 V over the beam (K_BS = −L/10 m/V)",
        gt=0.0,
        le=10.0,
        why="a strip read by a ±10 V card",
    )
    noise_v: float = param(
        0.005,
        "V",
        "assumed: 5 mV standard deviation of the wiper's contact noise on each reading (0.2 mm of x); fit from "
        "a log",
        ge=0.0,
        le=1.0,
        why="1 V of noise is 43 mm of ball, a fifth of the beam: a broken contact, not noise",
    )

    def __post_init__(self) -> None:
        check_group(self, "bb01_strip")
        if self.gain_m_per_v == 0.0:
            raise ParameterError(
                "bb01_strip.gain_m_per_v = 0.0 m/V is impossible: the strip would read nothing"
            )


register_group("bb01_strip", Bb01Strip)


def strip_volts(
    x_m: float | np.ndarray,
    gain_m_per_v: float | np.ndarray,
    offset_v: float | np.ndarray,
    supply_v: float | np.ndarray,
) -> float | np.ndarray:
    """The rod's volts with the ball at x: V₀ + x/K_BS clipped to ±V_s (module docstring). One float in, one
    float out; arrays elementwise, the same bits."""
    volts = np.clip(
        np.asarray(offset_v, dtype=float) + np.asarray(x_m, dtype=float) / gain_m_per_v,
        -np.asarray(supply_v, dtype=float),
        supply_v,
    )
    return float(volts) if np.ndim(volts) == 0 else volts


class Bb01StripBatch:
    """N runs' strips in step (``twin.parts.contract.BallSensorBatch``), each run its own parameters and seeded
    generator; ``readings`` the board's last reading of each, ``output`` the rod's noiseless volts."""

    def __init__(
        self,
        params: Sequence[Parameters],
        seeds: np.ndarray | Sequence[int | np.random.Generator | None],
        x0_m: np.ndarray,
        t0_s: float,
    ) -> None:
        x0 = np.asarray(x0_m, dtype=float)
        self.rngs = [make_rng(s) for s in (seeds.tolist() if isinstance(seeds, np.ndarray) else seeds)]
        if not len(params) == len(self.rngs) == len(x0):
            raise ValueError(f"{len(x0)} runs need {len(x0)} parameter sets and seeds")
        self.use_params(params)
        self.time_s = float(t0_s)
        runs = np.arange(len(x0))
        self.output = np.asarray(strip_volts(x0, self.gain, self.offset, self.supply), dtype=float)
        self.readings = np.asarray(self.adc(runs, self.output), dtype=float)  # at rest: the noiseless rod
        self.disturbed = np.zeros(len(x0), dtype=np.int64)  # the strip loses no readings

    def set_params(self, params: Sequence[Parameters]) -> None:
        """New parameters from now on; the generators run on."""
        self.use_params(params)

    def use_params(self, params: Sequence[Parameters]) -> None:
        strips = [p.of(Bb01Strip) for p in params]
        self.gain = np.array([s.gain_m_per_v for s in strips])
        self.offset = np.array([s.offset_v for s in strips])
        self.supply = np.array([s.supply_v for s in strips])
        self.noise = np.array([s.noise_v for s in strips])
        self.noisy = np.array([p.ball_sensor.noise_enabled for p in params])
        self.adc = board_batch_adc(params)

    def advance(
        self, runs: np.ndarray, times_s: np.ndarray, x_m: np.ndarray, on_track: np.ndarray
    ) -> np.ndarray:
        """The board's readings of the runs ``runs`` at the block's end: the rod's volts for x there, one noise
        draw each (each run's generator, in order), clipped to the strip's ends, through the board's ADC."""
        x = np.asarray(x_m, dtype=float)[:, -1]
        level = np.asarray(strip_volts(x, self.gain[runs], self.offset[runs], self.supply[runs]), dtype=float)
        z = np.array([self.rngs[i].standard_normal() for i in runs.tolist()])
        noise = np.where(self.noisy[runs], self.noise[runs] * z, 0.0)
        pin = np.clip(level + noise, -self.supply[runs], self.supply[runs])
        self.output[runs] = level
        self.readings[runs] = np.asarray(self.adc(runs, pin), dtype=float)
        self.time_s = float(np.asarray(times_s)[-1])
        return self.readings[runs].copy()


class Bb01StripChain(SampledChain):
    """One run of the strip (``twin.parts.contract.BallSensorChain``): the batch of one run."""

    def __init__(
        self, params: Parameters, seed: int | np.random.Generator | None, *, x_m: float = 0.0
    ) -> None:
        super().__init__(params, seed, _one_run, x_m=x_m)


def _one_run(
    params: Parameters, rng: np.random.Generator, x_m: float, t_s: float, present: bool
) -> Bb01StripBatch:
    """The batch of one run (the strip reads the ball where it is, on the track or not)."""
    return Bb01StripBatch([params], [rng], np.array([x_m]), t_s)


def _chain(params: Parameters, seed: int) -> Bb01StripChain:
    return Bb01StripChain(params, seed)


def strip_position_of(params: Parameters) -> Callable[[float], float]:
    """The lab software's conversion: the board's reading → volts → x = K_BS·V (config_bb.m); every finite volt is
    a position on the strip (NaN only for a reading that is not a number)."""
    gain = params.of(Bb01Strip).gain_m_per_v
    volts_of = board_volts_of(params)
    return lambda reading: gain * volts_of(reading) if math.isfinite(reading) else math.nan


# --- the batch form: a ball rolling through blocks of the rig, N runs at once ---------------------------------
_Q8 = Parameters().with_overrides({"parts.io_board": "quanser_q8_usb", "bb01_strip.noise_v": 0.05})


BB01_STRIP = register(
    BallSensorPart(
        name="bb01_strip",
        source="BB01 User Manual (Quanser Doc. No. 709 Rev 2.1) §2.2.1: the ball as the wiper of a wire-wound "
        "strip beside the steel rod; Quanser config_bb.m K_BS = −L/10 m/V over ±5 V; noise assumed (fit from a "
        "log)",
        groups={"bb01_strip": Bb01Strip},
        equations=(strip_volts, strip_position_of, Bb01StripBatch),
        mjcf=MjcfFragment(),
        batch=BatchForm(
            form_single(_chain),
            form_batch(Bb01StripBatch),
            form_inputs(_Q8, ("bb01_strip.gain_m_per_v", "bb01_strip.noise_v", "bb01_strip.offset_v")),
            "twin.parts.bb01_strip.Bb01StripBatch",
        ),
        chain=_chain,
        batch_chain=Bb01StripBatch,
        position_of=strip_position_of,
    )
)
