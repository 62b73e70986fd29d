"""The robust region of attraction: from which starts does the ball stay held for (nearly) every plausible rig?

``ballbeam sweep --spread FILE | --calibration DIR --rigs N``: N rigs drawn from the spread (as ``montecarlo``
draws them, seeded: the same N rigs for every start, so the map is coherent), every start of the grid run on
each, and per start the number of rigs that hold it with its exact one-sided lower bound (Clopper–Pearson at
``confidence``). The robust region is the starts whose lower bound reaches ``level``; since k of N held
bounds the rate below by (1 − confidence)^(1/N) at best, a level of 0.95 at 95 % confidence needs N ≥ 59
rigs — with fewer, the region is reported empty and the starts all N rigs hold are reported beside it.

With ``--refine`` every rig's map is refined (``twin.app.sweep.Refinement``), all rigs' starts of a wave
run as one job. Run i of rig m has the noise seed ``rig_point_seeds(seed, m)[i]``: a function of the seed,
the rig and the start alone, so the result is the same in this process, on workers and on a cluster.

``twin.app.robust_render`` draws the map and writes the folder (``write_robust``); nothing here imports
matplotlib.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from twin.app.fanout import Progress, Served, run_starts
from twin.app.options import MAX_RIGS
from twin.app.sweep import ASSUMPTION, Job, Refinement, SweepSettings, verdict_class
from twin.outputs import JobFiles
from twin.parameters import ParameterError, Parameters

__all__ = ["DEFAULT_LEVEL", "OUTPUT_FILES", "RobustResult", "lower_bound", "rig_point_seeds", "run_robust"]

# What write_robust (twin.app.robust_render) puts into its folder (checked before the runs).
OUTPUT_FILES = JobFiles("robust-sweep", ("robust.json", "robust.png"))
# The share of rigs a robust start is held by, as a lower bound (``sweep --level``'s default).
DEFAULT_LEVEL = 0.95
# Each rig's map in the JSON: one letter per start (twin.app.sweep.verdict_class).
CLASS_LETTERS = {"held": "h", "kept": "k", "lost": "l", "failed": "f"}


def rig_point_seeds(seed: int, rig: int, n: int) -> np.ndarray:
    """The noise seed of start i on rig ``rig``: a function of (seed, rig, i) only."""
    return np.array(
        [
            int(np.random.SeedSequence([seed, rig + 1, i]).generate_state(1, dtype=np.uint32)[0])
            for i in range(n)
        ],
        dtype=np.int64,
    )


def lower_bound(held: int, n: int, confidence: float) -> float:
    """The exact one-sided lower bound of the success rate at ``confidence`` (Clopper–Pearson)."""
    if held == 0:
        return 0.0
    import scipy.stats

    return float(scipy.stats.beta.ppf(1.0 - confidence, held, n - held + 1))


@dataclass
class RobustResult:
    settings: SweepSettings
    rigs: int
    level: float
    confidence: float
    source: str
    rig_values: list[dict[str, float]]
    rig_classes: list[str]  # per rig, one letter per start in the points' order (CLASS_LETTERS; "?": not run)
    points: list[dict[str, Any]]  # per start: x0_m, theta0_rad, held (rigs), lost, rigs, rate, lower_bound
    complete: bool
    wall_s: float = 0.0
    runs: int = 0
    refinement: dict[str, Any] | None = None
    screening: dict[str, Any] | None = None  # --engine screen: what each engine ran, the audit
    nominal_held: int | None = None
    summary: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        s = self.settings
        return {
            "settings": {**asdict(s), "x0": asdict(s.x0), "theta0": asdict(s.theta0)},
            "rigs": self.rigs,
            "level": self.level,
            "confidence": self.confidence,
            "spread": self.source,
            "complete": self.complete,
            "runs": self.runs,
            "wall_s": round(self.wall_s, 1),
            **({"refinement": self.refinement} if self.refinement is not None else {}),
            **({"screening": self.screening} if self.screening is not None else {}),
            "summary": self.summary,
            "rig_parameters": self.rig_values,
            "rig_classes": self.rig_classes,
            "rig_class_letters": {letter: name for name, letter in CLASS_LETTERS.items()},
            "points": self.points,
        }


def run_robust(
    settings: SweepSettings,
    base: Parameters,
    spread: Any,
    rigs: int,
    *,
    level: float = DEFAULT_LEVEL,
    confidence: float = 0.95,
    nominal: list[dict[str, Any]] | None = None,
    workers: int = 1,
    scheduler: str | None = None,
    nthread: int | None = None,
    progress: Progress | None = None,
    serve: Served | None = None,
) -> RobustResult:
    """Every start of ``settings``' grid on each of ``rigs`` rigs drawn from ``spread`` about ``base``.
    ``nominal``: the nominal rig's sweep points, for the area it holds (optional); ``serve``: every run a
    session to a client over the wire (without refinement)."""
    from twin.app.montecarlo import sample_parameters

    if isinstance(rigs, bool) or not isinstance(rigs, int) or not 1 <= rigs <= MAX_RIGS:
        raise ParameterError(f"--rigs {rigs!r}: 1…{MAX_RIGS} rigs")
    if not 0 < level <= 1 or not 0 < confidence < 1:
        raise ParameterError(f"level {level!r} in (0, 1], confidence {confidence!r} in (0, 1)")
    sets, values = sample_parameters(base, spread, rigs, settings.seed)
    grid = settings.starts()
    n = len(grid)
    seeds = [rig_point_seeds(settings.seed, m, n) for m in range(rigs)]
    start = time.perf_counter()

    def job(fast: bool | None) -> Job:
        runs = settings.runs(base, fast=fast)
        label = settings.policy.label(runs.plant)

        def run_job(
            requests: list[tuple[int, int]], within: Progress | None
        ) -> tuple[list[dict[str, Any] | None], bool]:
            idx = np.array([k for _, k in requests], dtype=np.int64)
            run_seeds = np.array([seeds[m][k] for m, k in requests], dtype=np.int64)
            records, complete = run_starts(
                runs,
                grid[idx],
                run_seeds,
                params=[sets[m] for m, _ in requests],
                workers=workers,
                scheduler=scheduler,
                nthread=nthread,
                progress=within,
                serve=serve,
            )
            return [None if r is None else {**r, "engine": label} for r in records], complete

        return run_job

    if serve is not None and (settings.refine or settings.screened):
        raise ParameterError("--refine and --engine screen run here or on workers, not as served sessions")
    ref = Refinement(settings.x0.n, settings.theta0.n, settings.refine, rigs, job(None), progress)
    screen = None
    if settings.screened:
        from twin.app.screening import MAP_MARGINAL, Screening, map_marginal

        screen = Screening(
            settings.x0.n, settings.theta0.n, rigs, job(True), job(False), band=settings.band,
            audit=settings.screen_audit, seed=settings.seed, progress=progress, marginal=map_marginal(base),
            marginal_text=MAP_MARGINAL,
        )  # fmt: skip
        screen.run()
        ref.known = [{k: r for k in range(n) if (r := screen.record(m, k)) is not None} for m in range(rigs)]
        ref.ran, ref.complete = screen.stats.fast + sum(map(len, screen.mujoco)), screen.complete
    elif settings.refine:
        ref.refine()
    else:
        ref.run([(m, k) for m in range(rigs) for k in range(n)])
    points, letters, complete = _per_start(ref, grid, confidence, level)
    names = spread.names
    result = RobustResult(
        settings=settings,
        rigs=rigs,
        level=level,
        confidence=confidence,
        source=spread.source,
        rig_values=[dict(zip(names, (float(v) for v in row), strict=True)) for row in values],
        rig_classes=["".join(row) for row in letters],
        points=points,
        complete=complete,
        wall_s=time.perf_counter() - start,
        runs=ref.ran,
    )
    if screen is not None:
        result.screening = screen.summary()
    if settings.refine:
        result.refinement = {
            "coarse_step": settings.refine,
            "waves": ref.waves,
            "run": ref.ran,
            "run_fraction": round(ref.ran / (rigs * n), 4),
            "assumption": f"on each rig: {ASSUMPTION}",
        }
    nominal_held = sum(bool(p and p["held"]) for p in nominal) if nominal is not None else None
    result.nominal_held = nominal_held
    result.summary = {
        "starts": n,
        "robust": sum(p["robust"] for p in points),
        "held_by_every_rig": sum(p["held"] == rigs for p in points),
        "kept_by_every_rig": sum(p["lost"] == 0 and p["rigs"] == rigs for p in points),
        "rate_at_least_level": sum(p["rate"] is not None and p["rate"] >= level for p in points),
        "best_possible_lower_bound": round(lower_bound(rigs, rigs, confidence), 6),
        **({"nominal_held": nominal_held} if nominal_held is not None else {}),
    }
    return result


def _per_start(
    ref: Refinement, grid: np.ndarray, confidence: float, level: float
) -> tuple[list[dict[str, Any]], list[list[str]], bool]:
    """Each start's held count over the rigs, its lower bound and robustness; each rig's class letters; and
    whether every rig's every start is known."""
    rigs, n = ref.maps, len(grid)
    points: list[dict[str, Any]] = []
    complete = ref.complete
    letters = [["?"] * n for _ in range(rigs)]
    for k in range(n):
        classes = []
        for m in range(rigs):
            if k in ref.known[m]:
                classes.append(verdict_class(ref.known[m][k]))
            elif k in ref.claims[m]:
                classes.append(ref.claims[m][k][0])
            else:
                continue
            letters[m][k] = CLASS_LETTERS[classes[-1]]
        if len(classes) < rigs:
            complete = False
        held = classes.count("held")
        bound = lower_bound(held, len(classes), confidence) if classes else 0.0
        points.append(
            {
                "x0_m": float(grid[k, 0]),
                "theta0_rad": float(grid[k, 1]),
                "rigs": len(classes),
                "held": held,
                "lost": classes.count("lost"),
                "rate": round(held / len(classes), 6) if classes else None,
                "lower_bound": round(bound, 6),
                "robust": bool(classes) and bound >= level,
            }
        )
    return points, letters, complete


