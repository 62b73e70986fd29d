"""``ballbeam validate``: a standard battery for a controller before it drives the rig, one report, one
verdict against stated criteria.

    nominal       the thesis's starts (chapter 4: x0 = ±0.2 m, θ0 = 0.3 rad; the chapter 6 experiments'
                  starts), several noise seeds: every run held
    region        a grid over the chapter 7 range: every start in the required box keeps the ball
    sensitivity   the counter's zeroing error (± a few encoder counts: the beam is zeroed by hand, Figure
                  7.20), the output latency (up to most of a period) and the start's free-run time (the
                  unknown 0–40 ms between release and the first command): every run held
    saturation    the share of nominal ticks at the amplifier's rails stays below a bound
    robust region (with --spread or --calibration) every required start of the region grid on N rigs drawn
                  from the spread (``twin.app.robust``: the same rigs for every start): the share of rigs
                  that keep the ball, its lower confidence bound at each start
    monte carlo   (with --spread or --calibration) the success rate's lower confidence bound

Every bound is a field of ``ValidationCriteria`` with its reason; ``--criteria FILE`` (TOML) overrides
them. On a rig that is not the thesis's the defaults are the rig's (``default_criteria``: its track, its
beam's travel, its board's period) and the battery runs what its parts have (``rig_battery``): a check they do
not have (a zeroing error, an output latency, amplifier rails, a spread of groups they use) is reported "not
applicable" with the reason, never passed. Every run goes through the batch engine (``twin.app.fanout``);
the numbers in the report are formatted from the runs' verdicts.
"""

from __future__ import annotations

import math
import time
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from controllers import thesis_numbers as T
from twin.app.fanout import Progress, Runs, Served, Stages, run_starts
from twin.app.hosts import host_of
from twin.app.montecarlo import MAX_RUNS, Distribution, MonteCarloSettings, run_montecarlo
from twin.app.options import MAX_JOB_RUN_S, MAX_RIGS
from twin.app.robust import run_robust
from twin.app.sweep import MAX_POINTS, Grid, SweepResult, SweepSettings, point_seeds, rig_box, run_sweep
from twin.outputs import JobFiles
from twin.parameters import ParameterError, Parameters, PartNames
from twin.physics import check_initial_state
from twin.requirements import Spec, violated
from twin.rigs.backends import stand_in_refusal
from twin.sensors import angle_count_step_rad

__all__ = [
    "RigBattery",
    "ValidationCriteria",
    "ValidationReport",
    "default_criteria",
    "load_criteria",
    "rig_battery",
    "validate",
]


# validate judges the twin itself (twin.rigs.backends: the plant whose stand-in screens the region).
PLANT = "twin"

# A validation runs 6 starts × nominal_seeds nominal runs; past 1000 seeds it is a typing error, not a study.
MAX_NOMINAL_SEEDS = 1000


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
    # Monte Carlo: the 95 % lower bound of the success rate (and, for the robust region, of the share of
    # rigs that keep the ball from each required start).
    montecarlo_runs: int = 100
    min_success_lower_bound: float = 0.9
    # The robust region's rigs: 40 keeping a start bound the share below by 0.912 (36 is the fewest that can
    # reach 0.9), so every one of them must keep every required start.
    robust_rigs: int = 40

    def __post_init__(self) -> None:
        """Refuse criteria without meaning (ParameterError naming the field and the value): a validation of
        no runs, negative counts, inverted or impossible bounds, a run too long to be kept."""

        def refuse(name: str, why: str) -> None:
            raise ParameterError(f"{name} = {_shown(getattr(self, name))}: {why}")

        if not 1 <= self.nominal_seeds <= MAX_NOMINAL_SEEDS:
            refuse(
                "nominal_seeds", f"1 … {MAX_NOMINAL_SEEDS} noise seeds per start (0 would validate no run)"
            )
        for name in ("duration_s", "region_duration_s"):
            if not 0 < getattr(self, name) <= MAX_JOB_RUN_S:
                refuse(name, f"a run lasts more than 0 and at most {MAX_JOB_RUN_S:g} s")
        for name in ("required_x0_m", "required_theta0_rad"):
            box = getattr(self, name)
            if len(box) != 2 or box[0] > box[1]:
                refuse(name, "[LO, HI] with LO ≤ HI")
        points = 1
        for name in ("region_x0", "region_theta0"):
            grid = getattr(self, name)
            if len(grid) != 3 or grid[0] > grid[1]:
                refuse(name, "[LO, HI, N]: a grid of N starts from LO to HI, LO ≤ HI")
            if not (float(grid[2]).is_integer() and 1 <= grid[2] <= MAX_POINTS):
                refuse(name, f"N (the third entry) is a whole number of starts, 1 … {MAX_POINTS}")
            object.__setattr__(self, name, (grid[0], grid[1], int(grid[2])))  # N = 17.0 from a file → 17
            points *= int(grid[2])
        if points > MAX_POINTS:
            refuse(
                "region_theta0", f"the region grid has {points} starts with region_x0; at most {MAX_POINTS}"
            )
        for name, region in (("required_x0_m", "region_x0"), ("required_theta0_rad", "region_theta0")):
            (lo, hi), (glo, ghi) = getattr(self, name), getattr(self, region)[:2]
            if lo < glo or hi > ghi:
                refuse(name, f"reaches outside {region} [{glo:g}, {ghi:g}]: those starts would never be run")
        if self.zeroing_counts < 0:
            refuse("zeroing_counts", "a number of encoder counts ≥ 0 (0: no zeroing error tried)")
        for name in ("latencies_s", "free_runs_s"):
            if any(v < 0 for v in getattr(self, name)):
                refuse(name, "times ≥ 0 s")
        if not 0 <= self.max_saturated_fraction <= 1:
            refuse("max_saturated_fraction", "a share of the ticks, 0 … 1")
        if not 1 <= self.montecarlo_runs <= MAX_RUNS:
            refuse("montecarlo_runs", f"1 … {MAX_RUNS} runs")
        if not 0 <= self.min_success_lower_bound <= 1:
            refuse("min_success_lower_bound", "a success rate, 0 … 1")
        if not 1 <= self.robust_rigs <= MAX_RIGS:
            refuse("robust_rigs", f"1 … {MAX_RIGS} rigs")
        for name, what in (("montecarlo_runs", "all runs held"), ("robust_rigs", "all rigs keeping a start")):
            best = best_success_lower_bound(getattr(self, name))
            if self.min_success_lower_bound > best:
                refuse(
                    "min_success_lower_bound",
                    f"unreachable: with {name} = {getattr(self, name)} even {what} give a 95 % lower bound "
                    f"of {best:.6g}",
                )


