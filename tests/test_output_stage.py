"""DAC → power amplifier → motor volts (§6.4, Table 6.4)."""

import math

import numpy as np
import pytest

from twin.output_stage import amplifier_volts, motor_volts, motor_volts_of
from twin.parameters import Parameters
from twin.rigs import measurements

P = Parameters()
DAC_LSB = 5.0 / 4096
# A command off the DAC grid moves by at most half a DAC step, ×9.6 at the motor: 5.86 mV.
DAC_TOLERANCE_V = 9.6 * DAC_LSB / 2


@pytest.mark.quick
def test_full_scale_commands_of_section_6_4_and_the_rails():
    volts = measurements.output_stage(P)
    # 1.25 / 2.5 / 3.75 V → −12 / 0 / +12 V (§6.4). These commands are exact DAC codes, so exact volts.
    # Beyond the software's limits the amplifier sits at its ±12 V rails (0 V, 5 V: the card's ends).
    assert volts == {0.0: -12.0, 1.25: -12.0, 2.5: 0.0, 3.75: 12.0, 5.0: 12.0}


@pytest.mark.quick
def test_amplifier_rails_clip_beyond_the_card():
    assert motor_volts(-3.0, P) == -12.0  # below the card's range: the DAC clips to 0 V first
    np.testing.assert_array_equal(motor_volts(np.array([1.0, 4.0]), P), [-12.0, 12.0])


def test_dac_quantization_shows_between_codes():
    commands = np.random.default_rng(3).uniform(1.3, 3.7, 500)
    ideal = 9.6 * (commands - 2.5)
    got = motor_volts(commands, P)
    err = np.abs(got - ideal)
    assert err.max() <= DAC_TOLERANCE_V + 1e-12
    # The quantization is really there: the error of a command uniform between codes is uniform on
    # [0, DAC_TOLERANCE_V], so the largest of 500 falls below 0.98 of it with probability 0.98^500 = 4e-5
    # (measured: 0.996).
    assert err.max() > 0.98 * DAC_TOLERANCE_V
    assert motor_volts(2.6, P) == 9.6 * (2130 * DAC_LSB - 2.5)  # code round(2.6/LSB) = 2130 (2129.92)


@pytest.mark.quick
def test_amplifier_alone():
    assert amplifier_volts(3.0, P.amplifier) == pytest.approx(4.8, abs=1e-12)
    assert amplifier_volts(4.9, P.amplifier) == 12.0


@pytest.mark.quick
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_command_raises_naming_it(bad):
    with pytest.raises(ValueError, match=f"command_v contains {bad!r}"):
        motor_volts(bad, P)


@pytest.mark.quick
def test_the_bound_per_tick_form_equals_motor_volts():
    """The rig's per-tick form gives motor_volts' bits for every command, in range and beyond both rails,
    with other amplifier and card constants too, and refuses what motor_volts refuses."""
    rng = np.random.default_rng(7)
    commands = np.concatenate([rng.uniform(-1.0, 6.0, 20000), [0.0, 1.25, 2.5, 3.75, 5.0, -0.0]])
    for params in (P, P.with_overrides({"amplifier.gain_v_per_v": 7.3, "daq.dac_bits": 10})):
        bound = motor_volts_of(params)
        assert all(bound(c) == motor_volts(c, params) for c in commands.tolist())
        with pytest.raises(ValueError, match="finite"):
            bound(math.nan)
