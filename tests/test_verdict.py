"""The verdict on trajectories whose figures are known by hand."""

import math

import numpy as np
import pytest

from twin.verdict import Criteria, Trace, evaluate, settling_time_s

RAIL_V, STOP_RAD = 12.0, math.radians(43.4)
T = np.round(np.arange(-0.02, 10.0 + 1e-9, 0.02), 10)  # the held row, then 50 Hz ticks from release


def _verdict(x, theta=None, volts=None, peaks=None, lost=None, x0=0.2, criteria=None):
    theta = np.zeros_like(T) if theta is None else theta
    volts = np.zeros_like(T) if volts is None else volts
    peaks = np.abs(theta) if peaks is None else peaks
    return evaluate(
        Trace(T, x, theta, volts, peaks), x0_m=x0, ball_lost_time_s=lost, rail_v=RAIL_V, stop_angle_rad=STOP_RAD,
        criteria=criteria,
    )  # fmt: skip


@pytest.mark.quick
def test_an_exponential_decay_to_an_offset_settles_when_the_band_says() -> None:
    """x = −4 mm + 0.204·e^(−2t): |x − steady| ≤ 4 mm (2 % of 0.2 m) from t = ln(0.204/0.004)/2 = 1.966 s."""
    x = -0.004 + 0.204 * np.exp(-2.0 * np.maximum(T, 0.0))
    v = _verdict(x)
    assert v.held and v.reason == "held"
    # The window's mean of the decay: 0.204/(2·3 s)·(e^(−14) − e^(−20)) = 2.8e-8 m on top of −4 mm (the 50 Hz samples
    # of it differ from the integral by 4e-10 m).
    assert v.steady_x_m == pytest.approx(-0.004 + 0.204 / 6 * (math.exp(-14) - math.exp(-20)), abs=1e-9)
    expected = math.log(0.204 / 0.004) / 2.0
    assert v.settling_time_s == pytest.approx(math.ceil(expected / 0.02) * 0.02, abs=1e-9)
    assert v.limit_cycle_x_pp_m == pytest.approx(0.204 * (math.exp(-14.0) - math.exp(-20.0)), rel=1e-6)


@pytest.mark.quick
def test_a_limit_cycle_is_measured_peak_to_peak_about_its_mean() -> None:
    """A 0.73 s orbit of ±1.5 mm about −3 mm and ±5 mrad: p-p 3 mm / 10 mrad, held; settling band 1 mm
    (2 % of 5 cm) is narrower than the orbit, so the run never settles into it."""
    x = -0.003 + 0.0015 * np.sin(2 * np.pi * T / 0.73)
    th = 0.005 * np.cos(2 * np.pi * T / 0.73)
    v = _verdict(x, th, x0=0.05)
    assert v.held
    assert v.limit_cycle_x_pp_m == pytest.approx(0.003, rel=2e-3)
    assert v.limit_cycle_theta_pp_rad == pytest.approx(0.010, rel=2e-3)
    assert v.steady_x_m == pytest.approx(-0.003, abs=1e-4)
    assert v.settling_time_s is None


@pytest.mark.quick
@pytest.mark.parametrize(
    ("offset_m", "amplitude_m", "fragment"),
    [
        (0.012, 0.0, "offset +12.0 mm beyond ±10 mm"),
        (0.0, 0.006, "ball limit cycle 12.0 mm p-p beyond 10 mm"),
    ],
)
def test_outside_the_bands_is_not_held_and_says_why(
    offset_m: float, amplitude_m: float, fragment: str
) -> None:
    x = offset_m + amplitude_m * np.sin(2 * np.pi * T / 0.5 + 0.1)
    v = _verdict(x)
    assert not v.held and not v.ball_lost
    assert fragment in v.reason


@pytest.mark.quick
def test_a_lost_ball_has_no_steady_state() -> None:
    x = 0.2 + 0.1 * T**2
    v = _verdict(x, lost=1.5)
    assert v.ball_lost and not v.held and v.ball_lost_time_s == 1.5
    assert v.steady_x_m is v.limit_cycle_x_pp_m is v.settling_time_s is None
    assert v.reason == "ball lost at 1.500 s"


def test_a_run_shorter_than_the_window_is_not_held() -> None:
    v = evaluate(
        Trace(T[:60], np.zeros(60), np.zeros(60), np.zeros(60), np.zeros(60)), x0_m=0.1, ball_lost_time_s=None,
        rail_v=RAIL_V, stop_angle_rad=STOP_RAD,
    )  # fmt: skip
    assert not v.held and "shorter than the final window" in v.reason


@pytest.mark.quick
def test_saturation_share_peak_volts_and_stops() -> None:
    """12 V for the first 50 of 501 ticks after release: 10 % saturated (the held row does not count);
    a beam that reached 43.4° hit the stops."""
    volts = np.where((T >= 0) & (T < 1.0), 12.0, 3.0)
    volts[0] = 12.0  # the held row
    peaks = np.zeros_like(T)
    peaks[30] = STOP_RAD
    v = _verdict(np.zeros_like(T), volts=volts, peaks=peaks)
    assert v.saturated_fraction == pytest.approx(50 / 501)
    assert v.peak_motor_voltage_v == 12.0
    assert v.hit_stops and v.peak_theta_rad == pytest.approx(STOP_RAD)
    assert not _verdict(np.zeros_like(T)).hit_stops


@pytest.mark.quick
def test_json_is_rounded_to_meaning_and_every_combination_is_consistent() -> None:
    x = -0.0031234567 + 0.0 * T
    out = _verdict(x).to_json()
    assert out["steady_x_m"] == -0.003123 and out["settling_time_s"] == 0.0 and out["held"] is True


def test_settling_time_is_none_when_the_last_excursion_is_in_the_window() -> None:
    x = np.zeros_like(T)
    x[-10] = 0.01
    assert settling_time_s(T, x, 0.0, 0.2, Criteria()) is None


def test_criteria_refuse_negative_values() -> None:
    with pytest.raises(ValueError, match="window_s = -1"):
        Criteria(window_s=-1)