def refinement_costs(rig_classes: list[str], nx: int, nt: int, step: int) -> dict[str, Any]:
    """What refining these rigs' maps (one letter per start each, no "?") costs in runs, three ways, on the
    maps alone (no physics): per rig (what ``run_robust`` does), jointly on every rig's class (a cell is split
    where any rig's corners disagree, and every rig runs its starts), and on the held count (the probability
    contour: split where the corners' counts differ). Each way's per-start held counts against the maps'."""
    rigs, n = len(rig_classes), nx * nt
    if any(len(row) != n or "?" in row for row in rig_classes):
        raise ValueError(f"refinement_costs: each rig's map needs {n} known starts")

    def counts_of(classes: list[list[Any]]) -> list[int]:
        return [sum(classes[m][k] == "h" for m in range(rigs)) for k in range(n)]

    truth = counts_of([list(row) for row in rig_classes])

    def refined(maps: int, record: Any, classify: Any) -> tuple[Refinement, list[dict[int, Any]]]:
        def run_job(requests: list[tuple[int, int]], within: Any) -> tuple[list[dict[str, Any] | None], bool]:
            return [{"c": record(m, k)} for m, k in requests], True

        ref = Refinement(nx, nt, step, maps, run_job, classify=classify)
        ref.refine()
        tables = [
            {k: classify(ref.known[m][k]) if k in ref.known[m] else ref.claims[m][k][0] for k in range(n)}
            for m in range(maps)
        ]
        return ref, tables

    def c_of(r: dict[str, Any]) -> Any:
        return r["c"]

    per_rig, tables = refined(rigs, lambda m, k: rig_classes[m][k], c_of)
    joint, joint_tables = refined(1, lambda m, k: tuple(row[k] for row in rig_classes), c_of)
    counted, count_tables = refined(1, lambda m, k: truth[k], c_of)
    return {
        "brute_force": rigs * n,
        "per_rig": {
            "runs": per_rig.ran,
            "counts_equal": counts_of([[t[k] for k in range(n)] for t in tables]) == truth,
        },
        "joint": {
            "runs": rigs * joint.ran,
            "counts_equal": [sum(c == "h" for c in joint_tables[0][k]) for k in range(n)] == truth,
        },
        "held_count": {
            "runs": rigs * counted.ran,
            "counts_equal": [count_tables[0][k] for k in range(n)] == truth,
        },
    }
