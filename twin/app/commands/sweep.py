"""``ballbeam sweep``: the region of attraction over a grid of starts, or a robust map over drawn rigs."""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from twin.app.commands.common import (
    JOB_RUN_S,
    SERVED_CONTROLLER,
    WORKERS,
    add_controller_timeout,
    add_engine_options,
    add_params_options,
    add_plant_options,
    add_served_options,
    add_spread_options,
    check_job,
    check_served,
    client_name,
    controller_failures,
    controller_help,
    interrupted,
    job_name,
    load_params,
    params_and_spread,
    progress_bar,
    resolve_engine,
    screen_audit_failure,
    screen_summary,
    served_stopped,
    serving,
    write_out,
)
from twin.app.options import DEFAULT_REFINE_STEP, MAX_LOCATE, MAX_RIGS, GridType, count, finite_float, seed
from twin.rigs.backends import backend

if TYPE_CHECKING:
    from twin.app.sweep import SweepResult, SweepSettings
    from twin.parameters import Parameters


HELP = "region of attraction: a grid of initial states, a map (PNG) and the verdict of every start (JSON)"


def _sweep_max_points() -> float:
    from twin.app.sweep import MAX_POINTS

    return MAX_POINTS


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--controller", metavar="NAME|MODULE:CLASS|avr:FILE.elf", help=controller_help() + SERVED_CONTROLLER
    )
    parser.add_argument(
        "--x0",
        type=GridType("--x0", max_n=_sweep_max_points),
        metavar="LO:HI:N",
        help="initial ball positions (default -0.32:0.32:41, the chapter 7 range)",
    )
    parser.add_argument(
        "--theta0",
        type=GridType("--theta0", max_n=_sweep_max_points),
        metavar="LO:HI:N",
        help="initial beam angles (default -0.7:0.7:41, the chapter 7 range)",
    )
    parser.add_argument(
        "--duration", type=JOB_RUN_S, default=10.0, metavar="S", help="seconds per run (default 10)"
    )
    parser.add_argument(
        "--seed", type=seed(), default=0, help="base seed; each start's seed follows from it and its index"
    )
    parser.add_argument("--no-noise", action="store_true", help="switch the ball sensor's contact noise off")
    add_plant_options(parser)
    add_engine_options(parser, "screen")
    add_params_options(parser)
    parser.add_argument(
        "--workers", type=WORKERS, default=1, help="local processes (default 1: this process)"
    )
    parser.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="a Dask distributed scheduler, e.g. tcp://10.0.0.5:8786, to fan the grid out to "
        "(pip install 'ballbeam-twin[distributed]'); results equal the local run's",
    )
    parser.add_argument(
        "--refine",
        type=count(2, 1024),
        nargs="?",
        const=DEFAULT_REFINE_STEP,
        default=0,
        metavar="STEP",
        help=f"boundary refinement: run a coarse grid (every STEP-th start, default {DEFAULT_REFINE_STEP}), "
        "bisect its lines where their classes change, then follow each boundary start by start; the other "
        "starts take the class of the run starts around them (assumed: every boundary crosses a coarse line "
        "between coarse starts of different classes)",
    )
    parser.add_argument(
        "--audit",
        type=count(0, 100_000),
        default=None,
        metavar="N",
        help="with --refine: also run N inferred starts, at random, and report any that differ (default 0); "
        "with --engine screen: N starts per map decided by the fast engine alone run on MuJoCo too "
        "(default 32); any that differs fails the command",
    )
    parser.add_argument(
        "--locate",
        type=count(0, MAX_LOCATE),
        default=0,
        metavar="K",
        help="bisect every grid edge the boundary crosses K times (off-grid starts, seeded), locating each "
        "crossing to 1/2^K of a grid step: K more runs per crossed edge; in sweep.json's 'boundary' and on "
        "the map",
    )
    add_spread_options(parser, "for the robust map's rigs (with --rigs N)")
    parser.add_argument(
        "--rigs",
        type=count(1, MAX_RIGS),
        metavar="N",
        help="robust map: every start on N rigs drawn from --spread or --calibration (the same N everywhere); "
        "per start the rigs that hold it and an exact lower bound; writes DIR/robust.json and DIR/robust.png",
    )
    parser.add_argument(
        "--level",
        type=finite_float(0.0, 1.0),
        metavar="P",
        help="robust map (with --rigs N): the share of rigs a start must be held by, as a 95 %% lower bound "
        "(default 0.95)",
    )
    add_served_options(parser)
    parser.add_argument("--out", metavar="DIR", help="write DIR/sweep.json and DIR/map.png")
    parser.add_argument("--overwrite", action="store_true", help="replace its own files in an existing --out")
    parser.add_argument("--json", action="store_true", help="print the whole result as JSON")
    add_controller_timeout(parser)