def success_lower_bound(successes: int, runs: int) -> float:
    """The 95 % lower bound of a success rate, as the Monte Carlo check computes and rounds it
    (twin.app.montecarlo: the low end of the exact binomial interval)."""
    import scipy.stats

    return round(float(scipy.stats.binomtest(successes, runs).proportion_ci(0.95, method="exact").low), 6)


def best_success_lower_bound(runs: int) -> float:
    """``success_lower_bound`` when all ``runs`` succeed."""
    return success_lower_bound(runs, runs)


def _shown(value: Any) -> str:
    text = repr(list(value) if isinstance(value, tuple) else value)
    return text if len(text) <= 60 else text[:57] + "..."


def check_criteria_for(criteria: ValidationCriteria, params: Parameters) -> None:
    """Refuse criteria that these parameters make impossible, before any run: a region or a required box
    off the track or past the stops, a sensitivity value the rig cannot take (ParameterError naming it)."""
    _check_boxes(criteria, params)
    _sensitivity_cases(criteria, params)


def _check_boxes(c: ValidationCriteria, params: Parameters) -> None:
    """Refuse a region or a required box off the track or past the beam's travel (ParameterError naming it)."""
    for name, (lo, hi) in (
        ("region_x0", c.region_x0[:2]),
        ("required_x0_m", c.required_x0_m),
        ("region_theta0", c.region_theta0[:2]),
        ("required_theta0_rad", c.required_theta0_rad),
    ):
        for v in (lo, hi):
            x, th = (v, 0.0) if "x0" in name else (0.0, v)
            try:
                check_initial_state(params, float(x), float(th), 0.0, 0.0)
            except ValueError as exc:
                raise ParameterError(f"{name} = {_shown(getattr(c, name))}: {exc}") from None


def _sensitivity_cases(
    c: ValidationCriteria, params: Parameters, firmware: bool = False
) -> list[tuple[str, str, Parameters]]:
    """Each sensitivity case: (parameter, label, the parameters with that value); a value the rig cannot
    take is refused naming the criterion (the largest zeroing error first: its count may be huge). For a
    ``firmware`` no output latency: its DAC writes at its own cycles. Only the cases the rig's parts have
    (``rig_battery``: a zeroing error where the angle sensor has one, a latency where the board has one)."""
    rig = rig_battery(params, c)
    values: list[tuple[str, str, str, float]] = []
    if c.zeroing_counts and rig.zeroing_field is not None:
        count, k, zeroing = angle_count_step_rad(params), c.zeroing_counts, rig.zeroing_field
        try:
            params.with_overrides({zeroing: k * count}, origin="validate")
        except ParameterError as exc:
            raise ParameterError(f"zeroing_counts = {k}: {exc}") from None
        values += [
            ("zeroing_counts", zeroing, f"{k:+d} counts", k * count)
            for k in range(-c.zeroing_counts, c.zeroing_counts + 1)
            if k
        ]
    # a firmware's output timing is its own (the card's latency does not apply)
    if not firmware and rig.latency_field is not None:
        values += [("latencies_s", rig.latency_field, f"{1e3 * v:g} ms", v) for v in c.latencies_s]
    values += [("free_runs_s", "start.free_run_s", f"{1e3 * v:g} ms", v) for v in c.free_runs_s]
    cases = []
    for criterion, name, label, value in values:
        try:
            p = params.with_overrides({name: value}, origin="validate")
        except ParameterError as exc:
            raise ParameterError(f"{criterion}: sensitivity {name} = {value!r}: {exc}") from None
        cases.append((name, label, p))
    return cases


# The groups every rig has whatever its parts (how a run starts, the physics, the software's conversion, an
# Arduino-class front end for a firmware): a spread may vary them on any rig.
_SHARED_GROUPS = ("physics", "software", "start", "mcu_io")


