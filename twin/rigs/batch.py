"""The batch engine: N closed-loop runs at once, each bit-identical to ``run_closed_loop`` alone.

    physics           one ``mujoco.batch.Batch`` call per tick for every run still going, on C threads
                      (one state row per run, solver warm start included, so a run's trajectory is the one
                      ``twin.plant.Plant`` steps alone)
    sensors, DAQ,     numpy over a leading batch axis with the functions a run alone uses
    output stage      (``twin.plant.Plant.track_coordinates``, ``twin.sensors.angle_block_means_v``,
                      ``BallChainBatch``, ``twin.output_stage.motor_volts``)
    controllers       a ``BatchController`` from the catalogue's optional ``make_batch`` (numpy over the
                      batch), otherwise one scalar ``Controller`` per run called in a loop

The tick sequence follows the single rig's ``twin.daq.TickSchedule`` (start timing, held rig, free run,
output latency: the same object type, so the same plan), its ideal converters are ``IdealSensors.read_v``,
and lost ball, recording and verdict are ``twin.engine.ClosedLoop``'s step for step; a test checks every log
array and the verdict against single runs. Runs whose lost ball ends them (``stop_when_lost``) leave the
batch. Laws on the true state (``StateLaw``) run one by one through ``run_closed_loop``. The reference plant's
runs are batched too, their physics in the compiled kernel (``ReferenceBatchRig``, the fast engine).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields
from typing import Protocol, runtime_checkable

import mujoco
import numpy as np
from mujoco import batch as mjbatch

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
    run_closed_loop,
    update_ticks,
)
from twin.guard import Guard, install_interrupt_handler, safe_name
from twin.interface import Controller, DaqSample
from twin.log import THESIS_FIELDS, TRUTH_FIELDS, RunLog
from twin.output_stage import ideal_motor_volts, motor_volts
from twin.parameters import Daq, Parameters
from twin.physics import check_initial_state
from twin.plant import (
    FULL_STATE,
    Plant,
    beyond_stops,
    failure_time_s,
    numerical_failure,
    stop_overshoot_bound_rad,
    warning_text,
)
from twin.rigs.sim import PlantKind, RigError, tick_schedule
from twin.sensors import BallChainBatch, IdealSensors, angle_block_means_v
from twin.verdict import Criteria, Trace

__all__ = [
    "BatchCatalogue",
    "BatchRig",
    "BatchController",
    "BatchSamples",
    "BatchTelemetry",
    "ReferenceBatchRig",
    "ScalarControllers",
    "batch_key",
    "run_batch",
]

_INTEGRATION = mujoco.mjtState.mjSTATE_INTEGRATION
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
        self, controllers: Sequence[Controller], timeout_s: float | None = None, daq: Daq | None = None
    ) -> None:
        """``timeout_s``: each call's watchdog budget (``twin.guard.Guard.for_period``); ``daq``: the card
        whose DAC range a command must be in."""
        install_interrupt_handler()  # before any user code runs: its KeyboardInterrupt is not the Ctrl-C
        self.controllers = list(controllers)
        self.name = safe_name(self.controllers[0])
        self.period_s = check_period_s(self.controllers[0])
        for c in self.controllers[1:]:
            check_period_s(c)
        self.guard = Guard.for_period(self.period_s, timeout_s)
        self.daq = daq
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
            out[i] = checked_update(c, sample, where, self.guard, self.daq)
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
    plant: PlantKind = "twin",
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
        run_params = [params or Parameters()] * n
    else:
        run_params = list(params)
        if len(run_params) != n:
            raise ValueError(f"params has {len(run_params)} entries for {n} runs: give one, or one per run")
    if n == 0:
        return []
    if plant not in ("twin", "reference"):
        raise RigError(f"plant = {plant!r}: expected 'twin' or 'reference'")
    probe = catalogue.make(name, run_params[0])
    # The 1 kHz laws on the true state, firmware and runs with a scenario take the single-run path; the others
    # are batched (the reference plant's in the compiled kernel: ReferenceBatchRig). A controller in a process of
    # its own (a controller FMU) runs one run at a time too: a batch would hold one process per run at once.
    every = not isinstance(probe, Controller) or bool(getattr(probe, "own_process", False))
    run_scenarios = list(scenarios) if scenarios is not None else [None] * n
    single = [i for i in range(n) if every or run_scenarios[i] is not None]
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
        make_batch = getattr(catalogue, "make_batch", None) if vectorized else None
        group_params = [run_params[i] for i in idx]
        controller = make_batch(name, group_params) if make_batch is not None else None
        if controller is None:
            made = [catalogue.make(name, p) for p in group_params]
            scalar = [c for c in made if isinstance(c, Controller)]
            if len(scalar) != len(made):
                raise TypeError(f"{name}: the catalogue made something that is not a Controller")
            controller = ScalarControllers(scalar, controller_timeout_s, group_params[0].daq)
        group = _group_rig(plant)(
            [noisy[id(run_params[i])] for i in idx],
            x0[rows],
            th0[rows],
            seed_arr[rows],
            ideal_sensors=ideal_sensors,
            nthread=threads,
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


def _group_rig(plant: PlantKind) -> type[BatchRig]:
    """The rig of a batch's group: MuJoCo's, or the reference plant's in the compiled kernel."""
    return ReferenceBatchRig if plant == "reference" else BatchRig


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
    batch together."""

    def shared(section: str) -> tuple:
        part = getattr(p, section)
        return tuple(
            (f.name, getattr(part, f.name)) for f in fields(part) if f.name not in PER_RUN_IO[section]
        )

    return (
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
        ideal_sensors: bool,
        nthread: int,
        record: bool,
        batch: mjbatch.Batch | None = None,
        ids: np.ndarray | None = None,
        plant_cache: dict[Parameters, Plant] | None = None,
    ) -> None:
        """``batch``/``ids``: step these runs as rows ``ids`` of a batch shared with other groups (whose
        models the owner sets), instead of a batch of their own. ``plant_cache``: plants already built, by
        parameters (a group built for each episode need not compile its models again)."""
        p = self.p = params[0]
        self.n = n = len(params)
        self.ideal = ideal_sensors
        self.record = record
        self.x0 = x0
        dt = p.physics.timestep_s
        self.dt = dt
        self.schedule = tick_schedule(p)  # the single rig's schedule (held, free run, release, latency)
        self.steps_per_tick = self.schedule.steps_per_tick
        self._start_physics(params, x0, theta0, nthread, batch, ids, plant_cache)
        # SimRig.reset
        self.held = np.stack([x0, theta0, np.zeros(n), np.zeros(n)], axis=1)
        chain_start = self.schedule.chain_start_step
        self.ball = None if ideal_sensors else BallChainBatch(params, seeds, x0, chain_start * dt)
        self.ideal_sensors = IdealSensors(p)
        # Each run's own (the group shares the rest of its I/O parameters: batch_key).
        self.gain_v_per_v = np.array([q.amplifier.gain_v_per_v for q in params])
        self.zeroing_error_rad = np.array([q.angle_sensor.zeroing_error_rad for q in params])
        self.command_v = np.full(n, p.amplifier.zero_command_v)
        self.applied_v = self._motor_volts_for(self.command_v, np.arange(n))
        self.pending_v = self.applied_v.copy()
        self.lost = np.zeros(n, dtype=bool)
        self.lost_time_s: list[float | None] = [None] * n
        self.lost_state = np.full((n, 4), math.nan)
        self.live = np.arange(n)  # the runs still going
        self.block_theta = np.zeros((n, 2))
        self.block_on = np.ones((n, 2), dtype=bool)

    # --- the physics: MuJoCo here; ``ReferenceBatchRig`` overrides these three ------------------------------
    def _start_physics(
        self,
        params: list[Parameters],
        x0: np.ndarray,
        theta0: np.ndarray,
        nthread: int,
        batch: mjbatch.Batch | None,
        ids: np.ndarray | None,
        plant_cache: dict[Parameters, Plant] | None,
    ) -> None:
        """Each run's physics reset to its start (the single run's reset and its checks); sets
        ``physics_time_s``."""
        n = len(params)
        # One Plant per distinct physics: its model for the batch, its geometry for the numpy stages.
        plants: dict[Parameters, Plant] = {}
        for q in params:
            if q not in plants:
                cached = None if plant_cache is None else plant_cache.get(q)
                plants[q] = cached if cached is not None else Plant(q)
        self.plants = [plants[q] for q in params]
        self.distinct = list(plants.values())
        # The numpy of the track's coordinates and the true state, once per track shape (Plant.frame_key)
        # rather than once per plant: each run's rows through one plant of its shape.
        shapes: dict[tuple, Plant] = {}
        for plant in self.distinct:
            shapes.setdefault(plant.frame_key, plant)
        self.shapes = list(shapes.values())
        shape_index = {key: k for k, key in enumerate(shapes)}
        self.shape_of = np.array([shape_index[plants[q].frame_key] for q in params])
        states = np.empty((n, mujoco.mj_stateSize(self.distinct[0].model, _INTEGRATION)))
        nfull = mujoco.mj_stateSize(self.distinct[0].model, FULL_STATE)
        self.last_row = np.empty((n, nfull))  # each run's state after its last step (MjData's, alone)
        for i, plant in enumerate(self.plants):
            plant.reset(float(x0[i]), float(theta0[i]))  # the single run's reset (and its checks)
            mujoco.mj_getState(plant.model, plant.data, states[i], _INTEGRATION)
            mujoco.mj_getState(plant.model, plant.data, self.last_row[i], FULL_STATE)
        if batch is None:
            self.batch = mjbatch.Batch(self.distinct[0].model, n, nthread=nthread)
            self.ids = np.arange(n)
            if len(self.distinct) > 1:
                self.batch.set_models([plant.model for plant in self.plants])
        else:
            assert ids is not None and len(ids) == n
            self.batch, self.ids = batch, np.asarray(ids)
            batch.warning[self.ids] = 0  # a row's counters are its run's (MjData's, reset with it)
        self.batch.state[self.ids] = states
        # Each run's furthest physical beam angle (Plant._check_numerics): past it, a numerical failure.
        self.theta_limit_rad = np.array([q.beam.stop_angle_rad + stop_overshoot_bound_rad(q) for q in params])
        plant0 = self.distinct[0]
        assert plant0._hinge_qpos is not None
        self.theta_col = 1 + plant0._hinge_qpos
        self.ball_col = 1 + plant0._ball_qpos
        self.physics_time_s = float(self.last_row[0, 0])

    # --- the rig, over the live runs --------------------------------------------------------------------
    def _motor_volts_for(self, command_v: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """The motor volts of runs ``rows`` for their commands."""
        gain = self.gain_v_per_v[rows]
        if self.ideal:
            return np.asarray(ideal_motor_volts(command_v, self.p, gain))
        return np.asarray(motor_volts(command_v, self.p, gain))

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

    def _advance(self, volts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Plant.advance for every live run: (times (m+1,), x, θ, on-track (live, m+1))."""
        t0 = self.physics_time_s
        out = self.batch.rollout(
            volts.shape[1], control=volts[:, :, None], record=(FULL_STATE,), ids=self.ids[self.live]
        )[FULL_STATE]
        return self._advanced(t0, out)

    def _advanced(self, t0: float, out: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``_advance`` once the live runs' physics has run from ``t0``: ``out`` their recorded states."""
        live, m = self.live, out.shape[1]
        self._check_numerics(t0, out)
        last = out[:, -1]
        if not np.isfinite(last).all():
            i = int(live[np.flatnonzero(~np.isfinite(last).all(axis=1))[0]])
            raise numerical_failure(
                self.plants[i].params, f"run {i}: the MuJoCo state is not finite", float(last[0, 0])
            )
        if not (last[:, 0] == last[0, 0]).all():
            raise RuntimeError("the runs of a batch fell out of step")
        theta = np.concatenate(
            [self.last_row[live, self.theta_col][:, None], out[:, :, self.theta_col]], axis=1
        )
        c = self.ball_col
        xyz = np.concatenate([self.last_row[live, None, c : c + 3], out[:, :, c : c + 3]], axis=1)
        along = np.empty_like(theta)
        on = np.empty(theta.shape, dtype=bool)
        which = self.shape_of[live]
        for k, plant in enumerate(self.shapes):
            rows = which == k
            if rows.all():
                along, on = plant.track_coordinates(theta, xyz)
            elif rows.any():
                along[rows], on[rows] = plant.track_coordinates(theta[rows], xyz[rows])
        lost = self.lost[live]
        on[lost] = False
        on[~lost, 0] = True
        for j in np.flatnonzero(
            ~lost & ~on.all(axis=1)
        ).tolist():  # latched from the first step off the track
            i = int(live[j])
            first_off = int(np.flatnonzero(~on[j])[0])
            row = out[j, first_off - 1]
            self.lost[i] = True
            self.lost_time_s[i] = float(row[0])
            self.lost_state[i] = self.plants[i]._row_state(row)
            on[j, first_off:] = False
        self.last_row[live] = last
        self.physics_time_s = float(last[0, 0])
        times = t0 + np.arange(m + 1) * self.dt  # as Plant.advance: its clock plus the step offsets
        return times, along, theta, on

    def _check_numerics(self, t0: float, out: np.ndarray) -> None:
        """Plant._check_numerics for every live run: a NumericalError for the first run MuJoCo warned in
        (a simulation that warns stops stepping: its clock stops) or whose beam went past its stops further
        than they can yield."""
        live = self.live
        # (lastinfo, number) per warning
        warned = np.flatnonzero(self.batch.warning[self.ids[live], :, 1].any(axis=1))
        theta = np.abs(out[:, :, self.theta_col])
        past = np.flatnonzero((theta > self.theta_limit_rad[live, None]).any(axis=1))
        if not (warned.size or past.size):
            return
        run = f"run {int(live[(warned if warned.size else past)[0]])}: " if self.n > 1 else ""
        if warned.size:
            j = int(warned[0])
            i = int(live[j])
            counts = dict(enumerate(self.batch.warning[self.ids[i], :, 1].tolist()))
            error = numerical_failure(
                self.plants[i].params, warning_text(counts), failure_time_s(np.r_[t0, out[j, :, 0]])
            )
        else:
            j = int(past[0])
            i = int(live[j])
            k = int(np.flatnonzero(theta[j] > self.theta_limit_rad[i])[0])
            error = beyond_stops(self.plants[i].params, float(theta[j, k]), float(out[j, k, 0]))
        raise type(error)(run + str(error))

    def read(self) -> BatchSamples:
        """SimRig._read for every live run: the same ``TickSchedule`` plan, the pieces as arrays over the runs."""
        live = self.live
        plan = self.schedule.next_block()
        t_start = plan.start_step * self.dt if plan.start_step < 0 else self.physics_time_s
        if plan.free_steps:  # released before this block begins: run free up to it, unobserved
            pre_t, pre_x, _, pre_on = self._advance(self._step_volts(plan.free_steps))
            t_start = self.physics_time_s
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
        their rollout, which the caller runs (with other groups' rows) before ``end_observed``."""
        plan = self.schedule.next_block()
        assert plan.free_steps == 0 and plan.held_end_step is None and plan.observed_steps
        return self.physics_time_s, self._step_volts(plan.observed_steps)

    def end_observed(self, t0: float, out: np.ndarray) -> BatchSamples:
        """The rest of ``read``: ``out`` the live runs' rollout of ``begin_observed``'s volts from ``t0``."""
        t, x, th, on = self._advanced(t0, out)
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
        if self.ball is None:
            ball_v, angle_v = self.ideal_sensors.read_v(
                block_x[:, -1], block_theta[:, -1], self.zeroing_error_rad[live]
            )
        else:
            angle_v = angle_block_means_v(block_t, block_theta, p, self.zeroing_error_rad[live])
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
        states = np.empty((len(live), 4))
        which = self.shape_of[live]
        for k, plant in enumerate(self.shapes):
            rows = which == k
            if rows.all():
                states = plant.row_states(self.last_row[live])
            elif rows.any():
                states[rows] = plant.row_states(self.last_row[live[rows]])
        lost = self.lost[live]
        states[lost] = self.lost_state[live[lost]]  # Plant.state: the state at the step it left the track
        return states

    @property
    def time_s(self) -> float:
        if self.held_now:
            return self.schedule.next_start_step * self.dt
        return self.physics_time_s

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
        if abs(controller.period_s - p.daq.period_s) > _PERIOD_TOLERANCE_S:
            raise RigError(
                f"{controller.name}: period_s = {controller.period_s!r} s does not match the DAQ's "
                f"daq.period_s = {p.daq.period_s!r} s"
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


class ReferenceBatchRig(BatchRig):
    """The fast engine's rig: ``BatchRig`` (the sensor chains, DAQ schedule, output stage and recorder over the
    batch, the very functions a single run uses) over the analytic reference plant in the compiled kernel
    (``twin.screen.plant``) instead of MuJoCo: each run is ``run_closed_loop(..., plant="reference")`` of the
    same start and seed bit for bit (the kernel steps as ``ReferencePlant.advance``; tests/test_screen.py)."""

    def _start_physics(
        self,
        params: list[Parameters],
        x0: np.ndarray,
        theta0: np.ndarray,
        nthread: int,
        batch: mjbatch.Batch | None,
        ids: np.ndarray | None,
        plant_cache: dict[Parameters, Plant] | None,
    ) -> None:
        """As ``ReferencePlant.reset``: each start checked, at rest, the clock at 0."""
        from twin.screen.plant import plant_rows  # numba is imported when the fast engine is asked for

        if batch is not None:
            raise ValueError("the reference plant's runs are not rows of a MuJoCo batch")
        for i, q in enumerate(params):
            check_initial_state(q, float(x0[i]), float(theta0[i]), 0.0, 0.0)
        self.plant = plant_rows(params)
        self.states = np.zeros((len(params), 4))
        self.states[:, 0], self.states[:, 1] = x0, theta0
        self.lost_step = np.full(len(params), -1, dtype=np.int64)  # ≥ 0 once lost: the kernel skips the run
        self.physics_time_s = 0.0

    def _advance(self, volts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``ReferencePlant.advance`` for every live run: (times (m+1,), x, θ, on-track (live, m+1))."""
        from twin.screen.plant import PlantRows, advance_plant

        live, m, h = self.live, volts.shape[1], self.dt
        t0 = self.physics_time_s
        every = len(live) == self.n
        plant = self.plant if every else PlantRows(self.plant.rows[live], self.plant.timestep_s)
        states, lost_step = self.states[live], self.lost_step[live]
        recorded = advance_plant(plant, states, lost_step, volts, record=True)
        assert recorded is not None
        along, theta = recorded
        if not np.isfinite(states).all():
            j = int(np.flatnonzero(~np.isfinite(states).all(axis=1))[0])
            raise FloatingPointError(
                f"run {int(live[j])}: reference model state is not finite by t = {t0 + m * h:.3f} s"
            )
        on = np.ones(along.shape, dtype=bool)
        was_lost = self.lost[live]
        on[was_lost] = False
        for j in np.flatnonzero(~was_lost & (lost_step >= 0)).tolist():
            i, k = int(live[j]), int(lost_step[j])
            self.lost[i] = True
            self.lost_time_s[i] = t0 + k * h  # ReferencePlant's: its clock plus the step's offset
            self.lost_state[i] = states[j]  # the state stays where the ball left the track
            on[j, k:] = False
        self.states[live], self.lost_step[live] = states, lost_step
        times = t0 + np.arange(m + 1) * h
        self.physics_time_s = float(times[-1])
        return times, along, theta, on

    def true_state(self) -> np.ndarray:
        """SimRig.true_state for every live run: the held start, or the kernel's state (frozen once lost)."""
        live = self.live
        if self.held_now:
            return self.held[live].copy()
        return self.states[live]
