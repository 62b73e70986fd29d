"""How close the fast engine is to MuJoCo, and what screening buys (docs/validation/screen_agreement.json).

    python scripts/screen_agreement.py [--write-docs]

1. Trajectories: each appendix controller from the thesis's hardware starts (Figures 6.16–6.20), 10 s, noise off
   and on (seed 0): the fast engine's true x and θ against the MuJoCo twin's, the largest and the RMS
   difference over the run.
2. Classes: the 41 × 41 chapter 7 map of each appendix controller, noise on and off, run brute force on MuJoCo
   and on the fast engine (the same seeds): the share of starts whose class (held, kept, lost) agrees, and how
   far each disagreeing start lies from the nearest class change of MuJoCo's map (grid steps, Chebyshev).
3. What it buys: the same maps screened (``ballbeam sweep``'s default, ``twin.app.screening``) against brute
   force: classes compared at every start, wall times in one run (ratios; the machine is shared).

``--write-docs`` writes the JSON and its table on docs/validation/engines.md between the screen-table markers
(``twin.app.screening.render_agreement``; tests/test_screening.py checks the page is the JSON rendered).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from controllers import registry
from controllers import thesis_numbers as T
from twin.app.screening import render_agreement
from twin.app.sweep import SweepSettings, run_sweep, verdict_class
from twin.rigs.sim import run_closed_loop

REPO = Path(__file__).resolve().parent.parent
CONTROLLERS = ("appendix-sf", "appendix-clp")


def trajectories() -> list[dict[str, Any]]:
    rows = []
    for name in CONTROLLERS:
        for figure, (x0, th0) in T.HARDWARE_STARTS.items():
            for noise in (False, True):
                runs = {
                    plant: run_closed_loop(
                        registry.make(name), x0_m=x0, theta0_rad=th0, duration_s=10.0, seed=0, noise=noise,
                        plant=plant, ideal_sensors=False,
                    ).log
                    for plant in ("twin", "reference")
                }  # fmt: skip
                a, b = runs["twin"], runs["reference"]
                assert a is not None and b is not None
                dx = np.abs(a.true_x_m - b.true_x_m)
                dth = np.abs(a.true_theta_rad - b.true_theta_rad)
                rows.append(
                    {
                        "controller": name,
                        "start": figure,
                        "noise": noise,
                        "max_dx_mm": round(1e3 * float(dx.max()), 3),
                        "rms_dx_mm": round(1e3 * float(np.sqrt(np.mean(dx**2))), 3),
                        "max_dtheta_mrad": round(1e3 * float(dth.max()), 3),
                        "rms_dtheta_mrad": round(1e3 * float(np.sqrt(np.mean(dth**2))), 3),
                    }
                )
    return rows


def _distance_to_change(classes: np.ndarray, i: int, j: int) -> int:
    """Grid steps (Chebyshev) from (i, j) to the nearest start whose class differs from its own."""
    nx, nt = classes.shape
    for r in range(1, max(nx, nt)):
        window = classes[max(0, i - r) : i + r + 1, max(0, j - r) : j + r + 1]
        if (window != classes[i, j]).any():
            return r
    return max(nx, nt)


def maps() -> list[dict[str, Any]]:
    rows = []
    for name in CONTROLLERS:
        for noise in (True, False):
            base = SweepSettings(name, noise=noise)
            timed: dict[str, Any] = {}
            for engine in ("mujoco", "fast", "screen"):
                t = time.perf_counter()
                result = run_sweep(SweepSettings(**{**base.__dict__, "engine": engine}), nthread=2)
                timed[engine] = (time.perf_counter() - t, result)
            brute = np.array([verdict_class(p) for p in timed["mujoco"][1].points]).reshape(41, 41)
            fast = np.array([verdict_class(p) for p in timed["fast"][1].points]).reshape(41, 41)
            screened = np.array([verdict_class(p) for p in timed["screen"][1].points]).reshape(41, 41)
            differ = np.argwhere(brute != fast)
            distances = [_distance_to_change(brute, int(i), int(j)) for i, j in differ]
            screen = timed["screen"][1].screening
            rows.append(
                {
                    "controller": name,
                    "noise": noise,
                    "starts": int(brute.size),
                    "fast_agrees": int((brute == fast).sum()),
                    "fast_agrees_share": round(float((brute == fast).mean()), 4),
                    "disagreements_steps_from_a_class_change": {
                        str(d): distances.count(d) for d in sorted(set(distances))
                    },
                    "screened_equals_brute_force": int((brute == screened).sum()),
                    "screened_mujoco_runs": screen["mujoco_runs"],
                    "screened_audit_mismatches": len(screen["audit"]["mismatches"]),
                    "brute_force_s": round(timed["mujoco"][0], 1),
                    "fast_s": round(timed["fast"][0], 1),
                    "screened_s": round(timed["screen"][0], 1),
                    "screened_over_brute_force": round(timed["screen"][0] / timed["mujoco"][0], 3),
                }
            )
            print(json.dumps(rows[-1]), flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args()
    data = {"load_1min": round(os.getloadavg()[0], 2), "trajectories": trajectories(), "maps": maps()}
    print(render_agreement(data))
    if args.write_docs:
        from twin.outputs import write_measured_table

        page = REPO / "docs" / "validation" / "engines.md"  # the manual's page of the table
        write_measured_table(
            REPO / "docs" / "validation" / "screen_agreement.json", data, page, "screen-table",
            render_agreement(data),
        )  # fmt: skip


if __name__ == "__main__":
    main()