@dataclass(frozen=True)
class RigBattery:
    """What the battery runs on a rig and why: its nominal starts, the sensitivity and Monte Carlo starts, the
    sensitivity parameters its parts have, and each check that does not apply to it with the reason.
    ``thesis``: the rig is the thesis's (its report is the thesis's, with no section on the rig)."""

    thesis: bool
    starts: tuple[tuple[float, float], ...]
    starts_why: str
    sensitivity_starts: tuple[tuple[float, float], ...]
    sensitivity_why: str
    montecarlo_start: tuple[float, float]
    zeroing_field: str | None  # the angle sensor's zeroing error ("angle_sensor.zeroing_error_rad"), if any
    latency_field: str | None  # the board's output latency ("daq.output_latency_s"), if any
    rail_v: float | None  # the amplifier's rails, if the actuator has them
    not_applicable: dict[str, str]  # check (or criterion) → why it does not apply to this rig
    groups: tuple[str, ...]  # the parameter groups this rig's parts use (and the shared ones)


def _field_of(part_groups: Mapping[str, type], name: str) -> str | None:
    """``group.name`` if one of a part's groups has a field ``name``."""
    for group, cls in part_groups.items():
        if name in {f.name for f in fields(cls)}:
            return f"{group}.{name}"
    return None


def _thesis_boxes_fit(params: Parameters) -> bool:
    """Whether the thesis's region (the chapter 7 range) and required box lie on this rig's track and travel."""
    try:
        _check_boxes(ValidationCriteria(), params)
    except ParameterError:
        return False
    return True


def rig_battery(params: Parameters, c: ValidationCriteria | None = None) -> RigBattery:
    """What the battery runs on the rig ``params`` names, under criteria ``c`` (default ``default_criteria``).
    A rig on which the thesis's region fits runs the thesis's starts; another runs starts from its own
    required box: its four corners and its two level edges (as the thesis's chapter 4 starts are its box's
    corners), the sensitivities from its two corners at the upper angle, the Monte Carlo from the one at −x."""
    from twin.parts import rig_parts

    c = c or default_criteria(params)
    parts = rig_parts(params)
    zeroing = _field_of(parts.angle_sensor.groups, "zeroing_error_rad")
    latency = _field_of(parts.io_board.groups, "output_latency_s")
    rails = _field_of(parts.actuator.groups, "rail_v")
    groups = tuple(dict.fromkeys([g for part in parts for g in part.groups] + list(_SHARED_GROUPS)))
    na: dict[str, str] = {}
    if zeroing is None:
        na["zeroing_counts"] = (
            f"parts.angle_sensor = {params.parts.angle_sensor!r} has no zeroing error (its groups: "
            f"{', '.join(parts.angle_sensor.groups) or 'none'})"
        )
    if latency is None:
        na["latencies_s"] = (
            f"parts.io_board = {params.parts.io_board!r} has no output latency (its groups: "
            f"{', '.join(parts.io_board.groups)}): its output is written at its tick"
        )
    if rails is None:
        na["saturation"] = (
            f"parts.actuator = {params.parts.actuator!r} has no amplifier rails (its groups: "
            f"{', '.join(parts.actuator.groups)}): its command is bounded by the board's output range"
        )
    thesis = params.parts == PartNames()
    if _thesis_boxes_fit(params):
        hardware = tuple(T.HARDWARE_STARTS.values())
        return RigBattery(
            thesis,
            (*T.CHAPTER4_STARTS, *hardware),
            f"the thesis's {len(T.CHAPTER4_STARTS) + len(hardware)} starts",
            T.CHAPTER4_STARTS,
            "from the chapter 4 starts",
            T.CHAPTER4_STARTS[1],
            zeroing,
            latency,
            None if rails is None else params.amplifier.rail_v,
            na,
            groups,
        )
    (xlo, xhi), (tlo, thi) = c.required_x0_m, c.required_theta0_rad
    corners = ((xhi, thi), (xlo, thi), (xhi, tlo), (xlo, tlo))
    level = ((xhi, 0.0), (xlo, 0.0)) if tlo <= 0.0 <= thi else ()
    starts = tuple(dict.fromkeys(corners + level))
    return RigBattery(
        thesis,
        starts,
        f"the required box's {len(starts)} starts (its corners and its edges at level)",
        tuple(dict.fromkeys(corners[:2])),
        "from the required box's corners at its upper angle",
        (xlo, thi),
        zeroing,
        latency,
        None if rails is None else params.amplifier.rail_v,
        na,
        groups,
    )


def _whole_steps(value_s: float, params: Parameters) -> float:
    """A time rounded to whole physics steps (the rig's schedule takes no other), to the µs."""
    dt = params.physics.timestep_s
    return round(round(value_s / dt) * dt, 6)


