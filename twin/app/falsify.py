"""``ballbeam falsify``: search a space of runs for the one that violates a requirement.

The space is a box of inputs (``Axis``: the start, the output latency, the zeroing error) and, optionally, the
rigs of a spread or calibration (``Distribution``). A point of the search is a point of the unit cube, one
coordinate per axis and per spread parameter (its quantile: a normal is searched within ±3 standard deviations,
``NORMAL_TAIL``); with noise on, each run gets its own noise seed from the search's seed (recorded, not
searched). The objective is the least robustness over the file's requirements: negative is a counterexample.

The search (``falsify``): a first batch of the cube's corners and its centre (at most ``CORNER_DIMS``
dimensions; more: a scrambled Sobol set, then the corner where a linear model of it is least), since a
requirement is most often violated at the edges of the space its inputs may take; then CMA-ES (``cma``: a
maintained implementation of the method falsification tools use for continuous searches; pure Python, seeded)
from the least robust point so far, restarted with a fresh spread when it converges. Each batch is one job of
the batch engine (``twin.app.fanout``: workers and Dask as every other job, the same records). It stops at the
first batch with a counterexample or at the budget. Every number comes from the runs' records;
``uniform_search`` samples the same cube uniformly (the baseline the bench compares with).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from twin.app.fanout import Progress, Runs, run_starts
from twin.app.montecarlo import Distribution, apply_values
from twin.app.replay import controller_identity, replay_entry
from twin.engine import Scenario
from twin.outputs import JobFiles
from twin.parameters import ParameterError, Parameters
from twin.requirements import Spec, stated
from twin.rigs.backends import DEFAULT_PLANT, ScreeningPolicy, engine_policy, label_backend

__all__ = ["Axis", "FalsifyResult", "FalsifySettings", "OUTPUT_FILES", "falsify", "uniform_search"]

CORNER_DIMS = 5  # up to 2^5 = 32 corners in the first batch; beyond, a Sobol set of one population
NORMAL_TAIL = 3.0  # a normal parameter is searched within ±3 standard deviations (99.73 % of its mass)
MAX_BUDGET = 100_000
SIGMA0 = 0.3  # CMA-ES's first step, in the unit cube (a third of every axis)
GRID = 2.0**12  # CMA-ES's points are run on this grid of the unit cube (``on_grid``)

# What ``Axis.name`` may be: the start, a flick or the setpoint of the run (``twin.engine.Scenario``), or a
# parameter by dotted name.
START_AXES = ("x0_m", "theta0_rad")
SCENARIO_AXES = ("flick_time_s", "flick_speed_m_s", "setpoint_m")


@dataclass(frozen=True)
class Axis:
    """One input: ``x0_m``, ``theta0_rad``, a ``SCENARIO_AXES`` name or a parameter (``group.name``) from ``low`` to
    ``high`` (searched when ``low < high``, else that value); ``step``: values are whole steps (the output
    latency: whole physics steps)."""

    name: str
    low: float
    high: float
    step: float = 0.0

    def at(self, u: float) -> float:
        v = self.low + (self.high - self.low) * float(u)
        if self.step > 0:
            v = min(max(round(v / self.step) * self.step, self.low), self.high)
        return float(v)


@dataclass(frozen=True)
class FalsifySettings:
    """Everything a search's result depends on (written into falsify.json)."""

    controller: str
    axes: tuple[Axis, ...]
    x0_m: float = 0.0  # the start where it is not an axis
    theta0_rad: float = 0.0
    duration_s: float = 10.0
    noise: bool = True
    budget: int = 300
    seed: int = 0  # the search's: its first batch, CMA-ES, the runs' noise seeds
    population: int = 0  # runs per CMA-ES generation (0: ``default_population``)
    keep_going: bool = False  # search the whole budget for the least robust point, past the first violation
    # "mujoco" (MuJoCo runs the search), "screen" (the fast engine runs it; MuJoCo re-runs every run the fast
    # engine found violating and each batch's least robust run, and only MuJoCo's violations count) or "fast".
    engine: str = "mujoco"

    @property
    def policy(self) -> ScreeningPolicy:
        """``engine`` as the backends' screening policy (``twin.rigs.backends.engine_policy``)."""
        return engine_policy(self.engine)


