"""The angle sensor parts beside the thesis's encoder: a potentiometer on the pivot (twin.parts.potentiometer),
the ams AS5600 (twin.parts.as5600) and none (twin.parts.no_angle). Each reading is checked against numbers
derived here (the divider by hand, the AS5600's counts from 4096 a turn, the filter's step from e^(−Δt/τ)), the
batch forms against the one-run forms bit for bit, and a simulated rig's readings against its true beam angle."""

from __future__ import annotations

import math
from collections.abc import Callable

import mujoco
import numpy as np
import pytest

from tests.test_parts import _check_part
from twin.daq import adc_quantize_v
from twin.model import build_model
from twin.parameters import ParameterError, Parameters
from twin.parts import AngleSensorPart, part_named, registered
from twin.parts.as5600 import AS5600_PART, AS5600Chain
from twin.parts.as5600 import HOUSING as AS5600_BOARD
from twin.parts.no_angle import NO_ANGLE
from twin.parts.potentiometer import HOUSING as POT_HOUSING
from twin.parts.potentiometer import POTENTIOMETER, PotentiometerChain
from twin.physics import PhysicsBlock
from twin.rigs.sim import SimRig

TRAVEL = math.radians(330.0)  # Bourns 3382
COUNT_RAD = 2.0 * math.pi / 4096  # one AS5600 LSB: 0.0879°


def _still(theta: float, t0: float = 0.0) -> PhysicsBlock:
    """A block of one 1 ms step ending (and starting) at θ."""
    return PhysicsBlock(
        np.array([t0, t0 + 1e-3]), np.zeros(2), np.array([theta, theta]), np.ones(2, dtype=bool)
    )


def _params(overrides: dict[str, object]) -> Parameters:
    return Parameters().with_overrides(overrides)  # type: ignore[arg-type]


# --- the potentiometer --------------------------------------------------------------------------------------
@pytest.mark.quick
def test_the_pots_wiper_at_three_angles_by_hand_read_by_an_arduino() -> None:
    p = _params(
        {
            "parts.angle_sensor": "potentiometer",
            "parts.io_board": "arduino_uno",
            "potentiometer.noise_rms_v": 0.0,
        }
    )
    chain = PotentiometerChain(p)
    # level: u = 1/2, sin(π) ≈ 0: 2.5 V, analogRead ⌊2.5·1024/5⌋ = 512
    assert chain.level_v(0.0) == 2.5
    assert chain.read_block_v(_still(0.0)) == 512.0
    # a quarter of the travel up (82.5°): u = 3/4, sin(3π/2) = −1: 5·(0.75 − 0.02) = 3.65 V → ⌊747.52⌋ = 747
    assert chain.level_v(TRAVEL / 4) == pytest.approx(3.65, abs=1e-12)
    assert chain.read_block_v(_still(TRAVEL / 4)) == 747.0
    # a quarter down: u = 1/4, sin(π/2) = 1: 5·(0.25 + 0.02) = 1.35 V → ⌊276.48⌋ = 276
    assert chain.level_v(-TRAVEL / 4) == pytest.approx(1.35, abs=1e-12)
    assert chain.read_block_v(_still(-TRAVEL / 4)) == 276.0
    # 0.3 rad, by the formula: u = 0.5 + 0.3/5.7596 = 0.552087, V = 5·(u + 0.02·sin 2πu) = 2.728...
    u = 0.5 + 0.3 / TRAVEL
    assert chain.level_v(0.3) == pytest.approx(5.0 * (u + 0.02 * math.sin(2 * math.pi * u)), rel=1e-14)
    # past the track's end (±165°) the wiper stays on its end: 5 V, 1023; 0 V, 0
    assert chain.level_v(3.0) == 5.0 and chain.read_block_v(_still(3.0)) == 1023.0
    assert chain.level_v(-3.0) == 0.0 and chain.read_block_v(_still(-3.0)) == 0.0


@pytest.mark.quick
def test_the_pot_on_the_thesis_card_reads_adc_volts_and_its_zero_shifts_the_curve() -> None:
    p = _params({"parts.angle_sensor": "potentiometer", "potentiometer.noise_rms_v": 0.0})
    assert p.parts.io_board == "pci1712"
    # the card's 12-bit ±5 V ADC (twin.daq): 3.65 V → code ⌊8.65/(10/4096) + ½⌋ = 3543, 3543·10/4096 − 5 V
    reading = PotentiometerChain(p).read_block_v(_still(TRAVEL / 4))
    assert reading == pytest.approx(3543 * 10 / 4096 - 5.0, abs=1e-12)
    assert reading == adc_quantize_v(PotentiometerChain(p).level_v(TRAVEL / 4), p.daq)
    # a 0.1 rad mounting zero: the level beam reads what a −0.1 rad beam read before
    shifted = PotentiometerChain(p.with_overrides({"potentiometer.zero_angle_rad": 0.1}))
    assert shifted.level_v(0.0) == PotentiometerChain(p).level_v(-0.1)