def default_criteria(params: Parameters) -> ValidationCriteria:
    """The criteria a user of the rig ``params`` would expect (``criteria_reasons`` says why each): the
    thesis's on a rig its region fits (the thesis's rig: ``ValidationCriteria()`` exactly), else the region
    over the rig's whole track less the ball's radius by its beam's whole travel (``twin.app.sweep.rig_box``,
    a map's too), the middle half of each required. The latencies and free runs scale with the board's period
    (the thesis's at its 20 ms)."""
    period = params.period_s
    timed = replace(
        ValidationCriteria(),
        latencies_s=tuple(_whole_steps(f * period, params) for f in (0.0, 0.25, 0.5, 0.75)),
        free_runs_s=tuple(_whole_steps(f * period, params) for f in (0.0, 0.5, 1.0, 2.0)),
    )
    if _thesis_boxes_fit(params):
        return timed
    # to the µm and µrad, rounded inward (a bound past the track or the travel by its last digit is refused)
    (_, x_hi), travel = rig_box(params)
    half = math.floor(1e6 * x_hi) / 1e6
    low, high = (f(1e6 * v) / 1e6 for f, v in zip((math.ceil, math.floor), travel, strict=True))
    return replace(
        timed,
        required_x0_m=(-half / 2, half / 2),
        required_theta0_rad=(low / 2, high / 2),
        region_x0=(-half, half, 17),
        region_theta0=(low, high, 15),
    )


def criteria_reasons(params: Parameters) -> dict[str, str]:
    """Why each default of ``default_criteria(params)`` that the rig sets is what it is (as the thesis's
    defaults say in ``ValidationCriteria``'s comments)."""
    from twin.parts import rig_parts

    period = f"the board's period {1e3 * params.period_s:g} ms ({params.period_field})"
    why = {"free_runs_s": f"the unknown time from release to the first command: 0 to two of {period}"}
    if _field_of(rig_parts(params).io_board.groups, "output_latency_s") is not None:
        why["latencies_s"] = f"0 to three quarters of {period}, in whole physics steps"
    if _thesis_boxes_fit(params):
        return {"region_x0": "the thesis's chapter 7 range: it lies on this rig's track and travel", **why}
    half, r = params.track.half_length_m, params.ball.radius_m
    _, (low, high) = rig_box(params)
    return {
        "region_x0": f"the whole track less the ball's radius at 17 points: ±({half:g} − {r:g}) m "
        "(track.half_length_m, ball.radius_m; a map's too: twin.app.sweep.rig_box)",
        "region_theta0": f"the beam's whole travel at 15 points: {low:.4g} … {high:.4g} rad (its stops narrowed "
        f"to the reach of parts.beam_drive = {params.parts.beam_drive!r}, twin.physics.beam_travel_rad)",
        "required_x0_m": "the middle half of the region's track",
        "required_theta0_rad": "the middle half of the beam's travel each side of level",
        **why,
    }


def load_criteria(path: str | Path, params: Parameters | None = None) -> ValidationCriteria:
    """Criteria from a TOML file (any subset of ``ValidationCriteria``'s fields), checked for meaning; the
    fields it leaves out are the rig ``params``'s defaults (``default_criteria``; none: the thesis's)."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ParameterError(f"{path}: cannot read criteria: {exc}") from None
    known = {f.name: f for f in fields(ValidationCriteria)}
    default = ValidationCriteria() if params is None else default_criteria(params)
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
    try:
        return replace(default, **values)
    except ParameterError as exc:
        raise ParameterError(f"{path}: {exc}") from None


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
    served: dict[str, Any] | None = None  # a served job: where, and the clients (fanout.Served.to_json)
    spec: str | None = None  # the requirements file the checks asked (None: the verdict's fields)
    # a rig that is not the thesis's: its name, parts, starts, the defaults' reasons, the checks that do not
    # apply (None: the thesis's rig, whose report says nothing of it)
    rig: dict[str, Any] | None = None

    @property
    def passed(self) -> bool:
        return self.complete and all(c.passed is not False for c in self.checks)

    def to_json(self) -> dict[str, Any]:
        return {
            "controller": self.controller,
            **({"served": self.served} if self.served is not None else {}),
            "passed": self.passed,
            "complete": self.complete,
            **({"spec": self.spec} if self.spec is not None else {}),
            "criteria": asdict(self.criteria),
            "checks": [asdict(c) for c in self.checks],
            "wall_s": round(self.wall_s, 1),
            **({"rig": self.rig} if self.rig is not None else {}),
        }


def validate(
    controller: str,
    params: Parameters,
    criteria: ValidationCriteria | None = None,
    *,
    spread: Distribution | None = None,
    seed: int = 0,
    workers: int = 1,
    progress: Progress | None = None,
    serve: Served | None = None,
    spec: Spec | None = None,
    engine: str = "mujoco",
    band: int = 1,
) -> ValidationReport:
    """The battery; ``serve``: every run a session to a client over the wire (``fanout.run_served``), the
    stages one after the other on its one server (``controller`` then only names what the client runs).
    ``spec``: the nominal, saturation, region and sensitivity checks ask its requirements of their runs
    (``SPEC_CHECKS``; its ``[validate]`` table says which each asks) instead of the verdict's fields.
    ``engine``, ``band``: who decides the region check's starts (``twin.app.sweep.SweepSettings``); the other
    checks are MuJoCo's."""
    report = _validate(
        controller, params, criteria, spread, seed, workers, progress, serve, spec, (engine, band)
    )
    report.spec = spec.source if spec is not None else None
    report.served = serve.to_json() if serve is not None else None
    return report


