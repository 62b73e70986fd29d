"""Benchmarks (measured here, never asserted in tests).

    OPENBLAS_NUM_THREADS=1 python scripts/bench.py [--view-seconds 60] [--skip-view] [--skip-batch]

- physics: µs per MuJoCo step of the rig, and per 20 ms tick of the TwinRig (sensor chains included);
- runs: computer time per 15 s closed-loop run (50 Hz controllers, a 1 kHz chapter 4 law on the true state,
  the reference rig), each as a ratio to the physical floor: raw ``mujoco.rollout`` of the same physics
  steps in one call, measured in the same run;
- batch: a 41×41 grid of 10 s appendix-sf runs (noise on) through the batch engine (``twin.batch``) on 2
  threads, as a ratio to raw ``mujoco.rollout`` of the same physics on 2 threads (the same starts and the
  motor volts the closed loop applied, so the same trajectories: checked bit for bit). Every run to the end
  (``stop_when_lost=False``), and as a sweep runs it (lost balls leave the batch; its floor is the full
  floor scaled by the physics steps done);
- calibration: wall time of a 5-parameter fit to a 60 s log;
- view: the live view's tick rate at speed 1.0 over the given wall time (target 50 Hz ± 1 %) and its CPU
  time per tick, headless (no browser attached).
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import time

# One BLAS thread: the batch's threads are MuJoCo's (set before numpy loads OpenBLAS).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import mujoco
import numpy as np
from mujoco import rollout

from controllers import registry
from twin.batch import run_batch
from twin.engine import run_closed_loop, update_ticks
from twin.parameters import Parameters
from twin.plant import Plant
from twin.rig import TwinRig


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


def rollout_floor_s(duration_s: float) -> float:
    """Raw ``mujoco.rollout`` of the physics steps a run of ``duration_s`` takes, in one call."""
    params = Parameters()
    steps = int(round((update_ticks(duration_s, params) * params.daq.period_s) / params.physics.timestep_s))
    plant = Plant(params)
    plant.reset(0.2, 0.3)
    state = np.empty((1, mujoco.mj_stateSize(plant.model, mujoco.mjtState.mjSTATE_FULLPHYSICS)))
    mujoco.mj_getState(plant.model, plant.data, state[0], mujoco.mjtState.mjSTATE_FULLPHYSICS)
    control = np.zeros((1, steps, plant.model.nu))
    start = time.perf_counter()
    rollout.rollout(plant.model, plant.data, state, control)
    return time.perf_counter() - start


def bench_runs() -> dict[str, float]:
    out: dict[str, float] = {"floor_15s_s": rollout_floor_s(15.0)}
    for name, plant in (
        ("appendix-clp", "twin"),
        ("lqr", "twin"),
        ("thesis-sf-continuous", "twin"),
        ("appendix-clp", "reference"),
    ):
        start = time.perf_counter()
        run_closed_loop(
            registry.make(name),
            x0_m=0.2,
            theta0_rad=0.3,
            duration_s=15.0,
            seed=0,
            plant=plant,
            ideal_sensors=plant == "reference",
            stop_when_lost=False,
        )
        elapsed = time.perf_counter() - start
        out[f"run_15s_{name}_{plant}_s"] = elapsed
        out[f"run_15s_{name}_{plant}_x_floor"] = elapsed / out["floor_15s_s"]
    return out


def _raw_rollout_s(
    plant: Plant, initial: np.ndarray, control: np.ndarray, nthread: int, chunk: int = 200
) -> tuple[float, np.ndarray]:
    """Raw ``mujoco.rollout`` of these runs on ``nthread`` threads (in chunks of runs, to bound the memory of
    its state output): the wall time of the rollout calls and each run's final state."""
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


