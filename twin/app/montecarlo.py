"""Monte Carlo robustness: one controller from one start over many perturbed rigs and noise seeds.

The perturbations come from a spread file (each parameter's uncertainty: a normal with ``sd`` or
``rel_sd``, or a uniform ``low``…``high``) or from a calibration directory (``ballbeam calibrate --out``:
the fitted values, their standard uncertainties and correlations, sampled as one multivariate normal).
A sample outside a parameter's physical bounds is drawn again. Every run has its own noise seed; the
samples and seeds follow from ``--seed`` alone, so a study is bit-identical locally, with workers and on a
cluster.

The result: the success rate (held) with its exact (Clopper-Pearson) 95 % interval, the lost count, the
worst runs with the parameters that caused them, and the distributions of settling time and steady offset.

Spread file (TOML or JSON), one entry per parameter::

    [motor]
    resistance_ohm = { rel_sd = 0.05 }     # normal about the nominal value, 5 % standard deviation
    [beam]
    pivot_friction_nm = { low = 0.0, high = 0.004 }   # uniform
    [angle_sensor]
    zero_error_rad = { sd = 0.0035 }        # normal, absolute standard deviation

What a spread must state (refused otherwise, naming the file, the entry and the value; ``load_spread``): a
regular file of at most 1 MiB (``twin.parameters.read_input_file``, as parameter files); a uniform inside the
parameter's physical bounds (its declaration in ``twin.parameters``); a normal whose nominal ± 3 standard
deviations lie inside them, except on a side where the nominal sits on the bound (there only its half on the
rig's side is drawn); not ``daq.period_s`` or ``physics.timestep_s``, which every rig of a study shares.
"""

from __future__ import annotations

import json
import math
import time
import tomllib
from dataclasses import asdict, dataclass, field, fields, is_dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.app.fanout import Progress, Runs, Served, run_starts
from twin.app.sweep import point_seeds
from twin.rigs.backends import DEFAULT_PLANT, ScreeningPolicy, engine_policy

if TYPE_CHECKING:
    from twin.app.screening import ListJob
from twin.outputs import JobFiles
from twin.parameters import (
    READING,
    DuplicateKeyError,
    ParameterError,
    Parameters,
    declaration,
    load_json,
    read_input_file,
    within_bounds,
)

__all__ = [
    "Distribution",
    "OUTPUT_FILES",
    "MonteCarloResult",
    "MonteCarloSettings",
    "apply_values",
    "load_calibration_spread",
    "load_spread",
    "run_montecarlo",
    "sample_parameters",
]

MAX_RUNS = 100_000
# What write_montecarlo (twin.app.montecarlo_render) puts into its folder (checked before the runs).
OUTPUT_FILES = JobFiles("montecarlo", ("montecarlo.json", "distributions.png"))
MAX_REDRAWS = 100  # a spread that puts a parameter outside its bounds this often is refused
# A normal spread's nominal ± 3 standard deviations (99.7 % of its draws) must lie inside the parameter's
# bounds (``_check_normal``); a uniform's low and high must.
NORMAL_SDS = 3.0
# What a spread may not vary: every rig of a study runs the controller at one period, and a batch of rigs steps
# together (twin.rigs.batch, twin.rigs.vector): the period and the physics step are the study's, not the rig's.
SHARED = {
    "daq.period_s": "the tick period is the controller's and the study's, the same for every rig: set it "
    "with --set daq.period_s=…, not in a spread",
    "physics.timestep_s": "the physics step is a numerical setting, the same for every rig (the period must be "
    "a whole number of steps): set it with --set physics.timestep_s=…, not in a spread",
}
WORST_SHOWN = 10


