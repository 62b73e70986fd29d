"""``ballbeam certify``: a statement with a confidence — every requirement holds with probability ≥ P at
confidence C over rigs drawn from a spread or calibration, starts drawn from a box and the sensor's noise.

Runs are drawn (rig, start, noise seed; ``draws``) and run in order, a batch of the engine at a time. The first
run that violates a requirement ends it: FAIL, with that run as a counterexample (``run --replay``). With none,
after ``runs_needed(P, C)`` runs the exact binomial bound states it: if the probability that a run violates
were above 1 − P, so many runs without a violation would happen with probability ≤ 1 − C (P^n ≤ 1 − C; 459
runs for 0.99 at 99 %). Then each requirement's least robust run is run again with ``NOISE_RERUNS`` other noise
seeds: a re-run that violates is a counterexample (FAIL); a requirement whose least robustness lies within
``NOISE_SIGMAS`` standard deviations of those re-runs' robustness from zero is INCONCLUSIVE — the sensor noise
alone could take it across — and the statement is not made for it.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from twin.app.fanout import Progress, Runs, run_starts
from twin.app.montecarlo import Distribution, sample_parameters
from twin.app.replay import controller_identity, replay_entry
from twin.app.sweep import point_seeds
from twin.outputs import JobFiles
from twin.parameters import ParameterError, Parameters
from twin.requirements import Spec, violated

__all__ = ["CertifySettings", "CertifyResult", "OUTPUT_FILES", "certify", "runs_needed"]

NOISE_RERUNS = 8  # other noise seeds for each requirement's least robust run
NOISE_SIGMAS = 3.0  # within this many standard deviations of the noise's spread from zero: inconclusive
MAX_CERTIFY_RUNS = 1_000_000


def runs_needed(probability: float, confidence: float) -> int:
    """The fewest runs without a violation that bound the violation probability by 1 − ``probability`` at
    ``confidence`` (the exact binomial bound with zero failures: probability^n ≤ 1 − confidence)."""
    if not (0 < probability < 1 and 0 < confidence < 1):
        raise ParameterError(
            f"--guarantee {probability!r} and --confidence {confidence!r}: each strictly 0 … 1"
        )
    n = math.ceil(math.log1p(-confidence) / math.log(probability))
    while probability ** (n - 1) <= 1 - confidence:  # the rounding of the logarithms, either way
        n -= 1
    while probability**n > 1 - confidence:
        n += 1
    return n


@dataclass(frozen=True)
class CertifySettings:
    controller: str
    x0_m: tuple[float, float]  # the box the starts are drawn from, uniformly
    theta0_rad: tuple[float, float]
    probability: float = 0.99
    confidence: float = 0.99
    duration_s: float = 15.0
    noise: bool = True
    seed: int = 0
    batch: int = 64  # runs per batch of the engine (a violation ends the job after its batch)


@dataclass
class CertifyResult:
    settings: CertifySettings
    spec: Spec
    spread: Distribution
    needed: int
    runs: list[dict[str, Any]]
    outcome: str  # "pass", "fail", "inconclusive", "interrupted"
    counterexample: dict[str, Any] | None
    requirements: dict[str, dict[str, Any]] = field(default_factory=dict)
    wall_s: float = 0.0
    controller_sha256: str | None = None  # ``controller_identity`` of the controller when the job started

    def statement(self) -> str:
        s = self.settings
        over = self.over()
        if self.outcome == "fail":
            first = self.first_violation
            where = f"run {first + 1} of {len(self.runs)} run" if first is not None else "a noise re-run"
            return f"FAIL: {where} violates {self.counterexample_names()} ({over})"
        if self.outcome == "interrupted":
            return f"interrupted after {len(self.runs)} of {self.needed} runs: no statement"
        names = [n for n, r in self.requirements.items() if r["status"] == "holds"]
        text = (
            f"{', '.join(names) or 'no requirement'}: each holds with probability ≥ {s.probability:g} at "
            f"confidence {s.confidence:g} ({self.needed} runs, none violated; {over})"
        )
        unsure = [n for n, r in self.requirements.items() if r["status"] == "inconclusive"]
        if unsure:
            text += f"; INCONCLUSIVE: {', '.join(unsure)} (within the sensor noise of violation)"
        return text

    @property
    def first_violation(self) -> int | None:
        """The index of the first drawn run that violated a requirement (None: none of them did)."""
        return next((i for i, r in enumerate(self.runs) if _fails(r)), None)

    def counterexample_names(self) -> str:
        cx = self.counterexample or {}
        return ", ".join(violated(cx.get("robustness", {}))) or "a requirement"

    def over(self) -> str:
        s = self.settings
        return (
            f"rigs from {self.spread.source}, starts uniform in x0 ∈ [{s.x0_m[0]:g}, {s.x0_m[1]:g}] m × "
            f"θ0 ∈ [{s.theta0_rad[0]:g}, {s.theta0_rad[1]:g}] rad, "
            + (f"sensor noise seeds from {s.seed}" if s.noise else "no sensor noise")
            + f", {s.duration_s:g} s runs"
        )

    def to_json(self) -> dict[str, Any]:
        return {
            "settings": asdict(self.settings),
            "spec": self.spec.source,
            "spread": self.spread.source,
            "outcome": self.outcome,
            "statement": self.statement(),
            "over": self.over(),
            "not": (
                "a statement about one run drawn as these were, not about every run; not about rigs outside the "
                "spread (its normal tails included as drawn), other starts, longer runs or other controllers; "
                "and about the twin: the rig itself only as far as the twin is faithful to it"
            ),
            "runs_needed": self.needed,
            "runs_spent": len(self.runs),
            "runs_to_first_violation": None if self.first_violation is None else self.first_violation + 1,
            "requirements": self.requirements,
            # the run to repeat comes before the runs: load_replay reads a large file's head only
            "counterexample": self.counterexample,
            "runs": [
                {
                    k: r[k]
                    for k in ("x0_m", "theta0_rad", "seed", "requirements", "parameters_drawn")
                    if k in r
                }
                for r in self.runs
            ],
            "wall_s": round(self.wall_s, 1),
        }


def draws(settings: CertifySettings, base: Parameters, spread: Distribution, n: int) -> tuple[
    np.ndarray, np.ndarray, list[Parameters], np.ndarray
]:  # fmt: skip
    """The first ``n`` runs' starts, noise seeds, rigs and drawn values: the same seed, the same runs."""
    rigs, values = sample_parameters(base, spread, n, settings.seed)
    rng = np.random.default_rng(np.random.SeedSequence([settings.seed, 0x43455254]))  # "CERT"
    u = rng.random((n, 2))
    (xa, xb), (ta, tb) = settings.x0_m, settings.theta0_rad
    starts = np.column_stack([xa + (xb - xa) * u[:, 0], ta + (tb - ta) * u[:, 1]])
    return starts, point_seeds(settings.seed, n), rigs, values