def bench_batch(side: int = 41, duration_s: float = 10.0, nthread: int = 2) -> dict[str, float]:
    """The 41×41 sweep of appendix-sf through the batch engine against raw rollout of the same physics."""
    params = Parameters()
    x0, theta0 = (
        a.ravel() for a in np.meshgrid(np.linspace(-0.32, 0.32, side), np.linspace(-0.7, 0.7, side))
    )
    seeds = np.arange(len(x0))
    kw = dict(x0_m=x0, theta0_rad=theta0, seeds=seeds, duration_s=duration_s, nthread=nthread)
    start, start_cpu = time.perf_counter(), time.process_time()
    full = run_batch(registry, "appendix-sf", **kw, stop_when_lost=False, record=True)
    batch_full_s, batch_full_cpu = time.perf_counter() - start, time.process_time() - start_cpu
    start, start_cpu = time.perf_counter(), time.process_time()
    sweep = run_batch(registry, "appendix-sf", **kw)
    batch_sweep_s, batch_sweep_cpu = time.perf_counter() - start, time.process_time() - start_cpu

    # The same physics open loop: each run's motor volts, held over the steps the closed loop held them.
    dt, period = params.physics.timestep_s, params.daq.period_s
    free = int(round(params.start.free_run_s / dt))
    per_tick = int(round(period / dt))
    volts = np.array([r.log.motor_volts_v for r in full])  # row k: after the k-th command
    steps = int(round(full[0].log.true_time_s[-1] / dt))
    control = np.empty((len(x0), steps, 1))
    control[:, :free, 0] = volts[:, :1]
    control[:, free:, 0] = np.repeat(volts[:, 1:], per_tick, axis=1)[:, : steps - free]
    plant = Plant(params)
    full_state = mujoco.mjtState.mjSTATE_FULLPHYSICS
    initial = np.empty((len(x0), mujoco.mj_stateSize(plant.model, full_state)))
    for i in range(len(x0)):
        plant.reset(float(x0[i]), float(theta0[i]))
        mujoco.mj_getState(plant.model, plant.data, initial[i], full_state)
    floor_s, floor_cpu, final = _raw_rollout_s(plant, initial, control, nthread)
    # The open loop reproduces the closed loop's trajectories bit for bit (runs whose ball stayed on).
    kept = np.array([not r.verdict.ball_lost for r in full])
    end_x = np.array([r.log.true_x_m[-1] for r in full])
    same = bool(np.array_equal(plant.row_states(final[kept])[:, 0], end_x[kept]))
    # Physics steps the sweep did: a run stops at the end of the block in which its ball left the track.
    lost_steps = [
        int(round(r.verdict.ball_lost_time_s / dt)) for r in sweep if r.verdict.ball_lost_time_s is not None
    ]
    sweep_steps = sum(
        min(steps, free + per_tick * max(0, -(-(k - free) // per_tick))) for k in lost_steps
    ) + steps * (len(sweep) - len(lost_steps))
    share = sweep_steps / (steps * len(x0))
    sweep_floor_s = floor_s * share

    def on_two_cores(cpu: float, floor: float) -> float:
        # Wall ratio on two otherwise idle cores, from CPU times (which other processes do not inflate): the
        # physics takes the floor's CPU on both threads; the rest of the batch runs on one.
        return 1.0 + 2.0 * (cpu - floor) / floor

    return {
        "runs": float(len(x0)),
        "floor_2threads_s": floor_s,
        "open_loop_reproduces_closed_loop": float(same),
        "batch_all_to_end_s": batch_full_s,
        "batch_all_to_end_x_floor": batch_full_s / floor_s,
        "sweep_stop_when_lost_s": batch_sweep_s,
        "sweep_floor_scaled_s": sweep_floor_s,
        "sweep_x_floor": batch_sweep_s / sweep_floor_s,
        "sweep_lost": float(len(lost_steps)),
        "floor_cpu_s": floor_cpu,
        "batch_all_to_end_cpu_s": batch_full_cpu,
        "batch_all_to_end_cpu_x_floor": batch_full_cpu / floor_cpu,
        "batch_all_to_end_x_floor_idle_2_cores": on_two_cores(batch_full_cpu, floor_cpu),
        "sweep_cpu_s": batch_sweep_cpu,
        "sweep_cpu_x_floor": batch_sweep_cpu / (floor_cpu * share),
        "sweep_x_floor_idle_2_cores": on_two_cores(batch_sweep_cpu, floor_cpu * share),
    }


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
    from twin.viewer import serve

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    stats = serve(registry, port=port, duration_s=seconds, speed=1.0, announce=False)
    stats["tick_rate_error_pct"] = 100.0 * (stats["tick_rate_hz"] / 50.0 - 1.0)
    stats["cpu_ms_per_tick"] = 1e3 * stats.pop("cpu_s_per_tick")
    return stats


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--view-seconds", type=float, default=60.0)
    parser.add_argument("--skip-view", action="store_true")
    parser.add_argument("--skip-calibration", action="store_true")
    parser.add_argument("--skip-batch", action="store_true")
    parser.add_argument("--batch-side", type=int, default=41, help="the batch grid's points per side")
    args = parser.parse_args()
    results = {"physics": bench_physics(), "runs": bench_runs()}
    if not args.skip_batch:
        results["batch"] = bench_batch(args.batch_side)
    if not args.skip_calibration:
        results["calibration"] = bench_calibration()
    if not args.skip_view:
        results["view"] = bench_view(args.view_seconds)
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
