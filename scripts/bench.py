"""Benchmarks (measured here, never asserted in tests): the twin's costs as ratios to the physical floor.

    python scripts/bench.py [--json] [--repeats 15] [--batch-side 41] [--skip-batch] [--skip-peers]
                            [--skip-calibration] [--skip-view] [--view-seconds 60] [--skip-wire] [--only-wire]
                            [--skip-vector-env] [--only-vector-env] [--skip-sweep-command] [--only-sweep-command]
                            [--skip-batched-laws] [--only-batched-laws] [--skip-firmware] [--only-firmware]
                            [--skip-fmi] [--only-fmi] [--skip-falsify] [--only-falsify]
                            [--skip-screen] [--only-screen]

One run measures, on the same work (a 10 s episode from x0 = 0.2 m, θ0 = 0.3 rad, noise on, seed 0):

- (a) floor: raw ``mujoco.rollout`` of the episode's physics steps in one call, single thread, with the motor
  volts the closed loop applied (so the same trajectory: checked bit for bit); and of the (c) grid's runs on
  2 threads;
- (b) episodes: the closed loop through the twin with the full I/O chain (``twin.rigs.sim.run_closed_loop``):
  appendix-sf (the target: ≤ 1.5 × its floor), appendix-clp, lqr, and the 1 kHz chapter 4 laws on the true
  state (thesis-sf/clp/smc-continuous: ≤ 3 × their floors), each against the floor of its own trajectory.
  Every episode runs to the end (``stop_when_lost=False``);
- (c) batch: a side × side grid (41 × 41 by default) of 10 s appendix-sf episodes (noise on) through the
  batch engine (``twin.rigs.batch``) on 2 threads, all to the end and as a sweep runs it (lost balls leave the
  batch; its floor is the full floor scaled by the physics steps done), against (a) on 2 threads, interleaved
  with it (the best of two of each);
- (d) peers: the same episode on the analytic model (the nonlinear ``twin.reference`` equations, no sensor
  chain) with §5.2.1's state feedback (``controllers.thesis_numbers.SF_DISC_K``) on the true state at 50 Hz,
  held between samples and clamped to the amplifier's ±12 V, each 20 ms interval integrated with the held
  input and the state output every 1 ms: python-control (``control.input_output_response`` on a
  ``control.nlsys``) and ``scipy.integrate.solve_ivp`` (both with their default method and tolerances);
- (e) calibration: wall time of a 5-parameter fit to a 60 s log;
- physics: µs per MuJoCo step, ms per 20 ms tick of the TwinRig;
- wire: a lock-step session over loopback UDP (``ballbeam serve`` in its own process, ``RemoteRig`` here) per tick
  against the same appendix-sf episode in process (target ≤ 2×);
- (g) the whole command: ``ballbeam sweep`` of the (c) grid in a new process (start-up, corners, JSON and
  map written) against the 2-thread floor of the sweep's steps, interleaved (target ≤ 1.2×);
- (f) vector env: 64 appendix-sf runs through ``BallBeamVectorEnv`` (replaying the batch engine's commands: the
  same trajectories) per env-step against the batch engine's per run-tick (target ≤ 1.3×);
- (h) batched laws: a 16 × 16 grid of 10 s runs (noise on) of clp, thesis-clp and smc through the batch engine
  on 2 threads, their controllers in numpy (``controllers.batch``) against one scalar controller per run
  (``vectorized=False``: the same bits), interleaved, the best of two;
- (i) firmware: examples/avr's image (built with its Makefile) in closed loop on a simulated ATmega328P
  (``--controller avr:…``) over the same episode: wall time against the episode's simulated time (the real-time
  factor; target ≥ 5×) and against appendix-sf in process (the same law in Python), interleaved, the best of
  ``--repeats``;
- (j) FMI: the exported unit (``ballbeam export-fmu``) stepped from FMPy over the same episode with the commands
  the in-process appendix-sf run wrote (the same trajectory, bit for bit), against that run; and
  examples/fmu's controller unit (``--controller fmu:…``, its own process) against appendix-sf in process;
  interleaved, the best of ``--repeats`` (at most 5); the unit's size;
- (k) falsification: runs to the first counterexample, median over 20 search seeds, of ``ballbeam falsify``'s
  search against uniform random sampling of the same space with the same budget (300), on two problems whose
  answer a brute-force map gives (a start box crossing appendix-sf's region at a corner; a start near its
  edge over docs/examples/spread.toml's rigs, whose tail loses the ball); and a falsification of budget 500 at
  10 s against a 500-run batch;
- (l) the compiled engine's plant (``twin.screen``, numba) against a plain C RK4 of the same equations and raw
  ``mujoco.rollout`` of the contact model on one thread: ns per state-step, interleaved;
- view: the live view's tick rate at speed 1.0 over the given wall time (target 50 Hz ± 1 %) and its CPU
  time per tick, with a client attached (a websocket speaking viser's protocol, draining every frame).

(a) and (b) are the best of ``--repeats`` interleaved repeats (15 by default: the shared machine's bursts of
load last seconds), wall time and CPU time (``process_time``, which other processes on a shared machine
inflate less); compare ratios within one run. Ratios printed: (b)/(a),
(c)/(a, 2 threads), (d)/(b) and (d)/(c per episode).
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import os
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

# One BLAS thread: the batch's threads are MuJoCo's (set before numpy loads OpenBLAS).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import mujoco
import numpy as np
from mujoco import rollout

from controllers import registry
from controllers import thesis_numbers as T
from twin.engine import RunResult, StateLaw, run_on_rig
from twin.interface import Controller, Telemetry
from twin.parameters import Parameters
from twin.plant import FULL_STATE, Plant
from twin.reference import ReferenceModel
from twin.rigs.batch import run_batch
from twin.rigs.sim import TwinRig, run_closed_loop

DURATION_S = 10.0
X0_M, THETA0_RAD = 0.2, 0.3
EPISODES = (
    "appendix-sf",
    "appendix-clp",
    "lqr",
    "thesis-sf-continuous",
    "thesis-clp-continuous",
    "thesis-smc-continuous",
)


def _timed(f: Callable[[], Any]) -> tuple[float, float]:
    """(wall, CPU) seconds of one call."""
    start, start_cpu = time.perf_counter(), time.process_time()
    f()
    return time.perf_counter() - start, time.process_time() - start_cpu


def bench_physics() -> dict[str, float]:
    plant = Plant()
    plant.reset(0.1, 0.05)
    n = 20000
    start = time.perf_counter()
    for _ in range(n):
        mujoco.mj_step(plant.model, plant.data)
    raw = (time.perf_counter() - start) / n
    rig = TwinRig(seed=0)
    rig.reset(0.1, 0.05)
    ticks = 500
    start = time.perf_counter()
    for _ in range(ticks):
        rig.read()
        rig.write(2.5)
    tick = (time.perf_counter() - start) / ticks
    return {"mj_step_us": 1e6 * raw, "twinrig_tick_ms": 1e3 * tick, "realtime_factor_50hz": 0.02 / tick}


# --- (a) and (b): one episode against raw rollout of its own physics -------------------------------------
class _RecordedLaw:
    """A state law that also records the volts it asks for (the replay's control for a 1 kHz law)."""

    def __init__(self, law: StateLaw, rail_v: float) -> None:
        self.law, self.rail_v = law, rail_v
        self.name, self.period_s = law.name, law.period_s
        self.volts: list[float] = []

    @property
    def telemetry(self) -> Telemetry:
        return self.law.telemetry

    def reset(self) -> None:
        self.law.reset()

    def motor_volts(self, state: np.ndarray) -> float:
        volts = self.law.motor_volts(state)
        self.volts.append(min(max(volts, -self.rail_v), self.rail_v))  # the rig clamps to the rails
        return volts


def _episode(name: str, controller: Any = None) -> RunResult:
    return run_closed_loop(
        controller or registry.make(name),
        x0_m=X0_M,
        theta0_rad=THETA0_RAD,
        duration_s=DURATION_S,
        seed=0,
        noise=True,
        stop_when_lost=False,
    )


def _replay_control(name: str, params: Parameters) -> tuple[np.ndarray, RunResult]:
    """The motor volts of every physics step of the episode (from release), and the episode."""
    made = registry.make(name, params)
    if registry.simulation_only(name):
        recorded = _RecordedLaw(made, params.amplifier.rail_v)  # type: ignore[arg-type]
        result = _episode(name, recorded)
        volts = np.array(recorded.volts)
    else:
        result = _episode(name, made)
        dt, per_tick = params.physics.timestep_s, int(round(params.period_s / params.physics.timestep_s))
        free = int(round(params.start.free_run_s / dt))
        logged = result.log.motor_volts_v  # row k: after the k-th command (row 0: before the first)
        volts = np.concatenate([np.full(free, logged[0]), np.repeat(logged[1:], per_tick)])
    steps = int(round(result.log.true_time_s[-1] / params.physics.timestep_s))
    # Before a state law's first evaluation the motor sees the zero command (0 V).
    control = np.concatenate([np.zeros(max(0, steps - len(volts))), volts])[:steps]
    return control, result


def bench_episode(name: str, repeats: int) -> dict[str, float]:
    """The episode and raw rollout of its physics, interleaved, best of ``repeats``."""
    params = Parameters()
    control, result = _replay_control(name, params)
    plant = Plant(params)
    plant.reset(X0_M, THETA0_RAD)
    initial = np.empty((1, mujoco.mj_stateSize(plant.model, FULL_STATE)))
    mujoco.mj_getState(plant.model, plant.data, initial[0], FULL_STATE)
    ctrl = control[None, :, None]
    states = np.empty((1, len(control), initial.shape[1]))  # allocated once: the floor is the stepping
    runner = rollout.Rollout(nthread=0)

    def floor() -> None:
        runner.rollout(plant.model, plant.data, initial, ctrl, state=states)

    best = {"floor": [np.inf, np.inf], "episode": [np.inf, np.inf]}
    for _ in range(repeats):
        for key, f in (("floor", floor), ("episode", lambda: _episode(name))):
            wall, cpu = _timed(f)
            best[key] = [min(best[key][0], wall), min(best[key][1], cpu)]
    # The replay reproduces the run: the true state at its last tick with the ball on the track.
    log = result.log
    k = int(np.flatnonzero(~log.ball_lost & (log.true_time_s > 0))[-1])
    step = int(round(log.true_time_s[k] / params.physics.timestep_s))
    same = bool(
        np.array_equal(
            plant.row_states(states[0, step - 1 : step])[0],
            [log.true_x_m[k], log.true_theta_rad[k], log.true_xdot_m_s[k], log.true_thetadot_rad_s[k]],
        )
    )
    (floor_s, floor_cpu), (run_s, run_cpu) = best["floor"], best["episode"]
    return {
        "physics_steps": float(len(control)),
        "floor_s": floor_s,
        "floor_cpu_s": floor_cpu,
        "run_s": run_s,
        "run_cpu_s": run_cpu,
        "x_floor": run_s / floor_s,
        "cpu_x_floor": run_cpu / floor_cpu,
        "floor_reproduces_run": float(same),
    }


# --- (c): the sweep through the batch engine ----------------------------------------------------------------
def _raw_rollout_s(
    plant: Plant, initial: np.ndarray, control: np.ndarray, nthread: int, chunk: int = 200
) -> tuple[float, float, np.ndarray]:
    """Raw ``mujoco.rollout`` of these runs on ``nthread`` threads (in chunks of runs, to bound the memory of
    its state output): the wall and CPU time of the rollout calls and each run's final state."""
    datas = [mujoco.MjData(plant.model) for _ in range(nthread)]
    final = np.empty_like(initial)
    elapsed = cpu = 0.0
    for lo in range(0, len(initial), chunk):
        hi = min(lo + chunk, len(initial))
        start, start_cpu = time.perf_counter(), time.process_time()
        states, _ = rollout.rollout(plant.model, datas, initial[lo:hi], control[lo:hi])
        elapsed += time.perf_counter() - start
        cpu += time.process_time() - start_cpu
        final[lo:hi] = states[:, -1]
    return elapsed, cpu, final


@dataclass
class _GridPhysics:
    """The physics of a side × side appendix-sf grid (10 s, noise on) as one open-loop job: each run's motor
    volts as the closed loop applied them, its initial state, and the share of its steps a sweep does (a
    run stops at the end of the block in which its ball left the track)."""

    x0: np.ndarray
    theta0: np.ndarray
    plant: Plant
    initial: np.ndarray
    control: np.ndarray
    share: float
    lost: int
    full: list[RunResult]
    sweep_s: float
    sweep_cpu_s: float
    full_s: float
    full_cpu_s: float


def _grid_physics(side: int, duration_s: float, nthread: int) -> _GridPhysics:
    params = Parameters()
    x0, theta0 = (
        a.ravel() for a in np.meshgrid(np.linspace(-0.32, 0.32, side), np.linspace(-0.7, 0.7, side))
    )
    seeds = np.arange(len(x0))
    kw: dict[str, Any] = dict(x0_m=x0, theta0_rad=theta0, seeds=seeds, duration_s=duration_s, nthread=nthread)
    start, start_cpu = time.perf_counter(), time.process_time()
    full = run_batch(registry, "appendix-sf", **kw, stop_when_lost=False, record=True)
    full_s, full_cpu = time.perf_counter() - start, time.process_time() - start_cpu
    start, start_cpu = time.perf_counter(), time.process_time()
    sweep = run_batch(registry, "appendix-sf", **kw)
    sweep_s, sweep_cpu = time.perf_counter() - start, time.process_time() - start_cpu
    dt, period = params.physics.timestep_s, params.period_s
    free = int(round(params.start.free_run_s / dt))
    per_tick = int(round(period / dt))
    volts = np.array([r.log.motor_volts_v for r in full])  # row k: after the k-th command
    steps = int(round(full[0].log.true_time_s[-1] / dt))
    control = np.empty((len(x0), steps, 1))
    control[:, :free, 0] = volts[:, :1]
    control[:, free:, 0] = np.repeat(volts[:, 1:], per_tick, axis=1)[:, : steps - free]
    plant = Plant(params)
    initial = np.empty((len(x0), mujoco.mj_stateSize(plant.model, FULL_STATE)))
    for i in range(len(x0)):
        plant.reset(float(x0[i]), float(theta0[i]))
        mujoco.mj_getState(plant.model, plant.data, initial[i], FULL_STATE)
    lost_steps = [
        int(round(r.verdict.ball_lost_time_s / dt)) for r in sweep if r.verdict.ball_lost_time_s is not None
    ]
    sweep_steps = sum(
        min(steps, free + per_tick * max(0, -(-(k - free) // per_tick))) for k in lost_steps
    ) + steps * (len(sweep) - len(lost_steps))
    return _GridPhysics(
        x0,
        theta0,
        plant,
        initial,
        control,
        sweep_steps / (steps * len(x0)),
        len(lost_steps),
        full,
        sweep_s,
        sweep_cpu,
        full_s,
        full_cpu,
    )


def bench_batch(
    side: int = 41, duration_s: float = DURATION_S, nthread: int = 2, repeats: int = 2
) -> dict[str, float]:
    """The side × side sweep of appendix-sf through the batch engine against raw rollout of the same physics,
    interleaved (floor, batch to the end, batch as a sweep, …; the best of each)."""
    g = _grid_physics(side, duration_s, nthread)
    floor_s, floor_cpu, final = _raw_rollout_s(g.plant, g.initial, g.control, nthread)
    seeds = np.arange(len(g.x0))
    kw: dict[str, Any] = dict(
        x0_m=g.x0, theta0_rad=g.theta0, seeds=seeds, duration_s=duration_s, nthread=nthread
    )
    for _ in range(repeats - 1):
        f_s, f_cpu, _ = _raw_rollout_s(g.plant, g.initial, g.control, nthread)
        floor_s, floor_cpu = min(floor_s, f_s), min(floor_cpu, f_cpu)
        wall, cpu = _timed(lambda: run_batch(registry, "appendix-sf", **kw, stop_when_lost=False))
        g.full_s, g.full_cpu_s = min(g.full_s, wall), min(g.full_cpu_s, cpu)
        wall, cpu = _timed(lambda: run_batch(registry, "appendix-sf", **kw))
        g.sweep_s, g.sweep_cpu_s = min(g.sweep_s, wall), min(g.sweep_cpu_s, cpu)
    # The open loop reproduces the closed loop's trajectories bit for bit (runs whose ball stayed on).
    kept = np.array([not r.verdict.ball_lost for r in g.full])
    end_x = np.array([r.log.true_x_m[-1] for r in g.full])
    same = bool(np.array_equal(g.plant.row_states(final[kept])[:, 0], end_x[kept]))
    return {
        "runs": float(len(g.x0)),
        "floor_2threads_s": floor_s,
        "open_loop_reproduces_closed_loop": float(same),
        "batch_all_to_end_s": g.full_s,
        "batch_all_to_end_per_episode_s": g.full_s / len(g.x0),
        "batch_all_to_end_x_floor": g.full_s / floor_s,
        "sweep_stop_when_lost_s": g.sweep_s,
        "sweep_floor_scaled_s": floor_s * g.share,
        "sweep_x_floor": g.sweep_s / (floor_s * g.share),
        "sweep_lost": float(g.lost),
        "floor_cpu_s": floor_cpu,
        "batch_all_to_end_cpu_x_floor": g.full_cpu_s / floor_cpu,
        "sweep_cpu_x_floor": g.sweep_cpu_s / (floor_cpu * g.share),
    }


def bench_sweep_command(side: int = 41, repeats: int = 3, nthread: int = 2) -> dict[str, float]:
    """``ballbeam sweep`` as a user runs it (a new process: start-up, the grid and the claims' corners, the
    JSON and the map written) against the 2-thread rollout floor of the sweep's physics steps, interleaved:
    floor, command, floor, command, …; the best of each counts."""
    import subprocess
    import sys
    import tempfile

    g = _grid_physics(side, DURATION_S, nthread)
    out = Path(tempfile.mkdtemp(prefix="bench-sweep-"))
    argv = [sys.executable, "-m", "twin.app.cli", "sweep", "--controller", "appendix-sf"]
    argv += [
        "--x0",
        f"-0.32:0.32:{side}",
        "--theta0",
        f"-0.7:0.7:{side}",
        "--out",
        str(out / "s"),
        "--overwrite",
    ]
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    floors, commands = [], []
    for _ in range(repeats):
        floors.append(_raw_rollout_s(g.plant, g.initial, g.control, nthread)[0] * g.share)
        start = time.perf_counter()
        subprocess.run(argv, check=True, capture_output=True, env=env)
        commands.append(time.perf_counter() - start)
    return {
        "starts": float(len(g.x0)),
        "sweep_floor_s": min(floors),
        "sweep_command_s": min(commands),
        "sweep_command_x_floor": min(commands) / min(floors),
    }


# --- (f): the vector environment against the batch engine ----------------------------------------------------
def bench_vector_env(n: int = 64, duration_s: float = DURATION_S, repeats: int = 3) -> dict[str, float]:
    """``n`` runs of appendix-sf (an 8 × 8 grid of the hardware box, noise on) through the batch engine, and the
    same runs through ``BallBeamVectorEnv`` replaying the batch's DAC commands as actions (the same
    trajectories: checked bit for bit): the cost per env-step against the batch's per run-tick. Interleaved
    repeats; the best of each counts."""
    from twin.app.envs import BallBeamVectorEnv

    side = int(round(np.sqrt(n)))
    x0, theta0 = (a.ravel() for a in np.meshgrid(np.linspace(-0.2, 0.2, side), np.linspace(-0.3, 0.3, side)))
    n = len(x0)
    seeds = np.arange(n) + 1000
    kw: dict[str, Any] = dict(x0_m=x0, theta0_rad=theta0, seeds=seeds, duration_s=duration_s, nthread=2)
    runs = run_batch(registry, "appendix-sf", **kw, stop_when_lost=False, record=True)
    commands = np.array([r.log.aout for r in runs])  # row 0: the start block's (no command)
    env = BallBeamVectorEnv(n, duration_s=duration_s, nthread=2)
    steps = env.cfg.ticks
    options = {"x0_m": x0, "theta0_rad": theta0, "noise_seed": seeds}

    def batch() -> None:
        run_batch(registry, "appendix-sf", **kw, stop_when_lost=False)

    def vector() -> np.ndarray:
        obs, _ = env.reset(seed=0, options=options)
        for k in range(steps):
            obs, *_ = env.step(commands[:, k + 1, None])
        return obs

    last = vector()
    same = bool(np.array_equal(last[:, 0], [r.log.datam1[steps + 1] for r in runs]))  # the last ball volts
    best_batch = best_vec = float("inf")
    for _ in range(repeats):
        best_batch = min(best_batch, _timed(batch)[0])
        best_vec = min(best_vec, _timed(vector)[0])
    ticks = len(runs[0].log.aout) - 1  # the batch's update ticks (its start block is not a tick)
    per_tick = best_batch / (n * ticks)
    per_step = best_vec / (n * steps)
    return {
        "envs": float(n),
        "same_trajectories": float(same),
        "batch_engine_us_per_run_tick": 1e6 * per_tick,
        "vector_env_us_per_env_step": 1e6 * per_step,
        "vector_env_over_batch_engine": per_step / per_tick,
    }


# --- (d): the peers a user would otherwise reach for ----------------------------------------------------
def _sampled_state_feedback(
    integrate: Callable[[float, np.ndarray, float], np.ndarray], params: Parameters
) -> np.ndarray:
    """The episode with §5.2.1's gains on the true state every 20 ms, the volts held in between: each
    interval integrated by ``integrate(t0, x0, volts) -> states at 1 ms`` (its last row the next sample)."""
    gain, rail = T.SF_DISC_K[0], params.amplifier.rail_v
    x = np.array([X0_M, THETA0_RAD, 0.0, 0.0])
    for k in range(int(round(DURATION_S / T.PERIOD_S))):
        volts = min(max(-float(gain @ x), -rail), rail)
        x = integrate(k * T.PERIOD_S, x, volts)[-1]
    return x


def bench_peers() -> dict[str, float]:
    """(d): python-control and scipy on the analytic model, 50 Hz state feedback with a zero-order hold."""
    import control
    import scipy.integrate

    params = Parameters()
    model = ReferenceModel(params)
    sample_offsets = T.PERIOD_S * np.arange(21) / 20  # the interval's start and its 20 ms at 1 ms

    def update(_t: float, x: np.ndarray, u: np.ndarray, _params: dict[str, Any]) -> np.ndarray:
        return model.derivative(x, float(u[0]))

    plant = control.nlsys(update, None, inputs=1, outputs=4, states=4, name="ballbeam")

    def with_control(t0: float, x0: np.ndarray, volts: float) -> np.ndarray:
        response = control.input_output_response(plant, T=t0 + sample_offsets, U=volts, X0=x0)
        return np.asarray(response.states).T

    def with_scipy(t0: float, x0: np.ndarray, volts: float) -> np.ndarray:
        times = t0 + sample_offsets
        solution = scipy.integrate.solve_ivp(
            lambda _t, x: model.derivative(x, volts), (times[0], times[-1]), x0, t_eval=times[1:]
        )
        return np.asarray(solution.y).T

    out: dict[str, float] = {}
    for key, integrate in (("python_control", with_control), ("scipy_solve_ivp", with_scipy)):
        final: np.ndarray | None = None

        def episode(integrate: Callable[[float, np.ndarray, float], np.ndarray] = integrate) -> None:
            nonlocal final
            final = _sampled_state_feedback(integrate, params)

        wall, cpu = _timed(episode)
        assert final is not None
        out[f"{key}_s"], out[f"{key}_cpu_s"], out[f"{key}_final_x_m"] = wall, cpu, float(final[0])
    return out


# --- (e) and the live view -----------------------------------------------------------------------------------
def bench_calibration() -> dict[str, float]:
    """Wall time of ``calibrate`` on a 60 s log of the recommended experiment, 5 parameters (the target:
    under 30 s on 2 cores)."""
    from calib.experiments import run_experiment
    from calib.identify import calibrate
    from calib.logs import rig_log

    start_params = Parameters().with_overrides({"beam.pivot_damping_nm_s_per_rad": 1e-3})
    truth = start_params.with_overrides({"motor.resistance_ohm": 10.5, "beam.inertia_pivot_kgm2": 3.7e-3})
    log = rig_log(run_experiment("square", truth, duration_s=60.0, seed=1).log)
    fit = [
        "motor.resistance_ohm",
        "beam.inertia_pivot_kgm2",
        "beam.pivot_damping_nm_s_per_rad",
        "beam.pivot_friction_nm",
        "angle_sensor.zeroing_error_rad",
    ]
    start = time.perf_counter()
    cal = calibrate([log], fit, start_params)
    return {"calibrate_60s_5_params_s": time.perf_counter() - start, "converged": float(cal.converged)}


def bench_view(seconds: float) -> dict[str, float]:
    """The live view at speed 1.0 with a client attached (a websocket speaking viser's protocol from the
    page's origin, draining every frame as a browser would; without one the view waits, paused): its tick
    rate and CPU time per tick over ``seconds`` of wall time, and the frames the client received."""
    import threading

    from viewer_client import ViewerClient

    from twin.viewer import Viewer, serve

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    ready = threading.Event()
    out: dict[str, Any] = {}

    def on_ready(viewer: Viewer) -> None:
        ready.set()

    def run() -> None:
        out["stats"] = serve(
            registry, port=port, duration_s=seconds, speed=1.0, announce=False, on_ready=on_ready
        )

    server = threading.Thread(target=run, daemon=True)
    server.start()
    if not ready.wait(60):
        raise RuntimeError("the view did not start")
    client = ViewerClient(port)
    server.join()
    client.close()
    stats = out["stats"]
    stats["tick_rate_error_pct"] = 100.0 * (stats["tick_rate_hz"] / 50.0 - 1.0)
    stats["cpu_ms_per_tick"] = 1e3 * stats.pop("cpu_s_per_tick")
    stats["client_messages"] = float(client.frames)
    return stats


def bench_wire(repeats: int) -> dict[str, float]:
    """Lock-step over loopback UDP per tick against the same episode in process (appendix-sf; target ≤ 2×),
    best of ``repeats``: ``ballbeam serve`` in its own process, ``twin.engine.run_on_rig`` here, timed from
    the handshake to the last sample (the server's start-up is not the session's cost)."""
    import subprocess
    import sys

    from twin.rigs.remote import RemoteRig, parse_udp_url

    serve = [sys.executable, "-m", "twin.app.cli", "serve", "--x0", str(X0_M), "--theta0", str(THETA0_RAD)]
    serve += ["--duration", str(DURATION_S), "--seed", "0", "--wait-client", "60", "--json"]

    def wire() -> tuple[float, int]:
        server = subprocess.Popen(serve, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        assert server.stdout is not None
        host, port = parse_udp_url(json.loads(server.stdout.readline())["serving_on"])
        start = time.perf_counter()
        with RemoteRig(host, port) as rig:
            controller = registry.make("appendix-sf", rig.parameters())
            assert isinstance(controller, Controller)
            ticks = run_on_rig(controller, rig).log.timem.size
        elapsed = time.perf_counter() - start
        server.communicate(timeout=60)
        return elapsed, int(ticks)

    best_in, best_wire, ticks = np.inf, np.inf, 0
    for _ in range(repeats):
        best_in = min(best_in, _timed(lambda: _episode("appendix-sf"))[0])
        elapsed, ticks = wire()
        best_wire = min(best_wire, elapsed)
    return {
        "ticks": float(ticks),
        "in_process_ms_per_tick": 1e3 * best_in / ticks,
        "lockstep_udp_ms_per_tick": 1e3 * best_wire / ticks,
        "lockstep_over_in_process": best_wire / best_in,
    }


BATCHED_LAWS = ("clp", "thesis-clp", "smc")


def bench_batched_laws(side: int = 16, repeats: int = 2, nthread: int = 2) -> dict[str, float]:
    """(h): each of ``BATCHED_LAWS`` over a side × side grid, batched controller against the scalar loop."""
    x0, theta0 = np.meshgrid(np.linspace(-0.3, 0.3, side), np.linspace(-0.6, 0.6, side))
    kw: dict[str, Any] = dict(
        x0_m=x0.ravel(),
        theta0_rad=theta0.ravel(),
        seeds=np.arange(side * side),
        duration_s=DURATION_S,
        nthread=nthread,
    )
    out: dict[str, float] = {"runs": float(side * side)}
    for name in BATCHED_LAWS:
        best = {True: np.inf, False: np.inf}
        for _ in range(repeats):
            for vectorized in (True, False):
                wall, _ = _timed(functools.partial(run_batch, registry, name, **kw, vectorized=vectorized))
                best[vectorized] = min(best[vectorized], wall)
        out[f"{name}_batched_s"] = best[True]
        out[f"{name}_scalar_loop_s"] = best[False]
        out[f"{name}_scalar_loop_over_batched"] = best[False] / best[True]
    return out


def bench_firmware(repeats: int) -> dict[str, float]:
    """(i): the firmware in the loop, against the rig's time and the same law in process."""
    import subprocess

    from twin.avr.firmware import AvrFirmware

    folder = Path(__file__).resolve().parents[1] / "examples" / "avr"
    subprocess.run(["make", "-s", "-C", str(folder)], check=True)
    params = Parameters()

    def firmware() -> RunResult:
        fw = AvrFirmware(folder / "bb_sf.elf", params)
        return run_closed_loop(fw, x0_m=X0_M, theta0_rad=THETA0_RAD, duration_s=DURATION_S, seed=0)

    best_fw, best_py, cpu_fw = np.inf, np.inf, np.inf
    for _ in range(repeats):
        wall, cpu = _timed(firmware)
        best_fw, cpu_fw = min(best_fw, wall), min(cpu_fw, cpu)
        best_py = min(best_py, _timed(lambda: _episode("appendix-sf"))[0])
    simulated_s = firmware().log.timem[-1]
    return {
        "simulated_s": float(simulated_s),
        "firmware_run_s": best_fw,
        "firmware_cpu_s": cpu_fw,  # this process's only: simavr's own process is not counted
        "real_time_factor": float(simulated_s) / best_fw,
        "appendix_sf_run_s": best_py,
        "firmware_over_appendix_sf": best_fw / best_py,
    }


def bench_fmi(repeats: int) -> dict[str, float]:
    """(j): the rig as an FMU and a controller FMU, against the engine in process."""
    import subprocess
    import sys
    import tempfile

    import fmpy
    from fmpy.fmi3 import FMU3Slave

    from twin.app.hosts import build

    root = Path(__file__).resolve().parents[1]
    subprocess.run(
        ["make", "-s", "-C", str(root / "examples" / "fmu"), f"PYTHON={sys.executable}"], check=True
    )
    controller_unit = f"fmu:{root / 'examples' / 'fmu' / 'BbStateFeedback.fmu'}"
    log = _episode("appendix-sf").log
    with tempfile.TemporaryDirectory() as tmp:
        unit = Path(tmp) / "BallBeam.fmu"
        subprocess.run([sys.executable, "-m", "twin.app.cli", "export-fmu", "--out", str(unit)], check=True)
        md = fmpy.read_model_description(str(unit))
        vr = {v.name: v.valueReference for v in md.modelVariables}
        unzipped = fmpy.extract(str(unit))

        def rig_unit() -> None:
            fmu = FMU3Slave(
                guid=md.guid, unzipDirectory=unzipped, modelIdentifier="BallBeam", instanceName="b"
            )
            fmu.instantiate()
            fmu.enterInitializationMode()
            fmu.setFloat64([vr["x0_m"], vr["theta0_rad"]], [X0_M, THETA0_RAD])
            fmu.exitInitializationMode()
            for k, command in enumerate(log.aout[:-1]):
                fmu.setFloat64([vr["dac_v"]], [float(command)])
                fmu.doStep(0.02 * k, 0.02)
            fmu.terminate()
            fmu.freeInstance()

        def controller() -> RunResult:
            made = build(controller_unit, Parameters())
            return run_closed_loop(made, x0_m=X0_M, theta0_rad=THETA0_RAD, duration_s=DURATION_S, seed=0)

        best = {"in_process": np.inf, "rig_unit": np.inf, "controller_unit": np.inf}
        for _ in range(repeats):
            best["in_process"] = min(best["in_process"], _timed(lambda: _episode("appendix-sf"))[0])
            best["rig_unit"] = min(best["rig_unit"], _timed(rig_unit)[0])
            best["controller_unit"] = min(best["controller_unit"], _timed(controller)[0])
        size = unit.stat().st_size
    return {
        "rig_unit_bytes": float(size),
        "in_process_s": best["in_process"],
        "rig_unit_s": best["rig_unit"],
        "rig_unit_over_in_process": best["rig_unit"] / best["in_process"],
        "controller_unit_s": best["controller_unit"],
        "controller_unit_over_in_process": best["controller_unit"] / best["in_process"],
    }


REPO = Path(__file__).resolve().parents[1]

# (k) the falsifier's problems: a start box whose corner leaves appendix-sf's region (the map of
# docs/examples/falsify.toml's requirement, 5 s, noise off, puts its lost starts in a corner triangle), and a
# start near the region's edge over the spread's rigs (its tail loses the ball).
FALSIFY_SECONDS = 5.0
FALSIFY_BUDGET = 300
FALSIFY_SEEDS = 20


def _falsify_problems() -> list[tuple[str, Any, Any]]:
    from twin.app.falsify import Axis, FalsifySettings
    from twin.app.montecarlo import load_spread
    from twin.parameters import Parameters

    corner = FalsifySettings(
        "appendix-sf",
        (Axis("x0_m", -0.05, 0.105), Axis("theta0_rad", -0.70, 0.0)),
        duration_s=FALSIFY_SECONDS,
        noise=False,
        budget=FALSIFY_BUDGET,
    )
    tail = FalsifySettings(
        "appendix-sf",
        (),
        x0_m=0.12,
        theta0_rad=-0.535,
        duration_s=FALSIFY_SECONDS,
        noise=False,
        budget=FALSIFY_BUDGET,
    )
    spread = load_spread(REPO / "docs" / "examples" / "spread.toml", Parameters())
    return [("corner", corner, None), ("spread_tail", tail, spread)]


def bench_falsify(seeds: int = FALSIFY_SEEDS) -> dict[str, float]:
    """(k) runs to the first counterexample, median over ``seeds`` search seeds: the falsifier against uniform
    random sampling of the same space with the same budget (a search without one counts budget + 1); each
    problem's violating share by brute force (the corner: a 41 × 41 map of the box; the tail: 2000 uniform
    draws), and what that share makes uniform sampling's median (ln 2 / −ln(1 − p)). Then a falsification of
    budget 500 at 10 s against a 500-run batch of the engine, interleaved, the best of two."""
    from twin.app.falsify import falsify, uniform_search
    from twin.parameters import Parameters
    from twin.requirements import load_spec

    spec = load_spec(REPO / "docs" / "examples" / "falsify.toml")
    p = Parameters()
    out: dict[str, float] = {}
    for name, settings, spread in _falsify_problems():
        share = _violating_share(name, settings, spread, spec)
        found: dict[str, list[int]] = {"falsifier": [], "uniform": []}
        for seed in range(seeds):
            s = replace(settings, seed=seed)
            for method, search in (("falsifier", falsify), ("uniform", uniform_search)):
                first = search(s, p, spec, spread).first_violation
                found[method].append(FALSIFY_BUDGET + 1 if first is None else first + 1)
        for method, runs in found.items():
            out[f"{name}_{method}_median_runs"] = float(np.median(runs))
            out[f"{name}_{method}_found_of_{seeds}"] = float(sum(r <= FALSIFY_BUDGET for r in runs))
        out[f"{name}_violating_share"] = share
        out[f"{name}_uniform_expected_median_runs"] = math.log(2) / -math.log1p(-share) if share else math.inf
        out[f"{name}_uniform_over_falsifier"] = (
            out[f"{name}_uniform_median_runs"] / out[f"{name}_falsifier_median_runs"]
        )
    out.update(_falsify_speed(spec))
    out["seeds"], out["budget"] = float(seeds), float(FALSIFY_BUDGET)
    return out


def write_falsify_table(bench: dict[str, float]) -> None:
    """(k) into docs/validation/falsify_bench.json and its table on docs/validation/engines.md between the
    falsify-table markers."""
    from twin.app.falsify_render import render_table
    from twin.outputs import write_measured_table

    page = REPO / "docs" / "validation" / "engines.md"  # the manual's page of the table
    write_measured_table(
        REPO / "docs" / "validation" / "falsify_bench.json", bench, page, "falsify-table", render_table(bench),
    )  # fmt: skip


def _violating_share(name: str, settings: Any, spread: Any, spec: Any) -> float:
    from twin.app.falsify import uniform_search
    from twin.app.fanout import Runs, run_starts
    from twin.parameters import Parameters

    if spread is None:
        (xa, xb), (ta, tb) = ((a.low, a.high) for a in settings.axes)
        grid = np.array([(x, t) for x in np.linspace(xa, xb, 41) for t in np.linspace(ta, tb, 41)])
        job = Runs(
            settings.controller, Parameters(), settings.duration_s, False, "twin", False, spec.requirements
        )
        records, _ = run_starts(job, grid, np.zeros(len(grid), dtype=np.int64))
        return float(np.mean([min(r["requirements"].values()) < 0 for r in records if r]))
    wide = uniform_search(
        replace(settings, budget=2000, keep_going=True, seed=999), Parameters(), spec, spread
    )
    return float(np.mean([r["objective"] < 0 for r in wide.runs]))


def _falsify_speed(spec: Any) -> dict[str, float]:
    """A falsification of 500 runs of 10 s (to the end of its budget) against 500 runs of one batch."""
    from twin.app.falsify import Axis, FalsifySettings, falsify
    from twin.app.fanout import Runs, run_starts
    from twin.parameters import Parameters

    settings = FalsifySettings(
        "appendix-sf", (Axis("x0_m", -0.2, 0.2), Axis("theta0_rad", -0.3, 0.3)), budget=500, keep_going=True
    )
    rng = np.random.default_rng(0)
    starts = np.column_stack([rng.uniform(-0.2, 0.2, 500), rng.uniform(-0.3, 0.3, 500)])
    job = Runs("appendix-sf", Parameters(), 10.0, True, "twin", False, spec.requirements)
    best = {"falsify_500_s": math.inf, "batch_500_s": math.inf}
    for _ in range(2):
        t = time.perf_counter()
        falsify(settings, Parameters(), spec)
        best["falsify_500_s"] = min(best["falsify_500_s"], time.perf_counter() - t)
        t = time.perf_counter()
        run_starts(job, starts, np.arange(500, dtype=np.int64))
        best["batch_500_s"] = min(best["batch_500_s"], time.perf_counter() - t)
    best["falsify_over_batch"] = best["falsify_500_s"] / best["batch_500_s"]
    return best


# (l) a plain C RK4 of the reference plant alone: the physical limit the compiled engine is measured against
# (a bench-only copy of eq 3.1.26/3.1.27 and 3.3.1 with the rows of twin.screen.plant.plant_rows).
_C_RK4 = r"""
#include <math.h>
static void f(const double *r, double x, double th, double xd, double thd, double v, double *d) {
    double s = sin(th), co = cos(th), fr = r[12] * fmax(-1.0, fmin(1.0, thd / 0.01));
    double tau = r[13] * (v - r[14] * thd);
    double rb = x * thd * thd - r[3] * s;
    double rt = tau - r[7] * s - r[8] * x * co - r[9] * x * xd * thd - r[10] * x * thd * thd - r[11] * thd - fr;
    double m11 = 1.0 + r[0], m12 = -(r[1] + r[2]), m21 = r[4], m22 = r[5] + r[6] * x * x;
    double det = m11 * m22 - m12 * m21;
    d[0] = xd; d[1] = thd; d[2] = (rb * m22 - m12 * rt) / det; d[3] = (m11 * rt - m21 * rb) / det;
}
void advance(int n, int m, const double *rows, double h, double *st, const double *volts, long *lost) {
    for (int i = 0; i < n; i++) {
        const double *r = rows + 18 * i; double *q = st + 4 * i;
        double x = q[0], th = q[1], xd = q[2], thd = q[3], a[4], b[4], c[4], e[4];
        for (int k = 0; k < m && lost[i] < 0; k++) {
            double v = fmin(fmax(volts[(long)i * m + k], -r[15]), r[15]);
            f(r, x, th, xd, thd, v, a);
            f(r, x + 0.5*h*a[0], th + 0.5*h*a[1], xd + 0.5*h*a[2], thd + 0.5*h*a[3], v, b);
            f(r, x + 0.5*h*b[0], th + 0.5*h*b[1], xd + 0.5*h*b[2], thd + 0.5*h*b[3], v, c);
            f(r, x + h*c[0], th + h*c[1], xd + h*c[2], thd + h*c[3], v, e);
            x += h/6.0*(a[0]+2*b[0]+2*c[0]+e[0]); th += h/6.0*(a[1]+2*b[1]+2*c[1]+e[1]);
            xd += h/6.0*(a[2]+2*b[2]+2*c[2]+e[2]); thd += h/6.0*(a[3]+2*b[3]+2*c[3]+e[3]);
            if (fabs(th) > r[16]) { th = copysign(r[16], th); if (thd * th > 0) thd = 0.0; }
            if (fabs(x) > r[17]) lost[i] = k + 1;
        }
        q[0] = x; q[1] = th; q[2] = xd; q[3] = thd;
    }
}
"""


def bench_screen(repeats: int = 3) -> dict[str, float]:
    """(l) state-steps per second on one core, interleaved, the best of ``repeats``: the compiled engine's plant
    (twin.screen, numba) against a plain C RK4 of the same equations (gcc -O2) and against raw
    ``mujoco.rollout`` of the contact model (one thread), over the same random held volts from the same starts
    (C and the kernel: the same states, checked)."""
    import ctypes
    import subprocess
    import tempfile

    from twin.screen import advance_plant, plant_rows

    n, m = 256, 2000
    rng = np.random.default_rng(0)
    start = np.column_stack(
        [rng.uniform(-0.02, 0.02, n), rng.uniform(-0.03, 0.03, n), np.zeros(n), np.zeros(n)]
    )
    volts = np.ascontiguousarray(np.repeat(rng.uniform(-1, 1, (n, m // 20)), 20, axis=1))
    plant = plant_rows([Parameters()] * n)
    thesis_rows = np.ascontiguousarray(plant.rows[:, :18])  # the C copy's rows: the thesis's 18 columns
    folder = Path(tempfile.mkdtemp())
    (folder / "rk4.c").write_text(_C_RK4)
    subprocess.run(
        ["gcc", "-O2", "-shared", "-fPIC", "-o", str(folder / "rk4.so"), str(folder / "rk4.c"), "-lm"],
        check=True,
    )
    lib = ctypes.CDLL(str(folder / "rk4.so"))
    ptr = ctypes.POINTER(ctypes.c_double)

    def c_run() -> tuple[np.ndarray, np.ndarray]:
        st, lost = start.copy(), np.full(n, -1, dtype=np.int64)
        lib.advance(
            ctypes.c_int(n), ctypes.c_int(m), thesis_rows.ctypes.data_as(ptr), ctypes.c_double(plant.timestep_s),
            st.ctypes.data_as(ptr), volts.ctypes.data_as(ptr), lost.ctypes.data_as(ctypes.POINTER(ctypes.c_long)),
        )  # fmt: skip
        return st, lost

    def kernel_run() -> tuple[np.ndarray, np.ndarray]:
        st, lost = start.copy(), np.full(n, -1, dtype=np.int64)
        advance_plant(plant, st, lost, volts)
        return st, lost

    model = Plant(Parameters()).model
    sims = 16
    data = [mujoco.MjData(model) for _ in range(1)]
    state0 = np.zeros((sims, mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_FULLPHYSICS)))
    for j in range(sims):
        plant_j = Plant(Parameters())
        plant_j.reset(float(start[j, 0]), float(start[j, 1]))
        mujoco.mj_getState(plant_j.model, plant_j.data, state0[j], mujoco.mjtState.mjSTATE_FULLPHYSICS)
    controls = np.ascontiguousarray(volts[:sims, :, None])

    def mujoco_run() -> None:
        rollout.rollout(model, data, state0, controls, nstep=m)

    # The fast engine with everything: appendix-sf closed over the full sensor chain (noise on), DAQ schedule
    # and amplifier, 10 s runs from starts it holds (none leaves early), on one core.
    runs, duration_s = 512, 10.0
    chain_x0, chain_th0 = rng.uniform(-0.1, 0.1, runs), rng.uniform(-0.2, 0.2, runs)
    chain_steps = runs * round(duration_s / Parameters().physics.timestep_s)

    def chain_run() -> None:
        results = run_batch(
            registry, "appendix-sf", x0_m=chain_x0, theta0_rad=chain_th0, seeds=np.arange(runs),
            duration_s=duration_s, plant="reference", nthread=1,
        )  # fmt: skip
        assert not any(r.verdict.ball_lost for r in results)

    kernel_run()  # compiled before timing
    # The steps the plant alone takes: a run stops at the step its ball leaves the track (most of these open-loop
    # runs do), as the kernel and the C loop do; MuJoCo's rollout steps every one.
    _, lost_at = c_run()
    taken = int(np.where(lost_at >= 0, lost_at, m).sum())
    best = {"c": math.inf, "kernel": math.inf, "mujoco": math.inf, "chain": math.inf}
    load = os.getloadavg()[0]
    for _ in range(repeats):
        for name, run, steps in (
            ("c", c_run, taken),
            ("kernel", kernel_run, taken),
            ("mujoco", mujoco_run, sims * m),
            ("chain", chain_run, chain_steps),
        ):
            t = time.perf_counter()
            run()
            best[name] = min(best[name], (time.perf_counter() - t) / steps)
    c_state, c_lost = c_run()
    k_state, k_lost = kernel_run()
    return {
        "kernel_ns_per_state_step": 1e9 * best["kernel"],
        "c_rk4_ns_per_state_step": 1e9 * best["c"],
        "mujoco_ns_per_state_step": 1e9 * best["mujoco"],
        "kernel_over_c_rk4": best["kernel"] / best["c"],
        "mujoco_over_kernel": best["mujoco"] / best["kernel"],
        "fast_engine_ns_per_state_step": 1e9 * best["chain"],
        "fast_engine_over_c_rk4": best["chain"] / best["c"],
        "mujoco_over_fast_engine": best["mujoco"] / best["chain"],
        "load_1min": load,
        "kernel_vs_c_max_state_diff": float(np.max(np.abs(k_state - c_state))),
        "kernel_vs_c_lost_differ": float(np.sum(k_lost != c_lost)),
    }


def _and_write(bench: dict[str, float], write: bool) -> dict[str, float]:
    if write:
        write_falsify_table(bench)
    return bench


def ratios(results: dict[str, Any]) -> dict[str, float]:
    """(b)/(a), (c)/(a, 2 threads), (d)/(b) and (d)/(c per episode), wall time (CPU time where noted)."""
    episode = results["episodes"]["appendix-sf"]
    out = {"b_over_a": episode["x_floor"], "b_over_a_cpu": episode["cpu_x_floor"]}
    for name in EPISODES[3:]:
        out[f"{name}_over_a"] = results["episodes"][name]["x_floor"]
        out[f"{name}_over_a_cpu"] = results["episodes"][name]["cpu_x_floor"]
    batch = results.get("batch")
    if batch is not None:
        out["c_over_a_2threads"] = batch["batch_all_to_end_x_floor"]
        out["c_sweep_over_a_2threads"] = batch["sweep_x_floor"]
    peers = results.get("peers")
    if peers is not None:
        for key in ("python_control", "scipy_solve_ivp"):
            out[f"d_{key}_over_b"] = peers[f"{key}_s"] / episode["run_s"]
            if batch is not None:
                out[f"d_{key}_over_c_per_episode"] = (
                    peers[f"{key}_s"] / batch["batch_all_to_end_per_episode_s"]
                )
    wire = results.get("wire")
    if wire is not None:
        out["wire_lockstep_over_in_process"] = wire["lockstep_over_in_process"]
    command = results.get("sweep_command")
    if command is not None:
        out["g_sweep_command_over_floor"] = command["sweep_command_x_floor"]
    vector = results.get("vector_env")
    if vector is not None:
        out["f_vector_env_over_batch_engine"] = vector["vector_env_over_batch_engine"]
    fmi = results.get("fmi")
    if fmi is not None:
        out["j_rig_unit_over_in_process"] = fmi["rig_unit_over_in_process"]
        out["j_controller_unit_over_in_process"] = fmi["controller_unit_over_in_process"]
    target = results.get("firmware")
    if target is not None:
        out["i_firmware_real_time_factor"] = target["real_time_factor"]
        out["i_firmware_over_appendix_sf"] = target["firmware_over_appendix_sf"]
    screen = results.get("screen")
    if screen is not None:
        out["l_kernel_over_c_rk4"] = screen["kernel_over_c_rk4"]
        out["l_mujoco_over_kernel"] = screen["mujoco_over_kernel"]
        out["l_fast_engine_over_c_rk4"] = screen["fast_engine_over_c_rk4"]
        out["l_mujoco_over_fast_engine"] = screen["mujoco_over_fast_engine"]
    search = results.get("falsify")
    if search is not None:
        for name in ("corner", "spread_tail"):
            out[f"k_{name}_uniform_over_falsifier"] = search[f"{name}_uniform_over_falsifier"]
        out["k_falsify_500_over_batch_500"] = search["falsify_over_batch"]
    laws = results.get("batched_laws")
    if laws is not None:
        for name in BATCHED_LAWS:
            out[f"h_{name}_scalar_loop_over_batched"] = laws[f"{name}_scalar_loop_over_batched"]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--repeats", type=int, default=15, help="repeats of (a) and (b); the best counts")
    parser.add_argument("--view-seconds", type=float, default=60.0)
    parser.add_argument("--skip-view", action="store_true")
    parser.add_argument("--skip-calibration", action="store_true")
    parser.add_argument("--skip-batch", action="store_true")
    parser.add_argument("--skip-peers", action="store_true")
    parser.add_argument("--skip-wire", action="store_true")
    parser.add_argument("--only-wire", action="store_true", help="measure the lock-step UDP session only")
    parser.add_argument("--skip-vector-env", action="store_true")
    parser.add_argument("--skip-sweep-command", action="store_true")
    parser.add_argument("--only-sweep-command", action="store_true", help="measure (g) only")
    parser.add_argument("--only-vector-env", action="store_true", help="measure (f) only")
    parser.add_argument("--skip-batched-laws", action="store_true")
    parser.add_argument("--only-batched-laws", action="store_true", help="measure (h) only")
    parser.add_argument("--skip-firmware", action="store_true")
    parser.add_argument("--skip-fmi", action="store_true")
    parser.add_argument("--only-fmi", action="store_true", help="measure (j) only")
    parser.add_argument("--only-firmware", action="store_true", help="measure (i) only")
    parser.add_argument("--skip-falsify", action="store_true")
    parser.add_argument("--skip-screen", action="store_true")
    parser.add_argument("--only-screen", action="store_true", help="measure (l) only")
    parser.add_argument("--only-falsify", action="store_true", help="measure (k) only")
    parser.add_argument(
        "--write-docs",
        action="store_true",
        help="with (k): write its table and JSON into docs/validation/",
    )
    parser.add_argument("--batch-side", type=int, default=41, help="the batch grid's points per side")
    args = parser.parse_args()
    # One measurement alone: (option, what it runs); the wire's JSON keeps its section's name.
    few = max(1, min(args.repeats, 5))
    alone: dict[str, Callable[[], dict[str, float]]] = {
        "only_wire": lambda: bench_wire(max(1, args.repeats)),
        "only_sweep_command": lambda: bench_sweep_command(args.batch_side),
        "only_batched_laws": bench_batched_laws,
        "only_fmi": lambda: bench_fmi(few),
        "only_firmware": lambda: bench_firmware(few),
        "only_vector_env": bench_vector_env,
        "only_falsify": lambda: _and_write(bench_falsify(), args.write_docs),
        "only_screen": bench_screen,
    }
    for option, measure in alone.items():
        if getattr(args, option):
            got = measure()
            if args.json:
                print(json.dumps({"wire": got} if option == "only_wire" else got))
            else:
                print("\n".join(f"{k:40s} {v:12.4f}" for k, v in got.items()))
            return
    episodes = {name: bench_episode(name, max(1, args.repeats)) for name in EPISODES}
    results: dict[str, Any] = {"physics": bench_physics(), "episodes": episodes}
    if not args.skip_batch:
        results["batch"] = bench_batch(args.batch_side)
    if not args.skip_peers:
        results["peers"] = bench_peers()
    if not args.skip_calibration:
        results["calibration"] = bench_calibration()
    if not args.skip_view:
        results["view"] = bench_view(args.view_seconds)
    if not args.skip_wire:
        results["wire"] = bench_wire(max(1, args.repeats))
    if not args.skip_vector_env:
        results["vector_env"] = bench_vector_env()
    if not args.skip_sweep_command:
        results["sweep_command"] = bench_sweep_command(args.batch_side)
    if not args.skip_batched_laws:
        results["batched_laws"] = bench_batched_laws()
    if not args.skip_firmware:
        results["firmware"] = bench_firmware(max(1, min(args.repeats, 5)))
    if not args.skip_fmi:
        results["fmi"] = bench_fmi(max(1, min(args.repeats, 5)))
    if not args.skip_falsify:
        results["falsify"] = bench_falsify()
    if not args.skip_screen:
        results["screen"] = bench_screen()
    results["ratios"] = ratios(results)
    if args.json:
        print(json.dumps(results))
        return
    for section, values in results.items():
        print(section)
        for key, value in values.items():
            if isinstance(value, dict):
                print(f"  {key}")
                for k, v in value.items():
                    print(f"    {k:38s} {v:12.4f}")
            else:
                print(f"  {key:40s} {value:12.4f}")


if __name__ == "__main__":
    main()
