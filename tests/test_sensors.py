"""Beam-angle chain (§6.2) and ball-position chain (§6.3), against the thesis's hardware data and
independent computations."""

import itertools
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from thesis_data import TABLE_6_3_POSITION_M, TABLE_6_3_VOLTAGE_V

from twin import converters as C
from twin import daq as D
from twin import sensors as S
from twin.parameters import Parameters
from twin.rigs import measurements

P = Parameters()
QUIET = P.with_overrides({"ball_sensor.noise_enabled": False})
ADC_LSB = 10.0 / 4096
STEP_RAD = 2 * math.pi / (256 * 7)  # eq 6.2.1
KNOTS = np.arange(21) * 1e-3  # one 20 ms block at the 1 ms physics step


def still_reading_v(theta_rad: float, params: Parameters = P) -> float:
    """Block-mean ADC volts of a beam held still at theta_rad."""
    return S.angle_block_mean_v(KNOTS, np.full(KNOTS.shape, theta_rad), params)


# --- beam angle ---------------------------------------------------------------------------------------------
@pytest.mark.quick
def test_count_step_is_eq_6_2_1():
    assert S.angle_count_step_rad(P) == STEP_RAD
    assert S.angle_count_step_rad(P) == pytest.approx(0.0035, abs=0.5e-4)  # as printed (2 digits)
    assert math.degrees(STEP_RAD) == pytest.approx(0.2, abs=0.005)


def test_counter_convention_and_range():
    assert S.counter_value(0.0, P) == 512  # zero switch (§6.6)
    assert S.counter_value(0.49 * STEP_RAD, P) == 512
    assert S.counter_value(0.51 * STEP_RAD, P) == 513
    assert S.counter_value(-0.51 * STEP_RAD, P) == 511
    # §6.2: ±43° of beam is ±301° of motor, "maximum ±214 pulses".
    assert S.counter_value(math.radians(43.0), P) == 512 + 214
    assert S.counter_value(math.radians(-43.0), P) == 512 - 214


@pytest.mark.quick
def test_dac_reproduces_measured_eq_6_2_4():
    measured = {0: -5.042, 512: -0.014, 1023: 5.002}  # eq 6.2.4, measured on the rig
    levels = measurements.counter_levels(P)
    assert {level.di: level.measured_v for level in levels} == measured
    for level in levels:
        assert level.dac_v == S.counter_dac_v(level.di, P)
        # Eq 6.2.6 (the DAC model) agrees with every measurement within 1 ADC LSB: −5.042 (0 mV),
        # −0.015184 vs −0.014 (1.18 mV = 0.48 LSB), 5.001814 vs 5.002 (0.19 mV).
        assert abs(level.dac_v - level.measured_v) <= ADC_LSB
        assert level.dac_error_lsb == pytest.approx(abs(level.dac_v - level.measured_v) / ADC_LSB, rel=1e-12)
        assert level.adc_error_lsb == pytest.approx(abs(level.adc_v - level.measured_v) / ADC_LSB, rel=1e-12)
    adc = {level.di: level.adc_v for level in levels}
    # After the ±5 V ADC only the mid-scale value is still within 1 LSB of the measurement (0.65 mV);
    # the two end values lie outside the ADC's range and saturate.
    assert abs(adc[512] - measured[512]) <= ADC_LSB
    assert adc[0] == -5.0
    assert adc[1023] == 5.0 - ADC_LSB
    with pytest.raises(ValueError, match="di = 1024"):
        S.counter_dac_v(1024, P)


