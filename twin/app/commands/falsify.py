"""``ballbeam falsify``: search for the run that violates a requirement (``twin.app.falsify``)."""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from twin.app.commands.common import (
    JOB_RUN_S,
    OutputOptions,
    ParamsOptions,
    SpreadOptions,
    add_controller_timeout,
    add_engine_options,
    add_job_outputs,
    add_params_options,
    add_requirements_job,
    check_flick,
    check_start_box,
    options_from,
    progress_bar,
    resolve_engine,
)
from twin.app.commands.job import ManyRunJob
from twin.app.options import SpanType, count, seed
from twin.rigs.backends import engine_policy

if TYPE_CHECKING:
    from twin.app.falsify import Axis
    from twin.parameters import Parameters

HELP = (
    "search starts, rigs, latency and zeroing for a run that violates a requirement; the counterexample "
    "(or the least robust run) in falsify.json, repeatable with run --replay; exit 1 when one is found"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_requirements_job(
        parser, "the search minimises their least robustness", "searched over (a normal within ±3 sd)"
    )
    parser.add_argument(
        "--x0",
        type=SpanType("--x0"),
        default="-0.2",
        metavar="A:B|M",
        help="initial ball position (m): a range or a value",
    )
    parser.add_argument(
        "--theta0",
        type=SpanType("--theta0"),
        default="0.3",
        metavar="A:B|RAD",
        help="initial beam angle (rad): a range or a value",
    )
    parser.add_argument(
        "--latency",
        type=SpanType("--latency"),
        metavar="A:B",
        help="output latency (s; daq.output_latency_s, whole physics steps, below a period): a range or a value",
    )
    parser.add_argument(
        "--zeroing",
        type=SpanType("--zeroing"),
        metavar="A:B",
        help="the counter's zeroing error (rad; angle_sensor.zeroing_error_rad)",
    )
    parser.add_argument(
        "--flick-time",
        type=SpanType("--flick-time"),
        metavar="A:B",
        help="flick the ball this long after release (s; with --flick-speed): a range or a value",
    )
    parser.add_argument(
        "--flick-speed",
        type=SpanType("--flick-speed"),
        metavar="A:B",
        help="the flick's kick (m/s along the beam)",
    )
    parser.add_argument(
        "--setpoint",
        type=SpanType("--setpoint"),
        metavar="A:B",
        help="the ball setpoint (m; a controller that has one): a range or a value",
    )
    parser.add_argument(
        "--duration", type=JOB_RUN_S, default=10.0, metavar="S", help="seconds per run (default 10)"
    )
    parser.add_argument("--no-noise", action="store_true", help="switch the ball sensor's contact noise off")
    parser.add_argument(
        "--budget", type=count(1, _max_budget), default=300, metavar="N", help="runs at most (default 300)"
    )
    parser.add_argument(
        "--population",
        type=count(2, 1000),
        metavar="N",
        help="runs per CMA-ES generation, one batch of the engine each (default: a tenth of the budget, at least "
        "4 + 3 ln d)",
    )
    parser.add_argument(
        "--keep-going",
        action="store_true",
        help="spend the whole budget on the least robust point instead of stopping at the first violation",
    )
    parser.add_argument(
        "--seed", type=seed(), default=0, help="the search's seed (its points and noise seeds)"
    )
    add_engine_options(
        parser, "screen", near="the fast engine found violating and each batch's least robust run", grid=False
    )
    add_params_options(parser)
    add_job_outputs(parser, "DIR/falsify.json and DIR/falsify.png")
    add_controller_timeout(parser)


def _max_budget() -> float:
    from twin.app.falsify import MAX_BUDGET

    return MAX_BUDGET


# The search runs the twin itself (MuJoCo, or the fast engine screened), here: no client is served.
PLANT = "twin"

Span = tuple[float, float]


@dataclass(frozen=True)
class Options:
    """``falsify``'s options."""

    controller: str
    spec: str
    x0: Span
    theta0: Span
    latency: Span | None
    zeroing: Span | None
    flick_time: Span | None
    flick_speed: Span | None
    setpoint: Span | None
    duration: float
    no_noise: bool
    budget: int
    population: int | None
    keep_going: bool
    seed: int
    engine: str | None
    workers: int
    scheduler: str | None
    controller_timeout: float | None
    parameters: ParamsOptions
    spread: SpreadOptions
    output: OutputOptions

    def job(self) -> ManyRunJob:
        return ManyRunJob.of("falsify", self, scheduler=self.scheduler, spec=self.spec)


def run(args: argparse.Namespace) -> int:
    return handle(options_from(Options, args))


def handle(o: Options) -> int:
    from twin.app.falsify import OUTPUT_FILES, Axis, FalsifySettings, falsify
    from twin.parameters import ParameterError
    from twin.requirements import check_timing, load_spec

    job = o.job()
    if o.population is not None and o.population > o.budget:
        raise ParameterError(
            f"--population {o.population}: above --budget {o.budget}: not one generation would run whole"
        )
    base, spread = job.params_and_spread()
    spec = load_spec(o.spec)
    check_timing(spec.requirements, o.spec, base.period_s, o.duration)
    x, th = o.x0, o.theta0
    check_start_box(base, x, th)
    axes = [Axis("x0_m", *x), Axis("theta0_rad", *th)]
    for option, span, name, grid in (
        ("--latency", o.latency, "daq.output_latency_s", base.physics.timestep_s),
        ("--zeroing", o.zeroing, "angle_sensor.zeroing_error_rad", 0.0),
    ):
        if span is not None:
            for v in span:
                try:
                    base.with_overrides({name: v}, origin=option)
                except ParameterError as exc:
                    raise ParameterError(f"{option} {span[0]:g}:{span[1]:g}: {exc}") from None
            axes.append(Axis(name, span[0], span[1], grid))
    axes += _scenario_axes(o, base)
    job.check(base, OUTPUT_FILES)
    settings = FalsifySettings(
        controller=o.controller,
        axes=tuple(axes),
        x0_m=x[0],
        theta0_rad=th[0],
        duration_s=o.duration,
        noise=not o.no_noise,
        budget=o.budget,
        seed=o.seed,
        population=o.population or 0,
        keep_going=o.keep_going,
        engine=resolve_engine(o.engine, PLANT, "screen", params=base),
    )
    result = falsify(
        settings,
        base,
        spec,
        spread,
        workers=o.workers,
        scheduler=o.scheduler,
        progress=progress_bar("falsify"),
    )
    from twin.app.falsify_render import write_falsify  # matplotlib: after the runs

    job.write(write_falsify, result)
    out = result.to_json()
    if o.output.json:
        print(json.dumps(out, allow_nan=False))
    else:
        _print(out, o)
    if not result.complete:
        return job.interrupted(": the runs done are reported")
    return 1 if out["found"] else 0


def _scenario_axes(o: Options, base: Parameters) -> list[Axis]:
    """--flick-time/--flick-speed and --setpoint as inputs of the search (checked: a flick after release, a
    setpoint on the track, for a controller that declares one)."""
    from twin.app.falsify import Axis
    from twin.app.hosts import build
    from twin.interface import Setpoint
    from twin.parameters import ParameterError
    from twin.physics import check_on_track

    axes = []
    check_flick(o.flick_time, o.flick_speed, o.duration)  # both, within the run and the Flick's range
    if o.flick_time is not None:
        if o.flick_time[0] < 0:
            raise ParameterError(f"--flick-time {o.flick_time[0]:g}: a time after release (≥ 0 s)")
        assert o.flick_speed is not None  # check_flick: both or neither
        axes += [Axis("flick_time_s", *o.flick_time), Axis("flick_speed_m_s", *o.flick_speed)]
    if o.setpoint is not None:
        for v in o.setpoint:
            try:
                check_on_track(base, "--setpoint", v)
            except ValueError as exc:
                raise ParameterError(str(exc)) from None
        if not isinstance(build(o.controller, base), Setpoint):
            raise ParameterError(f"--setpoint: {o.controller} has no ball setpoint (twin.interface.Setpoint)")
        axes.append(Axis("setpoint_m", *o.setpoint))
    return axes


def _print(out: dict, o: Options) -> None:
    best = out["least_robust"]
    if best is None:
        print("no run")
        return
    where = ", ".join(f"{k} = {v:.6g}" for k, v in best["searched"].items())
    margins = ", ".join(f"{k} {v:+.4g}" for k, v in best["robustness"].items())
    if out["found"]:
        print(
            f"counterexample at run {out['runs_to_first_violation']} ({out['runs_spent']} spent of "
            f"{o.budget}): {where}; seed {best['seed']}; robustness {margins}"
            + ("; the ball is lost" if best["ball_lost"] else "")
        )
    else:
        print(
            f"no violation in {out['runs_spent']} runs (budget {o.budget}); the least robust: {where}; "
            f"robustness {margins}"
        )
    decided = out["decided_by"]
    if decided["fast"]:
        print(
            f"engines: the fast engine decided {decided['fast']} runs, MuJoCo {decided['mujoco']}"
            + (
                " (every violation and each batch's least robust run)"
                if engine_policy(out["settings"]["engine"]).screened
                else ""
            )
        )
    if o.output.out is not None:
        path = Path(o.output.out) / "falsify.json"
        from twin.app.replay import replay_command

        print(f"wrote {path}; repeat it: {replay_command(path, o.controller)}")
