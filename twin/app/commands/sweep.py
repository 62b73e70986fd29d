"""``ballbeam sweep``: the region of attraction over a grid of starts, or a robust map over drawn rigs."""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from twin.app.commands.common import (
    JOB_RUN_S,
    SERVED_CONTROLLER,
    WORKERS,
    OutputOptions,
    ParamsOptions,
    ServedOptions,
    SpreadOptions,
    add_controller_timeout,
    add_engine_options,
    add_params_options,
    add_plant_options,
    add_served_options,
    add_spread_options,
    controller_help,
    options_from,
    progress_bar,
    resolve_band,
    resolve_engine,
    screen_summary,
)
from twin.app.commands.job import ManyRunJob
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
        help="initial ball positions (default -0.32:0.32:41, the chapter 7 range; on a rig whose track it "
        "leaves: its whole track in 41)",
    )
    parser.add_argument(
        "--theta0",
        type=GridType("--theta0", max_n=_sweep_max_points),
        metavar="LO:HI:N",
        help="initial beam angles (default -0.7:0.7:41, the chapter 7 range; on a rig whose travel it "
        "leaves: the beam's whole travel, its stops narrowed to its drive's reach, in 41)",
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


@dataclass(frozen=True)
class Options:
    """``sweep``'s options."""

    controller: str | None
    x0: str | None
    theta0: str | None
    duration: float
    seed: int
    no_noise: bool
    plant: str
    ideal_sensors: bool
    engine: str | None
    band: int | None
    refine: int
    audit: int | None
    locate: int
    rigs: int | None
    level: float | None
    workers: int
    scheduler: str | None
    controller_timeout: float | None
    parameters: ParamsOptions
    spread: SpreadOptions
    served: ServedOptions
    output: OutputOptions

    def job(self) -> ManyRunJob:
        return ManyRunJob.of("sweep", self, scheduler=self.scheduler, served=self.served)


def run(args: argparse.Namespace) -> int:
    return handle(options_from(Options, args))


def handle(o: Options) -> int:
    from twin.app.sweep import (
        MAX_POINTS,
        OUTPUT_FILES,
        SweepSettings,
        parse_range,
        rig_grids,
        run_sweep,
    )
    from twin.parameters import ParameterError

    job = o.job()
    job.check_served()
    if o.level is not None and o.rigs is None:
        raise ParameterError(
            f"--level {o.level:g}: the robust map's level, given with --rigs N (and --spread or --calibration)"
        )
    robust = o.rigs is not None or o.spread.spread is not None or o.spread.calibration is not None
    if robust:
        if o.rigs is None or (o.spread.spread is None and o.spread.calibration is None):
            raise ParameterError("a robust map needs --rigs N and one of --spread FILE or --calibration DIR")
        if job.is_served:
            raise ParameterError("a robust map runs here or on workers, not as served sessions")
    params, spread = job.params_and_spread() if robust else (job.params(), None)
    x0_default, theta0_default = rig_grids(params)  # the chapter 7 grid, or the rig's track and travel
    x0 = parse_range("--x0", o.x0) if o.x0 else x0_default
    theta0 = parse_range("--theta0", o.theta0) if o.theta0 else theta0_default
    engine = resolve_engine(
        o.engine, o.plant, "screen", plain=bool(o.refine), served=job.is_served, params=params
    )
    settings = SweepSettings(
        controller=job.name,
        x0=x0,
        theta0=theta0,
        duration_s=o.duration,
        noise=not o.no_noise,
        plant=o.plant,
        ideal_sensors=bool(o.ideal_sensors or backend(o.plant).ideal_converters),
        seed=o.seed,
        refine=o.refine,
        audit=o.audit or 0,
        locate=o.locate,
        engine=engine,
        band=resolve_band(o.band, engine, o.plant),
        screen_audit=32 if o.audit is None else o.audit,
    )
    if o.audit and not o.refine and not settings.policy.screened:
        raise ParameterError(
            "--audit checks a refined or a screened map: give --refine or --engine screen too"
        )
    if o.locate and robust:
        raise ParameterError("--locate finds one rig's boundary: not with a robust map (--rigs)")
    points = settings.x0.n * settings.theta0.n
    if points > MAX_POINTS:  # refused before the grid is built (its arrays alone may not fit in memory)
        raise ParameterError(
            f"--x0 {settings.x0.n} × --theta0 {settings.theta0.n} = {points} starts: at most {MAX_POINTS}"
        )
    if robust:
        return _robust_sweep(o, job, settings, params, spread)
    job.check(params, OUTPUT_FILES)
    with job.serving(params) as served:
        result = run_sweep(
            settings,
            params,
            workers=o.workers,
            scheduler=o.scheduler,
            progress=progress_bar("sweep"),
            serve=served,
        )
    if (client := job.client_name(served)) is not None:
        result.settings = settings = replace(settings, controller=client)
    from twin.app.sweep_render import write_sweep  # matplotlib: after the runs

    job.write(write_sweep, result)
    if o.output.json:
        print(json.dumps(result.to_json()))
    else:
        _print_sweep(o.output.out, settings, result)
    stopped = job.stopped(served, sum(map(bool, result.points)), len(result.points))
    if stopped is not None:
        return stopped
    if not result.complete:
        return _interrupted(job, "sweep.json", sum(map(bool, result.points)), len(result.points))
    if result.refinement is not None and (wrong := result.refinement["audit"]["mismatches"]):
        first = wrong[0]
        print(
            f"ballbeam sweep: the refinement's assumption fails: {len(wrong)} audited starts differ from their "
            f"inferred class (the first ({first['x0_m']:g}, {first['theta0_rad']:g}): inferred {first['inferred']}, "
            f"run {first['run']}); run with a smaller --refine step or without it",
            file=sys.stderr,
        )
        return 1
    if job.audit_failed(result.screening):
        return 1
    return job.failures(result.points)


def _print_sweep(out: str | None, settings: SweepSettings, result: SweepResult) -> None:
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
    if out is not None:
        print(f"wrote {Path(out) / 'sweep.json'} and {Path(out) / 'map.png'}")


def _robust_sweep(o: Options, job: ManyRunJob, settings: Any, params: Parameters, spread: Any) -> int:
    """``sweep --rigs N --spread|--calibration``: the nominal rig's map, then every start on N drawn rigs."""
    from twin.app.robust import DEFAULT_LEVEL, OUTPUT_FILES, run_robust
    from twin.app.sweep import run_sweep

    assert o.rigs is not None  # a robust map's (sweep checked it)
    job.check(params, OUTPUT_FILES)
    nominal = run_sweep(
        settings,
        params,
        workers=o.workers,
        scheduler=o.scheduler,
        progress=progress_bar("nominal map"),
    )
    result = run_robust(
        settings,
        params,
        spread,
        o.rigs,
        level=DEFAULT_LEVEL if o.level is None else o.level,
        nominal=nominal.points,
        workers=o.workers,
        scheduler=o.scheduler,
        progress=progress_bar("robust sweep"),
    )
    from twin.app.robust_render import write_robust  # matplotlib: after the runs

    job.write(write_robust, result)
    if o.output.json:
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
        if o.output.out is not None:
            print(f"wrote {Path(o.output.out) / 'robust.json'} and {Path(o.output.out) / 'robust.png'}")
    if not result.complete:
        run_on_every_rig = sum(p["rigs"] == result.rigs for p in result.points)
        return _interrupted(job, "robust.json", run_on_every_rig, len(result.points), " on every rig")
    for screened in (nominal.screening, result.screening):
        if job.audit_failed(screened):
            return 1
    return 0


def _interrupted(job: ManyRunJob, name: str, done: int, total: int, where: str = "") -> int:
    """An interrupted map (Ctrl-C, SIGTERM): what it kept, where, and 128 + the signal."""
    return job.interrupted(f" with {done} of {total} starts run{where}: the runs done are kept", name)
