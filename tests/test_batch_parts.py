"""The batch engine (twin.rigs.batch.run_batch) on rigs of other parts: every run of a batch equals the same run
alone on ``SimRig`` (``run_closed_loop``) bit for bit (every log array: readings, commands, true states; and the
verdict) for a servo rig (end lever, hobby servo, VL53L0X, no angle sensor, Arduino Uno) and for the thesis's
pivot rig with its sensors swapped (HC-SR04, potentiometer, AS5600), each run with its own parameters. The
controllers are written here from the boards' units alone: a PD on the decoded readings."""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable, Iterator
from dataclasses import fields

import numpy as np
import pytest

import twin.parts  # noqa: F401  (registers the parts)
from twin import converters
from twin.engine import RunResult
from twin.interface import CommandRange, Controller, DaqSample, RigError
from twin.log import RunLog
from twin.parameters import Parameters
from twin.parts import arduino, contract
from twin.parts.as5600 import AS5600
from twin.parts.gp2y0a21 import Gp2y0a21
from twin.parts.hcsr04 import Hcsr04
from twin.parts.potentiometer import Potentiometer
from twin.parts.servo import Servo, servo_rest_pulse_us
from twin.parts.vl53l0x import OUT_OF_RANGE_MM, Vl53l0x
from twin.rigs.batch import run_batch
from twin.rigs.sim import SimRig, run_closed_loop
from twin.rigs.vector import VectorRig

SERVO_RIG = Parameters().with_overrides(
    {
        "parts.beam_drive": "end_lever",
        "parts.actuator": "hobby_servo",
        "parts.ball_sensor": "vl53l0x",
        "parts.angle_sensor": "none",
        "parts.io_board": "arduino_uno",
    }
)

# --- decoding the boards' readings, by hand from the data sheets' laws -------------------------------------------


def _tof_x_m(p: Parameters) -> Callable[[float], float | None]:
    """VL53L0X: the range (mm) to the ball's near surface from the sensor at mount_x_m looking toward −x:
    x = mount − range/1000 − r; the out-of-range code is no position."""
    mount, r = p.of(Vl53l0x).mount_x_m, p.ball.radius_m
    return lambda mm: None if mm >= OUT_OF_RANGE_MM else mount - mm / 1000.0 - r


def _echo_x_m(p: Parameters) -> Callable[[float], float | None]:
    """HC-SR04: the echo's width (µs) is the round trip 2d/c, c = 331.3·√(1 + T/273.15) m/s (ideal gas); 0 is no
    echo."""
    g = p.of(Hcsr04)
    c = 331.3 * math.sqrt(1.0 + g.temperature_c / 273.15)
    return lambda us: None if us <= 0.0 else g.mount_x_m - us * 1e-6 * c / 2.0 - p.ball.radius_m


def _ir_x_m(p: Parameters) -> Callable[[float], float | None]:
    """GP2Y0A21 read by the card's ADC (volts): the inverse-distance curve V = a/(d + b) + c inverted,
    d = a/(V − c) − b (the fold below its peak read as the far branch)."""
    g = p.of(Gp2y0a21)

    def x_m(volts: float) -> float | None:
        if volts <= g.curve_c_v:
            return None
        return g.mount_x_m - (g.curve_a_v_m / (volts - g.curve_c_v) - g.curve_b_m) - p.ball.radius_m

    return x_m


def _wire_x_m(p: Parameters) -> Callable[[float], float | None]:
    return lambda volts: float(converters.ball_position_m(volts, p.software))  # eq 6.3.1


def _encoder_theta(p: Parameters) -> Callable[[float], float]:
    return lambda volts: float(converters.beam_angle_rad(volts, p.software))  # eq 6.2.6 inverted


def _pot_theta(p: Parameters) -> Callable[[float], float]:
    """A potentiometer read by the card's ADC (volts): the wiper at mid-track for θ = zero, linear in θ over the
    electrical travel (its linearity error ignored)."""
    pot = p.of(Potentiometer)
    return lambda volts: pot.zero_angle_rad + pot.electrical_travel_rad * (volts / pot.supply_v - 0.5)


