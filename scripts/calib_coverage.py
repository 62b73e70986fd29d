"""Coverage of the calibration's 95 % intervals, and the model resolution derived from it.

For each seed a rig is drawn from ``scripts/calib_coverage_spread.toml`` (resistance, inertia and pivot damping
±20 %, a zeroing error within ±15 mrad, the ball sensor's contact losses 0–10 per second), a 60 s log of the
recommended experiment is made on the twin (``calib.experiments``) and on the independent simulator
(``tests/independent_rig.py``, sharing only the parameter values), and the four parameters are fitted from
the study's start. Printed: per source and parameter, the share of seeds whose interval contains the truth,
with its exact (Clopper–Pearson) 95 % interval, the median |error| and the median interval half-width.

    PYTHONPATH=$PWD python scripts/calib_coverage.py [--seeds 20] [--first-seed 30] [--jobs 2]
        [--sources twin,independent] [--fixed-rig SEED] [--derive calib/resolution.toml] [--out cov.json]
        [--from cov.json]

``--derive FILE`` writes the model's resolution (``calib.identify.MODEL_RESOLUTION``) from the runs: per
parameter, the smallest floor that, added in quadrature to each fit's statistical half-width, puts the truth
inside the interval in 95 % of the runs of every source (``derive_floors``). Seeds 0…29 derive it (``--first-seed 0
--seeds 30 --derive calib/resolution.toml --out docs/calib_coverage_derive.json``, the runs a test derives it
from again); the default checks it on seeds 30…49, which did not. ``--fixed-rig SEED``: every run's rig is
seed SEED's draw, only the logs' noise varies (the coverage of one rig, as a user's repeated logs).
``--from cov.json``: the runs of an earlier ``--out`` instead of new ones (the table, or ``--derive``, again).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import scipy.stats

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from calib.experiments import STUDY_FIT, STUDY_START, run_experiment  # noqa: E402
from calib.identify import FITTABLE, calibrate  # noqa: E402
from calib.logs import RigLog, rig_log  # noqa: E402
from twin.app.montecarlo import load_spread  # noqa: E402
from twin.parameters import Parameters  # noqa: E402

FIT = list(STUDY_FIT)
START = Parameters().with_overrides(STUDY_START)
SPREAD = Path(__file__).resolve().with_name("calib_coverage_spread.toml")
DERIVING_SEEDS = range(0, 30)
COVERAGE = 0.95
# How the floor of each parameter scales: relative to its value, or absolute (the zeroing error, whose
# value can be anything near 0). A relative floor of a parameter that can be 0 (its search range reaches 0:
# the damping) has an absolute part, the floor at its typical size (``FitSpec.scale``), for a value near 0.
RELATIVE = {FIT[0]: True, FIT[1]: True, FIT[2]: True, FIT[3]: False}


def truth(seed: int) -> dict[str, float]:
    """Seed's rig: a draw from the spread (its own generator: the log's noise draws are the log seed's)."""
    spread = load_spread(SPREAD, START)
    values = spread.draw(np.random.default_rng(1000 + seed))
    return dict(zip(spread.names, (float(v) for v in values), strict=True))


def make_log(source: str, seed: int, rig_seed: int, duration_s: float = 60.0) -> RigLog:
    rig = START.with_overrides(truth(rig_seed))
    return LOG_SOURCES[source](rig, seed, duration_s)


def _twin_log(rig: Parameters, seed: int, duration_s: float) -> RigLog:
    return rig_log(run_experiment("square", rig, duration_s=duration_s, seed=seed).log, f"twin-{seed}")


def _independent_log(rig: Parameters, seed: int, duration_s: float) -> RigLog:
    from independent_rig import rig_log_of, simulate  # type: ignore[import-not-found]  # tests/, put on the path

    losses = rig.ball_sensor
    log = simulate(
        rig,
        duration_s=duration_s,
        seed=seed,
        dropout_rate_hz=losses.dropout_rate_hz,
        dropout_max_s=2 * losses.dropout_mean_duration_s,  # uniform 0…2μ: the twin's mean duration μ
    )
    return rig_log_of(log, f"independent-{seed}")


# Each --sources name's log maker: the twin, or the independent simulator of tests/ (the table is the choice).
LOG_SOURCES = {"twin": _twin_log, "independent": _independent_log}


def one(source: str, seed: int, rig_seed: int | None = None) -> dict[str, dict[str, float]]:
    rig_seed = seed if rig_seed is None else rig_seed
    true = truth(rig_seed)
    cal = calibrate([make_log(source, seed, rig_seed)], FIT, START)
    out: dict[str, dict[str, float]] = {}
    for name in FIT:
        v = cal.values[name]
        out[name] = {
            "inside": float(v.ci_low <= true[name] <= v.ci_high),
            "error": v.value - true[name],
            "value": v.value,
            "half": (v.ci_high - v.ci_low) / 2,
            "statistical_half": v.statistical_half,
            "truth": true[name],
            "trustworthy": float(cal.trustworthy),
        }
    return out


