"""``ballbeam validate``: a standard battery for a controller before it drives the rig, one report, one
verdict against stated criteria.

    nominal       the thesis's starts (chapter 4: x0 = ±0.2 m, θ0 = 0.3 rad; the chapter 6 experiments'
                  starts), several noise seeds: every run held
    region        a grid over the chapter 7 range: every start in the required box keeps the ball
    sensitivity   the counter's zeroing error (± a few encoder counts: the beam is zeroed by hand, Figure
                  7.20), the output latency (up to most of a period) and the start's free-run time (the
                  unknown 0–40 ms between release and the first command): every run held
    saturation    the share of nominal ticks at the amplifier's rails stays below a bound
    monte carlo   (with --spread or --calibration) the success rate's lower confidence bound

Every bound is a field of ``ValidationCriteria`` with its reason; ``--criteria FILE`` (TOML) overrides
them. Every run goes through the batch engine (``twin.app.fanout``); the numbers in the report are
formatted from the runs' verdicts.
"""

from __future__ import annotations

import json
import math
import time
import tomllib
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from controllers import thesis_numbers as T
from twin.app.fanout import Progress, Runs, Stages, run_starts
from twin.app.montecarlo import Distribution, MonteCarloSettings, run_montecarlo
from twin.app.sweep import Grid, SweepResult, SweepSettings, point_seeds, render_map, run_sweep
from twin.parameters import ParameterError, Parameters
from twin.sensors import angle_count_step_rad

__all__ = ["ValidationCriteria", "ValidationReport", "load_criteria", "validate", "write_validation"]


@dataclass(frozen=True)
class ValidationCriteria:
    """What passing means. Each default with its reason."""

    # Three noise realisations per start: a controller that holds only for a lucky seed is not validated.
    nominal_seeds: int = 3
    # The chapter 6 runs lasted about 15 s (Figures 6.16–6.20).
    duration_s: float = 15.0
    # The box every start of which must keep the ball: it contains the thesis's chapter 4 starts and all
    # the chapter 6 hardware starts (|x0| ≤ 0.14 m, |θ0| ≤ 0.29 rad).
    required_x0_m: tuple[float, float] = (-0.2, 0.2)
    required_theta0_rad: tuple[float, float] = (-0.3, 0.3)
    # The region grid: the chapter 7 range at 4 cm and 0.1 rad (17 × 15 starts), 10 s each.
    region_x0: tuple[float, float, int] = (-0.32, 0.32, 17)
    region_theta0: tuple[float, float, int] = (-0.7, 0.7, 15)
    region_duration_s: float = 10.0
    # The counter is zeroed by hand with the beam level: ± 3 counts (±10 mrad, a visible tilt of 0.6°).
    zeroing_counts: int = 3
    # Output latencies up to three quarters of the 20 ms period (a slow PC's timer callback).
    latencies_s: tuple[float, ...] = (0.0, 0.005, 0.010, 0.015)
    # The start's free run: the thesis leaves 0–40 ms open (twin.parameters: start.free_run_s).
    free_runs_s: tuple[float, ...] = (0.0, 0.01, 0.02, 0.04)
    # A controller that spends more than a fifth of its ticks at ±12 V has no authority left for a
    # disturbance.
    max_saturated_fraction: float = 0.2
    # Monte Carlo: the 95 % lower bound of the success rate.
    montecarlo_runs: int = 100
    min_success_lower_bound: float = 0.9


