"""The three ranging ball sensors (twin.parts.vl53l0x, hcsr04, gp2y0a21) against numbers derived here by hand or
computed independently: the echo of a ball at a known distance and temperature, the infrared curve against the
data sheet's points and its fold, the time-of-flight sensor's stale reads, the noise's statistics over many seeds,
seeded determinism, single = batch, each part's contract, and a simulated rig whose readings decode to the ball."""

from __future__ import annotations

import math
from dataclasses import fields

import mujoco
import numpy as np
import pytest
from test_parts import _equation_problems, _parameter_problems

from twin.model import build_model
from twin.parameters import ParameterError, Parameters
from twin.parts import BallSensorPart, part_named, registered
from twin.parts.gp2y0a21 import GP2Y0A21, Gp2y0a21, Gp2y0a21Batch, Gp2y0a21Chain, gp2y0a21_volts
from twin.parts.hcsr04 import HCSR04, Hcsr04, Hcsr04Batch, Hcsr04Chain, hcsr04_echo_us
from twin.parts.ranging import near_distance_m
from twin.parts.vl53l0x import OUT_OF_RANGE_MM, VL53L0X, Vl53l0x, Vl53l0xBatch, Vl53l0xChain
from twin.rigs.sim import SimRig

PARTS = (VL53L0X, HCSR04, GP2Y0A21)
R = 0.008329  # the thesis's ball radius (Table 3.1), m
MOUNT = 0.333  # every sensor's default mount, m
QUIET = {"ball_sensor.noise_enabled": False}  # the rig's noise switch: no draw has an effect


def _block(t0: float, n: int = 20, dt: float = 0.001) -> np.ndarray:
    return t0 + np.arange(n + 1) * dt


def _x_for_distance(d_m: float) -> float:
    """The ball's centre for its near surface d from the sensor: mount − x − r = d."""
    return MOUNT - R - d_m


# --- HC-SR04: the echo's width ------------------------------------------------------------------------------
@pytest.mark.quick
def test_the_echo_of_a_ball_200_mm_away_at_25_c_is_1155_us() -> None:
    # by hand: c = 331.3·√(1 + 25/273.15) = 331.3·1.0447606 = 346.129 m/s; 2·0.2/346.129 = 1155.64 µs → 1155
    c = 331.3 * math.sqrt(1.0 + 25.0 / 273.15)
    assert c == pytest.approx(346.129, abs=1e-3)
    p = Parameters().with_overrides({**QUIET, "hcsr04.temperature_c": 25.0})
    chain = Hcsr04Chain(p, 0, x_m=_x_for_distance(0.2))
    assert chain.reading_v == 1155.0
    # the user guide's rule (µs / 58 = cm) at 20 °C: 1 cm is 2·0.01/343.21 = 58.27 µs
    one_cm = hcsr04_echo_us(
        np.array([0.01]), np.array([True]), np.zeros(1), np.zeros(1, bool), np.array([np.inf]),
        temperature_c=20.0, jitter_us=0.0, max_range_m=4.0, timeout_us=30000.0,
    )  # fmt: skip
    assert one_cm[0][0] == 58.0 and one_cm[1][0] == pytest.approx(58.27e-6, abs=1e-8)
    # colder air, slower sound, a longer echo: at −10 °C c = 331.3·√(263.15/273.15) = 325.17 m/s → 1230.1 µs
    cold = Hcsr04Chain(Parameters().with_overrides({**QUIET, "hcsr04.temperature_c": -10.0}), 0)
    cold.reset(_x_for_distance(0.2))
    assert cold.reading_v == 1230.0