def derive_floors(results: dict[str, list[dict[str, dict[str, float]]]]) -> dict[str, dict[str, float]]:
    """Per parameter, the smallest floor F (relative or absolute, ``RELATIVE``) with |error| ≤
    hypot(statistical half, F·scale) in at least ``COVERAGE`` of the runs of every source: each run needs
    √(error² − statistical half²) (0 when the statistical interval holds the truth by itself), and the floor is
    that need's order statistic ⌈0.95·n⌉ of n, the largest over the sources."""
    floors: dict[str, dict[str, float]] = {}
    for name in FIT:
        per_source = []
        for runs in results.values():
            need = sorted(
                math.sqrt(max(r[name]["error"] ** 2 - r[name]["statistical_half"] ** 2, 0.0))
                / (abs(r[name]["value"]) if RELATIVE[name] else 1.0)
                for r in runs
            )
            per_source.append(need[math.ceil(COVERAGE * len(need)) - 1])
        floor = _two_digits_up(max(per_source))  # the study's own resolution, never below the need
        if RELATIVE[name]:
            can_vanish = FITTABLE[name].lower <= 0.0
            floors[name] = {
                "relative": floor,
                "absolute": floor * FITTABLE[name].scale if can_vanish else 0.0,
            }
        else:
            floors[name] = {"relative": 0.0, "absolute": floor}
    return floors


def _two_digits_up(x: float) -> float:
    if x <= 0.0:
        return 0.0
    unit = 10.0 ** (math.floor(math.log10(x)) - 1)
    return float(f"{math.ceil(x / unit - 1e-9) * unit:.2g}")


def scope() -> dict[str, float]:
    """What the study's rigs spanned that the fit does not fit (``calib.identify.RESOLUTION_SCOPE``)."""
    spread = load_spread(SPREAD, START)
    return {"contact_loss_rate_hz_max": spread.high[spread.names.index("ball_sensor.dropout_rate_hz")]}


def write_floors(path: Path, floors: dict[str, dict[str, float]], provenance: str) -> None:
    lines = [
        "# The smooth model's resolution added to each calibration interval (calib/identify.py MODEL_RESOLUTION).",
        "# Written by scripts/calib_coverage.py --derive: do not edit by hand, run the study again.",
        f"# {provenance}",
        "[floors]",
        *(
            f'"{n}" = {{ relative = {f["relative"]!r}, absolute = {f["absolute"]!r} }}'
            for n, f in floors.items()
        ),
        "[scope]",
        *(f"{k} = {v!r}" for k, v in scope().items()),
    ]
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")
    os.replace(tmp, path)


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
            rel = RELATIVE[name]
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


def _run(job: tuple[str, int, int | None]) -> dict[str, dict[str, float]]:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    return one(*job)


def _study(
    sources: list[str], seeds: range, fixed_rig: int | None, jobs: int
) -> dict[str, list[dict[str, dict[str, float]]]]:
    todo = [(source, seed, fixed_rig) for source in sources for seed in seeds]
    with ProcessPoolExecutor(max_workers=max(jobs, 1)) as pool:
        runs = list(pool.map(_run, todo))
    results: dict[str, list[dict[str, dict[str, float]]]] = {s: [] for s in sources}
    for (source, seed, _), run in zip(todo, runs, strict=True):
        results[source].append(run)
        shown = ", ".join(f"{n.split('.')[-1]} {'in' if r['inside'] else 'OUT'}" for n, r in run.items())
        print(f"{source} seed {seed}: {shown}", file=sys.stderr)
    return results


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument(
        "--first-seed", type=int, default=30, help="seeds 0…29 derive the resolution: check others"
    )
    ap.add_argument("--sources", default="twin,independent")
    ap.add_argument("--fixed-rig", type=int, default=None, help="every run on this seed's rig")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--derive", type=Path, help="write the resolution derived from these runs here")
    ap.add_argument("--out", type=Path)
    ap.add_argument("--from", dest="source_json", type=Path, help="the runs of an earlier --out")
    args = ap.parse_args(argv)
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    sources = args.sources.split(",")
    if args.source_json is not None:
        results = json.loads(args.source_json.read_text())
    else:
        results = _study(sources, seeds, args.fixed_rig, args.jobs)
    print("\n".join(table(results)))
    if args.derive is not None:
        floors = derive_floors(results)
        provenance = f"seeds {seeds.start}…{seeds.stop - 1} of {', '.join(sources)}, spread {SPREAD.name}"
        write_floors(args.derive, floors, provenance)
        print(f"wrote {args.derive}: {json.dumps(floors)}")
    if args.out is not None:
        args.out.write_text(json.dumps(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