def _as5600_theta(p: Parameters) -> Callable[[float], float]:
    """AS5600's RAW ANGLE over I²C: 4096 counts a turn, the magnet at φ_level for the level beam."""
    phase = p.of(AS5600).magnet_angle_at_level_rad
    return lambda counts: counts * 2.0 * math.pi / 4096.0 - phase


def _as5600_out_theta(p: Parameters) -> Callable[[float], float]:
    """AS5600's OUT pin read by the card's ADC (volts): V = VDD·(0.1 + 0.8·ANGLE/4096), ZPOS = 0 (data sheet,
    "Analog Output Mode", OUTS = 01)."""
    g = p.of(AS5600)
    return lambda volts: (volts / g.supply_v - 0.1) / 0.8 * 2.0 * math.pi - g.magnet_angle_at_level_rad


class PivotPD(Controller):
    """The pivot rig's PD (state feedback on finite differences, the thesis's gains) on the decoded readings,
    returning the card's DAC volts."""

    name = "pivot-pd"

    def __init__(self, p: Parameters, ball: Callable[[float], float | None], angle: Callable[[float], float]):
        super().__init__()
        self.sw, self.ball, self.angle = p.software, ball, angle

    def _measure(self, sample: DaqSample) -> tuple[float, float]:
        x = self.ball(sample.ball_v)
        return (self.previous[0] if x is None else x), self.angle(sample.angle_v)

    def start(self, sample: DaqSample) -> None:
        self.previous = (0.0, 0.0)
        self.previous = self._measure(sample)

    def update(self, sample: DaqSample) -> float:
        x, theta = self._measure(sample)
        xdot = (x - self.previous[0]) / self.period_s
        thetadot = (theta - self.previous[1]) / self.period_s
        self.previous = (x, theta)
        volts = -(-36.34 * x + 24.6 * theta - 15.96 * xdot + 3.98 * thetadot)
        return converters.clip_command_v(converters.dac_command_v(volts, self.sw), self.sw)


class ServoPD(Controller):
    """The servo rig's PD on the ball alone (no angle sensor) returning a pulse width (µs): the rest pulse plus
    600 µs/m·x + 400 µs/(m/s)·ẋ, held within ±300 µs of it."""

    name = "servo-pd"

    def __init__(self, p: Parameters) -> None:
        super().__init__()
        self.ball = _tof_x_m(p)
        self.rest_us = servo_rest_pulse_us(p)

    def start(self, sample: DaqSample) -> None:
        x = self.ball(sample.ball_v)
        self.previous = 0.0 if x is None else x

    def update(self, sample: DaqSample) -> float:
        x = self.ball(sample.ball_v)
        x = self.previous if x is None else x
        xdot = (x - self.previous) / self.period_s
        self.previous = x
        pulse = self.rest_us + 600.0 * x + 400.0 * xdot
        return min(max(pulse, self.rest_us - 300.0), self.rest_us + 300.0)


class Catalogue:
    """One controller, made for each run's parameters (no batched form: the batch engine's scalar loop)."""

    def __init__(self, make: Callable[[Parameters], Controller]) -> None:
        self.NAMES = ("pd",)
        self._make = make

    def make(self, name: str, params: Parameters | None = None) -> Controller:
        return self._make(params or Parameters())


def _assert_same_run(single: RunResult, batched: RunResult, what: str) -> None:
    assert json.dumps(single.verdict.to_json()) == json.dumps(batched.verdict.to_json()), what
    assert single.log is not None and batched.log is not None
    for f in fields(RunLog):
        a, b = getattr(single.log, f.name), getattr(batched.log, f.name)
        assert a.shape == b.shape and np.array_equal(a, b, equal_nan=True), f"{what}: {f.name}"