@pytest.mark.quick
def test_the_echo_comes_once_a_cycle_when_pulsein_returns_and_none_off_the_track() -> None:
    p = Parameters().with_overrides(QUIET)
    chain = Hcsr04Chain(p, 0)
    chain.reset(_x_for_distance(0.2), 0.0)
    first = chain.reading_v  # 0.2 m at 20 °C: 2·0.2/343.21 = 1165.4 µs
    assert first == 1165.0
    # the ball moves to 0.1 m away at once and stays: the trigger at 60 ms hears it, 582.7 µs later
    x = np.full(21, _x_for_distance(0.1))
    reads = [chain.advance(_block(0.02 * b), x) for b in range(4)]
    # 2·0.1/343.21 = 582.7 µs: the trigger at 60 ms, its echo over at 60.58 ms, in the block ending at 80 ms
    assert reads == [1165.0, 1165.0, 1165.0, 582.0]
    tail = Hcsr04Chain(p, 0)
    tail.reset(_x_for_distance(0.2), 0.0)
    assert tail.advance(np.array([0.0, 0.0605]), np.full(2, _x_for_distance(0.1))) == 1165.0  # echo not over
    assert tail.advance(np.array([0.0605, 0.061]), np.full(2, _x_for_distance(0.1))) == 582.0
    gone = Hcsr04Chain(p, 0)
    gone.reset(0.1, 0.0)
    t = _block(0.0, 89)
    off = np.zeros(90, bool)
    # off the track: the trigger at 60 ms hears nothing and pulseIn returns 0 at its 30 ms timeout, at 90 ms;
    # until then the last echo holds, the ball's at x = 0.1: 2·(0.333 − 0.1 − 0.008329)/343.21 = 1309.2 µs
    assert gone.advance(t, np.full(90, 0.4), off) == 1309.0
    assert gone.advance(np.array([0.089, 0.0901]), np.full(2, 0.4), off[:2]) == 0.0


@pytest.mark.quick
def test_new_parameters_act_from_the_next_cycle() -> None:
    p = Parameters().with_overrides(QUIET)
    chain = Hcsr04Chain(p, 0)
    chain.reset(_x_for_distance(0.2), 0.0)
    x = np.full(21, _x_for_distance(0.2))
    assert chain.advance(_block(0.0), x) == 1165.0  # 20 °C
    chain.set_params(p.with_overrides({"hcsr04.temperature_c": 25.0}))
    assert chain.reading_v == 1165.0  # the echo already heard holds
    reads = [chain.advance(_block(0.02 * b), x) for b in range(1, 4)]
    assert reads == [1165.0, 1165.0, 1155.0]  # the trigger at 60 ms in 25 °C air: 1155.6 µs


@pytest.mark.quick
def test_a_timeout_beyond_the_cycle_is_refused_naming_the_field() -> None:
    with pytest.raises(ParameterError, match=r"hcsr04.pulse_timeout_us = 70000.0 µs is impossible"):
        Parameters().with_overrides({"hcsr04.pulse_timeout_us": 70000.0})
    with pytest.raises(ParameterError, match=r"vl53l0x.timing_budget_s = 0.01 s is impossible"):
        Parameters().with_overrides({"vl53l0x.timing_budget_s": 0.01})


# --- GP2Y0A21YK0F: the curve, the fold, the update period --------------------------------------------------
# The data sheet's Fig. 2 (white paper) read at 10…80 cm: the points the default curve is fitted to.
FIG2_CM = np.array([10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0])
FIG2_V = np.array([2.25, 1.30, 0.90, 0.75, 0.60, 0.50, 0.45, 0.40])


def _fit_inverse(d_m: np.ndarray, v: np.ndarray) -> tuple[float, float, float, float]:
    """An independent fit of a/(d + b) + c: for each b on a fine grid, a and c by linear least squares; the best
    b (then refined on a finer grid). Returns a, b, c and the rms residual."""
    best = (math.inf, 0.0, 0.0, 0.0)
    for grid in (np.arange(0.0, 0.1, 1e-4), None):
        if grid is None:
            grid = best[2] + np.arange(-1e-4, 1e-4, 1e-7)
        for b in grid:
            basis = np.column_stack([1.0 / (d_m + b), np.ones_like(d_m)])
            (a, c), *_ = np.linalg.lstsq(basis, v, rcond=None)
            rms = float(np.sqrt(np.mean((basis @ np.array([a, c]) - v) ** 2)))
            if rms < best[0]:
                best = (rms, float(a), float(b), float(c))
    return best[1], best[2], best[3], best[0]


