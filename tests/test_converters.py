"""The rig software's conversions (appendix A, eq 6.3.1, eq 6.2.10, §6.4)."""

import math

import numpy as np
import pytest

from twin import converters as C
from twin.parameters import SoftwareCalibration

SW = SoftwareCalibration()


@pytest.mark.quick
def test_ball_position_is_eq_6_3_1():
    # 0.0693·V + 0.0018 (eq 6.3.1): 0 V → 1.8 mm, ±4.6 V (Table 6.3's ends) → ±0.32 m.
    assert C.ball_position_m(0.0, SW) == pytest.approx(0.0018, abs=1e-15)
    assert C.ball_position_m(4.6, SW) == pytest.approx(0.0693 * 4.6 + 0.0018, abs=1e-15)
    assert C.ball_position_m(-4.62, SW) == pytest.approx(-0.318366, abs=1e-12)
    out = C.ball_position_m(np.array([-1.0, 1.0]), SW)
    assert isinstance(out, np.ndarray)
    np.testing.assert_allclose(out, [-0.0675, 0.0711], atol=1e-15)
    assert isinstance(C.ball_position_m(1.0, SW), float)


@pytest.mark.quick
def test_beam_angle_matches_appendix_a_operation_by_operation():
    v = np.linspace(-5.0, 5.0, 101)
    # The MATLAB lines of appendix A, typed again here.
    x2_temp_2 = (143.22657649 * (v - 5.002) + 718.59375) / 7
    x2 = x2_temp_2 * (3.141592654 / 180)
    assert np.array_equal(C.beam_angle_rad(v, SW), x2)  # bit-identical, not just close
    assert np.array_equal(C.beam_angle_deg(v, SW), x2_temp_2)
    # DI = 1023 ↔ 5.002 V ↔ motor angle 718.59375° (§6.2) ↔ beam angle 102.65625°.
    assert C.beam_angle_deg(5.002, SW) == pytest.approx(718.59375 / 7, abs=1e-12)


def test_beam_angle_slope_is_one_count_per_dac_step():
    # One DAC step of eq 6.2.6 (0.009818 V) must read as one encoder count at the beam, 360/(256·7)°
    # (eq 6.2.1); the software's 143.22657649 is (360/256)/(5 kΩ·2.0108 mA/1024), so the two agree to 5e-5.
    step_deg = C.beam_angle_deg(0.009818, SW) - C.beam_angle_deg(0.0, SW)
    assert step_deg == pytest.approx(360 / 256 / 7, rel=5e-5)
    # The DAC level of eq 6.2.6 at DI = 512 (0.009818·512 − 5.042 = −0.015184 V) reads as 0° to 1e-4°.
    assert abs(C.beam_angle_deg(0.009818 * 512 - 5.042, SW)) < 1e-4


@pytest.mark.quick
def test_command_rescaling_of_section_6_4():
    # ±12 V at the motor ↔ 3.75 / 1.25 V command; 0 V ↔ 2.5 V (§6.4).
    assert C.dac_command_v(12.0, SW) == pytest.approx(3.75, abs=1e-15)
    assert C.dac_command_v(-12.0, SW) == pytest.approx(1.25, abs=1e-15)
    assert C.dac_command_v(0.0, SW) == 2.5
    assert C.motor_volts_from_command(3.75, SW) == pytest.approx(12.0, abs=1e-12)
    assert C.motor_volts_from_command(2.5, SW) == 0.0
    volts = np.linspace(-30.0, 30.0, 61)
    np.testing.assert_allclose(C.motor_volts_from_command(C.dac_command_v(volts, SW), SW), volts, atol=1e-13)


def test_clip_command_software_limits():
    assert C.clip_command_v(4.0, SW) == 3.75
    assert C.clip_command_v(0.3, SW) == 1.25
    assert C.clip_command_v(2.2, SW) == 2.2
    # Appendix B: reduced limits 2…3 V for a first run.
    np.testing.assert_array_equal(
        C.clip_command_v(np.array([1.5, 2.5, 3.5]), SW, low=2.0, high=3.0), [2.0, 2.5, 3.0]
    )
    with pytest.raises(ValueError, match="low = 3.0"):
        C.clip_command_v(2.5, SW, low=3.0, high=2.0)


@pytest.mark.quick
@pytest.mark.parametrize(
    "func, arg",
    [
        (C.ball_position_m, "volts"),
        (C.beam_angle_rad, "volts"),
        (C.dac_command_v, "motor_volts"),
        (C.motor_volts_from_command, "command_v"),
        (C.clip_command_v, "command_v"),
    ],
)
def test_nan_and_inf_raise_naming_the_argument(func, arg):
    with pytest.raises(ValueError, match=f"{arg} contains nan"):
        func(math.nan, SW)
    with pytest.raises(ValueError, match=f"{arg} contains -inf"):
        func(np.array([0.0, -math.inf]), SW)
    with pytest.raises(ValueError, match=arg):
        func("abc", SW)


@pytest.mark.quick
def test_ideal_sensor_volts_invert_the_software_conversions():
    x = np.linspace(-0.3, 0.3, 13)
    theta = np.linspace(-0.7, 0.7, 15)
    np.testing.assert_allclose(C.ball_position_m(C.ball_volts_v(x, SW), SW), x, rtol=0, atol=1e-15)
    np.testing.assert_allclose(C.beam_angle_rad(C.angle_volts_v(theta, SW), SW), theta, rtol=0, atol=1e-14)


@pytest.mark.quick
def test_a_recalibrated_software_converts_with_its_own_numbers():
    sw = SoftwareCalibration(ball_gain_m_per_v=0.07, ball_offset_m=-0.001, command_zero_v=2.4)
    assert C.ball_position_m(1.0, sw) == pytest.approx(0.069, abs=1e-15)
    assert C.dac_command_v(0.0, sw) == 2.4