@dataclass
class FalsifyResult:
    settings: FalsifySettings
    spec: Spec
    spread: Distribution | None
    runs: list[dict[str, Any]]  # in the order run: record, its inputs, its objective and batch
    complete: bool
    wall_s: float = 0.0
    base: dict[str, Any] = field(default_factory=dict)  # the base parameters' changes from the defaults
    controller_sha256: str | None = None  # ``controller_identity`` of the controller when the search started

    @property
    def first_violation(self) -> int | None:
        """The index of the first run that violated a requirement (None: none did)."""
        return next((i for i, r in enumerate(self.runs) if r["objective"] < 0), None)

    @property
    def least_robust(self) -> dict[str, Any] | None:
        """The least robust run; a screened search's among the runs MuJoCo made (each batch's least robust)."""
        policy = self.settings.policy
        confirmed = [r for r in self.runs if r.get("engine") == policy.label(policy.confirm)]
        pool = confirmed if policy.screened and confirmed else self.runs
        return min(pool, key=lambda r: r["objective"]) if pool else None

    def replay(self, run: dict[str, Any]) -> dict[str, Any]:
        """What ``ballbeam run --replay`` needs to repeat ``run`` bit for bit."""
        s = self.settings
        return {
            **replay_entry(
                s.controller,
                run,
                s.noise,
                s.duration_s,
                self.spec,
                controller_sha256=self.controller_sha256,
                # the engine that made this run: the fast engine's (the reference plant under the twin's
                # sensor chain) replays on it
                plant=label_backend(run["engine"]).name if "engine" in run else DEFAULT_PLANT,
            ),
            **{k: run["values"][k] for k in SCENARIO_AXES if k in run["values"]},
            "searched": run["values"],
            "objective": stated(run["objective"]),  # a failed controller's −inf: JSON has no infinities
        }

    def to_json(self) -> dict[str, Any]:
        first, best = self.first_violation, self.least_robust
        s = self.settings
        return {
            "settings": {**asdict(s), "axes": [asdict(a) for a in s.axes]},
            "spec": self.spec.source,
            "requirements": {r.name: r.formula for r in self.spec.requirements},
            "spread": None if self.spread is None else self.spread.source,
            "base_parameters": self.base,
            "complete": self.complete,
            "found": first is not None,
            "runs_spent": len(self.runs),
            "decided_by": {e: sum(r.get("engine") == e for r in self.runs) for e in ("fast", "mujoco")},
            "runs_to_first_violation": None if first is None else first + 1,
            # the runs to repeat come before the trace: load_replay reads a large file's head only
            "counterexample": None if first is None or best is None else self.replay(best),
            "least_robust": None if best is None else self.replay(best),
            "trace": [
                {
                    **{k: r[k] for k in ("batch", "x0_m", "theta0_rad", "seed", "values", "worst")},
                    "objective": stated(r["objective"]),
                    "engine": r.get("engine"),
                    **({"fast_objective": stated(r["fast_objective"])} if "fast_objective" in r else {}),
                }
                for r in self.runs
            ],
            "wall_s": round(self.wall_s, 2),
        }


class _Space:
    """The unit cube's points as runs: a start, a noise seed, the rig's parameters, a scenario."""

    def __init__(self, settings: FalsifySettings, base: Parameters, spread: Distribution | None) -> None:
        self.s, self.base, self.spread = settings, base, spread
        self.searched = [a for a in settings.axes if a.high > a.low]
        self.fixed = {a.name: a.low for a in settings.axes if a.high <= a.low}
        self.dims = len(self.searched) + (len(spread.names) if spread is not None else 0)
        self.scenario = any(a.name in SCENARIO_AXES for a in settings.axes)
        if self.dims == 0:
            raise ParameterError("nothing to search: give a range (A:B) to at least one input, or a spread")
        names = [a.name for a in settings.axes]
        if len(set(names)) != len(names):
            raise ParameterError(f"an input is searched twice: {names}")
        if spread is not None:
            both = sorted(set(names) & set(spread.names))
            if both:
                raise ParameterError(f"{both[0]} is both a searched range and in the spread {spread.source}")

    def run_of(self, u: np.ndarray) -> tuple[float, float, dict[str, float], Parameters, Scenario | None]:
        """The start, the inputs' values by name, the parameters and the scenario of point ``u``."""
        s, k = self.s, len(self.searched)
        values = {**self.fixed, **{a.name: a.at(x) for a, x in zip(self.searched, u[:k], strict=True)}}
        overrides = {n: v for n, v in values.items() if n not in START_AXES + SCENARIO_AXES}
        params = self.base.with_overrides(overrides, origin="falsify") if overrides else self.base
        if self.spread is not None:
            drawn = self.spread.at(u[k:], NORMAL_TAIL)
            params = apply_values(params, self.spread, drawn)
            values.update({n: float(v) for n, v in zip(self.spread.names, drawn, strict=True)})
        scenario = (
            Scenario(values.get("flick_time_s"), values.get("flick_speed_m_s", 0.0), values.get("setpoint_m"))
            if self.scenario
            else None
        )
        return values.get("x0_m", s.x0_m), values.get("theta0_rad", s.theta0_rad), values, params, scenario