@pytest.mark.quick
def test_the_infrared_curve_is_the_fit_of_the_data_sheets_points() -> None:
    g = Gp2y0a21()
    a, b, c, rms = _fit_inverse(FIG2_CM / 100.0, FIG2_V)
    assert (g.curve_a_v_m, g.curve_b_m, g.curve_c_v) == pytest.approx((a, b, c), rel=2e-3, abs=2e-4)
    curve = gp2y0a21_volts(
        FIG2_CM / 100.0, a_v_m=g.curve_a_v_m, b_m=g.curve_b_m, c_v=g.curve_c_v, fold_m=g.fold_distance_m
    )
    residual = curve - FIG2_V
    assert rms == pytest.approx(0.0135, abs=5e-4)  # the residual the group's source states
    assert np.max(np.abs(residual)) < 0.029  # the largest 28.5 mV at 40 cm (a reading of the figure: ±0.05 V)
    # the data sheet's table: VO at 80 cm 0.25…0.55 V (0.4 typ); VO(10 cm) − VO(80 cm) 1.65…2.15 V (1.9 typ)
    assert 0.25 <= curve[-1] <= 0.55 and 1.65 <= curve[0] - curve[-1] <= 2.15


@pytest.mark.quick
def test_closer_than_the_fold_the_volts_fall_and_a_near_ball_reads_like_a_far_one() -> None:
    g = Gp2y0a21()
    peak = (
        g.curve_a_v_m / (g.fold_distance_m + g.curve_b_m) + g.curve_c_v
    )  # 0.28474/0.08999 + 0.05926 = 3.2234
    assert peak == pytest.approx(3.2234, abs=1e-4)
    p = Parameters().with_overrides(QUIET)
    volts = []
    for d in (0.06, 0.04, 0.03, 0.01):
        chain = Gp2y0a21Chain(p, 0, x_m=_x_for_distance(d))
        volts.append(chain.filtered_v)
    # the straight line from the peak at 6 cm to 0 V at 0 cm: peak·d/6 cm
    assert volts == pytest.approx([peak, peak * 4 / 6, peak * 3 / 6, peak * 1 / 6], abs=1e-12)
    # 4 cm reads 2.149 V, as the curve does at a/(V − c) − b = 0.28474/2.0897 − 0.02999 = 0.1063 m
    far = g.curve_a_v_m / (volts[1] - g.curve_c_v) - g.curve_b_m
    assert far == pytest.approx(0.1063, abs=1e-4)
    assert Gp2y0a21Chain(p, 0, x_m=_x_for_distance(far)).filtered_v == pytest.approx(volts[1], abs=1e-12)