def _validate(
    controller: str,
    params: Parameters,
    criteria: ValidationCriteria | None,
    spread: Distribution | None,
    seed: int,
    workers: int,
    progress: Progress | None,
    serve: Served | None,
    spec: Spec | None,
    engine: tuple[str, int],
) -> ValidationReport:
    c = criteria or default_criteria(params)
    check_criteria_for(c, params)  # before any run
    started = time.perf_counter()
    runs = Runs(
        controller, params, c.duration_s, True, "twin", False, spec.requirements if spec is not None else ()
    )
    rig = rig_battery(params, c)
    starts = list(rig.starts)
    cases = _sensitivity_cases(c, params, host_of(controller).kind == "firmware")
    engine_note = ""
    if (refusal := stand_in_refusal(PLANT, params)) is not None:
        # the fast engine cannot run this rig's parts (twin.screen.plant.kernel_refusal): MuJoCo decides alone
        engine, engine_note = ("mujoco", 1), f" (MuJoCo alone: the fast engine refuses this rig: {refusal})"
    spread_na = _spread_not_applicable(spread, rig)
    if spread_na is not None:
        spread = None
    x_required, theta_required = _required_grid(c)
    # One progress over the five stages' runs, counted up front (the region's corner states join its count
    # when it starts). A screened map runs every start on the fast engine and, at most, every start again on
    # MuJoCo: planned so, its count shrinks to what it ran when the next stage starts.
    per_start = 1 if engine[0] == "mujoco" else 2
    stages = Stages(
        progress,
        {
            "nominal": len(starts) * c.nominal_seeds,
            "region": c.region_x0[2] * c.region_theta0[2] * per_start,
            "sensitivity": len(cases) * len(rig.sensitivity_starts),
            "robust region": x_required.n * theta_required.n * c.robust_rigs * per_start
            if spread is not None
            else 0,
            "monte carlo": c.montecarlo_runs if spread is not None else 0,
        },
    )
    b = _Battery(
        controller, params, c, spread, seed, workers, serve, runs, stages, started, _Judge(c, spec), rig
    )
    b.engine_note, b.spread_na = engine_note, spread_na
    # The stages in order; the first one interrupted ends the battery with the checks done so far.
    if not _nominal_stage(b, starts):
        return b.report(None, complete=False)
    settings = SweepSettings(
        controller,
        x0=Grid(*c.region_x0),
        theta0=Grid(*c.region_theta0),
        duration_s=c.region_duration_s,
        noise=True,
        seed=seed,
        engine=engine[0],
        band=engine[1],
    )
    region = _region_stage(b, settings)
    if region is None:
        return b.report(None, complete=False)
    if not _sensitivity_stage(b, cases):
        return b.report(region, complete=False)
    if not _robust_region_stage(b, settings, x_required, theta_required):
        return b.report(region, complete=False)
    if not _montecarlo_stage(b):
        return b.report(region, complete=False)
    return b.report(region)


# The checks a requirements file's [validate] table may name (what each asks of which runs: README).
SPEC_CHECKS = ("nominal", "saturation", "region", "sensitivity")


@dataclass(frozen=True)
class _Judge:
    """What a check asks of a run's record: the verdict's fields, or (with a requirements file) that the
    run meets the requirements the check asks (each robustness ≥ 0; a failed run meets none)."""

    c: ValidationCriteria
    spec: Spec | None

    def meets(self, check: str, record: dict[str, Any]) -> bool:
        if self.spec is None:
            if check == "region":
                return not record["ball_lost"]
            if check == "saturation":
                return record.get("saturated_fraction") is None or (
                    record["saturated_fraction"] <= self.c.max_saturated_fraction
                )
            return bool(record["held"])
        margins = record.get("requirements")
        if margins is None:  # the controller failed: no signals to judge
            return False
        return not violated({r.name: margins[r.name] for r in self.spec.asked(check)})

    def asked(self, check: str) -> str:
        """What a check asks in words, with a requirements file ("" without one)."""
        if self.spec is None:
            return ""
        return "meets " + ", ".join(r.name for r in self.spec.asked(check))

    def why_not(self, check: str, record: dict[str, Any]) -> str:
        """Why a run does not meet what the check asks: the verdict's reason, or each requirement it violates
        with its robustness (a failed run: its reason)."""
        margins = record.get("requirements")
        if self.spec is None or margins is None:
            return str(record["reason"])
        asked = self.spec.asked(check)
        return ", ".join(f"{r.name} {margins[r.name]:+.4g}" for r in asked if not margins[r.name] >= 0)

    def worst(self, check: str, records: list[dict[str, Any]]) -> str:
        """With a requirements file: each requirement the check asks, its least robustness and where."""
        if self.spec is None:
            return ""
        parts = []
        judged = [r for r in records if r.get("requirements")]
        for req in self.spec.asked(check):
            if not judged:
                break
            r = min(judged, key=lambda r: r["requirements"][req.name])
            parts.append(
                f"{req.name} {r['requirements'][req.name]:+.4g} at ({r['x0_m']:+.2f}, {r['theta0_rad']:+.2f})"
            )
        return "; least robust: " + ", ".join(parts) if parts else ""