def _objective(record: dict[str, Any]) -> tuple[float, str]:
    """The least robustness of a run and the requirement that has it; a failed controller is −inf."""
    margins = record.get("requirements")
    if record.get("failed") or not margins:
        return -math.inf, "the controller failed" if record.get("failed") else "no signals"
    name = min(margins, key=lambda k: margins[k] if not math.isnan(margins[k]) else -math.inf)
    value = margins[name]
    return (-math.inf if math.isnan(value) else float(value)), name


@dataclass
class _Search:
    """The runs so far, shared by the search strategies."""

    space: _Space
    runs_job: Runs  # MuJoCo's (or the fast engine's with --engine fast)
    fast_job: Runs | None  # with --engine screen: the fast engine's, confirmed by ``runs_job``
    rng: np.random.Generator
    workers: int
    scheduler: str | None
    progress: Progress | None
    runs: list[dict[str, Any]] = field(default_factory=list)
    complete: bool = True

    @property
    def left(self) -> int:
        return self.space.s.budget - len(self.runs)

    def found(self) -> bool:
        return not self.space.s.keep_going and any(r["objective"] < 0 for r in self.runs)

    def evaluate(self, points: np.ndarray) -> list[float]:
        """Run the points (one batch) and return their objectives; points the rig cannot take are +inf."""
        batch = len({r["batch"] for r in self.runs})
        rows: list[dict[str, Any]] = []
        starts, params, seeds, scenarios = [], [], [], []
        for u in points[: self.left]:
            u = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
            seed = int(self.rng.integers(2**31)) if self.space.s.noise else 0
            try:
                x0, th0, values, p, scenario = self.space.run_of(u)
            except ParameterError as exc:  # a point outside a parameter's bounds: no rig, no run
                rows.append({"infeasible": str(exc)})
                continue
            rows.append({"values": values, "seed": seed, "u": u.tolist(), "p": p})
            starts.append((x0, th0))
            params.append(p)
            seeds.append(seed)
            scenarios.append(scenario)
        records, complete = self._run(self.fast_job or self.runs_job, starts, seeds, params, scenarios)
        if self.fast_job is not None and complete:
            records, complete = self._confirm(records, starts, seeds, params, scenarios)
        self.complete = self.complete and complete
        done = iter(records)
        objectives = []
        for row in rows:
            if "infeasible" in row:
                objectives.append(math.inf)
                continue
            record = next(done)
            if record is None:
                objectives.append(math.inf)
                continue
            value, worst = _objective(record)
            p = row.pop("p")
            self.runs.append(
                {
                    **record,
                    **row,
                    "objective": value,
                    "worst": worst,
                    "batch": batch,
                    "parameters": p.changed(),
                }
            )
            objectives.append(value)
        if self.progress is not None:
            self.progress(len(self.runs), self.space.s.budget)
        return objectives

    def _run(
        self, job: Runs, starts: list, seeds: list, params: list, scenarios: list
    ) -> tuple[list[dict[str, Any] | None], bool]:
        if not starts:
            return [], True
        records, complete = run_starts(
            job,
            np.array(starts, dtype=float).reshape(-1, 2),
            np.array(seeds, dtype=np.int64),
            params=params,
            workers=self.workers,
            scheduler=self.scheduler,
            scenarios=scenarios if self.space.scenario else None,
        )
        label = self.space.s.policy.label(job.plant)
        return [None if r is None else {**r, "engine": label} for r in records], complete

    def _confirm(
        self, records: list[dict[str, Any] | None], starts: list, seeds: list, params: list, scenarios: list
    ) -> tuple[list[dict[str, Any] | None], bool]:
        """MuJoCo re-runs the fast engine's violations and the batch's least robust run; its records replace
        theirs (each keeps the fast engine's objective as ``fast_objective``)."""
        value = [math.inf if r is None else _objective(r)[0] for r in records]
        picks = sorted(
            {i for i, v in enumerate(value) if v < 0} | ({int(np.argmin(value))} if value else set())
        )
        picks = [i for i in picks if records[i] is not None]
        again, complete = self._run(
            self.runs_job, [starts[i] for i in picks], [seeds[i] for i in picks], [params[i] for i in picks],
            [scenarios[i] for i in picks],
        )  # fmt: skip
        out = list(records)
        for i, r in zip(picks, again, strict=True):
            if r is not None:
                out[i] = {**r, "fast_objective": value[i]}
        return out, complete