def test_read_back_angle_is_a_staircase_of_one_count():
    offsets = np.array([-0.45, -0.2, 0.0, 0.2, 0.45])  # positions within each count
    staircase = measurements.angle_staircase(P, offsets)
    counts = staircase.counts
    np.testing.assert_array_equal(counts, np.arange(-216, 217))  # the whole ±43.4° range of the beam
    assert staircase.count_step_rad == STEP_RAD
    readings = staircase.readings_v
    # The readings are the block means of a beam held still there (an independent call per point).
    for c, f in ((-216, -0.45), (0, 0.0), (17, 0.2), (216, 0.45)):
        assert readings[c + 216, list(offsets).index(f)] == still_reading_v((c + f) * STEP_RAD)
    assert np.all(readings == readings[:, :1])  # flat within each count
    volts = readings[:, 0]
    angle = C.beam_angle_rad(volts, P.software)
    np.testing.assert_array_equal(staircase.angle_rad, angle)
    steps_lsb = staircase.steps_lsb
    steps_count = staircase.steps_count
    np.testing.assert_allclose(steps_lsb, np.diff(volts) / ADC_LSB, rtol=0, atol=1e-9)
    # One DAC step (0.009818 V = 4.02 ADC LSB) shows as 4 LSB, or as 5 LSB once every ≈ 46 counts.
    assert set(np.round(steps_lsb, 9)) == {4.0, 5.0}
    assert np.sum(np.round(steps_lsb) == 5) == 9
    # Measured: 4-LSB steps are 0.9946 Δ, 5-LSB steps 1.2433 Δ; the mean step over the range is 0.99981 Δ.
    assert np.all(np.abs(steps_count[np.round(steps_lsb) == 4] - 1) < 0.01)
    assert abs(steps_count.mean() - 1) < 0.01
    # The read-back angle is the count's angle within 0.13 Δ (ADC quantization and converter offset).
    assert np.max(np.abs(angle - counts * STEP_RAD)) < 0.13 * STEP_RAD


@pytest.mark.quick
def test_counter_wraps_modulo_1024():
    # Zeroed with the beam at +1.1 rad (≈ 63°, far outside the stops), so that θ = −0.7 rad reaches count −1.
    params = P.with_overrides({"angle_sensor.zeroing_error_rad": 1.1})
    theta = np.linspace(-0.75, 0.0, 400)
    unwrapped = 512 + np.floor((theta - 1.1) / STEP_RAD + 0.5)
    assert unwrapped.min() < 0
    np.testing.assert_array_equal(S.counter_value(theta, params), np.mod(unwrapped, 1024))
    # Across the wrap the analog output jumps from the bottom (DI = 0) to the top (DI = 1023) of the DAC.
    below = S.angle_sensor_v(1.1 - 512 * STEP_RAD - 0.6 * STEP_RAD, params)
    above = S.angle_sensor_v(1.1 - 512 * STEP_RAD + 0.1 * STEP_RAD, params)
    assert below == pytest.approx(0.009818 * 1023 - 5.042, abs=1e-12)
    assert above == pytest.approx(-5.042, abs=1e-12)


def test_zeroing_error_shifts_the_reading():
    # Fig 7.20: zeroing the counter with the beam at 0.05 rad makes the software read θ − 0.05 rad.
    error_rad = 0.05
    shifted = P.with_overrides({"angle_sensor.zeroing_error_rad": error_rad})
    for theta in np.linspace(-0.6, 0.6, 61):
        read_shifted = C.beam_angle_rad(still_reading_v(theta, shifted), P.software)
        assert read_shifted == C.beam_angle_rad(still_reading_v(theta - error_rad, P), P.software)
        assert abs(read_shifted - (theta - error_rad)) <= 0.5 * STEP_RAD + 0.13 * STEP_RAD


def _random_trajectories(n: int, seed: int):
    rng = np.random.default_rng(seed)
    for trial in range(n):
        t0 = rng.uniform(0.0, 100.0)
        if trial % 3 == 0:  # knots off the sample grid, block end overshot
            times = np.concatenate(
                [[t0], np.sort(rng.uniform(t0, t0 + 0.02, 12)), [t0 + 0.02 + rng.uniform(0, 1e-3)]]
            )
        else:
            times = t0 + KNOTS
        speed_rad_s = rng.choice([0.0, 0.3, 2.0, 6.0, 40.0])
        theta = rng.uniform(-0.7, 0.7) + np.cumsum(rng.normal(0.0, 1.0, times.size)) * speed_rad_s * 1e-3
        zero = 1.2 if trial % 5 == 0 else 0.0  # every fifth: zeroed far off, so the counter wraps
        yield times, theta, P.with_overrides({"angle_sensor.zeroing_error_rad": zero})