@pytest.mark.quick
def test_the_pots_noise_is_seeded_by_its_parameter_and_has_its_rms() -> None:
    base = {"parts.angle_sensor": "potentiometer", "potentiometer.noise_rms_v": 0.01}
    p = _params(base)

    def readings(params: Parameters, n: int = 4000) -> np.ndarray:
        chain = PotentiometerChain(params)
        return np.array([chain.read_block_v(_still(0.2, 0.02 * k)) for k in range(n)])

    first, again = readings(p), readings(p)
    assert np.array_equal(first, again)  # the same parameters: the same bits
    other = readings(p.with_overrides({"potentiometer.noise_seed": 1}))
    assert not np.array_equal(first, other)
    # 10 mV RMS through the card's 2.44 mV steps: σ² + LSB²/12 → 10.02 mV; the mean on the wiper's volts
    lsb = 10.0 / 4096
    level = PotentiometerChain(p).level_v(0.2)
    assert float(np.std(first)) == pytest.approx(math.sqrt(0.01**2 + lsb**2 / 12), rel=0.05)
    assert abs(float(np.mean(first)) - level) < 4 * 0.01 / math.sqrt(4000) + lsb / 2


# --- the AS5600 ----------------------------------------------------------------------------------------------
def _as5600(**values: object) -> AS5600Chain:
    """An AS5600 chain without noise or filter unless asked."""
    overrides = {"parts.angle_sensor": "as5600", "as5600.noise_rms_rad": 0.0, "as5600.settling_time_s": 0.0}
    overrides.update({f"as5600.{k}": v for k, v in values.items()})
    return AS5600Chain(_params(overrides))


@pytest.mark.quick
def test_the_as5600_counts_at_known_angles() -> None:
    chain = _as5600()
    # the magnet at half a turn on the level beam: 2048; 4096 counts a turn
    assert chain.read_block_v(_still(0.0)) == 2048.0
    assert _as5600().read_block_v(_still(0.1)) == 2113.0  # 0.1·4096/2π = 65.19 → 2113
    assert _as5600().read_block_v(_still(-0.1)) == 1983.0  # 2048 − 65.19 = 1982.81 → 1983
    assert _as5600().read_block_v(_still(10.4 * COUNT_RAD)) == 2058.0
    assert _as5600().level_v(0.25) == 2048.0 + round(0.25 / COUNT_RAD)  # 162.97 → 2211


@pytest.mark.quick
def test_the_as5600_wraps_from_4095_to_0() -> None:
    # the magnet mounted at count 4095 on the level beam: one count up is 0, two are 1, one down 4094
    chain = _as5600(magnet_angle_at_level_rad=4095 * COUNT_RAD)
    reads = [
        chain.read_block_v(_still(k * COUNT_RAD, 1e-3 * i)) for i, k in enumerate([-1, 0, 1, 2, 1, 0, -1])
    ]
    assert reads == [4094.0, 4095.0, 0.0, 1.0, 0.0, 4095.0, 4094.0]


@pytest.mark.quick
def test_the_as5600_hysteresis_holds_the_count_until_the_angle_leaves_its_band() -> None:
    chain = _as5600(hysteresis_lsb=2)
    t = iter(np.arange(100) * 1e-3)

    def at(counts_from_level: float) -> float:
        return chain.read_block_v(_still(counts_from_level * COUNT_RAD, float(next(t))))

    assert at(0.0) == 2048.0
    assert at(2.0) == 2048.0  # 2 LSB: within 2 + ½
    assert at(2.6) == 2049.0  # past it: the count 2 behind the angle, rounded (2050.6 − 2 → 2049)
    assert at(4.0) == 2050.0  # 2052 − 2
    assert at(2.0) == 2050.0  # back 2: held
    assert at(-0.6) == 2049.0  # 2047.4 is 2.6 below 2050: 2 above the angle, rounded (2049.4 → 2049)
    # across the wrap: the band is measured around the circle
    wrap = _as5600(hysteresis_lsb=1, magnet_angle_at_level_rad=4095.4 * COUNT_RAD)
    assert wrap.read_block_v(_still(0.0)) == 4095.0
    assert wrap.read_block_v(_still(1.0 * COUNT_RAD, 1e-3)) == 4095.0  # 4096.4: 1.4 from 4095, within 1.5
    # 4097.4: 2.4 away → ⌊4097.4 − 1 + ½⌋ mod 4096
    assert wrap.read_block_v(_still(2.0 * COUNT_RAD, 2e-3)) == 0.0