def certify(
    settings: CertifySettings,
    base: Parameters,
    spec: Spec,
    spread: Distribution,
    *,
    workers: int = 1,
    scheduler: str | None = None,
    progress: Progress | None = None,
) -> CertifyResult:
    """The runs in order to the first violation or ``runs_needed``, then the noise re-runs (module doc)."""
    needed = runs_needed(settings.probability, settings.confidence)
    if needed > MAX_CERTIFY_RUNS:
        raise ParameterError(f"{needed} runs needed; at most {MAX_CERTIFY_RUNS}: ask less")
    if settings.batch < 1:
        raise ParameterError(f"--batch {settings.batch}: at least 1 run")
    started = time.perf_counter()
    identity = controller_identity(settings.controller, missing_ok=True)
    starts, seeds, rigs, values = draws(settings, base, spread, needed)
    job = Runs(
        settings.controller, base, settings.duration_s, settings.noise, "twin", False, spec.requirements
    )
    runs: list[dict[str, Any]] = []
    for lo in range(0, needed, settings.batch):
        hi = min(lo + settings.batch, needed)
        records, complete = run_starts(
            job, starts[lo:hi], seeds[lo:hi], params=rigs[lo:hi], workers=workers, scheduler=scheduler
        )
        for i, record in zip(range(lo, hi), records, strict=True):
            if record is None:
                continue
            runs.append(
                {
                    **record,
                    "draw": i,
                    "parameters": rigs[i].changed(),
                    "parameters_drawn": dict(zip(spread.names, map(float, values[i]), strict=True)),
                }
            )
        if progress is not None:
            progress(len(runs), needed)
        bad = next((r for r in runs[lo:] if _fails(r)), None)
        if bad is not None:
            cx = replay_entry(
                settings.controller,
                bad,
                settings.noise,
                settings.duration_s,
                spec,
                controller_sha256=identity,
                plant="twin",
            )
            return CertifyResult(
                settings,
                spec,
                spread,
                needed,
                runs,
                "fail",
                cx,
                wall_s=time.perf_counter() - started,
                controller_sha256=identity,
            )
        if not complete:
            return CertifyResult(
                settings,
                spec,
                spread,
                needed,
                runs,
                "interrupted",
                None,
                wall_s=time.perf_counter() - started,
                controller_sha256=identity,
            )
    result = CertifyResult(settings, spec, spread, needed, runs, "pass", None, controller_sha256=identity)
    _noise_reruns(result, rigs, job, workers, scheduler)
    result.wall_s = time.perf_counter() - started
    return result


