"""The batch engine: N closed-loop runs at once, each bit-identical to ``run_closed_loop`` alone.

    physics           a ``twin.physics.BatchPhysics`` from the backend's registry row (``twin.rigs.backends``):
                      MuJoCo's batch (``twin.plant_batch``: one ``mujoco.batch.Batch`` call per tick for every
                      run still going, each run the trajectory ``twin.plant.Plant`` steps alone), or the
                      reference plant's compiled kernel (``twin.screen.plant``, the fast engine)
    sensors, board,   the rig's parts' batch runtimes (``twin.parts.contract``: ``BallSensorPart.batch_chain``,
    actuator          ``AngleSensorPart.batch_read``, ``IoBoardPart.batch_dac``, ``ActuatorPart.batch_drive``),
                      numpy over a leading batch axis, each run its ``SimRig``'s chains and write path bit for
                      bit (the thesis's: ``BallChainBatch``, ``angle_block_means_v``, ``dac_quantize_v`` and
                      ``amplifier_volts``: ``twin.output_stage.motor_volts``)
    controllers       a ``BatchController`` from the catalogue's optional ``make_batch`` (numpy over the
                      batch), otherwise one scalar ``Controller`` per run called in a loop

The tick sequence follows the single rig's ``twin.daq.TickSchedule`` (start timing, held rig, free run,
output latency: the same object type, so the same plan), its ideal converters are ``IdealSensors.read_v``,
and lost ball, recording and verdict are ``twin.engine.ClosedLoop``'s step for step; a test checks every log
array and the verdict against single runs. Runs whose lost ball ends them (``stop_when_lost``) leave the
batch. Laws on the true state (``StateLaw``) run one by one through ``run_closed_loop``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields
from typing import Protocol, runtime_checkable

import numpy as np

from twin.daq import block_time_s
from twin.engine import (
    Catalogue,
    ControllerError,
    RunResult,
    Scenario,
    check_period_s,
    checked_start,
    checked_update,
    judge,
    update_ticks,
)
from twin.guard import Guard, install_interrupt_handler, safe_name
from twin.interface import CommandRange, Controller, DaqSample, RigError
from twin.log import THESIS_FIELDS, TRUTH_FIELDS, RunLog
from twin.output_stage import ideal_motor_volts
from twin.parameters import Parameters
from twin.parts import rig_parts
from twin.parts.contract import AngleSensorBatch, BallSensorBatch, BatchWrite, missing_batch_runtime
from twin.physics import BatchBlock, BatchPhysics
from twin.rigs.backends import DEFAULT_PLANT, backend
from twin.rigs.sim import refuse_ideal_converters, run_closed_loop, tick_schedule
from twin.sensors import IdealSensors
from twin.verdict import Criteria, Trace

__all__ = [
    "BatchCatalogue",
    "BatchRig",
    "BatchController",
    "BatchSamples",
    "BatchTelemetry",
    "ScalarControllers",
    "batch_key",
    "run_batch",
]

# Two periods agree when they differ by less than this (as twin.engine).
_PERIOD_TOLERANCE_S = 1e-12


@dataclass(frozen=True)
class BatchSamples:
    """One block for each run of a batch (``twin.interface.DaqSample`` over a leading batch axis)."""

    time_s: float  # the same for every run: the runs are in step
    ball_v: np.ndarray  # (n,)
    angle_v: np.ndarray  # (n,)


@dataclass
class BatchTelemetry:
    """``twin.interface.Telemetry`` over the batch: x1…x4 (n, 4), u (n,), uhesap (n,)."""

    estimate: np.ndarray
    u: np.ndarray
    u_computed: np.ndarray


@runtime_checkable
class BatchController(Protocol):
    """N controllers of one kind in numpy: the DAC commands of every run of a batch at once.

    Each run's commands and telemetry must be those of its own scalar ``Controller`` bit for bit."""

    name: str
    period_s: float
    telemetry: BatchTelemetry

    def start(self, samples: BatchSamples) -> None: ...

    def update(self, samples: BatchSamples) -> np.ndarray:
        """The DAC commands (n,) for the blocks just read."""
        ...

    def keep(self, runs: np.ndarray) -> None:
        """Go on with these runs only (indices into the current batch, in order): the others ended."""
        ...


