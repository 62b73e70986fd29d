"""Benchmarks (measured here, never asserted in tests).

    python scripts/bench.py [--view-seconds 60] [--skip-view]

- physics: µs per MuJoCo step of the rig, and per 20 ms tick of the TwinRig (sensor chains included);
- runs: seconds of computer time per 15 s closed-loop run (50 Hz controller, and a 1 kHz chapter 4 one);
- view: the live view's tick rate at speed 1.0 over the given wall time (target 50 Hz ± 1 %) and its CPU
  time per tick, headless (no browser attached).
"""

from __future__ import annotations

import argparse
import json
import socket
import time

import mujoco

from controllers import registry
from twin.plant import Plant
from twin.rig import TwinRig
from twin.runner import run_closed_loop


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


def bench_runs() -> dict[str, float]:
    out = {}
    for name in ("appendix-clp", "thesis-sf-continuous"):
        start = time.perf_counter()
        run_closed_loop(registry.make(name), x0_m=0.2, theta0_rad=0.3, duration_s=15.0, seed=0)
        out[f"run_15s_{name}_s"] = time.perf_counter() - start
    return out


def bench_view(seconds: float) -> dict[str, float]:
    from twin.viewer import serve

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    stats = serve(port=port, duration_s=seconds, speed=1.0, announce=False)
    stats["tick_rate_error_pct"] = 100.0 * (stats["tick_rate_hz"] / 50.0 - 1.0)
    stats["cpu_ms_per_tick"] = 1e3 * stats.pop("cpu_s_per_tick")
    return stats


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--view-seconds", type=float, default=60.0)
    parser.add_argument("--skip-view", action="store_true")
    args = parser.parse_args()
    results = {"physics": bench_physics(), "runs": bench_runs()}
    if not args.skip_view:
        results["view"] = bench_view(args.view_seconds)
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