@pytest.mark.quick
def test_the_infrared_output_holds_between_updates_and_the_board_reads_it_with_its_adc() -> None:
    p = Parameters().with_overrides({**QUIET, "gp2y0a21.update_period_s": 0.0383})
    chain = Gp2y0a21Chain(p, 0)
    chain.reset(_x_for_distance(0.3), 0.0)
    v30 = chain.filtered_v  # a/(0.3 + b) + c = 0.28474/0.32999 + 0.05926 = 0.92213 V
    assert v30 == pytest.approx(0.92213, abs=1e-5)
    near = np.full(21, _x_for_distance(0.2))  # the ball jumps to 20 cm: 0.28474/0.22999 + 0.05926 = 1.29731 V
    held = [chain.advance(_block(0.02 * b), near) for b in range(2)]
    adc = part_named("io_board", "pci1712").adc(p)  # type: ignore[attr-defined]
    # the PCI-1712's 12-bit ±5 V ADC: the update at 38.3 ms is in the second block
    v20 = 0.2847360505 / (0.2 + 0.0299884788) + 0.0592608702
    assert held == [adc(v30), adc(v20)] and chain.filtered_v == pytest.approx(1.29731, abs=1e-5)
    assert held[0] == pytest.approx(0.92213, abs=10.0 / 4096)
    arduino = Parameters().with_overrides({**QUIET, "parts.io_board": "arduino_uno"})
    counts = Gp2y0a21Chain(arduino, 0, x_m=_x_for_distance(0.3)).reading_v
    assert counts == part_named("io_board", "arduino_uno").adc(arduino)(v30)  # type: ignore[attr-defined]
    assert abs(counts - 0.92213 / 5.0 * 1024) <= 1.0  # analogRead: 1024 counts over its 5 V reference
    gone = Gp2y0a21Chain(p, 0)
    gone.reset(0.1, 0.0)
    gone.advance(_block(0.0, 50), np.full(51, 0.5), np.zeros(51, bool))
    # no ball: the wall 1 m away, 0.28474/1.02999 + 0.05926 = 0.33571 V
    assert gone.filtered_v == pytest.approx(0.33571, abs=1e-5)


# --- VL53L0X: the budget and the board's stale reads --------------------------------------------------------
@pytest.mark.quick
def test_a_33_ms_budget_read_every_20_ms_reads_each_range_once_or_twice() -> None:
    p = Parameters().with_overrides(QUIET)
    chain = Vl53l0xChain(p, 0)
    chain.reset(0.0, 0.0)
    v = 0.2  # the ball rolls toward the sensor at 0.2 m/s from x = 0
    reads = []
    for b in range(15):
        t = _block(0.02 * b)
        reads.append(chain.advance(t, v * t))
    # by hand: range i completes at 33·i ms, the mean distance over its budget, the ball's at 33·i − 16.5 ms:
    # 1000·(0.333 − 0.2·(0.033·i − 0.0165) − r) mm, rounded; range 0 is the ball at rest at x = 0
    expected = []
    for k in range(1, 16):
        i = math.floor(20 * k / 33)
        x_mean = 0.0 if i == 0 else v * (0.033 * i - 0.0165)
        expected.append(float(round(1000.0 * (MOUNT - x_mean - R))))
    assert reads == expected
    assert reads[:8] == [325.0, 321.0, 321.0, 315.0, 308.0, 308.0, 302.0, 302.0]
    # a new range at reads 2, 4, 5, 7, 9, 10, 12, 14, 15: the others repeat the last (stale)
    stale = [k for k in range(1, 15) if reads[k] == reads[k - 1]]
    assert stale == [2, 5, 7, 10, 12]


@pytest.mark.quick
def test_crosstalk_and_no_target_and_a_wall_within_range() -> None:
    p = Parameters().with_overrides({**QUIET, "vl53l0x.crosstalk_offset_mm": 12.0})
    chain = Vl53l0xChain(p, 0, x_m=_x_for_distance(0.2))
    assert chain.reading_v == 188.0  # 200 mm less the cover glass's 12 mm
    gone = Vl53l0xChain(Parameters().with_overrides(QUIET), 0)
    gone.reset(0.0, 0.0)
    assert gone.advance(_block(0.0, 40), np.full(41, 0.4), np.zeros(41, bool)) == OUT_OF_RANGE_MM
    wall = Parameters().with_overrides({**QUIET, "vl53l0x.background_mm": 900.0})
    assert Vl53l0xChain(wall, 0, x_m=0.6).reading_v == 900.0  # no ball: the wall within range
    far = Parameters().with_overrides({**QUIET, "vl53l0x.mount_x_m": 1.5})
    assert Vl53l0xChain(far, 0, x_m=0.0).reading_v == OUT_OF_RANGE_MM  # 1.49 m: beyond the 1.2 m range