class BatchCatalogue(Catalogue, Protocol):
    """A catalogue that may also build batched controllers (``controllers.registry`` is one)."""

    def make_batch(self, name: str, params: Sequence[Parameters]) -> BatchController | None: ...


class ScalarControllers:
    """One scalar ``Controller`` per run, called in a loop: any controller runs in a batch this way."""

    def __init__(
        self,
        controllers: Sequence[Controller],
        timeout_s: float | None = None,
        limits: CommandRange | None = None,
    ) -> None:
        """``timeout_s``: each call's watchdog budget (``twin.guard.Guard.for_period``); ``limits``: the range a
        command must be in (the board's output, ``IoBoardPart.output_range``, as ``SimRig.command_range``)."""
        install_interrupt_handler()  # before any user code runs: its KeyboardInterrupt is not the Ctrl-C
        self.controllers = list(controllers)
        self.name = safe_name(self.controllers[0])
        self.period_s = check_period_s(self.controllers[0])
        for c in self.controllers[1:]:
            check_period_s(c)
        self.guard = Guard.for_period(self.period_s, timeout_s)
        self.limits = limits
        self.tick = 1  # the blocks read, as ``SimRig.ticks``: the start's block is the first
        self.telemetry = BatchTelemetry(np.empty((0, 4)), np.empty(0), np.empty(0))

    def _collect(self) -> None:
        tel = [c.telemetry for c in self.controllers]
        self.telemetry = BatchTelemetry(
            np.array([t.estimate for t in tel]).reshape(len(tel), 4),
            np.array([t.u for t in tel], dtype=float),
            np.array([t.u_computed for t in tel], dtype=float),
        )

    def start(self, samples: BatchSamples) -> None:
        for i, c in enumerate(self.controllers):
            sample = DaqSample(samples.time_s, float(samples.ball_v[i]), float(samples.angle_v[i]))
            checked_start(c, sample, f"(run {i})", self.guard)
        self._collect()

    def update(self, samples: BatchSamples) -> np.ndarray:
        out = np.empty(len(self.controllers))
        self.tick += 1
        for i, c in enumerate(self.controllers):
            sample = DaqSample(samples.time_s, float(samples.ball_v[i]), float(samples.angle_v[i]))
            run = f", run {i}" if len(self.controllers) > 1 else ""  # a run alone is the run
            where = f"at tick k = {self.tick} (t = {samples.time_s:.3f} s{run})"
            out[i] = checked_update(c, sample, where, self.guard, self.limits)
        self._collect()
        return out

    def keep(self, runs: np.ndarray) -> None:
        self.controllers = [self.controllers[i] for i in runs.tolist()]