def _first_batch(dims: int, rng: np.random.Generator) -> np.ndarray:
    """The cube's corners and centre (``CORNER_DIMS`` dimensions at most), else a scrambled Sobol set of the
    fewest points (a power of two, at least 8) that fit a linear model (d + 1 coefficients)."""
    if dims <= CORNER_DIMS:
        corners = np.array(np.meshgrid(*[[0.0, 1.0]] * dims, indexing="ij")).reshape(dims, -1).T
        return np.vstack([corners, np.full((1, dims), 0.5)])
    from scipy.stats import qmc

    return qmc.Sobol(dims, scramble=True, seed=rng).random_base2(math.ceil(math.log2(max(dims + 1, 8))))


def falsify(
    settings: FalsifySettings,
    base: Parameters,
    spec: Spec,
    spread: Distribution | None = None,
    *,
    workers: int = 1,
    scheduler: str | None = None,
    progress: Progress | None = None,
) -> FalsifyResult:
    """The search (see the module's doc): the runs in order, each with its objective."""
    if not 1 <= settings.budget <= MAX_BUDGET:
        raise ParameterError(f"--budget {settings.budget}: 1 … {MAX_BUDGET} runs")
    space = _Space(settings, base, spread)
    identity = controller_identity(settings.controller, missing_ok=True)
    search = _new_search(settings, base, spec, space, workers, scheduler, progress)
    started = time.perf_counter()
    _cma_search(search)
    return _result(search, spec, spread, base, started, identity)


def uniform_search(
    settings: FalsifySettings,
    base: Parameters,
    spec: Spec,
    spread: Distribution | None = None,
    *,
    workers: int = 1,
    batch: int = 64,
) -> FalsifyResult:
    """The baseline: the same cube sampled uniformly at random (seeded), in batches of ``batch``, to the
    first violation or the budget."""
    space = _Space(settings, base, spread)
    identity = controller_identity(settings.controller, missing_ok=True)
    search = _new_search(settings, base, spec, space, workers, None, None)
    started = time.perf_counter()
    while search.left > 0 and not search.found() and search.complete:
        search.evaluate(search.rng.random((min(batch, search.left), space.dims)))
    return _result(search, spec, spread, base, started, identity)


def _new_search(
    settings: FalsifySettings,
    base: Parameters,
    spec: Spec,
    space: _Space,
    workers: int,
    scheduler: str | None,
    progress: Progress | None,
) -> _Search:
    def job(plant: str) -> Runs:
        return Runs(
            settings.controller, base, settings.duration_s, settings.noise, plant, False, spec.requirements
        )

    try:
        policy = settings.policy
    except ValueError:
        raise ParameterError(f"--engine {settings.engine!r}: one of screen, fast, mujoco") from None
    runs = job(policy.decider)
    fast = job(policy.screen) if policy.screen is not None and policy.screened else None
    rng = np.random.default_rng(np.random.SeedSequence([settings.seed, 0x46414C]))  # "FAL"
    return _Search(space, runs, fast, rng, workers, scheduler, progress)