@pytest.mark.quick
def test_the_as5600_hysteresis_stops_the_noise_toggling_a_still_magnet() -> None:
    # the magnet half-way between 2048 and 2049, the data sheet's 0.015° RMS (0.17 LSB) of noise
    def still_readings(hysteresis: int) -> set[float]:
        chain = AS5600Chain(
            _params(
                {
                    "as5600.hysteresis_lsb": hysteresis,
                    "as5600.magnet_angle_at_level_rad": 2048.5 * COUNT_RAD,
                    "as5600.noise_seed": 11,
                }
            )
        )
        return {chain.read_block_v(_still(0.0, 1e-3 * k)) for k in range(400)}

    assert still_readings(0) == {2048.0, 2049.0}  # toggles
    assert len(still_readings(1)) == 1  # 1.5 LSB is 9σ: held


@pytest.mark.quick
def test_the_as5600_slow_filter_lags_a_step_by_its_settling_time() -> None:
    chain = _as5600(settling_time_s=2.2e-3)
    assert chain.read_block_v(_still(0.0)) == 2048.0
    # a 100-count step over one 1 ms step: y = 2048 + 100·(1 − e^(−1/(2.2/3))) = 2122.43 → 2122
    step = PhysicsBlock(
        np.array([1e-3, 2e-3]), np.zeros(2), np.array([0.0, 100 * COUNT_RAD]), np.ones(2, bool)
    )
    expected = 2048 + 100 * (1 - math.exp(-1e-3 / (2.2e-3 / 3)))
    assert chain.read_block_v(step) == float(math.floor(expected + 0.5)) == 2122.0
    # held there for a 20 ms block: settled on 2148
    held = PhysicsBlock(
        2e-3 + np.arange(21) * 1e-3, np.zeros(21), np.full(21, 100 * COUNT_RAD), np.ones(21, bool)
    )
    assert chain.read_block_v(held) == 2148.0


@pytest.mark.quick
def test_the_as5600_analog_output_through_the_boards_adc() -> None:
    # OUTS = 01: VDD·(0.1 + 0.8·ANGLE/4096); 2048 → 2.5 V → analogRead 512
    chain = _as5600(analog_output=True)
    p_uno = {"parts.io_board": "arduino_uno"}
    uno = AS5600Chain(
        _params(
            {
                **p_uno,
                "as5600.analog_output": True,
                "as5600.noise_rms_rad": 0.0,
                "as5600.settling_time_s": 0.0,
            }
        )
    )
    assert uno.read_block_v(_still(0.0)) == 512.0
    assert chain.level_v(0.0) == 2.5
    # ZPOS = 1024: ANGLE = 1024 → 5·(0.1 + 0.2) = 1.5 V → ⌊307.2⌋ = 307
    zpos = AS5600Chain(
        _params(
            {
                **p_uno,
                "as5600.analog_output": True,
                "as5600.zpos_counts": 1024,
                "as5600.noise_rms_rad": 0.0,
                "as5600.settling_time_s": 0.0,
            }
        )
    )
    assert zpos.level_v(0.0) == pytest.approx(1.5, abs=1e-15) and zpos.read_block_v(_still(0.0)) == 307.0
    # on the thesis card: 2.5 V is an exact code of its ±5 V ADC
    assert chain.read_block_v(_still(0.0)) == 2.5


@pytest.mark.quick
def test_the_as5600_group_refuses_what_the_chip_cannot_do() -> None:
    with pytest.raises(
        ParameterError, match=r"as5600\.hysteresis_lsb = 4 LSB is impossible: it must be <= 3"
    ):
        _params({"as5600.hysteresis_lsb": 4})
    with pytest.raises(ParameterError, match=r"as5600\.zpos_counts = 4096 count is impossible"):
        _params({"as5600.zpos_counts": 4096})