def _check(
    catalogue: Catalogue,
    x0: np.ndarray,
    theta0: np.ndarray,
    seeds: np.ndarray,
    params: list[Parameters],
    duration_s: float,
) -> list[RunResult]:
    """``run_batch`` against ``run_closed_loop`` run by run: every log array and the verdict, bit for bit."""
    runs = run_batch(
        catalogue,
        "pd",
        x0_m=x0,
        theta0_rad=theta0,
        seeds=seeds,
        duration_s=duration_s,
        params=params,
        nthread=2,
        record=True,
    )
    assert len(runs) == len(x0)
    for i, batched in enumerate(runs):
        single = run_closed_loop(
            catalogue.make("pd", params[i]),
            x0_m=float(x0[i]),
            theta0_rad=float(theta0[i]),
            duration_s=duration_s,
            seed=int(seeds[i]),
            params=params[i],
        )
        _assert_same_run(single, batched, f"run {i} (x0 = {x0[i]}, θ0 = {theta0[i]}, seed {seeds[i]})")
    return runs


# --- the servo rig -----------------------------------------------------------------------------------------------


@pytest.mark.quick
def test_a_servo_rig_batch_equals_its_single_runs_bit_for_bit() -> None:
    """Five runs, noise on (wrong returns, range noise), each its own servo dead band and range noise; one start
    loses the ball: the runs that go on after it keep their bits."""
    x0 = np.array([0.1, -0.15, 0.3, 0.0, 0.05])
    theta0 = np.array([0.0, 0.03, 0.1, 0.0, -0.02])
    seeds = np.array([0, 1, 2, 3, 4])
    params = [
        SERVO_RIG.with_overrides(
            {"servo.deadband_us": 2.0 + 4.0 * i, "vl53l0x.sigma_fraction": 0.02 + 0.01 * i}
        )
        for i in range(len(x0))
    ]
    runs = _check(Catalogue(ServoPD), x0, theta0, seeds, params, duration_s=3.0)
    lost = [r.verdict.ball_lost for r in runs]
    assert any(lost) and not all(lost)  # some runs leave the batch, the others go on


@pytest.mark.quick
def test_the_servo_rigs_batch_reads_millimetres_and_writes_the_servos_target() -> None:
    """Noise off: the held ball's first range is the distance by hand, rint(1000·(mount − x0 − r)) mm; each
    tick's actuator control is the SG90's target for the pulse the servo accepted (its dead band by hand:
    a pulse moves the target only if it differs from the accepted one by more than the band)."""
    p = SERVO_RIG
    x0 = np.array([0.1, -0.12])
    (run, _) = run_batch(
        Catalogue(ServoPD),
        "pd",
        x0_m=x0,
        theta0_rad=np.zeros(2),
        seeds=np.array([5, 6]),
        duration_s=1.0,
        noise=False,
        params=p,
        nthread=1,
        record=True,
    )
    log = run.log
    assert log is not None
    g, s = p.of(Vl53l0x), p.of(Servo)
    assert log.datam1[0] == round(1000.0 * (g.mount_x_m - 0.1 - p.ball.radius_m))  # 333 − 100 − 8.329 → 225
    assert log.datam1[0] == 225.0
    assert np.all(log.datam2 == 0.0)  # no angle sensor: a grounded input
    accepted = math.nan
    for k, (pulse, target) in enumerate(zip(log.aout.tolist(), log.motor_volts_v.tolist(), strict=True)):
        written = float(math.trunc(pulse))  # writeMicroseconds(int): whole µs at 16 MHz
        if math.isnan(accepted) or abs(written - accepted) > s.deadband_us:
            accepted = written
        by_hand = -math.pi / 2 + (accepted - 1000.0) * math.pi / 1000.0  # SG90: ±90° at 1…2 ms
        assert target == pytest.approx(by_hand, abs=1e-12), f"tick {k}"
    assert log.aout[0] == 1500.0  # the rest pulse: the horn level with the beam level