# --- the noise's statistics over many seeds ----------------------------------------------------------------
N_SEEDS = 4000


@pytest.mark.quick
def test_the_time_of_flight_noise_and_wrong_returns_have_their_parameters_statistics() -> None:
    d_mm = 250.0
    p = Parameters().with_overrides({"vl53l0x.wrong_return_probability": 0.1, "vl53l0x.background_mm": 900.0})
    batch = Vl53l0xBatch(p, np.arange(N_SEEDS), np.full(N_SEEDS, _x_for_distance(d_mm / 1000.0)), 0.0)
    ranges = batch.readings
    wrong = ranges > 600.0
    # wrong returns: a binomial share of 0.1 within 4 standard errors
    assert abs(wrong.mean() - 0.1) < 4.0 * math.sqrt(0.1 * 0.9 / N_SEEDS)
    ball = ranges[~wrong]
    sigma = 0.04 * d_mm  # the part's default accuracy: 4 % of the distance at the 33 ms budget
    n = len(ball)
    assert abs(ball.mean() - d_mm) < 4.0 * sigma / math.sqrt(n)
    spread = math.sqrt(sigma**2 + 1.0 / 12.0)  # whole mm add a rounding's variance
    assert abs(ball.std() - spread) < 4.0 * spread / math.sqrt(2 * n)
    assert abs(ranges[wrong].mean() - 900.0) < 4.0 * 0.04 * 900.0 / math.sqrt(wrong.sum())
    assert batch.disturbed.sum() == wrong.sum()


@pytest.mark.quick
def test_the_echoes_jitter_and_losses_have_their_parameters_statistics() -> None:
    p = Parameters().with_overrides(
        {
            "hcsr04.lost_echo_probability": 0.05,
            "hcsr04.spurious_echo_probability": 0.0,
            "hcsr04.echo_jitter_us": 20.0,
        }
    )
    batch = Hcsr04Batch(p, np.arange(N_SEEDS), np.full(N_SEEDS, _x_for_distance(0.2)), 0.0)
    echo = batch.readings
    lost = echo == 0.0
    assert abs(lost.mean() - 0.05) < 4.0 * math.sqrt(0.05 * 0.95 / N_SEEDS)
    heard = echo[~lost]
    true_us = 2 * 0.2 / (331.3 * math.sqrt(1.0 + 20.0 / 273.15)) * 1e6  # 1165.40 µs
    n = len(heard)
    assert abs(heard.mean() - (true_us - 0.5)) < 4.0 * 20.0 / math.sqrt(n)  # pulseIn truncates: −0.5 µs
    spread = math.sqrt(20.0**2 + 1.0 / 12.0)
    assert abs(heard.std() - spread) < 4.0 * spread / math.sqrt(2 * n)
    early = Parameters().with_overrides(
        {"hcsr04.spurious_echo_probability": 0.2, "hcsr04.lost_echo_probability": 0.0}
    )
    spurious = Hcsr04Batch(early, np.arange(N_SEEDS), np.full(N_SEEDS, _x_for_distance(0.2)), 0.0).readings
    # 50 µs short of the ball's echo is 50e-6·343.21/2 = 8.58 mm nearer than the ball (the jitter is 5 µs)
    short = spurious < true_us - 50.0
    near = 0.18 - 0.00858  # a spurious echo comes from uniformly between 2 cm and the ball (0.2 m)
    assert abs(short.mean() - 0.2 * near / 0.18) < 4.0 * math.sqrt(0.2 * 0.8 / N_SEEDS)
    # those short ones: uniform over [0.02, 0.19142] m, their mean width the midpoint's, less pulseIn's 0.5 µs
    c = 331.3 * math.sqrt(1.0 + 20.0 / 273.15)
    mid_us = 2 * (0.02 + 0.2 - 0.00858) / 2 / c * 1e6 - 0.5
    spread_us = 2 * near / c * 1e6 / math.sqrt(12)
    assert abs(spurious[short].mean() - mid_us) < 4.0 * spread_us / math.sqrt(short.sum())