def run(args: argparse.Namespace) -> int:
    from twin.app.sweep import (
        DEFAULT_THETA0,
        DEFAULT_X0,
        MAX_POINTS,
        OUTPUT_FILES,
        SweepSettings,
        parse_range,
        run_sweep,
    )
    from twin.parameters import ParameterError

    check_served(args)
    if args.level is not None and args.rigs is None:
        raise ParameterError(
            f"--level {args.level:g}: the robust map's level, given with --rigs N (and --spread or --calibration)"
        )
    robust = args.rigs is not None or args.spread is not None or args.calibration is not None
    if robust:
        if args.rigs is None or (args.spread is None and args.calibration is None):
            raise ParameterError("a robust map needs --rigs N and one of --spread FILE or --calibration DIR")
        if args.serve is not None:
            raise ParameterError("a robust map runs here or on workers, not as served sessions")
    params, spread = params_and_spread(args) if robust else (load_params(args), None)
    settings = SweepSettings(
        controller=job_name(args),
        x0=parse_range("--x0", args.x0) if args.x0 else DEFAULT_X0,
        theta0=parse_range("--theta0", args.theta0) if args.theta0 else DEFAULT_THETA0,
        duration_s=args.duration,
        noise=not args.no_noise,
        plant=args.plant,
        ideal_sensors=bool(args.ideal_sensors or backend(args.plant).ideal_converters),
        seed=args.seed,
        refine=args.refine,
        audit=args.audit or 0,
        locate=args.locate,
        engine=resolve_engine(args, "screen"),
        band=args.band,
        screen_audit=32 if args.audit is None else args.audit,
    )
    if args.audit and not args.refine and not settings.policy.screened:
        raise ParameterError(
            "--audit checks a refined or a screened map: give --refine or --engine screen too"
        )
    if args.locate and robust:
        raise ParameterError("--locate finds one rig's boundary: not with a robust map (--rigs)")
    points = settings.x0.n * settings.theta0.n
    if points > MAX_POINTS:  # refused before the grid is built (its arrays alone may not fit in memory)
        raise ParameterError(
            f"--x0 {settings.x0.n} × --theta0 {settings.theta0.n} = {points} starts: at most {MAX_POINTS}"
        )
    if robust:
        return _robust_sweep(args, settings, params, spread)
    check_job(args, params, OUTPUT_FILES)
    with serving(args, params) as served:
        result = run_sweep(
            settings,
            params,
            workers=args.workers,
            scheduler=args.scheduler,
            progress=progress_bar("sweep"),
            serve=served,
        )
    if (client := client_name(args, served)) is not None:
        result.settings = settings = replace(settings, controller=client)
    from twin.app.sweep_render import write_sweep  # matplotlib: after the runs

    write_out(args, write_sweep, result)
    if args.json:
        print(json.dumps(result.to_json()))
    else:
        _print_sweep(args, settings, result)
    stopped = served_stopped(served, "sweep", sum(map(bool, result.points)), len(result.points))
    if stopped is not None:
        return stopped
    if not result.complete:
        return _interrupted(args, "sweep.json", sum(map(bool, result.points)), len(result.points))
    if result.refinement is not None and (wrong := result.refinement["audit"]["mismatches"]):
        first = wrong[0]
        print(
            f"ballbeam sweep: the refinement's assumption fails: {len(wrong)} audited starts differ from their "
            f"inferred class (the first ({first['x0_m']:g}, {first['theta0_rad']:g}): inferred {first['inferred']}, "
            f"run {first['run']}); run with a smaller --refine step or without it",
            file=sys.stderr,
        )
        return 1
    if result.screening is not None and (wrong := result.screening["audit"]["mismatches"]):
        print(screen_audit_failure("sweep", wrong), file=sys.stderr)
        return 1
    return controller_failures(result.points, "sweep")