@pytest.mark.quick
def test_each_servo_rig_of_a_vector_is_its_single_rig() -> None:
    """The vector environment's rigs (``VectorRig``, a ``BatchRig`` per cohort) on the servo rig: each rig's
    readings, true state and actuator control are its ``SimRig``'s, pulses inside and across the dead band."""
    x0, th0, seeds = np.array([0.1, -0.05]), np.array([0.0, 0.02]), np.array([3, 4])
    vector = VectorRig(2, SERVO_RIG, nthread=1)
    start, first = vector.reset([0, 1], [SERVO_RIG, SERVO_RIG], x0, th0, seeds)
    singles = [SimRig(SERVO_RIG, seed=int(seed)) for seed in seeds]
    for rig, x, th in zip(singles, x0, th0, strict=True):
        rig.reset(float(x), float(th))
    steps = [start, first]
    pulses = ([1500.0, 1500.0], [1504.5, 1460.0], [1540.0, 1466.0], [1600.0, 1700.0])
    for k in range(len(steps) + len(pulses)):
        if k >= 2:
            command = pulses[k - 2]
            for rig, c in zip(singles, command, strict=True):
                rig.write(c)
            steps.append(vector.step([0, 1], np.array(command)))
        reads = [rig.read() for rig in singles]
        blocks = steps[k]
        np.testing.assert_array_equal(blocks.ball_v, [r.ball_v for r in reads])
        np.testing.assert_array_equal(blocks.angle_v, [r.angle_v for r in reads])
        np.testing.assert_array_equal(blocks.state, [rig.true_state() for rig in singles])
        np.testing.assert_array_equal(blocks.motor_v, [rig.motor_volts_v for rig in singles])


# --- the pivot rig with its sensors swapped ------------------------------------------------------------------------

VARIANTS: dict[str, tuple[dict[str, object], Callable[[Parameters], Controller]]] = {
    "hcsr04+encoder": (
        {"parts.ball_sensor": "hcsr04"},
        lambda p: PivotPD(p, _echo_x_m(p), _encoder_theta(p)),
    ),
    "gp2y0a21+encoder": (
        {"parts.ball_sensor": "gp2y0a21"},
        lambda p: PivotPD(p, _ir_x_m(p), _encoder_theta(p)),
    ),
    "wire+potentiometer": (
        {"parts.angle_sensor": "potentiometer"},
        lambda p: PivotPD(p, _wire_x_m(p), _pot_theta(p)),
    ),
    "hcsr04+as5600": (
        {"parts.ball_sensor": "hcsr04", "parts.angle_sensor": "as5600", "as5600.hysteresis_lsb": 1},
        lambda p: PivotPD(p, _echo_x_m(p), _as5600_theta(p)),
    ),
    "vl53l0x+as5600-analog": (
        {"parts.ball_sensor": "vl53l0x", "parts.angle_sensor": "as5600", "as5600.analog_output": True},
        lambda p: PivotPD(p, _tof_x_m(p), _as5600_out_theta(p)),
    ),
}


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_a_sensor_swapped_pivot_rig_batch_equals_its_single_runs_bit_for_bit(variant: str) -> None:
    """Four runs of the thesis's pivot, motor and card with other sensors, each run its own noise seeds (the
    angle sensors' are parameters) and sensor constants, noise on."""
    overrides, make = VARIANTS[variant]
    base = Parameters().with_overrides(overrides)
    x0 = np.array([0.14, -0.13, 0.25, 0.0])
    theta0 = np.array([-0.2, 0.29, -0.7, 0.0])
    seeds = np.array([0, 1, 2, 3])
    # each run's own: the air's temperature (°C), the range noise, the angle sensor's noise seed
    own = {
        "hcsr04": lambda i: {"hcsr04.temperature_c": 5.0 + 10.0 * i},
        "vl53l0x": lambda i: {"vl53l0x.sigma_fraction": 0.02 + 0.01 * i},
        "gp2y0a21": lambda i: {"gp2y0a21.noise_v": 0.005 + 0.005 * i},
        "potentiometer": lambda i: {"potentiometer.noise_seed": i + 1, "potentiometer.noise_rms_v": 0.002},
        "as5600": lambda i: {"as5600.noise_seed": i + 1},
    }
    params = []
    for i in range(len(x0)):
        values: dict[str, object] = {}
        for role in ("parts.ball_sensor", "parts.angle_sensor"):
            values.update(own.get(str(overrides.get(role, "")), lambda i: {})(i))
        params.append(base.with_overrides(values))
    runs = _check(Catalogue(make), x0, theta0, seeds, params, duration_s=2.0)
    assert any(r.verdict.ball_lost for r in runs)  # the −0.7 rad start loses its ball