@dataclass
class _Battery:
    """What every stage of a validation shares, and the checks done so far (in the stages' order)."""

    controller: str
    params: Parameters
    c: ValidationCriteria
    spread: Distribution | None
    seed: int
    workers: int
    serve: Served | None
    runs: Runs
    stages: Stages
    started: float
    judge: _Judge
    rig: RigBattery
    checks: list[Check] = field(default_factory=list)
    engine_note: str = ""  # the region's engine when the one asked for cannot run the rig
    spread_na: str | None = None  # why the spread given does not apply to this rig

    def report(self, region: SweepResult | None, *, complete: bool = True) -> ValidationReport:
        wall_s = time.perf_counter() - self.started
        report = ValidationReport(self.controller, self.checks, region, wall_s, self.c, complete=complete)
        if not self.rig.thesis:
            report.rig = _rig_json(self.params, self.rig)
        return report

    def interrupted(
        self, stage: str, records: Sequence[dict[str, Any] | None], of: int, what: str = "runs"
    ) -> bool:
        """The stage interrupted (Ctrl-C, SIGTERM): a check not judged (``passed`` None) whose rows are what
        it finished (``of`` asked), so that the report keeps them. False: the battery ends."""
        done = [r for r in records if r]
        self.checks.append(
            Check(
                stage,
                None,
                "not judged: the validation was interrupted in this stage",
                f"interrupted after {len(done)} of {of} {what} (kept in the rows)",
                done,
            )
        )
        return False


def _nominal_stage(b: _Battery, starts: list[tuple[float, float]]) -> bool:
    """The thesis's starts, several seeds: the nominal and the saturation checks. False: interrupted."""
    c = b.c
    grid = np.array([s for s in starts for _ in range(c.nominal_seeds)], dtype=float)
    seeds = point_seeds(b.seed, len(grid))
    records, complete = run_starts(
        b.runs, grid, seeds, workers=b.workers, progress=b.stages.stage("nominal"), serve=b.serve
    )
    if not complete:
        return b.interrupted("nominal", records, len(records))
    done = [r for r in records if r]
    held = sum(b.judge.meets("nominal", r) for r in done)
    asked = b.judge.asked("nominal")
    b.checks.append(
        Check(
            "nominal",
            held == len(done),
            f"every run {asked or 'held'} from {b.rig.starts_why} × {c.nominal_seeds} noise seeds",
            f"{'met' if asked else 'held'} {held} of {len(done)}" + b.judge.worst("nominal", done),
            done,
        )
    )
    b.checks.append(_saturation_check(b, records, done))
    target = [r for r in records if r and r.get("firmware")]
    if target:
        b.checks.append(_target_check(target))
    return True


def _saturation_check(b: _Battery, records: list[dict[str, Any] | None], done: list[dict[str, Any]]) -> Check:
    """The share of the nominal runs' ticks at the amplifier's rails; not applicable to an actuator without."""
    c, rail = b.c, b.rig.rail_v
    asked = b.judge.asked("saturation")
    criterion = (
        f"every nominal run {asked}"
        if asked
        else f"at most {100 * c.max_saturated_fraction:g} % of the ticks at the "
        + ("amplifier's" if rail is None else f"±{rail:g} V")
        + " rails in any nominal run"
    )
    if rail is None:
        return Check("saturation", None, criterion, "not applicable: " + b.rig.not_applicable["saturation"])
    # A run whose controller failed has no figures (it already fails the nominal check).
    saturated = max((r["saturated_fraction"] for r in records if r and not r.get("failed")), default=0.0)
    return Check(
        "saturation",
        all(b.judge.meets("saturation", r) for r in done if not r.get("failed")),
        criterion,
        f"at most {100 * saturated:.1f} %" + b.judge.worst("saturation", done),
    )


def _target_check(records: list[dict[str, Any]]) -> Check:
    """A firmware's timing and stack over the nominal runs: no update past its period (a positive deadline
    margin), no period without an output, the stack's high-water mark below the room above the static data."""
    figures = [r["firmware"] for r in records]
    margin = min(f["deadline_margin_s"] for f in figures)
    missed = sum(f["missed_periods"] for f in figures)
    stack = max(f["stack_high_water_bytes"] for f in figures)
    room = min(f["stack_room_bytes"] for f in figures)
    cycles = max(f["update_cycles_max"] for f in figures)
    stack_ok = stack < room if math.isfinite(room) else True
    return Check(
        "target",
        margin > 0 and missed == 0 and stack_ok,
        "every update within its period (deadline margin > 0), no period missed, the stack's high-water mark "
        "below the room above the static data, in every nominal run",
        f"longest update {cycles:g} cycles (margin {1e3 * margin:.2f} ms), {missed} periods missed, stack "
        f"{stack} of {room:g} bytes",
        [
            {"x0_m": r["x0_m"], "theta0_rad": r["theta0_rad"], "seed": r["seed"], **r["firmware"]}
            for r in records
        ],
    )