# --- none -----------------------------------------------------------------------------------------------------
@pytest.mark.quick
def test_none_reads_zero_at_any_angle() -> None:
    chain = NO_ANGLE.chain(_params({"parts.angle_sensor": "none"}))
    assert [chain.read_block_v(_still(t)) for t in (-0.7, 0.0, 0.3)] == [0.0, 0.0, 0.0]
    assert chain.level_v(0.5) == 0.0
    with pytest.raises(ParameterError, match=r"no_angle\.grounded_reading = 1\.0"):
        _params({"no_angle.grounded_reading": 1.0})


# --- every angle part: the contract, batch = single, the MJCF --------------------------------------------------
ANGLE_PARTS = [POTENTIOMETER, AS5600_PART, NO_ANGLE]


@pytest.mark.quick
@pytest.mark.parametrize("part", ANGLE_PARTS, ids=lambda p: p.name)
def test_each_angle_part_keeps_the_contract_and_its_batch_is_its_single_bit_for_bit(
    part: AngleSensorPart,
) -> None:
    assert part in registered("angle_sensor") and part_named("angle_sensor", part.name) is part
    # the equations' home is the part's own module (tests/test_parts.py's own_home is for the thesis's parts)
    _check_part(part, seed=20261207, own_home=False)
    module = part.batch.home.rsplit(".", 1)[0]
    assert all(eq.__module__ == module for eq in part.equations)
    assert part.batch.tolerance == 0.0
    for seed in (1, 2, 3):
        assert part.batch.difference(np.random.default_rng(seed), 64) == 0.0


@pytest.mark.quick
@pytest.mark.parametrize(("name", "geom"), [("potentiometer", POT_HOUSING), ("as5600", AS5600_BOARD)])
def test_the_sensors_housing_is_drawn_at_the_pivot_without_contact(name: str, geom: str) -> None:
    assert mujoco.mj_name2id(build_model(), mujoco.mjtObj.mjOBJ_GEOM, geom) < 0  # not in the thesis's rig
    model = build_model(_params({"parts.angle_sensor": name}))
    g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, geom)
    assert g >= 0
    assert (model.geom_contype[g], model.geom_conaffinity[g], model.geom_group[g]) == (0, 0, 2)
    assert model.geom_bodyid[g] == 0  # on the frame: the body is fixed, the shaft turns with the beam
    pivot = build_model().body("beam").pos
    assert model.geom_pos[g][0] == pivot[0] and model.geom_pos[g][2] == pivot[2]  # on the hinge's axis
    assert model.nbody == build_model().nbody and model.body_mass.sum() == build_model().body_mass.sum()


# --- a simulated rig with each sensor ----------------------------------------------------------------------------
def _pot_angle(reading_v: float, params: Parameters) -> float:
    """The beam angle whose wiper volts are ``reading_v``, by bisection on the divider written here."""

    def wiper(theta: float) -> float:
        u = min(max(0.5 + theta / TRAVEL, 0.0), 1.0)
        return 5.0 * min(max(u + 0.02 * math.sin(2 * math.pi * u), 0.0), 1.0)

    lo, hi = -1.0, 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if wiper(mid) < reading_v else (lo, mid)
    return 0.5 * (lo + hi)


def _as5600_angle(reading: float, params: Parameters) -> float:
    return reading * COUNT_RAD - math.pi


def _zero(reading: float, params: Parameters) -> float:
    assert reading == 0.0
    return 0.0


# decode, the angle resolution at the reading (the card's 2.44 mV over the divider's slope, one AS5600 count)
SENSORS: list[tuple[dict[str, object], Callable[[float, Parameters], float], float]] = [
    (
        {"parts.angle_sensor": "potentiometer", "potentiometer.noise_rms_v": 0.0},
        _pot_angle,
        10 / 4096 / 5 * TRAVEL,
    ),
    ({"parts.angle_sensor": "as5600", "as5600.noise_rms_rad": 0.0}, _as5600_angle, COUNT_RAD),
]


def _run(
    overrides: dict[str, object], theta0: float
) -> tuple[list[float], list[float], list[float], Parameters]:
    """1 s of the rig held at θ0 and released at the amplifier's zero (the thesis's DAC at 2.5 V)."""
    params = _params(overrides)
    rig = SimRig(params, seed=5)
    rig.reset(0.0, theta0)
    readings, angles, rates = [], [], []
    for _ in range(51):  # the start block and 1 s of 20 ms blocks
        sample = rig.read()
        rig.write(2.5)
        block = rig.last_block
        assert block is not None
        readings.append(sample.angle_v)
        angles.append(float(block.theta_rad[-1]))
        rates.append(float(np.max(np.abs(np.diff(block.theta_rad) / np.diff(block.time_s)))))
    assert rig.parts.angle_sensor.name == params.parts.angle_sensor
    return readings, angles, rates, params