def _print_sweep(args: argparse.Namespace, settings: SweepSettings, result: SweepResult) -> None:
    """A map's summary in words: its classes, refinement, boundary and the region claims it judges."""
    report = result.to_json()
    summary = report["summary"]
    print(
        f"{settings.controller}: {summary['done']} of {summary['points']} starts: held {summary['held']}, "
        f"not held {summary['not_held']}, lost {summary['lost']} ({result.wall_s:.1f} s)"
    )
    if (ref := result.refinement) is not None:
        audit = ref["audit"]
        print(
            f"refined from a step of {ref['coarse_step']}: {ref['run']} starts run "
            f"({100 * ref['run_fraction']:.1f} %), {ref['inferred']} inferred"
            + (
                f"; audit: {audit['checked']} inferred starts run, {len(audit['mismatches'])} differ"
                if audit["checked"]
                else ""
            )
        )
    if (screen := result.screening) is not None:
        print(screen_summary(screen))
    if (boundary := result.boundary) is not None:
        print(
            f"boundary: {boundary['edges']} grid edges crossed, each located to 1/{2 ** boundary['bisections']} "
            f"of a grid step ({boundary['run']} more runs)"
        )
    for claim in result.claims:
        print(
            f"claim ({claim['source']}): {claim['statement']}: {claim['verdict']} "
            f"({claim['kept']} of {claim['grid_points_inside']} grid starts keep the ball)"
        )
    if args.out is not None:
        print(f"wrote {Path(args.out) / 'sweep.json'} and {Path(args.out) / 'map.png'}")


def _robust_sweep(args: argparse.Namespace, settings: Any, params: Parameters, spread: Any) -> int:
    """``sweep --rigs N --spread|--calibration``: the nominal rig's map, then every start on N drawn rigs."""
    from twin.app.robust import DEFAULT_LEVEL, OUTPUT_FILES, run_robust
    from twin.app.sweep import run_sweep

    check_job(args, params, OUTPUT_FILES)
    nominal = run_sweep(
        settings,
        params,
        workers=args.workers,
        scheduler=args.scheduler,
        progress=progress_bar("nominal map"),
    )
    result = run_robust(
        settings,
        params,
        spread,
        args.rigs,
        level=DEFAULT_LEVEL if args.level is None else args.level,
        nominal=nominal.points,
        workers=args.workers,
        scheduler=args.scheduler,
        progress=progress_bar("robust sweep"),
    )
    from twin.app.robust_render import write_robust  # matplotlib: after the runs

    write_out(args, write_robust, result)
    if args.json:
        print(json.dumps(result.to_json()))
    else:
        m = result.summary
        print(
            f"{settings.controller}: {m['starts']} starts on {result.rigs} rigs ({result.runs} runs, "
            f"{result.wall_s:.1f} s): kept by every rig {m['kept_by_every_rig']}, held by every rig "
            f"{m['held_by_every_rig']}, lower bound ≥ {result.level:g}: "
            f"{m['robust']} (the best bound {result.rigs} rigs give: {m['best_possible_lower_bound']:.3f}); the "
            f"nominal rig holds {m['nominal_held']}"
        )
        if result.screening is not None:
            print(screen_summary(result.screening))
        if args.out is not None:
            print(f"wrote {Path(args.out) / 'robust.json'} and {Path(args.out) / 'robust.png'}")
    if not result.complete:
        run_on_every_rig = sum(p["rigs"] == result.rigs for p in result.points)
        return _interrupted(args, "robust.json", run_on_every_rig, len(result.points), " on every rig")
    for screened in (nominal.screening, result.screening):
        if screened is not None and (wrong := screened["audit"]["mismatches"]):
            print(screen_audit_failure("sweep", wrong), file=sys.stderr)
            return 1
    return 0


def _interrupted(args: argparse.Namespace, name: str, done: int, total: int, where: str = "") -> int:
    """An interrupted map (Ctrl-C, SIGTERM): what it kept, where, and 128 + the signal."""
    kept = f" with {done} of {total} starts run{where}: the runs done are kept"
    return interrupted("sweep", kept, args.out, name)
