"""The batch engine (twin.rigs.batch.run_batch): every run of a batch equals the same run alone, bit for bit —
every log array and the verdict — with the controllers vectorized or one scalar instance per run."""

import json
from dataclasses import fields

import numpy as np
import pytest

from controllers import registry
from twin import converters
from twin.engine import RunResult
from twin.interface import Controller, DaqSample
from twin.log import RunLog
from twin.parameters import Parameters, SoftwareCalibration
from twin.rigs.batch import run_batch
from twin.rigs.sim import run_closed_loop

# Hardware starts, a start that loses the ball quickly, and the origin.
X0 = np.array([0.14, -0.13, 0.25, 0.0])
THETA0 = np.array([-0.2, 0.29, -0.7, 0.0])
SEEDS = np.array([0, 1, 2])


class FiniteDifferenceFeedback(Controller):
    """A user's own scalar controller (the README's example): state feedback with finite-difference rates."""

    name = "mine"

    def __init__(self, software: SoftwareCalibration) -> None:
        super().__init__()
        self.sw = software

    def _measure(self, sample: DaqSample) -> tuple[float, float]:
        return converters.ball_position_m(sample.ball_v, self.sw), converters.beam_angle_rad(
            sample.angle_v, self.sw
        )

    def start(self, sample: DaqSample) -> None:
        self.previous = self._measure(sample)

    def update(self, sample: DaqSample) -> float:
        x, theta = self._measure(sample)
        xdot = (x - self.previous[0]) / self.period_s
        thetadot = (theta - self.previous[1]) / self.period_s
        self.previous = (x, theta)
        volts = -(-36.34 * x + 24.6 * theta - 15.96 * xdot + 3.98 * thetadot)
        return converters.clip_command_v(converters.dac_command_v(volts, self.sw), self.sw)


class UserCatalogue:
    """A catalogue with the user's controller only (no batched version: the scalar loop runs it)."""

    NAMES = ("mine",)

    def make(self, name: str, params: Parameters | None = None) -> Controller:
        return FiniteDifferenceFeedback((params or Parameters()).software)


def _assert_same_run(single: RunResult, batched: RunResult, what: str) -> None:
    assert json.dumps(single.verdict.to_json()) == json.dumps(batched.verdict.to_json()), what
    for f in fields(RunLog):
        a, b = getattr(single.log, f.name), getattr(batched.log, f.name)
        assert a.shape == b.shape and np.array_equal(a, b, equal_nan=True), f"{what}: {f.name}"


def _check(catalogue, name: str, x0, theta0, seeds, *, duration_s: float, params=None, vectorized=True, **kw):
    runs = run_batch(
        catalogue,
        name,
        x0_m=x0,
        theta0_rad=theta0,
        seeds=seeds,
        duration_s=duration_s,
        params=params,
        nthread=2,
        record=True,
        vectorized=vectorized,
        **kw,
    )
    assert len(runs) == len(x0)
    for i, batched in enumerate(runs):
        p = params[i] if isinstance(params, list) else params
        single = run_closed_loop(
            catalogue.make(name, p),
            x0_m=float(x0[i]),
            theta0_rad=float(theta0[i]),
            duration_s=duration_s,
            seed=int(seeds[i]),
            params=p,
            **kw,
        )
        _assert_same_run(single, batched, f"{name} run {i} (x0 = {x0[i]}, θ0 = {theta0[i]}, seed {seeds[i]})")
    return runs