@dataclass(frozen=True)
class Distribution:
    """Independent parameters: normal (``sd`` about ``mean``) or uniform (``low``…``high``); or, for a
    calibration, one multivariate normal (``names``, ``mean``, ``cov``)."""

    names: tuple[str, ...]
    kind: str  # "independent" or "multivariate"
    mean: tuple[float, ...]
    sd: tuple[float, ...] = ()  # independent normals (NaN where uniform)
    low: tuple[float, ...] = ()  # independent uniforms (NaN where normal)
    high: tuple[float, ...] = ()
    cov: tuple[tuple[float, ...], ...] = ()
    source: str = ""

    def draw(self, rng: np.random.Generator) -> np.ndarray:
        if self.kind == "multivariate":
            return rng.multivariate_normal(np.array(self.mean), np.array(self.cov), method="eigh")
        normal = rng.standard_normal(len(self.names))
        uniform = rng.random(len(self.names))
        mean, sd, low, high = (np.array(v) for v in (self.mean, self.sd, self.low, self.high))
        return np.where(np.isnan(sd), low + (high - low) * uniform, mean + sd * normal)

    def at(self, u: np.ndarray, tail_sd: float) -> np.ndarray:
        """The parameters at point ``u`` of the unit cube (one coordinate each): a uniform's ``low + (high −
        low)·u``, a normal's quantile within ±``tail_sd`` standard deviations; a multivariate normal's
        independent quantiles through the square root of its covariance (its eigenvectors)."""
        from scipy.stats import norm

        q = float(norm.cdf(-tail_sd))
        z = norm.ppf(q + (1.0 - 2.0 * q) * np.clip(np.asarray(u, dtype=float), 0.0, 1.0))
        mean = np.array(self.mean)
        if self.kind == "multivariate":
            w, v = np.linalg.eigh(np.array(self.cov))
            return mean + v @ (np.sqrt(np.clip(w, 0.0, None)) * z)
        sd, low, high = (np.array(x) for x in (self.sd, self.low, self.high))
        uniform = low + (high - low) * np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
        return np.where(np.isnan(sd), uniform, mean + sd * z)


def _nominal(params: Parameters, name: str) -> float:
    """The value of parameter ``group.name`` (a field, not a derived property; a part's own group too)."""
    group, _, field_name = name.partition(".")
    try:
        section = params.group(group)
    except ParameterError:
        section = None
    if section is None or not is_dataclass(section) or field_name not in {f.name for f in fields(section)}:
        raise ParameterError(f"unknown parameter {name!r} (see ballbeam params)")
    value = getattr(section, field_name)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError(f"{name}: only numeric parameters can be perturbed")
    return float(value)


def load_spread(path: str | Path, params: Parameters) -> Distribution:
    """A spread file (TOML or JSON) about the nominal ``params``; refused naming the file and entry."""
    path = Path(path)
    raw = read_input_file(path, "spread file", "a spread of every parameter is a few kB")
    try:
        text = raw.decode("utf-8-sig")
        data = load_json(text) if path.suffix.lower() == ".json" else tomllib.loads(text)
    except UnicodeDecodeError as exc:
        raise ParameterError(f"{path}: cannot read: not UTF-8 text ({exc})") from None
    except DuplicateKeyError as exc:
        raise ParameterError(f"{path}: {exc}") from None
    except (tomllib.TOMLDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise ParameterError(
            f"{path}: not valid {path.suffix.lstrip('.').upper() or 'TOML'}: {exc}"
        ) from None
    if not isinstance(data, dict) or not data:
        raise ParameterError(
            f"{path}: expected tables of parameters, e.g. [motor] resistance_ohm = {{ rel_sd = 0.05 }}"
        )
    rows: list[tuple[str, float, float, float, float]] = []  # name, nominal, sd, low, high
    for group, entries in data.items():
        if not isinstance(entries, dict):
            raise ParameterError(f"{path}: [{group}] is not a table of parameters")
        for name, spec in entries.items():
            full = f"{group}.{name}"
            try:
                nominal = _nominal(params, full)
            except ParameterError as exc:
                raise ParameterError(f"{path}: {exc}") from None
            if full in SHARED:
                raise ParameterError(f"{path}: {full}: {SHARED[full]}")
            keys = set(spec) if isinstance(spec, dict) else set()
            values = {k: spec[k] for k in keys} if isinstance(spec, dict) else {}
            if not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                for v in values.values()
            ):
                raise ParameterError(f"{path}: {full} = {spec!r}: the numbers must be finite")
            if keys == {"sd"} or keys == {"rel_sd"}:
                s = float(values["sd"]) if "sd" in keys else float(values["rel_sd"]) * abs(nominal)
                if s < 0:
                    raise ParameterError(f"{path}: {full}: a standard deviation is ≥ 0")
                if "rel_sd" in keys and nominal == 0 and values["rel_sd"] != 0:
                    raise ParameterError(
                        f"{path}: {full} = {spec!r}: its nominal value is 0, so a relative spread perturbs "
                        "nothing; give { sd = … } in its unit"
                    )
                _check_normal(path, full, spec, nominal, s)
                rows.append((full, nominal, s, math.nan, math.nan))
            elif keys == {"low", "high"}:
                lo, hi = float(values["low"]), float(values["high"])
                if lo > hi:
                    raise ParameterError(f"{path}: {full}: low = {lo:g} is above high = {hi:g}")
                for key, end in (("low", lo), ("high", hi)):
                    if not within_bounds(full, end):
                        raise ParameterError(
                            f"{path}: {full} = {spec!r}: {key} = {end:g} is outside the parameter's bounds "
                            f"({_bounds_text(full)}): a uniform spread lies inside them"
                        )
                rows.append((full, nominal, math.nan, lo, hi))
            else:
                raise ParameterError(
                    f"{path}: {full} = {spec!r}: give {{ sd = … }}, {{ rel_sd = … }} or {{ low = …, high = … }}"
                )
    names, mean, sd, low, high = zip(*rows, strict=True)
    return Distribution(names, "independent", mean, sd, low, high, source=str(path))


