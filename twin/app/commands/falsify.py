"""``ballbeam falsify``: search for the run that violates a requirement (``twin.app.falsify``)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING

from twin.app.commands.common import (
    JOB_RUN_S,
    add_controller_timeout,
    add_engine_options,
    add_job_outputs,
    add_params_options,
    add_requirements_job,
    check_flick,
    check_job,
    check_start_box,
    interrupted,
    params_and_spread,
    progress_bar,
    resolve_engine,
    write_out,
)
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


def run(args: argparse.Namespace) -> int:
    from twin.app.falsify import OUTPUT_FILES, Axis, FalsifySettings, falsify
    from twin.parameters import ParameterError
    from twin.requirements import check_timing, load_spec

    args.serve = None  # a search runs here (check_job's served case does not apply)
    args.plant = "twin"
    if args.population is not None and args.population > args.budget:
        raise ParameterError(
            f"--population {args.population}: above --budget {args.budget}: not one generation would run whole"
        )
    base, spread = params_and_spread(args)
    spec = load_spec(args.spec)
    check_timing(spec.requirements, args.spec, base.daq.period_s, args.duration)
    x, th = args.x0, args.theta0
    check_start_box(base, x, th)
    axes = [Axis("x0_m", *x), Axis("theta0_rad", *th)]
    for option, span, name, grid in (
        ("--latency", args.latency, "daq.output_latency_s", base.physics.timestep_s),
        ("--zeroing", args.zeroing, "angle_sensor.zeroing_error_rad", 0.0),
    ):
        if span is not None:
            for v in span:
                try:
                    base.with_overrides({name: v}, origin=option)
                except ParameterError as exc:
                    raise ParameterError(f"{option} {span[0]:g}:{span[1]:g}: {exc}") from None
            axes.append(Axis(name, span[0], span[1], grid))
    axes += _scenario_axes(args, base)
    check_job(args, base, OUTPUT_FILES)
    settings = FalsifySettings(
        controller=args.controller,
        axes=tuple(axes),
        x0_m=x[0],
        theta0_rad=th[0],
        duration_s=args.duration,
        noise=not args.no_noise,
        budget=args.budget,
        seed=args.seed,
        population=args.population or 0,
        keep_going=args.keep_going,
        engine=resolve_engine(args, "screen"),
    )
    result = falsify(
        settings,
        base,
        spec,
        spread,
        workers=args.workers,
        scheduler=args.scheduler,
        progress=progress_bar("falsify"),
    )
    from twin.app.falsify_render import write_falsify  # matplotlib: after the runs

    write_out(args, write_falsify, result)
    out = result.to_json()
    if args.json:
        print(json.dumps(out, allow_nan=False))
    else:
        _print(out, args)
    if not result.complete:
        return interrupted("falsify", ": the runs done are reported")
    return 1 if out["found"] else 0


def _scenario_axes(args: argparse.Namespace, base: Parameters) -> list[Axis]:
    """--flick-time/--flick-speed and --setpoint as inputs of the search (checked: a flick after release, a
    setpoint on the track, for a controller that declares one)."""
    from twin.app.falsify import Axis
    from twin.app.hosts import build
    from twin.interface import Setpoint
    from twin.parameters import ParameterError
    from twin.physics import check_on_track

    axes = []
    check_flick(
        args.flick_time, args.flick_speed, args.duration
    )  # both, within the run and the Flick's range
    if args.flick_time is not None:
        if args.flick_time[0] < 0:
            raise ParameterError(f"--flick-time {args.flick_time[0]:g}: a time after release (≥ 0 s)")
        axes += [Axis("flick_time_s", *args.flick_time), Axis("flick_speed_m_s", *args.flick_speed)]
    if args.setpoint is not None:
        for v in args.setpoint:
            try:
                check_on_track(base, "--setpoint", v)
            except ValueError as exc:
                raise ParameterError(str(exc)) from None
        if not isinstance(build(args.controller, base), Setpoint):
            raise ParameterError(
                f"--setpoint: {args.controller} has no ball setpoint (twin.interface.Setpoint)"
            )
        axes.append(Axis("setpoint_m", *args.setpoint))
    return axes


def _print(out: dict, args: argparse.Namespace) -> None:
    best = out["least_robust"]
    if best is None:
        print("no run")
        return
    where = ", ".join(f"{k} = {v:.6g}" for k, v in best["searched"].items())
    margins = ", ".join(f"{k} {v:+.4g}" for k, v in best["robustness"].items())
    if out["found"]:
        print(
            f"counterexample at run {out['runs_to_first_violation']} ({out['runs_spent']} spent of "
            f"{args.budget}): {where}; seed {best['seed']}; robustness {margins}"
            + ("; the ball is lost" if best["ball_lost"] else "")
        )
    else:
        print(
            f"no violation in {out['runs_spent']} runs (budget {args.budget}); the least robust: {where}; "
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
    if args.out is not None:
        path = Path(args.out) / "falsify.json"
        from twin.app.replay import replay_command

        print(f"wrote {path}; repeat it: {replay_command(path, args.controller)}")
