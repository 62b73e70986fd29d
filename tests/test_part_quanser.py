"""Quanser's parts: the Q8-USB card (``twin.parts.quanser_q8``: 16-bit ±10 V converters) and the BB01's strip
(``twin.parts.bb01_strip``: V = x/K_BS over ±5 V, K_BS = −L/10 m/V), their readings worked by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

import twin.parts  # noqa: F401  (registers the parts)
from twin.parameters import ParameterError, Parameters
from twin.parts import rig_parts
from twin.parts.bb01_strip import Bb01StripBatch, Bb01StripChain, strip_volts
from twin.parts.description import preset
from twin.parts.quanser_q8 import q8_quantize_v

BB01 = preset("quanser-bb01")
QUIET = BB01.with_overrides({"ball_sensor.noise_enabled": False})
LSB_V = 20.0 / 65536  # ±10 V over 2^16 codes: 0.30518 mV
K_BS = -0.42545 / 10  # config_bb.m: −L/10 m/V


@pytest.mark.quick
@pytest.mark.parametrize(
    ("volts", "reading"),
    [
        (1.0, 3277 * LSB_V),  # 1/LSB = 3276.8 codes → 3277
        (-2.35045, -7702 * LSB_V),  # −7701.95 → −7702
        (10.0, 32767 * LSB_V),  # the top code, 9.99969 V
        (-12.0, -10.0),  # clipped to the bottom code, −32768·LSB
    ],
)
def test_the_q8s_converters_round_to_the_nearest_16_bit_code(volts: float, reading: float) -> None:
    board = rig_parts(BB01).io_board
    assert board.adc(BB01)(volts) == pytest.approx(reading, abs=1e-12)
    assert board.dac_writer(BB01)(volts) == pytest.approx(reading, abs=1e-12)
    assert q8_quantize_v(np.array([volts]), 16, 10.0)[0] == pytest.approx(reading, abs=1e-12)


@pytest.mark.quick
def test_the_q8s_output_range_is_its_dacs_and_a_12_bit_card_is_coarser() -> None:
    limits = rig_parts(BB01).io_board.output_range(BB01)
    assert (limits.low, limits.high, limits.unit) == (-10.0, 10.0, "V")
    coarse = BB01.with_overrides({"quanser_q8.adc_bits": 12})
    assert rig_parts(coarse).io_board.adc(coarse)(1.0) == pytest.approx(205 * 20.0 / 4096)  # 204.8 → 205
    with pytest.raises(ParameterError, match="quanser_q8.dac_range_v"):
        BB01.with_overrides({"quanser_q8.dac_range_v": 24.0})


@pytest.mark.quick
@pytest.mark.parametrize(
    ("x_m", "volts"),
    [
        (0.0, 0.0),  # the beam's middle: the strip's midpoint
        (0.1, -2.350452462),  # 0.1/(−0.042545): V falls as x rises
        (-0.2, 4.700904924),  # the −x end of the ball's travel
        (0.25, -5.0),  # past the strip's end: its −5 V end
    ],
)
def test_the_strips_volts_fall_as_the_ball_rolls_toward_plus_x(x_m: float, volts: float) -> None:
    assert strip_volts(x_m, K_BS, 0.0, 5.0) == pytest.approx(volts, abs=1e-9)
    chain = Bb01StripChain(QUIET, 0, x_m=0.0)
    t = np.array([0.0, 0.01, 0.02])
    reading = chain.advance(t, np.array([0.0, x_m / 2, x_m]))
    assert chain.filtered_v == pytest.approx(volts, abs=1e-9)
    assert reading == pytest.approx(math.floor(volts / LSB_V + 0.5) * LSB_V, abs=1e-12)  # the Q8's ADC
    position_of = rig_parts(QUIET).ball_sensor.position_of
    assert position_of is not None
    # the lab's x = K_BS·V recovers x to the ADC's step (0.3 mV: 13 µm), not past the strip's ends
    if abs(volts) < 5.0:
        assert position_of(QUIET)(reading) == pytest.approx(x_m, abs=abs(K_BS) * LSB_V)


@pytest.mark.quick
def test_the_strips_noise_is_seeded_and_of_its_stated_size() -> None:
    t = np.array([0.0, 0.02])
    x = np.array([0.05, 0.05])

    def readings(seed: int) -> np.ndarray:
        chain = Bb01StripChain(BB01, seed, x_m=0.05)
        out = []
        for k in range(2000):
            out.append(chain.advance(t + 0.02 * k, x))
        return np.array(out)

    a, b = readings(7), readings(7)
    assert np.array_equal(a, b)  # the same seed, the same bits
    assert not np.array_equal(a, readings(8))
    # 5 mV standard deviation (assumed), around 0.05/K_BS = −1.1752 V
    assert np.std(a) == pytest.approx(0.005, rel=0.05)
    assert np.mean(a) == pytest.approx(0.05 / K_BS, abs=5e-4)


@pytest.mark.quick
def test_the_strips_batch_is_each_runs_chain_bit_for_bit() -> None:
    rigs = [BB01, BB01.with_overrides({"bb01_strip.offset_v": 0.2, "bb01_strip.noise_v": 0.01})]
    seeds = np.array([3, 4])
    batch = Bb01StripBatch(rigs, seeds, np.array([0.0, 0.1]), 0.0)
    chains = [
        Bb01StripChain(p, int(s), x_m=x0) for p, s, x0 in zip(rigs, seeds.tolist(), (0.0, 0.1), strict=True)
    ]
    t = np.linspace(0.0, 0.02, 21)
    for k in range(5):
        x = np.array([0.01 * k * np.ones(21), 0.1 - 0.02 * k * np.ones(21)])
        got = batch.advance(np.arange(2), t + 0.02 * k, x, np.ones((2, 21), dtype=bool))
        one = [c.advance(t + 0.02 * k, x[i]) for i, c in enumerate(chains)]
        assert got.tolist() == one


@pytest.mark.quick
def test_a_zero_gain_is_refused_naming_the_field() -> None:
    with pytest.raises(ParameterError, match="bb01_strip.gain_m_per_v"):
        Parameters().with_overrides({"bb01_strip.gain_m_per_v": 0.0})
