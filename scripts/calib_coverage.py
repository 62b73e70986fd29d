"""Coverage of the calibration's 95 % intervals: how often they contain the truth, per parameter.

For each seed a rig is drawn (resistance, inertia and pivot damping up to ±20 % from the start of the fit,
a zeroing error up to ±15 mrad), a 60 s log of the recommended experiment is made on the twin
(``calib.experiments``) and on the independent simulator (``tests/independent_rig.py``, sharing only the
parameter values), and the four parameters are fitted from the thesis's values. Printed: per source and
parameter, the share of seeds whose interval contains the truth, with its exact (Clopper–Pearson) 95 %
interval, the median |error| and the median interval half-width.

    PYTHONPATH=$PWD python scripts/calib_coverage.py [--seeds 20] [--first-seed 20] [--sources twin,independent]
        [--out cov.json]

Seeds 0…19 were used to measure the model's resolution (``calib.identify.MODEL_RESOLUTION``); the default
checks the intervals on seeds 20…39, which did not set them.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

import numpy as np
import scipy.stats

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from calib.experiments import (  # noqa: E402
    STUDY_FIT,
    STUDY_START,
    run_experiment,
)
from calib.identify import calibrate  # noqa: E402
from calib.logs import RigLog, rig_log  # noqa: E402
from twin.parameters import Parameters  # noqa: E402

FIT = list(STUDY_FIT)
START = Parameters().with_overrides(STUDY_START)


def truth(seed: int) -> dict[str, float]:
    rng = np.random.default_rng(1000 + seed)
    f = rng.uniform(-0.2, 0.2, 3)
    return {
        FIT[0]: START.motor.resistance_ohm * (1 + f[0]),
        FIT[1]: START.beam.inertia_pivot_kgm2 * (1 + f[1]),
        FIT[2]: START.beam.pivot_damping_nm_s_per_rad * (1 + f[2]),
        FIT[3]: float(rng.uniform(-0.015, 0.015)),
    }


def make_log(source: str, seed: int, duration_s: float = 60.0) -> RigLog:
    rig = START.with_overrides(truth(seed))
    if source == "twin":
        return rig_log(run_experiment("square", rig, duration_s=duration_s, seed=seed).log, f"twin-{seed}")
    from independent_rig import rig_log_of, simulate  # type: ignore[import-not-found]  # tests/, put on the path

    return rig_log_of(simulate(rig, duration_s=duration_s, seed=seed), f"independent-{seed}")


def one(source: str, seed: int) -> dict[str, dict[str, float]]:
    true = truth(seed)
    cal = calibrate([make_log(source, seed)], FIT, START)
    out: dict[str, dict[str, float]] = {}
    for name in FIT:
        v = cal.values[name]
        out[name] = {
            "inside": float(v.ci_low <= true[name] <= v.ci_high),
            "error": v.value - true[name],
            "half": (v.ci_high - v.ci_low) / 2,
            "truth": true[name],
            "trustworthy": float(cal.trustworthy),
        }
    return out


def clopper_pearson(k: int, n: int) -> tuple[float, float]:
    lo = float(scipy.stats.beta.ppf(0.025, k, n - k + 1)) if k > 0 else 0.0
    hi = float(scipy.stats.beta.ppf(0.975, k + 1, n - k)) if k < n else 1.0
    return lo, hi


def table(results: dict[str, list[dict[str, dict[str, float]]]]) -> list[str]:
    lines = [
        f"{'source':<12} {'parameter':<34} {'coverage':>9} {'95 % CI':>14} {'median |err|':>13} {'median half':>12}"
    ]
    for source, runs in results.items():
        for name in FIT:
            k = int(sum(r[name]["inside"] for r in runs))
            n = len(runs)
            lo, hi = clopper_pearson(k, n)
            rel = name != FIT[3]
            err = statistics.median(
                abs(r[name]["error"] / r[name]["truth"]) if rel else abs(r[name]["error"]) for r in runs
            )
            half = statistics.median(
                r[name]["half"] / r[name]["truth"] if rel else r[name]["half"] for r in runs
            )
            shown = (lambda x: f"{100 * x:.3f} %") if rel else (lambda x: f"{1e3 * x:.3f} mrad")
            lines.append(
                f"{source:<12} {name:<34} {k:>3}/{n:<5} [{lo:.2f}, {hi:.2f}] {shown(err):>13} {shown(half):>12}"
            )
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument(
        "--first-seed", type=int, default=20, help="seeds 0…19 set MODEL_RESOLUTION: check others"
    )
    ap.add_argument("--sources", default="twin,independent")
    ap.add_argument("--out", type=Path)
    args = ap.parse_args(argv)
    results: dict[str, list[dict[str, dict[str, float]]]] = {}
    for source in args.sources.split(","):
        results[source] = []
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            results[source].append(one(source, seed))
            print(
                f"{source} seed {seed}: "
                + ", ".join(
                    f"{n.split('.')[-1]} {'in' if r['inside'] else 'OUT'}"
                    for n, r in results[source][-1].items()
                ),
                file=sys.stderr,
                flush=True,
            )
    print("\n".join(table(results)))
    if args.out is not None:
        args.out.write_text(json.dumps(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