@pytest.mark.quick
def test_the_infrared_noise_has_its_parameters_statistics() -> None:
    p = Parameters().with_overrides({"gp2y0a21.noise_v": 0.02})
    batch = Gp2y0a21Batch(p, np.arange(N_SEEDS), np.full(N_SEEDS, _x_for_distance(0.3)), 0.0)
    volts = batch.output
    assert abs(volts.mean() - 0.92213) < 4.0 * 0.02 / math.sqrt(N_SEEDS)
    assert abs(volts.std() - 0.02) < 4.0 * 0.02 / math.sqrt(2 * N_SEEDS)


# --- seeds, batches, contracts ------------------------------------------------------------------------------
def _run(chain: Vl53l0xChain | Hcsr04Chain | Gp2y0a21Chain, seed: int) -> list[float]:
    chain.reset(-0.2, 0.0, seed=seed)
    out = []
    for b in range(40):
        t = _block(0.02 * b)
        out.append(chain.advance(t, -0.2 + 0.5 * t))
    return out


@pytest.mark.quick
@pytest.mark.parametrize("part", PARTS, ids=lambda p: p.name)
def test_the_same_seed_gives_the_same_readings_and_another_seed_others(part: BallSensorPart) -> None:
    p = Parameters().with_overrides(
        {"vl53l0x.wrong_return_probability": 0.2, "hcsr04.lost_echo_probability": 0.2}
    )
    one = _run(part.chain(p, 0), 11)  # type: ignore[arg-type]
    two = _run(part.chain(p, 1), 11)  # type: ignore[arg-type]
    other = _run(part.chain(p, 0), 12)  # type: ignore[arg-type]
    assert one == two  # reset(seed=11) restarts the noise from that seed, whatever came before
    assert one != other


@pytest.mark.quick
@pytest.mark.parametrize("part", PARTS, ids=lambda p: p.name)
def test_each_part_keeps_the_parts_contract_and_its_batch_is_its_single_run_bit_for_bit(
    part: BallSensorPart,
) -> None:
    assert part in registered("ball_sensor")
    assert not _parameter_problems(part)
    assert not _equation_problems(part, own_home=False)  # a new part's equations are at home in its module
    params = Parameters().with_overrides({"parts.ball_sensor": part.name})
    model = build_model(params)
    assert not part.mjcf.missing(model)
    assert part.batch.tolerance == 0.0
    for seed in (1, 2, 3):
        assert part.batch.difference(np.random.default_rng(seed), 24) == 0.0


@pytest.mark.quick
@pytest.mark.parametrize("part", PARTS, ids=lambda p: p.name)
def test_the_housing_is_drawn_at_the_mount_on_the_beam_without_contacts_or_mass(part: BallSensorPart) -> None:
    group = next(iter(part.groups))
    params = Parameters().with_overrides({"parts.ball_sensor": part.name, f"{group}.mount_x_m": 0.34})
    model = build_model(params)
    (_, housing), (_, aperture) = part.mjcf.elements
    geom, site = model.geom(housing), model.site(aperture)
    beam = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "beam")
    assert geom.bodyid[0] == beam and site.bodyid[0] == beam
    assert (geom.contype[0], geom.conaffinity[0], geom.group[0]) == (0, 0, 2)
    assert site.pos[0] == pytest.approx(0.34) and site.pos[1] == 0.0
    assert site.pos[2] == pytest.approx(
        params.ball_centre_height_m
    )  # the aperture at the ball's centre height
    assert geom.pos[0] - geom.size[0] == pytest.approx(0.34)  # the housing behind its aperture
    thesis = build_model()
    assert np.array_equal(model.body_mass, thesis.body_mass) and np.array_equal(
        model.body_inertia, thesis.body_inertia
    )
    assert model.ngeom == thesis.ngeom + 1 and model.nsite == thesis.nsite + 1