def _fails(record: dict[str, Any]) -> bool:
    return (
        bool(record.get("failed")) or not record.get("requirements") or bool(violated(record["requirements"]))
    )


def _noise_reruns(
    result: CertifyResult, rigs: list[Parameters], job: Runs, workers: int, scheduler: str | None
) -> None:
    """Each requirement's least robust run again with other noise seeds (``rigs``: each drawn run's): its noise
    spread, a counterexample or an inconclusive requirement (module doc). A run least robust for several
    requirements is run again once."""
    s = result.settings
    again: dict[int, list[dict[str, Any]]] = {}  # by draw: the re-runs' records
    for req in result.spec.requirements:
        worst = min(result.runs, key=lambda r: r["requirements"][req.name])
        least = float(worst["requirements"][req.name])
        entry: dict[str, Any] = {
            "least_robustness": least,
            "at": {"x0_m": worst["x0_m"], "theta0_rad": worst["theta0_rad"], "seed": worst["seed"]},
        }
        if s.noise:
            draw = worst["draw"]
            if draw not in again:
                records, _ = run_starts(
                    job,
                    np.tile([worst["x0_m"], worst["theta0_rad"]], (NOISE_RERUNS, 1)),
                    point_seeds(int(worst["seed"]) + 1, NOISE_RERUNS),
                    params=[rigs[draw]] * NOISE_RERUNS,
                    workers=workers,
                    scheduler=scheduler,
                )
                again[draw] = [r for r in records if r is not None]
            rob = np.array([r["requirements"][req.name] for r in again[draw]], dtype=float)
            entry["noise_reruns"] = rob.tolist()
            entry["noise_sd"] = float(np.std(rob, ddof=1)) if rob.size > 1 else 0.0
            bad = next((r for r in again[draw] if _fails(r)), None)
            if bad is not None and result.counterexample is None:
                result.outcome = "fail"
                result.counterexample = replay_entry(
                    s.controller,
                    {**bad, "parameters": worst["parameters"]},
                    s.noise,
                    s.duration_s,
                    result.spec,
                    controller_sha256=result.controller_sha256,
                    plant="twin",
                )
        else:
            entry["noise_sd"] = 0.0
        margin = NOISE_SIGMAS * entry["noise_sd"]
        entry["status"] = "holds" if least > margin or (margin == 0 and least > 0) else "inconclusive"
        result.requirements[req.name] = entry
    if result.outcome == "pass" and any(r["status"] == "inconclusive" for r in result.requirements.values()):
        result.outcome = "inconclusive"


# What write_certify (twin.app.commands.certify) puts into its folder (checked before the runs).
OUTPUT_FILES = JobFiles("certify", ("certify.json",))