def run_batch(
    catalogue: Catalogue,
    name: str,
    *,
    x0_m: np.ndarray,
    theta0_rad: np.ndarray,
    seeds: np.ndarray,
    duration_s: float = 10.0,
    noise: bool = True,
    params: Parameters | Sequence[Parameters] | None = None,
    plant: str = DEFAULT_PLANT,
    ideal_sensors: bool = False,
    stop_when_lost: bool = True,
    criteria: Criteria | None = None,
    nthread: int | None = None,
    record: bool = False,
    vectorized: bool = True,
    controller_timeout_s: float | None = None,
    progress: Callable[[float], None] | None = None,
    scenarios: Sequence[Scenario | None] | None = None,
) -> list[RunResult]:
    """Run controller ``name`` from each (x0_m[i], theta0_rad[i]) with noise seed seeds[i]: element i is
    ``run_closed_loop(catalogue.make(name, params_i), x0_m=x0_m[i], …, seed=seeds[i], …)`` bit for bit.

    ``params``: one for every run or one per run (runs whose sensor, DAQ, amplifier, software and timing
    parameters agree, but for ``PER_RUN_IO``, share one batch; each run's physics has its own MuJoCo
    model). ``nthread``: physics threads (default: every CPU). ``record``: keep each run's log (17 arrays
    per run); without it a result's ``log`` is not kept (``RunResult.recorded`` is false) and only the
    verdict is. ``vectorized=False`` calls one scalar controller per run even when the catalogue has a
    batched one (for tests).
    ``controller_timeout_s``: the watchdog's budget per call of a scalar controller (``twin.guard``). ``progress``
    is called as the runs advance with how many are done, a float: a group's runs advance together, so k of
    its T ticks count k/T of each (a job's progress moves before its batch ends; it changes no number).
    ``scenarios``: per run, a flick or a setpoint (``twin.engine.Scenario``) or None; a run with one takes the
    single-run path (``run_closed_loop`` with it), the others the batch."""
    x0, th0, seed_arr, run_params = _run_inputs(x0_m, theta0_rad, seeds, duration_s, params)
    n = len(x0)
    if n == 0:
        return []
    try:
        physics = backend(plant).batch  # the backend's batch (twin.rigs.backends)
    except ValueError as exc:
        raise RigError(str(exc)) from None
    probe = catalogue.make(name, run_params[0])
    # The 1 kHz laws on the true state, firmware and runs with a scenario take the single-run path; the others
    # are batched (each group's physics the backend's BatchPhysics). A controller in a process of
    # its own (a controller FMU) runs one run at a time too: a batch would hold one process per run at once.
    every = not isinstance(probe, Controller) or bool(getattr(probe, "own_process", False))
    run_scenarios = list(scenarios) if scenarios is not None else [None] * n
    # An actuator stepped with the physics (ActuatorPart.step_law: the stepper) runs one run at a time as well:
    # the batch's rollout cannot call its law between MuJoCo's steps (BatchRig refuses it).
    single = [
        i
        for i in range(n)
        if every or run_scenarios[i] is not None or rig_parts(run_params[i]).actuator.step_law is not None
    ]
    batched = sorted(set(range(n)) - set(single))
    results: list[RunResult | None] = [None] * n
    noisy: dict[int, Parameters] = {}  # the rig's parameters (noise switched as asked), per distinct object
    groups: dict[tuple, list[int]] = {}
    for i in batched:
        p = run_params[i]
        if id(p) not in noisy:
            noisy[id(p)] = p.with_overrides({"ball_sensor.noise_enabled": bool(noise)})
        groups.setdefault(batch_key(noisy[id(p)]), []).append(i)
    threads = (os.cpu_count() or 1) if nthread is None else int(nthread)
    runs_before = 0  # the runs of the groups already run (progress)
    for idx in groups.values():
        rows = np.array(idx)
        controller = _group_controller(
            catalogue, name, [run_params[i] for i in idx], vectorized, controller_timeout_s
        )
        group_rig_params = [noisy[id(run_params[i])] for i in idx]
        tick_schedule(group_rig_params[0])  # a schedule the rig cannot run is refused before any physics
        group = BatchRig(
            group_rig_params,
            x0[rows],
            th0[rows],
            seed_arr[rows],
            physics=physics(group_rig_params, x0[rows], th0[rows], threads),
            ideal_sensors=ideal_sensors,
            record=record,
        )
        on_tick = None if progress is None else _group_progress(progress, runs_before, len(idx))
        for j, result in enumerate(group.run(controller, duration_s, stop_when_lost, criteria, on_tick)):
            results[idx[j]] = result
        runs_before += len(idx)
    for i in single:
        results[i] = run_closed_loop(
            catalogue.make(name, run_params[i]),
            x0_m=float(x0[i]),
            theta0_rad=float(th0[i]),
            duration_s=duration_s,
            seed=int(seed_arr[i]),
            noise=noise,
            params=run_params[i],
            plant=plant,
            ideal_sensors=ideal_sensors,
            stop_when_lost=stop_when_lost,
            criteria=criteria,
            controller_timeout_s=controller_timeout_s,
            scenario=run_scenarios[i],
        )
        runs_before += 1
        if progress is not None:
            progress(float(runs_before))
    return [r for r in results if r is not None]