def _bounds_text(name: str) -> str:
    """The physical bounds parameter ``name`` declares, in words (``> 0``, ``>= 0 and <= 1``)."""
    md = declaration(name)
    signs = {"gt": ">", "ge": ">=", "lt": "<", "le": "<="}
    return " and ".join(f"{signs[k]} {md[k]:g}" for k in signs if md.get(k) is not None) or "none"


def _check_normal(path: Path, name: str, spec: object, nominal: float, sd: float) -> None:
    """A normal spread's rule: nominal ± ``NORMAL_SDS`` · sd inside the parameter's bounds, except on a side
    where the nominal value sits on the bound itself (a pivot friction of 0 ± sd: only the half on the rig's
    side is drawn, the rest drawn again). Otherwise a sizeable share of the draws would be drawn again and the
    distribution sampled would not be the one stated (``rel_sd = 0.9`` of a mass: a third of it below 0)."""
    for sign, side in ((-1.0, "below"), (1.0, "above")):
        end = nominal + sign * NORMAL_SDS * sd
        on_bound = not within_bounds(name, math.nextafter(nominal, sign * math.inf))
        if not on_bound and not within_bounds(name, end):
            raise ParameterError(
                f"{path}: {name} = {spec!r}: its nominal {nominal:g} {side} by {NORMAL_SDS:g} standard "
                f"deviations ({sd:g}) is {end:g}, outside the parameter's bounds ({_bounds_text(name)}): "
                "narrow the spread, or give a uniform { low = …, high = … } inside the bounds"
            )


def load_calibration_spread(directory: str | Path) -> tuple[Parameters, Distribution]:
    """A calibration's fitted parameters (``params.toml``) and the multivariate normal of its values
    (``calibration.json``: values, standard uncertainties, correlations)."""
    directory = Path(directory)
    params = Parameters.from_file(directory / "params.toml")
    path = directory / "calibration.json"
    try:
        data = json.loads(path.read_text())
        fitted = data["params"]
        names = list(data["correlation"]["names"])
        corr = np.array(data["correlation"]["matrix"], dtype=float)
        sd = {name: float(fitted[name]["sd"]) for name in fitted}
        value = {name: float(fitted[name]["value"]) for name in fitted}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ParameterError(f"{path}: not a calibration result ({type(exc).__name__}: {exc})") from None
    if corr.shape != (len(names), len(names)) or not all(n in fitted for n in names):
        raise ParameterError(f"{path}: the correlation matrix does not match its names")
    ordered = names + [n for n in fitted if n not in names]  # e.g. the dropout rate, fitted separately
    full = np.eye(len(ordered))
    full[: len(names), : len(names)] = corr
    s = np.array([sd[n] for n in ordered])
    if not np.all(np.isfinite(s)):
        raise ParameterError(f"{path}: a fitted value has no standard uncertainty (an older calibration?)")
    cov = full * np.outer(s, s)
    return params, Distribution(
        tuple(ordered),
        "multivariate",
        tuple(value[n] for n in ordered),
        cov=tuple(tuple(float(v) for v in row) for row in cov),
        source=str(directory),
    )