@pytest.mark.quick
def test_every_group_field_has_a_unit_a_source_and_bounds_with_reasons() -> None:
    for cls in (Vl53l0x, Hcsr04, Gp2y0a21):
        for f in fields(cls):
            md = f.metadata
            assert md["unit"] and md["source"] and md["why"], f"{cls.__name__}.{f.name}"
            assumed = "assumed" in md["source"]
            cited = any(word in md["source"] for word in ("data sheet", "user guide", "fit"))
            assert assumed or cited, f"{cls.__name__}.{f.name}: neither a source nor 'assumed'"


# --- a simulated rig reads the ball through the ultrasonic sensor ------------------------------------------
@pytest.mark.quick
@pytest.mark.parametrize("x0", [0.0, 0.05])
def test_a_rig_with_the_ultrasonic_sensor_reads_the_ball_within_its_resolution(x0: float) -> None:
    p = Parameters().with_overrides(
        {
            "parts.ball_sensor": "hcsr04",
            "hcsr04.lost_echo_probability": 0.0,
            "hcsr04.spurious_echo_probability": 0.0,
        }
    )
    rig = SimRig(p, seed=4)
    rig.reset(x0, 0.0)
    c = 331.3 * math.sqrt(1.0 + 20.0 / 273.15)
    times, xs, ons, reads, ends = [], [], [], [], []
    for _ in range(50):  # 1 s at 50 Hz, the DAC at 2.5 V: 0 V at the motor
        sample = rig.read()
        rig.write(2.5)
        block = rig.last_block
        assert block is not None
        times.append(block.time_s)
        xs.append(block.x_m)
        ons.append(block.on_track)
        reads.append(sample.ball_v)
        ends.append(float(block.time_s[-1]))
    t, x, on = np.concatenate(times), np.concatenate(xs), np.concatenate(ons)
    t0 = float(times[0][0])  # the chain starts with the first block: a trigger every 60 ms from there

    def on_track(trigger: float) -> bool:
        return (
            bool(on[min(np.searchsorted(t, trigger), len(t) - 1)])
            and abs(float(np.interp(trigger, t, x))) <= 0.323
        )

    def echo_end_s(
        trigger: float,
    ) -> float:  # when pulseIn returns: 2·d/c after the trigger, or at its timeout
        if not on_track(trigger):
            return trigger + 0.030
        return trigger + 2.0 * (MOUNT - R - float(np.interp(trigger, t, x))) / c

    for reading, end in zip(reads, ends, strict=True):
        k = math.floor((end - t0) / 0.060 + 1e-9)  # the last trigger by the block's end
        if echo_end_s(t0 + 0.060 * k) > end:
            k -= 1  # its echo not over yet: the board has the one before
        trigger = t0 + 0.060 * k
        x_true = float(np.interp(trigger, t, x))
        if not on_track(trigger):
            assert reading == 0.0  # no ball on the track: no echo
            continue
        decoded = MOUNT - R - reading * 1e-6 * c / 2.0
        assert abs(decoded - x_true) <= 0.003, (end, reading, decoded, x_true)  # the user guide's 0.3 cm
    assert x0 == 0.0 or 0.0 in reads  # the ball that rolls off the +x end leaves no echo


@pytest.mark.quick
def test_the_distance_a_rangefinder_sees_is_to_the_balls_near_surface() -> None:
    # mount 0.333 m out, ball centre at 0.1 m, radius 8.329 mm: 0.333 − 0.1 − 0.008329 = 0.224671 m (by hand)
    assert float(near_distance_m(np.array(0.333), np.array(0.1), np.array(0.008329))) == pytest.approx(
        0.224671, abs=1e-12
    )
    touching = near_distance_m(np.array(0.333), np.array(0.33), np.array(0.008329))
    assert float(touching) == 0.0  # the ball against the sensor: never negative