def _grid(seeds: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every start with every seed."""
    x0, seed = np.meshgrid(X0, seeds)
    theta0, _ = np.meshgrid(THETA0, seeds)
    return x0.ravel(), theta0.ravel(), seed.ravel()


@pytest.mark.parametrize(
    ("name", "vectorized"),
    [
        pytest.param("appendix-sf", True, id="appendix-sf-vectorized"),  # the fast tier keeps one of them
        pytest.param("appendix-sf", False, id="appendix-sf-scalar-loop", marks=pytest.mark.slow),
        pytest.param("appendix-clp", True, id="appendix-clp-vectorized", marks=pytest.mark.slow),
        pytest.param("appendix-clp", False, id="appendix-clp-scalar-loop", marks=pytest.mark.slow),
        pytest.param("lqr", True, id="lqr-vectorized", marks=pytest.mark.slow),
        pytest.param("lqr", False, id="lqr-scalar-loop", marks=pytest.mark.slow),
        pytest.param("clp", True, id="clp-vectorized", marks=pytest.mark.slow),
        pytest.param("smc", True, id="smc-vectorized", marks=pytest.mark.slow),
        pytest.param("thesis-clp", True, id="thesis-clp-vectorized", marks=pytest.mark.slow),
    ],
)
def test_batch_equals_single_runs_bit_for_bit(name: str, vectorized: bool) -> None:
    """3 seeds × 4 starts (held and lost balls), noise on: every log array and the verdict."""
    x0, theta0, seeds = _grid(SEEDS)
    runs = _check(registry, name, x0, theta0, seeds, duration_s=2.0, vectorized=vectorized)
    assert any(r.verdict.ball_lost for r in runs) and not all(r.verdict.ball_lost for r in runs)


def test_a_users_scalar_controller_runs_in_the_batch_bit_for_bit() -> None:
    x0, theta0, seeds = _grid(SEEDS)
    _check(UserCatalogue(), "mine", x0, theta0, seeds, duration_s=2.0)


def test_per_run_parameters_each_run_its_own_physics() -> None:
    """Monte Carlo: each run its own motor resistance and beam inertia (one MuJoCo model each), two runs
    sharing one parameter set, and runs whose sensor parameters differ (batched apart)."""
    base = Parameters()
    params = [
        base.with_overrides(
            {"motor.resistance_ohm": 9.5 + 0.5 * i, "beam.inertia_pivot_kgm2": 3.4e-3 + 1e-4 * i}
        )
        for i in range(4)
    ]
    params[2] = params[1]
    params[3] = params[3].with_overrides({"angle_sensor.zeroing_error_rad": 0.002})
    for name in (
        "lqr",
        "appendix-sf",
        "clp",
        "smc",
    ):  # clp, smc: each run its own design (terms, gains, motor)
        _check(registry, name, X0, THETA0, np.array([5, 6, 7, 8]), duration_s=1.5, params=params)


@pytest.mark.parametrize("stop_when_lost", [False, True])
def test_many_sensor_groups_are_each_their_single_runs(stop_when_lost: bool) -> None:
    """Six runs in three sensor groups: free runs of 0, 20 and 40 ms (groups of different tick counts), a
    zeroing error of its own in each run (a group's arrays), held and lost balls; with stop_when_lost a
    group whose every ball is lost stops while the others go on. Each run is its single run, bit for bit."""
    base = Parameters()
    params = [
        base.with_overrides(
            {"angle_sensor.zeroing_error_rad": 0.0005 * i, "start.free_run_s": 0.02 * (i % 3)}
        )
        for i in range(6)
    ]
    x0 = np.array([-0.2, 0.3, 0.1, 0.32, -0.05, 0.31])
    theta0 = np.array([0.3, 0.6, -0.2, 0.7, 0.0, -0.7])
    runs = _check(
        registry,
        "appendix-sf",
        x0,
        theta0,
        np.arange(11, 17),
        duration_s=3.0,
        params=params,
        stop_when_lost=stop_when_lost,
    )
    lost = [r.verdict.ball_lost for r in runs]
    assert any(lost) and not all(lost)


@pytest.mark.parametrize("ideal_sensors", [False, True])
def test_rigs_of_a_spread_share_one_group(monkeypatch, ideal_sensors: bool) -> None:
    """Rigs that differ in their physics, amplifier gain, encoder zeroing, RC filter and dropout rate (a
    robust map's, a Monte Carlo's) are one group of one track shape, its numpy stages paid once per tick for
    all: each run is still its single run, bit for bit (the gains move the motor volts, the zeroing errors
    of about a count the angle readings, the filters the ball readings)."""
    from twin.rigs import batch

    built: list[tuple[int, int, int]] = []  # per group: its runs, their models, their track shapes
    init = batch.BatchRig.__init__

    def counting(self, params, *args, **kwargs):  # noqa: ANN001, ANN002, ANN003
        init(self, params, *args, **kwargs)
        built.append((len(params), len(self.physics.distinct), len(self.physics.shapes)))

    monkeypatch.setattr(batch.BatchRig, "__init__", counting)
    step = 2 * np.pi / (256 * 7)  # one encoder count at the beam (eq 6.2.1)
    params = [
        Parameters().with_overrides(
            {
                "amplifier.gain_v_per_v": 9.6 * (0.98 + 0.01 * i),
                "angle_sensor.zeroing_error_rad": step * (i - 2) * 0.7,
                "motor.resistance_ohm": 9.4 + 0.1 * i,
                "ball_sensor.rc_resistance_ohm": 147.0 * (0.95 + 0.025 * i),
                "ball_sensor.rc_capacitance_f": 22e-6 * (0.8 + 0.1 * i),
                "ball_sensor.dropout_rate_hz": 5.0 * i,
            }
        )
        for i in range(5)
    ]
    x0 = np.array([-0.2, 0.3, 0.1, -0.05, 0.31])
    theta0 = np.array([0.3, 0.6, -0.2, 0.0, -0.7])
    runs = _check(
        registry,
        "appendix-sf",
        x0,
        theta0,
        np.arange(21, 26),
        duration_s=2.0,
        params=params,
        ideal_sensors=ideal_sensors,
    )
    assert built == [(5, 5, 1)]
    # The gains and zeroing errors reach the runs: the same start on each rig reads and drives differently.
    same = _check(
        registry,
        "appendix-sf",
        np.full(5, 0.1),
        np.full(5, 0.2),
        np.full(5, 3),
        duration_s=1.0,
        params=params,
        ideal_sensors=ideal_sensors,
    )
    assert len({r.log.datam2[0] for r in same}) > 1 and len({r.log.motor_volts_v[-1] for r in same}) == 5
    if not ideal_sensors:
        assert len({r.log.datam1[10] for r in same}) > 1
    assert len(runs) == 5


@pytest.mark.quick
def test_without_record_only_the_verdicts_are_kept() -> None:
    runs = run_batch(registry, "appendix-sf", x0_m=X0, theta0_rad=THETA0, seeds=np.arange(4), duration_s=1.0)
    single = run_closed_loop(registry.make("appendix-sf"), x0_m=0.14, theta0_rad=-0.2, duration_s=1.0, seed=0)
    assert runs[0].verdict.to_json() == single.verdict.to_json()
    assert not runs[0].recorded
    with pytest.raises(RuntimeError, match="verdict only"):
        runs[0].log  # noqa: B018


@pytest.mark.quick
def test_bad_inputs_are_refused() -> None:
    with pytest.raises(ValueError, match="one value per run"):
        run_batch(registry, "lqr", x0_m=X0, theta0_rad=THETA0[:2], seeds=np.arange(4))
    with pytest.raises(ValueError, match="params has 2 entries"):
        run_batch(registry, "lqr", x0_m=X0, theta0_rad=THETA0, seeds=np.arange(4), params=[Parameters()] * 2)
    with pytest.raises(ValueError, match="off the track"):
        run_batch(registry, "lqr", x0_m=np.array([0.5]), theta0_rad=np.array([0.0]), seeds=np.array([0]))
    assert run_batch(registry, "lqr", x0_m=np.array([]), theta0_rad=np.array([]), seeds=np.array([])) == []


@pytest.mark.slow
@pytest.mark.parametrize(
    "overrides",
    [
        {"start.free_run_s": 0.0},
        {"start.free_run_s": 0.04},
        {"start.free_run_s": 0.05},  # the rig runs free before the start block
        {"daq.output_latency_s": 0.003},
    ],
)
def test_start_timing_and_latency_as_single_runs(overrides: dict) -> None:
    params = Parameters().with_overrides(overrides)
    _check(registry, "appendix-clp", X0, THETA0, np.array([1, 2, 3, 4]), duration_s=2.0, params=params)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "kw"),
    [
        ("sf", {}),
        ("thesis-sf", {}),
        ("thesis-clp", {}),
        ("clp", {}),
        ("smc", {}),
        ("appendix-clp", {"stop_when_lost": False}),
        ("lqr", {"noise": False}),
        ("lqr", {"ideal_sensors": True}),
        ("thesis-sf-continuous", {}),
        ("appendix-sf", {"plant": "reference", "ideal_sensors": True}),
    ],
)
def test_other_controllers_and_rigs_as_single_runs(name: str, kw: dict) -> None:
    _check(registry, name, X0, THETA0, np.array([3, 4, 5, 6]), duration_s=3.0, **kw)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["appendix-sf", "appendix-clp", "lqr"])
def test_long_runs_as_single_runs(name: str) -> None:
    """10 s runs: limit cycles, dropouts and table points crossed many times."""
    x0, theta0, seeds = _grid(SEEDS)
    _check(registry, name, x0, theta0, seeds, duration_s=10.0)


@pytest.mark.quick
def test_the_single_rig_and_the_batch_follow_one_tick_schedule() -> None:
    """``twin.daq.TickSchedule`` is the one home of the start timing and the output latency, which SimRig
    and the batch's groups both build with ``twin.rigs.sim.tick_schedule``: a 50 ms free run (longer than a
    period) with 5 ms latency, and the default 10 ms, in 1 ms steps."""
    from twin.daq import BlockPlan, TickSchedule
    from twin.rigs.sim import tick_schedule

    params = Parameters().with_overrides({"start.free_run_s": 0.05, "daq.output_latency_s": 0.005})
    schedule = tick_schedule(params)
    assert (schedule.steps_per_tick, schedule.latency_steps, schedule.free_run_steps) == (20, 5, 50)
    # The start block ends 20 ms before the first command: released at 0, the chain starts there.
    assert schedule.held is False and schedule.chain_start_step == 0 and schedule.next_end_step == 30
    assert schedule.next_block() == BlockPlan(10, 30, 10, None, 20)  # 10 steps unobserved, then the block
    assert schedule.command_written() is False  # the command acts 5 steps later...
    assert schedule.next_block() == BlockPlan(30, 50, 0, None, 20)
    assert schedule.switch_at(20) == 5 and schedule.switch_at(20) is None  # ...5 steps into the next block
    assert schedule.next_is_plain()
    held = TickSchedule(20, 0, 10)  # the default 10 ms: the start block is half held
    assert held.held and held.chain_start_step == -30
    assert held.next_block() == BlockPlan(-30, -10, 0, -10, 0)
    assert held.next_block() == BlockPlan(-10, 10, 0, 0, 10)
    assert held.command_written() is True and held.next_is_plain()


def _extreme_states(rng: np.random.Generator) -> np.ndarray:
    """Random states over many decades, with the edges a law's arithmetic has: ±0, a sliding surface at
    exactly zero, x² and θ̇² overflowing, NaN."""
    x = rng.standard_normal((400, 4)) * 10.0 ** rng.uniform(-8, 3, (400, 4))
    x[:20] = 0.0
    x[20:40] = -0.0
    x[40:60, 0] = 1e200
    x[60:80, 3] = -1e200
    x[80:90, 2] = np.nan
    return x


@pytest.mark.quick
@pytest.mark.parametrize("name", ["clp", "thesis-clp", "smc", "sf", "lqr"])
def test_each_batched_law_gives_the_scalar_laws_bits_on_any_state(name: str) -> None:
    """The batch's law on 400 states at once against the scalar law state by state (``of_floats``), bit for
    bit, NaN where the scalar law gives NaN. A surface exactly zero: smc's states on S̄·x = 0."""
    from controllers.batch import BatchLoopController

    scalar = registry.make(name)
    law = BatchLoopController([scalar]).law
    x = _extreme_states(np.random.default_rng(sum(map(ord, name))))
    if name == "smc":
        surface = np.asarray(scalar.law.surface, dtype=float)[0]
        x[100:110] = np.array([surface[1], -surface[0], 0.0, 0.0]) * 2.0 ** np.arange(10)[:, None]
    with np.errstate(invalid="ignore", over="ignore"):
        batched = law(x)
    single = np.array([scalar.law.of_floats(*row) for row in x.tolist()])
    assert batched.tobytes() == single.tobytes() or np.array_equal(batched, single, equal_nan=True)
    assert np.signbit(batched).tolist() == np.signbit(single).tolist()
    assert np.isfinite(single).sum() > 300  # the states are mostly ordinary ones