def _apply(
    base: Parameters, names: tuple[str, ...], values: np.ndarray, fitted: dict[str, float]
) -> Parameters:
    plain = {n: float(v) for n, v in zip(names, values, strict=True) if n not in READING}
    out = base.with_overrides(plain, origin="Monte Carlo sample") if plain else base
    reading = {n: float(v) for n, v in zip(names, values, strict=True) if n in READING}
    if reading:
        # The base already reads g₀·r + b₀ (the calibration folded its fit into the curve): apply the
        # sample relative to it, g·r + b = (g/g₀)·(g₀·r + b₀) + (b − b₀·g/g₀).
        g0, b0 = fitted.get("ball_reading.gain", 1.0), fitted.get("ball_reading.offset_m", 0.0)
        g = reading.get("ball_reading.gain", g0) / g0
        b = reading.get("ball_reading.offset_m", b0) - b0 * g
        out = out.with_values({"ball_reading.gain": g, "ball_reading.offset_m": b})
    return out


def apply_values(base: Parameters, spread: Distribution, values: np.ndarray) -> Parameters:
    """``base`` with the spread's parameters at ``values`` (as a Monte Carlo sample is applied)."""
    fitted = dict(zip(spread.names, spread.mean, strict=True)) if spread.kind == "multivariate" else {}
    return _apply(base, spread.names, values, fitted)


def sample_parameters(
    base: Parameters, spread: Distribution, n: int, seed: int
) -> tuple[list[Parameters], np.ndarray]:
    """``n`` parameter sets and their sampled values ((n, k)); a draw outside a parameter's bounds is
    drawn again (the same seed always gives the same sets)."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x4D43]))  # "MC": apart from the noise seeds
    fitted = dict(zip(spread.names, spread.mean, strict=True)) if spread.kind == "multivariate" else {}
    sets, values = [], []
    for i in range(n):
        for attempt in range(MAX_REDRAWS):
            draw = spread.draw(rng)
            try:
                sets.append(_apply(base, spread.names, draw, fitted))
            except ParameterError as exc:
                if attempt == MAX_REDRAWS - 1:
                    raise ParameterError(
                        f"{spread.source}: sample {i}: {MAX_REDRAWS} draws in a row fall outside the parameters' "
                        f"bounds (last: {exc}); narrow the spread"
                    ) from None
                continue
            values.append(draw)
            break
    return sets, np.array(values).reshape(n, len(spread.names))


@dataclass(frozen=True)
class MonteCarloSettings:
    controller: str
    n: int
    x0_m: float = -0.2  # a thesis start (Figures 5.5 and 5.10: [−0.2 m, 0.3 rad])
    theta0_rad: float = 0.3
    duration_s: float = 15.0
    noise: bool = True
    plant: str = DEFAULT_PLANT
    ideal_sensors: bool = False
    seed: int = 0
    # "mujoco" (MuJoCo alone), "screen" (the fast engine runs every rig, MuJoCo every rig it did not hold or
    # held near a band, and an audit sample: twin.app.screening.confirm_list) or "fast" (the fast engine
    # alone, and the audit).
    engine: str = "mujoco"
    audit: int = 32

    @property
    def policy(self) -> ScreeningPolicy:
        """``engine`` for ``plant`` as the backends' policy (a plant no backend stands in for runs alone)."""
        return engine_policy(self.engine, self.plant, strict=False)


@dataclass
class MonteCarloResult:
    settings: MonteCarloSettings
    spread: Distribution
    # Per run done: seed, verdict and the sampled values, in the job's order; an interrupted job (complete
    # false) lists only the runs it finished (settings.n says how many were asked).
    runs: list[dict[str, Any]]
    complete: bool
    wall_s: float = 0.0
    summary: dict[str, Any] = field(default_factory=dict)
    served: dict[str, Any] | None = None  # a served job: where, and the clients (fanout.Served.to_json)
    screening: dict[str, Any] | None = None  # --engine screen or fast: what each engine ran, the audit

    def to_json(self) -> dict[str, Any]:
        return {
            "settings": asdict(self.settings),
            **({"served": self.served} if self.served is not None else {}),
            **({"screening": self.screening} if self.screening is not None else {}),
            "spread": {
                "source": self.spread.source,
                "kind": self.spread.kind,
                "names": list(self.spread.names),
            },
            "complete": self.complete,
            "summary": self.summary,
            "runs": self.runs,
        }