@pytest.mark.quick
@pytest.mark.parametrize("overrides", [s[0] for s in SENSORS] + [{"parts.angle_sensor": "none"}], ids=str)
def test_a_level_beam_on_the_rig_reads_level(overrides: dict[str, object]) -> None:
    decode = {s[0]["parts.angle_sensor"]: s[1] for s in SENSORS}.get(overrides["parts.angle_sensor"], _zero)
    readings, angles, _, params = _run(overrides, 0.0)
    assert max(abs(a) for a in angles) < 1e-9  # the balanced beam at 0 V stays level
    expected = {"potentiometer": 2.5, "as5600": 2048.0, "none": 0.0}[params.parts.angle_sensor]
    assert readings == [expected] * len(readings)
    assert all(decode(r, params) == pytest.approx(0.0, abs=1e-12) for r in readings)


@pytest.mark.quick
@pytest.mark.parametrize(
    ("overrides", "decode", "resolution"), SENSORS, ids=[str(s[0]["parts.angle_sensor"]) for s in SENSORS]
)
def test_a_swinging_beam_on_the_rig_decodes_to_its_true_angle(
    overrides: dict[str, object], decode: Callable[[float, Parameters], float], resolution: float
) -> None:
    # released at 0.1 rad with the motor at 0 V, the beam falls toward its stop (0.74 rad after 1 s)
    readings, angles, rates, params = _run(overrides, 0.1)
    assert max(angles) > 0.5
    lag_s = 2.2e-3 / 3 if params.parts.angle_sensor == "as5600" else 0.0  # the AS5600's slow filter
    for reading, angle, rate in zip(readings, angles, rates, strict=True):
        assert abs(decode(reading, params) - angle) <= resolution + rate * lag_s + 1e-9, (reading, angle)


@pytest.mark.quick
@pytest.mark.parametrize("name", ["potentiometer", "as5600"])
def test_a_reset_rig_reads_as_a_fresh_one_noise_and_filter_included(name: str) -> None:
    # the chain has no reset (AngleSensorChain): a block that starts before the last one ended starts a new run
    params = _params({"parts.angle_sensor": name})  # the thesis's card and motor, 2.5 V: 0 V at the motor

    def ticks(rig: SimRig, n: int = 12) -> list[float]:
        out = []
        for _ in range(n):
            out.append(rig.read().angle_v)
            rig.write(2.5)
        return out

    used = SimRig(params, seed=2)
    used.reset(0.0, -0.2)
    ticks(used)
    used.reset(0.0, 0.3)
    fresh = SimRig(params, seed=2)
    fresh.reset(0.0, 0.3)
    again, first = ticks(used), ticks(fresh)
    assert again == first
    # and they read the new start at once (within the noise), not the old run's angle through a filter
    level = {"potentiometer": PotentiometerChain(params).level_v(0.3), "as5600": 2048 + 0.3 / COUNT_RAD}[name]
    if name == "potentiometer":
        assert abs(first[0] - level) <= 0.01  # 1 mV RMS of noise, the card's 2.44 mV steps
    else:
        assert abs(first[0] - level) <= 1.5


@pytest.mark.quick
def test_the_as5600_filter_runs_on_over_steps_the_rig_did_not_show_it() -> None:
    chain = _as5600(settling_time_s=2.2e-3)
    assert chain.read_block_v(_still(0.0)) == 2048.0
    # 10 ms unobserved, the magnet moved 100 counts: e^(−10/0.733) ≈ 1e-6 of the step is left → 2148, where
    # one 1 ms step alone would give 2122 (the previous test)
    assert chain.read_block_v(_still(100 * COUNT_RAD, 11e-3)) == 2148.0


@pytest.mark.quick
def test_the_parts_groups_go_through_a_parameter_file_and_back(tmp_path) -> None:
    p = _params(
        {
            "parts.angle_sensor": "as5600",
            "parts.io_board": "arduino_nano",
            "as5600.analog_output": True,
            "as5600.hysteresis_lsb": 2,
            "potentiometer.noise_seed": 5,
            "arduino.servo_min_us": 1000,
        }
    )
    p.save(tmp_path / "rig.toml")
    assert Parameters.from_file(tmp_path / "rig.toml") == p