def _region_stage(b: _Battery, settings: SweepSettings) -> SweepResult | None:
    """The region of attraction over the criteria's grid: the region check. None: interrupted."""
    region = run_sweep(
        settings,
        b.params,
        workers=b.workers,
        progress=b.stages.stage("region"),
        serve=b.serve,
        requirements=b.runs.requirements,
    )
    if not region.complete:
        b.interrupted("region", region.points, len(region.points), "starts")
        return None
    (xlo, xhi), (tlo, thi) = b.c.required_x0_m, b.c.required_theta0_rad
    inside = [p for p in region.points if p and xlo <= p["x0_m"] <= xhi and tlo <= p["theta0_rad"] <= thi]
    lost_inside = [(p["x0_m"], p["theta0_rad"]) for p in inside if not b.judge.meets("region", p)]
    kept_all = sum(not p["ball_lost"] for p in region.points if p)
    asked = b.judge.asked("region")
    b.checks.append(
        Check(
            "region",
            bool(inside) and not lost_inside,
            f"every grid start with x0 ∈ [{xlo:g}, {xhi:g}] m, θ0 ∈ [{tlo:g}, {thi:g}] rad "
            + (asked or "keeps the ball"),
            f"{len(inside) - len(lost_inside)} of {len(inside)} required starts {'meet them' if asked else 'keep it'}"
            + b.judge.worst("region", inside)
            + (
                f" (lost from {', '.join(f'({x:+.2f}, {t:+.2f})' for x, t in lost_inside[:5])})"
                if lost_inside
                else ""
            )
            + f"; {kept_all} of {len(region.points)} over the whole grid"
            + _decided_by(region)
            + b.engine_note,
        )
    )
    return region


def _decided_by(region: SweepResult) -> str:
    """Who decided the region's starts, when not MuJoCo alone."""
    if region.screening is not None:
        s = region.screening
        return f" (screened: MuJoCo decided {s['mujoco_runs']} of {len(region.points)}, the fast engine the rest)"
    if region.settings.policy.stand_alone:
        return " (the fast engine alone, not confirmed by MuJoCo)"
    return ""


def _sensitivity_stage(b: _Battery, cases: list[tuple[str, str, Parameters]]) -> bool:
    """One parameter at a time, from the chapter 4 starts, seed-matched: a check per parameter. False:
    interrupted."""
    per_run: list[Parameters] = []
    labels = []
    for name, label, p in cases:
        for start in b.rig.sensitivity_starts:
            per_run.append(p)
            labels.append((name, label, start))
    grid = np.array([start for _, _, start in labels], dtype=float)
    records, complete = run_starts(
        b.runs,
        grid,
        point_seeds(b.seed + 1, len(grid)),
        params=per_run,
        workers=b.workers,
        progress=b.stages.stage("sensitivity"),
        serve=b.serve,
    )
    if not complete:
        return b.interrupted("sensitivity", records, len(records))
    by_param: dict[str, list[tuple[str, dict[str, Any]]]] = {}
    for (name, label, _), record in zip(labels, records, strict=True):
        if record:
            by_param.setdefault(name, []).append((label, record))
    for name, rows in by_param.items():
        bad = [
            f"{label} from ({r['x0_m']:+.2f}, {r['theta0_rad']:+.2f}): " + b.judge.why_not("sensitivity", r)
            for label, r in rows
            if not b.judge.meets("sensitivity", r)
        ]
        b.checks.append(
            Check(
                f"sensitivity: {name}",
                not bad,
                f"held at every value ({', '.join(dict.fromkeys(label for label, _ in rows))}) "
                + b.rig.sensitivity_why,
                ("met at every value" if b.judge.spec else "held at every value")
                if not bad
                else "; ".join(bad[:4]),
                [{"value": label, **r} for label, r in rows],
            )
        )
    for criterion, what in (("zeroing_counts", "zeroing error"), ("latencies_s", "output latency")):
        if criterion in b.rig.not_applicable and getattr(b.c, criterion):
            b.checks.append(
                Check(
                    f"sensitivity: {what}",
                    None,
                    f"held at every {what} ({criterion}) {b.rig.sensitivity_why}",
                    "not applicable: " + b.rig.not_applicable[criterion],
                )
            )
    return True


def _robust_region_stage(
    b: _Battery, settings: SweepSettings, x_required: Grid, theta_required: Grid
) -> bool:
    """The required starts (the region's settings on the required grid) on rigs drawn from the spread: the
    robust region check, not run without a spread. False: interrupted."""
    c, spread = b.c, b.spread
    if spread is None:
        b.checks.append(
            Check(
                "robust region",
                None,
                f"every required start kept by a share of plausible rigs with a 95 % lower bound ≥ "
                f"{c.min_success_lower_bound:g}",
                _no_spread(b),
            )
        )
        return True
    robust = run_robust(
        replace(settings, x0=x_required, theta0=theta_required),
        b.params,
        spread,
        c.robust_rigs,
        workers=b.workers,
        progress=b.stages.stage("robust region"),
        serve=b.serve,
    )
    if not robust.complete:
        return b.interrupted(
            "robust region",
            [p for p in robust.points if p["rigs"]],
            len(robust.points),
            "starts run on any rig",
        )
    kept_rows = [
        {
            **point,
            "kept": point["rigs"] - point["lost"],
            "kept_lower_bound": success_lower_bound(point["rigs"] - point["lost"], point["rigs"]),
        }
        for point in robust.points
    ]
    worst = min(kept_rows, key=lambda r: (r["kept_lower_bound"], r["kept"]))
    short = [r for r in kept_rows if r["kept_lower_bound"] < c.min_success_lower_bound]
    b.checks.append(
        Check(
            "robust region",
            not short,
            f"every required start ({len(kept_rows)}) kept by a share of {c.robust_rigs} rigs from "
            f"{spread.source} with a 95 % lower bound ≥ {c.min_success_lower_bound:g}",
            f"{len(kept_rows) - len(short)} of {len(kept_rows)} starts; worst ({worst['x0_m']:+.2f}, "
            f"{worst['theta0_rad']:+.2f}): kept by {worst['kept']} of {worst['rigs']} rigs, held by "
            f"{worst['held']}, bound {worst['kept_lower_bound']:.3f}",
            sorted(kept_rows, key=lambda r: (r["kept_lower_bound"], r["kept"]))[:20],
        )
    )
    return True