def _percentiles(values: list[float]) -> dict[str, float] | None:
    if not values:
        return None
    a = np.array(values)
    return {f"p{q}": round(float(np.percentile(a, q)), 6) for q in (5, 50, 95)} | {
        "min": round(float(a.min()), 6),
        "max": round(float(a.max()), 6),
    }


def summarize(runs: list[dict[str, Any]], confidence: float = 0.95) -> dict[str, Any]:
    """Success rate (held) with its exact interval, the worst runs, the distributions."""
    import scipy.stats

    done = [r for r in runs if r]
    held = sum(bool(r["held"]) for r in done)
    n = len(done)
    ci = scipy.stats.binomtest(held, n).proportion_ci(confidence, method="exact") if n else None

    def badness(r: dict[str, Any]) -> tuple[int, float]:
        offset = abs(r["steady_x_m"]) if r["steady_x_m"] is not None else math.inf
        return (0 if r["ball_lost"] else (1 if not r["held"] else 2), -offset)

    worst = sorted(done, key=badness)[:WORST_SHOWN]
    return {
        "runs": n,
        "held": held,
        "lost": sum(bool(r["ball_lost"]) for r in done),
        "success_rate": round(held / n, 6) if n else None,
        "success_ci": [round(ci.low, 6), round(ci.high, 6)] if ci else None,
        "ci_level": confidence,
        "settling_time_s": _percentiles(
            [r["settling_time_s"] for r in done if r["held"] and r["settling_time_s"] is not None]
        ),
        "steady_x_m": _percentiles([r["steady_x_m"] for r in done if r["steady_x_m"] is not None]),
        "worst": worst,
    }


def run_montecarlo(
    settings: MonteCarloSettings,
    base: Parameters,
    spread: Distribution,
    *,
    workers: int = 1,
    scheduler: str | None = None,
    progress: Progress | None = None,
    serve: Served | None = None,
) -> MonteCarloResult:
    """The runs (``serve``: each a session to a client over the wire, ``fanout.run_served``) and their
    summary."""
    if not 1 <= settings.n <= MAX_RUNS:
        raise ParameterError(f"--n = {settings.n}: 1 … {MAX_RUNS} runs")
    sets, values = sample_parameters(base, spread, settings.n, settings.seed)
    seeds = point_seeds(settings.seed, settings.n)
    starts = np.tile([settings.x0_m, settings.theta0_rad], (settings.n, 1))
    start = time.perf_counter()

    def job(plant: str) -> ListJob:
        runs = Runs(
            settings.controller, base, settings.duration_s, settings.noise, plant, settings.ideal_sensors
        )

        def run(idx: list[int]) -> tuple[list[dict[str, Any] | None], bool]:
            return run_starts(
                runs, starts[idx], seeds[idx], params=[sets[i] for i in idx], workers=workers,
                scheduler=scheduler, progress=progress, serve=serve,
            )  # fmt: skip

        return run

    every = list(range(settings.n))
    screening = None
    policy = settings.policy
    if policy.screen is None:
        records, complete = job(policy.confirm)(every)
        label = policy.label(policy.confirm)
        records = [None if r is None else {**r, "engine": label} for r in records]
    else:
        from twin.app.screening import confirm_list, near_class_change, near_track_end

        fast, complete = job(policy.screen)(every)
        confirm = [i for i, r in enumerate(fast) if r and (near_class_change(r) or near_track_end(r, base))]
        records, screening, confirmed = confirm_list(
            fast, job(policy.confirm), confirm=confirm if policy.screened else [], audit=settings.audit,
            seed=settings.seed,
        )  # fmt: skip
        complete = complete and confirmed
        if policy.stand_alone:
            screening["confirmed"] = "none (the fast engine alone)"
    out: list[dict[str, Any]] = []
    for record, sample in zip(records, values, strict=True):
        if record is None:  # not run (interrupted): not listed
            continue
        out.append({**record, "parameters": {n: float(v) for n, v in zip(spread.names, sample, strict=True)}})
    result = MonteCarloResult(settings, spread, out, complete, wall_s=time.perf_counter() - start)
    result.summary = summarize(out)
    result.served = serve.to_json() if serve is not None else None
    result.screening = screening
    return result