def load_criteria(path: str | Path) -> ValidationCriteria:
    """Criteria from a TOML file (any subset of ``ValidationCriteria``'s fields)."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ParameterError(f"{path}: cannot read criteria: {exc}") from None
    known = {f.name: f for f in fields(ValidationCriteria)}
    default = ValidationCriteria()
    values: dict[str, Any] = {}
    for name, value in data.items():
        if name not in known:
            raise ParameterError(f"{path}: unknown criterion {name!r}; known: {', '.join(known)}")
        current = getattr(default, name)
        if isinstance(current, tuple):
            if not isinstance(value, list) or not all(_is_number(v) for v in value):
                raise ParameterError(f"{path}: {name} = {value!r} must be a list of numbers")
            value = tuple(value)
        elif not _is_number(value) or (isinstance(current, int) and not float(value).is_integer()):
            raise ParameterError(f"{path}: {name} = {value!r} must be a {type(current).__name__}")
        values[name] = type(current)(value) if not isinstance(current, tuple) else value
    return replace(default, **values)


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


@dataclass
class Check:
    name: str
    passed: bool | None  # None: not run (e.g. no spread for Monte Carlo)
    criterion: str
    measured: str
    rows: list[dict[str, Any]] = field(default_factory=list)


@dataclass
class ValidationReport:
    controller: str
    checks: list[Check]
    region: SweepResult | None
    wall_s: float
    criteria: ValidationCriteria
    complete: bool = True  # False: interrupted (Ctrl-C); the checks done so far

    @property
    def passed(self) -> bool:
        return self.complete and all(c.passed is not False for c in self.checks)

    def to_json(self) -> dict[str, Any]:
        return {
            "controller": self.controller,
            "passed": self.passed,
            "complete": self.complete,
            "criteria": asdict(self.criteria),
            "checks": [asdict(c) for c in self.checks],
            "wall_s": round(self.wall_s, 1),
        }


def _runs_held(records: list[dict[str, Any] | None]) -> tuple[int, int]:
    done = [r for r in records if r]
    return sum(bool(r["held"]) for r in done), len(done)


def _sensitivity_cases(params: Parameters, c: ValidationCriteria) -> list[tuple[str, str, float]]:
    """(parameter, label, value) of each sensitivity case: the zeroing error in counts, latencies, free runs."""
    count = angle_count_step_rad(params)
    cases: list[tuple[str, str, float]] = [
        ("angle_sensor.zeroing_error_rad", f"{k:+d} counts", k * count)
        for k in range(-c.zeroing_counts, c.zeroing_counts + 1)
        if k
    ]
    cases += [("daq.output_latency_s", f"{1e3 * v:g} ms", v) for v in c.latencies_s]
    cases += [("start.free_run_s", f"{1e3 * v:g} ms", v) for v in c.free_runs_s]
    return cases


def validate(
    controller: str,
    params: Parameters,
    criteria: ValidationCriteria | None = None,
    *,
    spread: Distribution | None = None,
    seed: int = 0,
    workers: int = 1,
    progress: Progress | None = None,
) -> ValidationReport:
    c = criteria or ValidationCriteria()
    started = time.perf_counter()
    runs = Runs(controller, params, c.duration_s, True, "twin", False)
    checks: list[Check] = []
    starts = [*T.CHAPTER4_STARTS, *T.HARDWARE_STARTS.values()]
    cases = _sensitivity_cases(params, c)
    # One progress over the four stages' runs (the region's corner states join its count when it starts).
    stages = Stages(
        progress,
        {
            "nominal": len(starts) * c.nominal_seeds,
            "region": c.region_x0[2] * c.region_theta0[2],
            "sensitivity": len(cases) * len(T.CHAPTER4_STARTS),
            "monte carlo": c.montecarlo_runs if spread is not None else 0,
        },
    )

    # Nominal: the thesis's starts, several seeds.
    grid = np.array([s for s in starts for _ in range(c.nominal_seeds)], dtype=float)
    seeds = point_seeds(seed, len(grid))
    records, complete = run_starts(runs, grid, seeds, workers=workers, progress=stages.stage("nominal"))
    if not complete:
        return ValidationReport(controller, checks, None, time.perf_counter() - started, c, complete=False)
    held, n = _runs_held(records)
    checks.append(
        Check(
            "nominal",
            held == n,
            f"every run held from the thesis's {len(starts)} starts × {c.nominal_seeds} noise seeds",
            f"held {held} of {n}",
            [r for r in records if r],
        )
    )
    saturated = max((r["saturated_fraction"] for r in records if r), default=0.0)
    checks.append(
        Check(
            "saturation",
            saturated <= c.max_saturated_fraction,
            f"at most {100 * c.max_saturated_fraction:g} % of the ticks at the ±12 V rails in any nominal run",
            f"at most {100 * saturated:.1f} %",
        )
    )

    # Region of attraction.
    settings = SweepSettings(
        controller,
        x0=Grid(*c.region_x0),
        theta0=Grid(*c.region_theta0),
        duration_s=c.region_duration_s,
        noise=True,
        seed=seed,
    )
    region = run_sweep(settings, params, workers=workers, progress=stages.stage("region"))
    if not region.complete:
        return ValidationReport(controller, checks, None, time.perf_counter() - started, c, complete=False)
    (xlo, xhi), (tlo, thi) = c.required_x0_m, c.required_theta0_rad
    inside = [p for p in region.points if p and xlo <= p["x0_m"] <= xhi and tlo <= p["theta0_rad"] <= thi]
    lost_inside = [(p["x0_m"], p["theta0_rad"]) for p in inside if p["ball_lost"]]
    kept_all = sum(not p["ball_lost"] for p in region.points if p)
    checks.append(
        Check(
            "region",
            bool(inside) and not lost_inside,
            f"every grid start with x0 ∈ [{xlo:g}, {xhi:g}] m, θ0 ∈ [{tlo:g}, {thi:g}] rad keeps the ball",
            f"{len(inside) - len(lost_inside)} of {len(inside)} required starts keep it"
            + (
                f" (lost from {', '.join(f'({x:+.2f}, {t:+.2f})' for x, t in lost_inside[:5])})"
                if lost_inside
                else ""
            )
            + f"; {kept_all} of {len(region.points)} over the whole grid",
        )
    )

    # Sensitivity: one parameter at a time, from the chapter 4 starts, seed-matched.
    per_run: list[Parameters] = []
    labels = []
    for name, label, value in cases:
        try:
            p = params.with_overrides({name: value}, origin="validate")
        except ParameterError as exc:
            raise ParameterError(f"sensitivity {name} = {value!r}: {exc}") from None
        for start in T.CHAPTER4_STARTS:
            per_run.append(p)
            labels.append((name, label, start))
    grid = np.array([start for _, _, start in labels], dtype=float)
    records, complete = run_starts(
        runs,
        grid,
        point_seeds(seed + 1, len(grid)),
        params=per_run,
        workers=workers,
        progress=stages.stage("sensitivity"),
    )
    if not complete:
        return ValidationReport(controller, checks, region, time.perf_counter() - started, c, complete=False)
    by_param: dict[str, list[tuple[str, dict[str, Any]]]] = {}
    for (name, label, _), record in zip(labels, records, strict=True):
        if record:
            by_param.setdefault(name, []).append((label, record))
    for name, rows in by_param.items():
        bad = [
            f"{label} from ({r['x0_m']:+.2f}, {r['theta0_rad']:+.2f}): {r['reason']}"
            for label, r in rows
            if not r["held"]
        ]
        checks.append(
            Check(
                f"sensitivity: {name}",
                not bad,
                f"held at every value ({', '.join(dict.fromkeys(label for label, _ in rows))}) "
                "from the chapter 4 starts",
                "held at every value" if not bad else "; ".join(bad[:4]),
                [{"value": label, **r} for label, r in rows],
            )
        )

    # Monte Carlo.
    if spread is None:
        checks.append(
            Check(
                "monte carlo",
                None,
                f"95 % lower bound of the success rate ≥ {c.min_success_lower_bound:g}",
                "not run: give --spread FILE or --calibration DIR",
            )
        )
    else:
        mc = run_montecarlo(
            MonteCarloSettings(
                controller, c.montecarlo_runs, *T.CHAPTER4_STARTS[1], duration_s=c.duration_s, seed=seed
            ),
            params,
            spread,
            workers=workers,
            progress=stages.stage("monte carlo"),
        )
        if not mc.complete:
            return ValidationReport(
                controller, checks, region, time.perf_counter() - started, c, complete=False
            )
        s = mc.summary
        checks.append(
            Check(
                "monte carlo",
                s["success_ci"] is not None and s["success_ci"][0] >= c.min_success_lower_bound,
                f"95 % lower bound of the success rate ≥ {c.min_success_lower_bound:g} "
                f"({c.montecarlo_runs} runs, spread {spread.source})",
                f"held {s['held']} of {s['runs']}, 95 % interval {s['success_ci'][0]:.3f}–{s['success_ci'][1]:.3f}",
                s["worst"],
            )
        )
    return ValidationReport(controller, checks, region, time.perf_counter() - started, c)


def write_validation(report: ValidationReport, out_dir: str | Path, *, overwrite: bool = False) -> Path:
    """``report.md``, ``validation.json`` and ``region.png`` into ``out_dir``, atomically."""
    from twin.log import atomic_directory

    with atomic_directory(out_dir, overwrite=overwrite) as tmp:
        (tmp / "validation.json").write_text(json.dumps(report.to_json(), indent=1) + "\n")
        if report.region is not None:
            render_map(report.region, tmp / "region.png")
        (tmp / "report.md").write_text(render_markdown(report))
    return Path(out_dir)


def render_markdown(report: ValidationReport) -> str:
    mark = {True: "pass", False: "**FAIL**", None: "not run"}
    lines = [
        f"# Validation of `{report.controller}`",
        "",
        f"**Verdict: {'PASS' if report.passed else 'FAIL'}** ({report.wall_s:.0f} s of computing)"
        + ("" if report.complete else " — **interrupted**: only the checks below were run"),
        "",
        "| check | result | criterion | measured |",
        "| --- | --- | --- | --- |",
    ]
    for c in report.checks:
        lines.append(f"| {c.name} | {mark[c.passed]} | {c.criterion} | {c.measured} |")
    if report.region is not None:
        lines += ["", "![region of attraction](region.png)", ""]
    nominal = next((c for c in report.checks if c.name == "nominal"), None)
    if nominal is None:
        return "\n".join(lines) + "\n"
    lines += [
        "## Nominal runs",
        "",
        "| x0 (m) | θ0 (rad) | seed | held | settling (s) | steady x (mm) | cycle (mm p-p) | peak V | rails |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in nominal.rows:
        settle = "—" if r["settling_time_s"] is None else f"{r['settling_time_s']:.2f}"
        steady = "—" if r["steady_x_m"] is None else f"{1e3 * r['steady_x_m']:+.1f}"
        cycle = "—" if r["limit_cycle_x_pp_m"] is None else f"{1e3 * r['limit_cycle_x_pp_m']:.1f}"
        lines.append(
            f"| {r['x0_m']:+.2f} | {r['theta0_rad']:+.2f} | {r['seed']} | {'yes' if r['held'] else r['reason']} | "
            f"{settle} | {steady} | {cycle} | {r['peak_motor_voltage_v']:.1f} | {100 * r['saturated_fraction']:.0f} % |"
        )
    lines += ["", "Criteria (override with `--criteria FILE`):", ""]
    lines += [f"- `{k}` = {v}" for k, v in asdict(report.criteria).items()]
    return "\n".join(lines) + "\n"