@pytest.mark.quick
def test_exact_block_mean_equals_40khz_brute_force():
    distinct, wrapped = [], 0
    for times, theta, params in _random_trajectories(400, seed=11):
        fast = S.angle_block_mean_v(times, theta, params)
        brute = S.angle_block_mean_bruteforce_v(times, theta, params)
        assert abs(fast - brute) <= 1e-9, (times, theta)
        samples = np.interp(D.block_sample_times_s(times[0], params.daq), times, theta)
        counts = S.counter_value(samples, params)
        distinct.append(np.unique(counts).size)
        wrapped += int(counts.min() < 100 and counts.max() > 900)
    distinct = np.array(distinct)
    assert np.mean(distinct >= 3) > 0.4  # the trajectories really cross several counts …
    assert distinct.max() > 100  # … up to the 800-sample fallback
    assert wrapped > 0  # … and some cross the counter's wrap


@pytest.mark.quick
def test_brute_force_is_the_per_sample_definition():
    # The brute-force reference itself against an explicit loop over the 800 samples.
    times = 5.0 + KNOTS
    theta = 0.1 + 1.5 * (times - 5.0) + 0.02 * np.sin(300 * (times - 5.0))
    total = 0.0
    for ts in D.block_sample_times_s(5.0, P.daq):
        di = S.counter_value(float(np.interp(ts, times, theta)), P)
        total += D.adc_quantize_v(0.009818 * di - 5.042, P.daq)
    assert S.angle_block_mean_bruteforce_v(times, theta, P) == pytest.approx(total / 800, abs=1e-12)
    assert S.angle_block_mean_v(times, theta, P) == pytest.approx(total / 800, abs=1e-12)


def test_angle_chain_object_and_bad_input():
    chain = S.AngleChain(P)
    assert chain.read_v(KNOTS, np.full(21, 0.2)) == still_reading_v(0.2)
    assert chain.counter_value(0.0) == 512
    with pytest.raises(ValueError, match="theta_rad contains nan"):
        chain.read_v(KNOTS, np.full(21, math.nan))
    with pytest.raises(ValueError, match="must cover the whole block"):
        chain.read_v(KNOTS[:-1], np.zeros(20))
    with pytest.raises(ValueError, match="increase strictly"):
        chain.read_v(KNOTS[::-1], np.zeros(21))
    with pytest.raises(ValueError, match="must match times_s"):
        chain.read_v(KNOTS, np.zeros(20))


# --- ball position ------------------------------------------------------------------------------------------
@pytest.mark.quick
def test_static_curve_is_table_6_3_interpolated():
    assert S.wiper_static_v(0.18, P.ball_sensor) == 2.470
    assert S.wiper_static_v(0.195, P.ball_sensor) == pytest.approx((2.470 + 3.000) / 2, abs=1e-12)
    assert S.wiper_static_v(0.4, P.ball_sensor) == 4.600  # clamped to the end value
    assert np.all(np.diff(TABLE_6_3_VOLTAGE_V) > 0)  # the measured curve is monotone
    # The default curve is Table 6.3 as printed.
    np.testing.assert_array_equal(P.ball_sensor.curve_position_m, TABLE_6_3_POSITION_M)
    np.testing.assert_array_equal(P.ball_sensor.curve_volts_v, TABLE_6_3_VOLTAGE_V)


def test_ball_at_rest_on_each_table_point():
    lsb_m = 0.0693 * ADC_LSB  # one ADC step in eq 6.3.1's metres: 0.17 mm
    chain = S.BallPositionChain(QUIET, seed=0)
    for x, volts in zip(TABLE_6_3_POSITION_M, TABLE_6_3_VOLTAGE_V, strict=True):
        chain.reset(float(x), t_s=1.0)
        reading = chain.advance(1.0 + KNOTS, np.full(21, x))
        assert abs(reading - volts) <= ADC_LSB  # measured: ≤ 0.5 LSB
        fit_residual_m = abs(0.0693 * volts + 0.0018 - x)  # eq 6.3.1's own error at this point (≤ 7.0 mm)
        assert abs(C.ball_position_m(reading, P.software) - x) <= fit_residual_m + lsb_m


@pytest.mark.quick
def test_rc_time_constant_from_a_step():
    """The wiper opens (0 V) for 15 ms, then closes (back to 4.340 V at x = 0.30 m), sampled every 0.1 ms."""
    step = measurements.rc_step(P)
    for tau in (step.tau_fall_s, step.tau_rise_s):
        assert tau == pytest.approx(147 * 22e-6, rel=0.02)  # 3.234 ms (§6.3); measured: exact to 1e-4
    assert step.final_reading_v == D.adc_quantize_v(step.final_filtered_v, P.daq)


