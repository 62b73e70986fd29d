"""Memory and time of calibrating a 1-hour log (docs/design.md, Calibration: the memory).

Builds a log of the recommended experiment on the twin (``--minutes``, default 60) for a perturbed rig,
calibrates the four parameters of the README's example from the thesis's values, and prints the fitted
values against the truth, the wall time of the calibration and the process's peak resident memory
(``resource.getrusage``: the peak of the whole process, the log's simulation included).

    PYTHONPATH=$PWD python scripts/calib_long.py [--minutes 60]
"""

from __future__ import annotations

import os

# One BLAS thread (before numpy loads), as scripts/bench.py: the solver's many short vector products pay
# OpenBLAS's thread wake-ups otherwise (a 60 s fit on the busy 2-core machine: 38 s → 24 s).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import resource  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

from calib.experiments import (  # noqa: E402
    STUDY_FIT,
    STUDY_START,
    run_experiment,
)
from calib.identify import calibrate  # noqa: E402
from calib.logs import rig_log  # noqa: E402
from twin.parameters import Parameters  # noqa: E402

FIT = list(STUDY_FIT)
# The rig: 5 % more resistance, 8 % less inertia, viscous pivot friction and a zeroing error (the start of
# the fit is the thesis's rig with 1e-3 N·m·s/rad of pivot damping).
START = Parameters().with_overrides(STUDY_START)
TRUTH = {FIT[0]: 9.4 * 1.05, FIT[1]: 4e-3 * 0.92, FIT[2]: 1.2e-3, FIT[3]: 0.004}


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: kilobytes


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    run = run_experiment("square", START.with_overrides(TRUTH), duration_s=60 * args.minutes, seed=args.seed)
    log = rig_log(run.log)
    del run
    built_s, built_mb = time.perf_counter() - t0, _peak_rss_mb()
    minutes = log.duration_s / 60
    print(f"log: {log.ticks} ticks ({minutes:.1f} min) built in {built_s:.1f} s, peak RSS {built_mb:.0f} MB")
    t1 = time.perf_counter()
    cal = calibrate([log], FIT, START)
    wall = time.perf_counter() - t1
    for name in FIT:
        v = cal.values[name]
        print(f"{name:<36} {v.value:.6g}  [{v.ci_low:.6g}, {v.ci_high:.6g}]  truth {TRUTH[name]:.6g}")
    print(f"converged: {cal.converged} ({cal.message}); windows {cal.n_windows}")
    for w in cal.warnings:
        print(f"warning: {w}")
    print(f"calibration wall time {wall:.1f} s; peak RSS of the process {_peak_rss_mb():.0f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