def _run_inputs(
    x0_m: np.ndarray,
    theta0_rad: np.ndarray,
    seeds: np.ndarray,
    duration_s: float,
    params: Parameters | Sequence[Parameters] | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[Parameters]]:
    """``run_batch``'s starts, seeds and parameters as one value per run, or a ``ValueError`` naming the misfit."""
    x0 = np.asarray(x0_m, dtype=float).reshape(-1)
    th0 = np.asarray(theta0_rad, dtype=float).reshape(-1)
    seed_arr = np.asarray(seeds).reshape(-1)
    n = len(x0)
    if len(th0) != n or len(seed_arr) != n:
        raise ValueError(
            f"x0_m, theta0_rad and seeds must have one value per run: {n}, {len(th0)}, {len(seed_arr)}"
        )
    if not (isinstance(duration_s, (int, float)) and math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration_s = {duration_s!r} must be a positive number of seconds")
    if params is None or isinstance(params, Parameters):
        return x0, th0, seed_arr, [params or Parameters()] * n
    run_params = list(params)
    if len(run_params) != n:
        raise ValueError(f"params has {len(run_params)} entries for {n} runs: give one, or one per run")
    return x0, th0, seed_arr, run_params


def _group_controller(
    catalogue: Catalogue,
    name: str,
    group_params: list[Parameters],
    vectorized: bool,
    controller_timeout_s: float | None,
) -> BatchController:
    """A group's controller: the catalogue's batched one if it has one (and ``vectorized``), else one scalar
    controller per run behind ``ScalarControllers``."""
    make_batch = getattr(catalogue, "make_batch", None) if vectorized else None
    controller = make_batch(name, group_params) if make_batch is not None else None
    if controller is not None:
        return controller
    made = [catalogue.make(name, p) for p in group_params]
    scalar = [c for c in made if isinstance(c, Controller)]
    if len(scalar) != len(made):
        raise TypeError(f"{name}: the catalogue made something that is not a Controller")
    p = group_params[0]
    # the board's output range, as SimRig.command_range (the guard refuses a command outside it)
    return ScalarControllers(scalar, controller_timeout_s, rig_parts(p).io_board.output_range(p))


def _group_progress(progress: Callable[[float], None], before: int, size: int) -> Callable[[int, int], None]:
    """A group's tick k of T as the batch's runs done: the groups before it, and k/T of its own runs."""
    return lambda k, ticks: progress(before + size * k / ticks)


# The I/O parameters a group holds per run (arrays over its runs, or each run's own ball chain): a spread's
# rigs differ in them, and a group per rig would pay the per-tick numpy once per rig.
PER_RUN_IO = {
    "amplifier": ("gain_v_per_v",),
    "angle_sensor": ("zeroing_error_rad",),
    "ball_sensor": ("rc_resistance_ohm", "rc_capacitance_f", "dropout_rate_hz"),
}


def batch_key(p: Parameters) -> tuple:
    """What the numpy stages of a batch share: runs that differ only in their physics and in ``PER_RUN_IO``
    batch together (and only runs of the same parts: a part's batch runtime takes each run's own group)."""

    def shared(section: str) -> tuple:
        part = getattr(p, section)
        return tuple(
            (f.name, getattr(part, f.name)) for f in fields(part) if f.name not in PER_RUN_IO[section]
        )

    return (
        p.parts,
        p.daq,
        p.start,
        shared("amplifier"),
        p.software,
        shared("angle_sensor"),
        shared("ball_sensor"),
        p.track,
        p.physics.timestep_s,
        p.motor.gear_ratio,
        p.beam.stop_angle_rad,
    )


class _Columns:
    """The log's columns of every run of a group, one row per tick (row k: the k-th block read)."""

    def __init__(self, ticks: int, n: int, record: bool) -> None:
        names = (
            [f for f in THESIS_FIELDS + TRUTH_FIELDS if f != "ball_lost"]
            if record
            else ["true_time_s", "true_x_m", "true_theta_rad", "motor_volts_v"]
        )
        self.cols = {f: np.zeros((ticks, n)) for f in names}
        self.lost = np.zeros((ticks, n), dtype=bool)
        self.peak_theta = np.zeros((ticks, n))


class BatchRig:
    """N simulated rigs that share their sensor/DAQ/timing parameters (``batch_key``), stepped together: the
    single rig's (``SimRig``) state as arrays over the runs, each run its single rig bit for bit (the comments
    name the ``SimRig`` lines each step mirrors). ``run_batch`` runs one per group of a batch's runs;
    ``twin.rigs.vector.VectorRig`` one per cohort of rigs reset together."""

    def __init__(
        self,
        params: list[Parameters],
        x0: np.ndarray,
        theta0: np.ndarray,
        seeds: np.ndarray,
        *,
        physics: BatchPhysics,
        ideal_sensors: bool,
        record: bool,
    ) -> None:
        """``physics``: the runs' physics, started from (x0, theta0) with ``params`` (a backend's
        ``BatchFactory``, ``twin.rigs.backends``)."""
        p = self.p = params[0]
        parts = rig_parts(p)  # the group's (batch_key: every run names the same parts)
        missing = [] if ideal_sensors else missing_batch_runtime(parts)
        if missing:  # the chains and write path are the parts' batch runtimes: never another rig's silently
            raise RigError(
                f"the batch engine has no batch runtime for {'; '.join(missing)} (run the rig one run at a time)"
            )
        if parts.actuator.step_law is not None:  # its torque is computed in Python between MuJoCo's steps
            raise RigError(
                f"parts.actuator = {parts.actuator.name!r} computes its torque each physics step "
                "(ActuatorPart.step_law), which the batch engine's rollout cannot run: run the rig one run at a time"
            )
        refuse_ideal_converters(p, ideal_sensors)
        self.n = n = len(params)
        self.ideal = ideal_sensors
        self.record = record
        self.x0 = x0
        dt = p.physics.timestep_s
        self.dt = dt
        self.schedule = tick_schedule(p)  # the single rig's schedule (held, free run, release, latency)
        self.steps_per_tick = self.schedule.steps_per_tick
        self.physics = physics
        # SimRig.reset
        self.held = np.stack([x0, theta0, np.zeros(n), np.zeros(n)], axis=1)
        chain_start = self.schedule.chain_start_step
        # the parts' batch runtimes (SimRig.__init__ and reset: the chains from the parts, a fresh write path)
        self.ball: BallSensorBatch | None = None
        self.angle: AngleSensorBatch | None = None
        self.dac: BatchWrite | None = None
        self.drive: BatchWrite | None = None
        if not ideal_sensors:
            assert parts.ball_sensor.batch_chain is not None and parts.angle_sensor.batch_read is not None
            assert parts.io_board.batch_dac is not None and parts.actuator.batch_drive is not None
            self.ball = parts.ball_sensor.batch_chain(params, seeds, x0, chain_start * dt)
            self.angle = parts.angle_sensor.batch_read(params)
            self.dac = parts.io_board.batch_dac(params)
            self.drive = parts.actuator.batch_drive(params)
        self.ideal_sensors = IdealSensors(p)
        # Each run's own, for the ideal converters (the group shares the rest of its I/O parameters: batch_key).
        self.gain_v_per_v = np.array([q.amplifier.gain_v_per_v for q in params])
        self.zeroing_error_rad = np.array([q.angle_sensor.zeroing_error_rad for q in params])
        # SimRig.reset: the actuator's rest command, through the write path (a servo's dead band accepts it)
        self.command_v = np.array([float(parts.actuator.rest_command(q)) for q in params])
        self.applied_v = self._motor_volts_for(self.command_v, np.arange(n))
        self.pending_v = self.applied_v.copy()
        self.live = np.arange(n)  # the runs still going
        self.block_theta = np.zeros((n, 2))
        self.block_on = np.ones((n, 2), dtype=bool)

    @property
    def lost(self) -> np.ndarray:
        """(n,) bool: each run's ball has left the track (latched; the physics says when)."""
        return self.physics.lost

    @property
    def lost_time_s(self) -> list[float | None]:
        return self.physics.lost_time_s

    # --- the rig, over the live runs --------------------------------------------------------------------
    def _motor_volts_for(self, command_v: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """The actuator's control of runs ``rows`` for their commands (SimRig._motor_volts_for): the board's DAC,
        then the actuator (``RigParts.motor_volts_of``); the ideal converters' exact DAC and amplifier."""
        if self.ideal:
            return np.asarray(ideal_motor_volts(command_v, self.p, self.gain_v_per_v[rows]))
        assert self.dac is not None and self.drive is not None
        return np.asarray(self.drive(rows, self.dac(rows, command_v)), dtype=float)

    def write(self, command_v: np.ndarray) -> None:
        live = self.live
        self.command_v[live] = command_v
        volts = self._motor_volts_for(command_v, live)
        self.pending_v[live] = volts
        if self.schedule.command_written():
            self.applied_v[live] = volts

    def _step_volts(self, n: int) -> np.ndarray:
        live = self.live
        volts = np.repeat(self.applied_v[live][:, None], n, axis=1)
        k = self.schedule.switch_at(n)
        if k is not None:
            volts[:, k:] = self.pending_v[live][:, None]
            self.applied_v[live] = self.pending_v[live]
        return volts

    def _advance(self, volts: np.ndarray) -> BatchBlock:
        """The physics of every live run over ``volts`` (live, steps)."""
        return self.physics.advance(self.live, volts)

    def read(self) -> BatchSamples:
        """SimRig._read for every live run: the same ``TickSchedule`` plan, the pieces as arrays over the runs."""
        live = self.live
        plan = self.schedule.next_block()
        t_start = plan.start_step * self.dt if plan.start_step < 0 else self.physics.time_s
        if plan.free_steps:  # released before this block begins: run free up to it, unobserved
            pre_t, pre_x, _, pre_on = self._advance(self._step_volts(plan.free_steps))
            t_start = self.physics.time_s
            if self.ball is not None:
                self.ball.advance(live, pre_t, pre_x, pre_on)
        times: list[np.ndarray] = []
        xs: list[np.ndarray] = []
        thetas: list[np.ndarray] = []
        ons: list[np.ndarray] = []
        if plan.held_end_step is not None:  # the held rig, until release at t = 0 (or the block's end)
            times.append(np.array([t_start, plan.held_end_step * self.dt]))
            xs.append(np.repeat(self.held[live, 0:1], 2, axis=1))
            thetas.append(np.repeat(self.held[live, 1:2], 2, axis=1))
            ons.append(np.ones((len(live), 2), dtype=bool))
        if plan.observed_steps:
            t, x, th, on = self._advance(self._step_volts(plan.observed_steps))
            skip = 1 if times else 0  # consecutive pieces share their joining entry (rig._join)
            times.append(t[skip:])
            xs.append(x[:, skip:])
            thetas.append(th[:, skip:])
            ons.append(on[:, skip:])
        return self._sense(t_start, times, xs, thetas, ons)

    def begin_observed(self) -> tuple[float, np.ndarray]:
        """The first half of ``read`` when the next block is physics alone (``TickSchedule.next_is_observed``):
        the schedule moves past it; (the physics clock, the live runs' volts per step (live, steps)) for
        their physics, which the caller runs (with other groups' rows) before ``end_observed``."""
        plan = self.schedule.next_block()
        assert plan.free_steps == 0 and plan.held_end_step is None and plan.observed_steps
        return self.physics.time_s, self._step_volts(plan.observed_steps)

    def end_observed(self, t0: float, block: BatchBlock) -> BatchSamples:
        """The rest of ``read``: ``block`` the live runs' physics under ``begin_observed``'s volts from ``t0``."""
        t, x, th, on = block
        return self._sense(t0, [t], [x], [th], [on])

    def _sense(
        self,
        t_start: float,
        times: list[np.ndarray],
        xs: list[np.ndarray],
        thetas: list[np.ndarray],
        ons: list[np.ndarray],
    ) -> BatchSamples:
        """A block's pieces (as ``SimRig._read``'s) through the sensor chains or the ideal converters."""
        p, live = self.p, self.live
        block_t = np.concatenate(times)
        block_x = np.concatenate(xs, axis=1)
        block_theta = np.concatenate(thetas, axis=1)
        block_on = np.concatenate(ons, axis=1)
        self.block_theta, self.block_on = block_theta, block_on
        if self.ball is None or self.angle is None:
            ball_v, angle_v = self.ideal_sensors.read_v(
                block_x[:, -1], block_theta[:, -1], self.zeroing_error_rad[live]
            )
        else:  # SimRig._read: the angle chain, then the ball chain
            angle_v = self.angle.read(live, block_t, block_theta)
            ball_v = self.ball.advance(live, block_t, block_x, block_on)
        return BatchSamples(time_s=block_time_s(t_start, p.daq), ball_v=ball_v, angle_v=angle_v)

    def block_peaks(self) -> np.ndarray:
        """The largest |θ| of each live run's last block over its steps with the ball on the track (0 when
        none: |θ| ≥ 0, so the steps off the track can count as 0)."""
        return np.max(np.abs(np.where(self.block_on, self.block_theta, 0.0)), axis=1)

    @property
    def held_now(self) -> bool:
        return self.schedule.held

    def true_state(self) -> np.ndarray:
        """SimRig.true_state for every live run (n_live, 4)."""
        live = self.live
        if self.held_now:
            return self.held[live].copy()
        return self.physics.true_state(live)

    @property
    def time_s(self) -> float:
        if self.held_now:
            return self.schedule.next_start_step * self.dt
        return self.physics.time_s

    # --- the closed loop ----------------------------------------------------------------------------------
    def _add(self, k: int, cols: _Columns, samples: BatchSamples, controller: BatchController) -> None:
        """ClosedLoop's recorder, one row for every live run."""
        live, c = self.live, cols.cols
        state = self.true_state()
        c["true_time_s"][k, live] = self.time_s
        c["true_x_m"][k, live] = state[:, 0]
        c["true_theta_rad"][k, live] = state[:, 1]
        c["motor_volts_v"][k, live] = self.applied_v[live]
        if self.record:
            tel = controller.telemetry
            c["timem"][k, live] = samples.time_s
            c["datam1"][k, live] = samples.ball_v
            c["datam2"][k, live] = samples.angle_v
            c["aout"][k, live] = self.command_v[live]
            for j, f in enumerate(("x1", "x2", "x3", "x4")):
                c[f][k, live] = tel.estimate[:, j]
            c["u"][k, live] = tel.u
            c["uhesap"][k, live] = tel.u_computed
            c["true_xdot_m_s"][k, live] = state[:, 2]
            c["true_thetadot_rad_s"][k, live] = state[:, 3]
        cols.lost[k, live] = self.lost[live]
        cols.peak_theta[k, live] = self.block_peaks()

    def run(
        self,
        controller: BatchController,
        duration_s: float,
        stop_when_lost: bool,
        criteria: Criteria | None,
        on_tick: Callable[[int, int], None] | None = None,
    ) -> list[RunResult]:
        p = self.p
        if abs(controller.period_s - p.period_s) > _PERIOD_TOLERANCE_S:
            raise RigError(
                f"{controller.name}: period_s = {controller.period_s!r} s does not match the DAQ's "
                f"{p.period_field} = {p.period_s!r} s"
            )
        ticks = update_ticks(duration_s, p)
        cols = _Columns(ticks + 1, self.n, self.record)
        rows_done = np.zeros(self.n, dtype=np.int64)
        samples = self.read()
        try:
            controller.start(samples)
        except ControllerError:
            raise
        except Exception as exc:  # noqa: BLE001 - report which controller, do not crash
            raise ControllerError(f"{controller.name}.start raised {type(exc).__name__}: {exc}") from exc
        self._add(0, cols, samples, controller)
        rows_done[self.live] = 1
        for k in range(1, ticks + 1):
            samples = self.read()
            try:
                command = np.asarray(controller.update(samples), dtype=float)
            except ControllerError:
                raise
            except Exception as exc:  # noqa: BLE001
                raise ControllerError(
                    f"{controller.name}.update raised {type(exc).__name__} at tick k = {k} "
                    f"(t = {samples.time_s:.3f} s): {exc}"
                ) from exc
            bad = ~np.isfinite(command)
            if bad.any():
                j = int(np.flatnonzero(bad)[0])
                raise ControllerError(
                    f"{controller.name}.update returned {command[j]!r} at tick k = {k} (t = {samples.time_s:.3f} s, "
                    f"run {int(self.live[j])}): the DAC command must be a finite number of volts"
                )
            self.write(command)
            self._add(k, cols, samples, controller)
            rows_done[self.live] = k + 1
            if on_tick is not None:
                on_tick(k, ticks)
            if stop_when_lost:
                going = ~self.lost[self.live]
                if not going.all():
                    kept = np.flatnonzero(going)
                    self.live = self.live[kept]
                    if not len(self.live):
                        break
                    controller.keep(kept)
        return [self._result(i, int(rows_done[i]), cols, controller.name, criteria) for i in range(self.n)]

    def _result(self, i: int, n: int, cols: _Columns, name: str, criteria: Criteria | None) -> RunResult:
        c = cols.cols
        verdict = judge(
            self.p,
            Trace(
                c["true_time_s"][:n, i],
                c["true_x_m"][:n, i],
                c["true_theta_rad"][:n, i],
                c["motor_volts_v"][:n, i],
                cols.peak_theta[:n, i],
            ),  # fmt: skip
            x0_m=float(self.x0[i]),
            ball_lost_time_s=self.lost_time_s[i],
            criteria=criteria,
        )
        log = None
        if self.record:
            log = RunLog(**{f: col[:n, i] for f, col in c.items()}, ball_lost=cols.lost[:n, i])
        return RunResult(controller=name, log=log, verdict=verdict)