def test_rc_filter_is_exact_against_an_ode_solver():
    """A moving ball crossing table points, leaving the track, and frequent dropouts, against solve_ivp."""
    params = P.with_overrides(
        {"ball_sensor.dropout_rate_hz": 150.0, "ball_sensor.dropout_mean_duration_s": 2e-3}
    )
    chain = S.BallPositionChain(params, seed=5, x_m=0.25)
    tau = 147 * 22e-6
    blocks, ends = [], []
    for k in range(6):
        times = 0.02 * k + KNOTS
        x = 0.25 + 0.09 * np.sin(40 * times)  # up to 0.34 m: beyond the 0.323 m track end
        contact = np.ones(21, dtype=bool)
        if k == 4:  # ball on the track (x ≈ 0.18 m) but flagged out of contact for 4 ms
            contact[8:12] = False
        chain.advance(times, x, contact)
        blocks.append((times, x, contact))
        ends.append(chain.filtered_v)
    drops = chain.dropout_intervals
    assert len(drops) >= 5

    def wiper(t: float, times, x, contact) -> float:
        j = min(np.searchsorted(times, t, side="left"), len(times) - 1)
        xt = float(np.interp(t, times, x))
        if not contact[j] or abs(xt) > 0.323 or any(a < t < b for a, b in drops):
            return 0.0
        return float(np.interp(xt, TABLE_6_3_POSITION_M, TABLE_6_3_VOLTAGE_V))

    y = float(np.interp(0.25, TABLE_6_3_POSITION_M, TABLE_6_3_VOLTAGE_V))
    for (times, x, contact), expected in zip(blocks, ends, strict=True):
        # Integrate piece by piece between every discontinuity of the input.
        cuts = [t for a, b in drops for t in (a, b) if times[0] < t < times[-1]]
        cuts = np.unique(np.concatenate([times, cuts]))

        def rhs(t, v, times=times, x=x, contact=contact):
            return [(wiper(t, times, x, contact) - v[0]) / tau]

        for a, b in itertools.pairwise(cuts):
            sol = solve_ivp(
                rhs,
                (a, b),
                [y],
                method="DOP853",
                rtol=1e-12,
                atol=1e-13,
            )
            y = float(sol.y[0, -1])
        assert expected == pytest.approx(y, abs=1e-9)


def _run(chain: S.BallPositionChain, seconds: float, block_s: float = 0.02) -> np.ndarray:
    steps = round(block_s / 1e-3)
    readings = []
    for _k in range(round(seconds / block_s)):
        times = chain.time_s + np.arange(steps + 1) * 1e-3
        readings.append(chain.advance(times, 0.2 * np.sin(1.3 * times)))
    return np.array(readings)


def test_dropout_rate_over_200_seconds():
    drops = measurements.dropouts(P, seconds=200.0, seed=2024)
    expected = 5.0 * 200.0  # dropout_rate_hz × duration
    assert abs(drops.count - expected) <= 3 * math.sqrt(expected)  # measured: 1012 (5.06 Hz)
    mean_s = 0.5e-3  # exponential: σ of the mean = mean/√N
    assert abs(drops.durations_s.mean() - mean_s) <= 3 * mean_s / math.sqrt(
        drops.durations_s.size
    )  # measured: 0.516 ms


@pytest.mark.quick
def test_noise_off_means_no_dropouts_and_the_static_reading():
    chain = S.BallPositionChain(QUIET, seed=2024, x_m=0.3)
    readings = []
    for _k in range(500):
        readings.append(chain.advance(chain.time_s + KNOTS, np.full(21, 0.3)))
    assert chain.dropout_count == 0
    assert set(readings) == {D.adc_quantize_v(4.340, P.daq)}
    noisy = S.BallPositionChain(P.with_overrides({"ball_sensor.dropout_rate_hz": 50.0}), seed=2024, x_m=0.3)
    readings = [noisy.advance(noisy.time_s + KNOTS, np.full(21, 0.3)) for k in range(500)]
    assert min(readings) < D.adc_quantize_v(4.340, P.daq) - 0.1  # dropouts pull the reading towards 0 V