def _montecarlo_stage(b: _Battery) -> bool:
    """The success rate on rigs drawn from the spread: the Monte Carlo check, not run without a spread.
    False: interrupted."""
    c, spread = b.c, b.spread
    if spread is None:
        b.checks.append(
            Check(
                "monte carlo",
                None,
                f"95 % lower bound of the success rate ≥ {c.min_success_lower_bound:g}",
                _no_spread(b),
            )
        )
        return True
    mc = run_montecarlo(
        MonteCarloSettings(
            b.controller, c.montecarlo_runs, *b.rig.montecarlo_start, duration_s=c.duration_s, seed=b.seed
        ),
        b.params,
        spread,
        workers=b.workers,
        progress=b.stages.stage("monte carlo"),
        serve=b.serve,
    )
    if not mc.complete:
        return b.interrupted("monte carlo", mc.runs, c.montecarlo_runs)
    s = mc.summary
    b.checks.append(
        Check(
            "monte carlo",
            s["success_ci"] is not None and s["success_ci"][0] >= c.min_success_lower_bound,
            f"95 % lower bound of the success rate ≥ {c.min_success_lower_bound:g} "
            f"({c.montecarlo_runs} runs, spread {spread.source})",
            f"held {s['held']} of {s['runs']}, 95 % interval {s['success_ci'][0]:.3f}–{s['success_ci'][1]:.3f}",
            s["worst"],
        )
    )
    return True


def _no_spread(b: _Battery) -> str:
    """Why a check on rigs drawn from a spread did not run: no spread given, or one this rig's parts do not use."""
    if b.spread_na is not None:
        return "not applicable: " + b.spread_na
    if b.rig.thesis:
        return "not run: give --spread FILE or --calibration DIR"
    # a spread draws any of the rig's groups (twin.app.montecarlo), the parts' own (servo, vl53l0x, …) too
    drawable = [g for g in b.rig.groups if g not in _SHARED_GROUPS]
    return (
        "not run: no spread given, and the parts have no spread of their own; give --calibration DIR, or "
        f"--spread FILE over this rig's {', '.join(drawable)}"
    )


def _spread_not_applicable(spread: Distribution | None, rig: RigBattery) -> str | None:
    """Why ``spread`` does not describe this rig: it varies parameters of groups that none of its parts use
    (a thesis spread on a servo rig would draw rigs that all run alike and pass for nothing). None: it does."""
    if spread is None:
        return None
    unused = [n for n in spread.names if n.partition(".")[0] not in rig.groups]
    if not unused:
        return None
    return (
        f"the spread ({spread.source}) varies {', '.join(unused[:6])}{' …' if len(unused) > 6 else ''}, "
        f"which no part of this rig uses (its groups: {', '.join(rig.groups)}); the parts have no spread of "
        "their own: give one of this rig's parameters (--spread FILE) or its calibration (--calibration DIR)"
    )


def _rig_json(params: Parameters, rig: RigBattery) -> dict[str, Any]:
    """The report's section on a rig that is not the thesis's: its parts, starts, the defaults' reasons and the
    checks that do not apply to it."""
    return {
        "parts": asdict(params.parts),
        "starts": [list(s) for s in rig.starts],
        "starts_why": rig.starts_why,
        "sensitivity_starts": [list(s) for s in rig.sensitivity_starts],
        "montecarlo_start": list(rig.montecarlo_start),
        "default_reasons": criteria_reasons(params),
        "not_applicable": dict(rig.not_applicable),
    }


def _required_grid(c: ValidationCriteria) -> tuple[Grid, Grid]:
    """The region grid's starts inside the required box, as grids of their own."""
    grids = []
    for (lo, hi), region in ((c.required_x0_m, c.region_x0), (c.required_theta0_rad, c.region_theta0)):
        inside = [float(v) for v in Grid(*region).values() if lo <= v <= hi]
        grids.append(Grid(inside[0], inside[-1], len(inside)) if inside else Grid(lo, lo, 1))
    return grids[0], grids[1]


# What write_validation (twin.app.validate_render) puts into its folder (checked before the battery runs).
OUTPUT_FILES = JobFiles("validate", ("validation.json", "region.png", "report.md"))