@pytest.mark.quick
def test_the_arduinos_batch_write_is_its_write_for_servo_pulses_and_step_targets(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """``batch_dac`` against ``dac_writer`` run by run, bit for bit (the sign of a zero too): pulses truncated
    to whole µs within 544…2400 µs (Servo.h), and for a STEP/DIR actuator the moveTo target, a C long within the
    travel (here ±1000 microsteps)."""
    board = contract.part_named("io_board", "arduino_uno")
    assert isinstance(board, contract.IoBoardPart) and board.batch_dac is not None
    commands = np.array([-3000.0, -0.5, -0.0, 0.4, 1499.9, 1500.2, 2400.7, 1e9, -math.inf, math.inf])
    runs = np.arange(len(commands))
    pulses = board.batch_dac([SERVO_RIG] * len(commands))(runs, commands)
    assert pulses.tolist() == [544.0, 544.0, 544.0, 544.0, 1499.0, 1500.0, 2400.0, 2400.0, 544.0, 2400.0]
    monkeypatch.setitem(arduino._STEP_DIR_ACTUATORS, "hobby_servo", lambda p: CommandRange(-1000.0, 1000.0))
    params = [SERVO_RIG] * len(commands)
    targets = board.batch_dac(params)(runs, commands)
    assert targets.tolist() == [-1000.0, 0.0, 0.0, 0.0, 1000.0, 1000.0, 1000.0, 1000.0, -1000.0, 1000.0]
    one = [board.dac_writer(p)(float(c)) for p, c in zip(params, commands.tolist(), strict=True)]
    assert targets.tobytes() == np.array(one).tobytes()  # −0.5 → +0.0, as math.trunc's int
    with pytest.raises(ValueError, match="moveTo takes a number of microsteps"):
        board.batch_dac(params)(runs[:1], np.array([math.nan]))


# --- a part with no batch runtime ---------------------------------------------------------------------------------


@pytest.fixture
def fresh_registry(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """The registry as it is, restored after the test (a test's registrations do not leak)."""
    monkeypatch.setattr(
        contract, "_REGISTRY", {role: dict(parts) for role, parts in contract._REGISTRY.items()}
    )
    contract._rig_parts.cache_clear()
    yield
    contract._rig_parts.cache_clear()


@pytest.mark.quick
@pytest.mark.usefixtures("fresh_registry")
def test_a_part_without_a_batch_runtime_is_refused_naming_it() -> None:
    one_run = contract.register(
        dataclasses.replace(
            contract.part_named("ball_sensor", "vl53l0x"), name="vl53l0x_alone", batch_chain=None
        )
    )
    assert isinstance(one_run, contract.BallSensorPart)
    p = SERVO_RIG.with_overrides({"parts.ball_sensor": "vl53l0x_alone"})
    with pytest.raises(
        RigError,
        match=r"no batch runtime for parts\.ball_sensor = 'vl53l0x_alone' \(no BallSensorPart\.batch_chain\)",
    ):
        run_batch(
            Catalogue(ServoPD),
            "pd",
            x0_m=np.array([0.1]),
            theta0_rad=np.zeros(1),
            seeds=np.array([0]),
            params=p,
        )
    # the same rig runs one run at a time
    alone = run_closed_loop(ServoPD(p), x0_m=0.1, theta0_rad=0.0, duration_s=0.2, seed=0, params=p)
    assert alone.ended == "all ticks"
