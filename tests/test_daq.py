"""The PCI-1712 as the thesis software used it (Table 6.4, §6.5, appendix A)."""

import math

import numpy as np
import pytest

from twin import daq as D
from twin.parameters import Parameters

P = Parameters()
ADC_LSB = 10.0 / 4096  # 12 bit over −5…+5 V (Table 6.4, §6.5)
DAC_LSB = 5.0 / 4096  # 12 bit over 0…5 V


@pytest.mark.quick
def test_lsb_sizes():
    assert D.adc_lsb_v(P.daq) == ADC_LSB == 0.00244140625
    assert D.dac_lsb_v(P.daq) == DAC_LSB


def _nearest_level(v: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """Independent reference: the closest of all 4096 levels, by brute force."""
    return levels[np.argmin(np.abs(v[:, None] - levels[None, :]), axis=1)]


def test_adc_is_the_nearest_of_4096_levels_and_saturates():
    levels = -5.0 + ADC_LSB * np.arange(4096)
    v = np.random.default_rng(7).uniform(-5.2, 5.2, 3000)
    np.testing.assert_array_equal(D.adc_quantize_v(v, P.daq), _nearest_level(v, levels))
    assert D.adc_quantize_v(0.0, P.daq) == 0.0
    assert D.adc_quantize_v(0.0012, P.daq) == 0.0  # below half a step (1.22 mV)
    assert D.adc_quantize_v(0.0013, P.daq) == ADC_LSB
    assert D.adc_quantize_v(-5.042, P.daq) == -5.0  # saturates at the bottom …
    assert D.adc_quantize_v(5.002, P.daq) == 5.0 - ADC_LSB  # … and at the top code 4095
    assert D.adc_code(-7.0, P.daq) == 0 and D.adc_code(7.0, P.daq) == 4095
    # The float fast path and the array path agree bit for bit.
    assert all(
        D.adc_quantize_v(float(x), P.daq) == y
        for x, y in zip(v[:200], D.adc_quantize_v(v[:200], P.daq), strict=True)
    )


@pytest.mark.quick
def test_dac_is_the_nearest_of_4096_levels_and_clips():
    levels = DAC_LSB * np.arange(4096)
    v = np.random.default_rng(8).uniform(-0.5, 5.5, 3000)
    np.testing.assert_array_equal(D.dac_quantize_v(v, P.daq), _nearest_level(v, levels))
    # The software's commands 1.25 / 2.5 / 3.75 V are exact codes.
    for volts, code in ((1.25, 1024), (2.5, 2048), (3.75, 3072)):
        assert D.dac_code(volts, P.daq) == code
        assert D.dac_quantize_v(volts, P.daq) == volts
    assert D.dac_quantize_v(-1.0, P.daq) == 0.0
    assert D.dac_quantize_v(6.0, P.daq) == 5.0 - DAC_LSB


@pytest.mark.quick
def test_quantizers_refuse_nan():
    with pytest.raises(ValueError, match="nan"):
        D.adc_quantize_v(math.nan, P.daq)
    with pytest.raises(ValueError, match="volts contains inf"):
        D.dac_quantize_v(np.array([1.0, math.inf]), P.daq)


@pytest.mark.quick
def test_block_of_800_samples_ends_at_its_time_stamp():
    times = D.block_sample_times_s(2.0, P.daq)
    assert times.shape == (800,)  # 40 kHz × 20 ms (Table 6.4)
    assert times[0] == pytest.approx(2.0 + 25e-6, abs=1e-15)
    assert times[-1] == pytest.approx(2.02, abs=1e-15)
    np.testing.assert_allclose(np.diff(times), 25e-6, atol=1e-15)
    assert D.block_time_s(2.0, P.daq) == pytest.approx(2.02, abs=1e-15)


@pytest.mark.quick
def test_software_block_reading_is_last_ball_sample_and_mean_angle():
    data = np.column_stack([np.linspace(-1.0, 1.0, 800), np.arange(800.0)])
    ball_v, angle_v = D.software_block_reading_v(data, P.daq)
    assert ball_v == 1.0  # data(blocksize,1)
    assert angle_v == 399.5  # mean(data(:,2))
    with pytest.raises(ValueError, match=r"shape \(799, 2\)"):
        D.software_block_reading_v(data[:-1], P.daq)