def _result(
    search: _Search,
    spec: Spec,
    spread: Distribution | None,
    base: Parameters,
    started: float,
    identity: str | None,
) -> FalsifyResult:
    return FalsifyResult(
        search.space.s,
        spec,
        spread,
        search.runs,
        search.complete,
        time.perf_counter() - started,
        base.changed(),
        identity,
    )


def _cma_search(search: _Search) -> None:
    """Corners first, then CMA-ES from the least robust point, restarted when it converges."""
    import cma  # type: ignore[import-untyped]

    s, d = search.space.s, search.space.dims
    population = s.population or default_population(d, s.budget)
    first = _first_batch(d, search.rng)
    search.evaluate(first)
    corner = _linear_corner(search.runs, d) if d > CORNER_DIMS else None
    while search.left > 0 and not search.found() and search.complete:
        best = min(search.runs, key=lambda r: r["objective"]) if search.runs else None
        x0 = np.array(best["u"]) if best is not None else np.full(d, 0.5)
        if corner is not None:  # the first strategy starts toward the linear model's worst corner
            x0 = 0.15 + 0.7 * corner
        # cma searches two coordinates or more: a one-input search carries a second that changes nothing
        es = _strategy(cma, np.r_[x0, 0.5] if d == 1 else x0, population, int(search.rng.integers(2**31)))
        if corner is not None:
            es.inject([corner], force=True)
            corner = None
        while search.left > 0 and not search.found() and search.complete and not es.stop():
            points = on_grid(np.asarray(es.ask(), dtype=float))
            values = search.evaluate(points[:, :d])
            if len(values) < len(points):  # the budget's last, partial generation: nothing to learn
                break
            # the injected corner comes back from the bounds' repair, on the grid: cma's warning is moot
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                es.tell(list(points), [_finite(v) for v in values])


def default_population(dims: int, budget: int) -> int:
    """Runs per CMA-ES generation: a tenth of the budget, at least CMA-ES's own 4 + 3 ln d. A batch of the engine
    pays its per-tick Python once for all its runs (a 6-run batch costs ~1.2 ms a tick, a 500-run one ~70 µs a
    run-tick), so a search of about ten generations runs near a batch's speed; a smaller population finds in
    fewer runs on hard problems and costs more wall time per run (``--population``)."""
    return max(4 + int(3 * math.log(max(dims, 2))), math.ceil(budget / 10))


def on_grid(points: np.ndarray) -> np.ndarray:
    """CMA-ES's points on a grid of 2^-12 of each axis (50 µm of a 0.2 m start box): its sampling and updates
    go through BLAS, whose kernel (OPENBLAS_CORETYPE) changes their last bits (1e-11 after two generations,
    measured); on the grid, and told the points as run, every machine runs the same points."""
    return np.clip(np.round(points * GRID) / GRID, 0.0, 1.0)


def _linear_corner(runs: list[dict[str, Any]], dims: int) -> np.ndarray | None:
    """The corner of the cube where a least-squares linear model of the first batch's objectives is least
    (each coordinate at the end its slope points down): where a monotone requirement is weakest. None with
    fewer finite runs than the model has coefficients."""
    finite = [r for r in runs if math.isfinite(r["objective"])]
    if len(finite) < dims + 1:
        return None
    u = np.array([r["u"] for r in finite], dtype=float)
    y = np.array([r["objective"] for r in finite], dtype=float)
    coef = np.linalg.lstsq(np.column_stack([np.ones(len(u)), u]), y, rcond=None)[0]
    return np.where(coef[1:] > 0, 0.0, 1.0)


def _strategy(cma: Any, x0: np.ndarray, population: int, seed: int) -> Any:
    options = {"bounds": [0.0, 1.0], "popsize": population, "seed": seed + 1, "verbose": -9}
    options.update({"tolx": 1e-4, "tolfun": 1e-9})
    return cma.CMAEvolutionStrategy(list(np.clip(x0, 0.02, 0.98)), SIGMA0, options)


def _finite(v: float) -> float:
    """CMA-ES ranks finite numbers: a failed run the worst-but-finite low, a point without a rig high."""
    return -1e9 if v == -math.inf else 1e9 if v == math.inf else float(v)


# What write_falsify (twin.app.falsify_render) puts into its folder (checked before the search).
OUTPUT_FILES = JobFiles("falsify", ("falsify.json", "falsify.png"))