def test_same_seed_same_readings_different_seed_different():
    a = _run(S.BallPositionChain(P, seed=9, x_m=0.0), 20.0)
    b = _run(S.BallPositionChain(P, seed=9, x_m=0.0), 20.0)
    c = _run(S.BallPositionChain(P, seed=10, x_m=0.0), 20.0)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    # Re-seeding on reset replays the same noise.
    chain = S.BallPositionChain(P, seed=1, x_m=0.0)
    chain.reset(0.0, seed=9)
    assert np.array_equal(_run(chain, 20.0), a)


def test_noise_realization_does_not_depend_on_block_length():
    whole = S.BallPositionChain(P, seed=4, x_m=0.0)
    halves = S.BallPositionChain(P, seed=4, x_m=0.0)
    _run(whole, 10.0, block_s=0.02)
    _run(halves, 10.0, block_s=0.01)
    assert whole.dropout_intervals == halves.dropout_intervals
    assert whole.filtered_v == pytest.approx(halves.filtered_v, abs=1e-12)


def test_no_contact_off_the_track_or_when_flagged():
    chain = S.BallPositionChain(QUIET, seed=0, x_m=0.33)  # beyond 0.323 m: the ball has left the track
    assert chain.filtered_v == 0.0 == chain.wiper_v
    chain.reset(0.1)
    for _k in range(10):
        chain.advance(chain.time_s + KNOTS, np.full(21, 0.1), in_contact=False)
    assert chain.wiper_v == 0.0 and abs(chain.filtered_v) < 1e-20  # 200 ms = 62 τ
    assert chain.reading_v == 0.0


def test_ball_chain_bad_input():
    chain = S.BallPositionChain(P, seed=0)
    with pytest.raises(ValueError, match="x_m contains nan"):
        chain.advance(KNOTS, np.full(21, math.nan))
    with pytest.raises(ValueError, match="must start at the chain's time"):
        chain.advance(1.0 + KNOTS, np.zeros(21))
    with pytest.raises(ValueError, match="in_contact"):
        chain.advance(KNOTS, np.zeros(21), in_contact=np.ones(3, dtype=bool))
    with pytest.raises(ValueError, match="seed = -1"):
        S.BallPositionChain(P, seed=-1)


def test_rig_block_filter_equals_the_piecewise_filter():
    """The rig's blocks (equal steps, one piece of the curve) take the uniform-step filter plus each dropout's
    closed-form effect; the piecewise filter of ``advance`` (proven against solve_ivp above) must agree to
    float rounding, block after block, with dropouts of every kind: inside one step, across steps, several
    overlapping, covering the block's end."""
    params = P.with_overrides(
        {"ball_sensor.dropout_rate_hz": 120.0, "ball_sensor.dropout_mean_duration_s": 1.5e-3}
    )
    fast, piecewise = (
        S.BallPositionChain(params, seed=11, x_m=0.05),
        S.BallPositionChain(params, seed=11, x_m=0.05),
    )
    rng = np.random.default_rng(3)
    worst, with_dropouts = 0.0, 0
    for k in range(400):
        times = 0.02 * k + KNOTS
        x = 0.05 + 0.004 * np.sin(7 * times + rng.uniform(0, 0.1))  # stays between two table points
        contact = np.ones(times.size, dtype=bool)
        reading = fast.advance_rig_block(times, x, contact, True)
        assert reading == piecewise.advance(times, x, contact)
        worst = max(worst, abs(fast.filtered_v - piecewise.filtered_v))
        with_dropouts += any(a < times[-1] and b > times[0] for a, b in fast.dropout_intervals)
    off = np.zeros(KNOTS.size, dtype=bool)  # then the ball off the track: the wiper open throughout
    for k in range(400, 450):
        times = 0.02 * k + KNOTS
        x = np.full(times.size, 0.4)
        assert fast.advance_rig_block(times, x, off, True) == piecewise.advance(times, x, off)
        worst = max(worst, abs(fast.filtered_v - piecewise.filtered_v))
    assert fast.dropout_intervals == piecewise.dropout_intervals  # the same draws in the same order
    assert with_dropouts > 300
    assert worst < 1e-13
