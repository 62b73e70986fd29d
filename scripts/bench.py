"""Benchmarks (measured here, never asserted in tests).

    python scripts/bench.py [--view-seconds 60] [--skip-view]

- physics: µs per MuJoCo step of the rig, and per 20 ms tick of the TwinRig (sensor chains included);
- runs: computer time per 15 s closed-loop run (50 Hz controllers, a 1 kHz chapter 4 law on the true state,
  the reference rig), each as a ratio to the physical floor: raw ``mujoco.rollout`` of the same physics
  steps in one call, measured in the same run;
- calibration: wall time of a 5-parameter fit to a 60 s log;
- view: the live view's tick rate at speed 1.0 over the given wall time (target 50 Hz ± 1 %) and its CPU
  time per tick, headless (no browser attached).
"""

from __future__ import annotations

import argparse
import json
import socket
import time

import mujoco
import numpy as np
from mujoco import rollout

from controllers import registry
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
    args = parser.parse_args()
    results = {"physics": bench_physics(), "runs": bench_runs()}
    if not args.skip_calibration:
        results["calibration"] = bench_calibration()
    if not args.skip_view:
        results["view"] = bench_view(args.view_seconds)
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
