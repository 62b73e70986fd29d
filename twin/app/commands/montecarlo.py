"""``ballbeam montecarlo``: one start over many perturbed rigs and noise seeds."""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass, replace
from pathlib import Path

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
    refuse_unused,
    resolve_engine,
    screen_summary,
)
from twin.app.commands.job import ManyRunJob
from twin.app.options import count, finite_float, seed
from twin.rigs.backends import backend

HELP = "robustness: one start over many perturbed rigs and noise seeds; success rate with its interval"


def _mc_max_runs() -> float:
    from twin.app.montecarlo import MAX_RUNS

    return MAX_RUNS


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--controller", metavar="NAME|MODULE:CLASS|avr:FILE.elf", help=controller_help() + SERVED_CONTROLLER
    )
    parser.add_argument("--n", type=count(1, _mc_max_runs), default=200, help="runs (default 200)")
    add_spread_options(parser, "for the perturbed rigs")
    parser.add_argument(
        "--x0", type=finite_float(), default=-0.2, metavar="M", help="initial ball position (default -0.2)"
    )
    parser.add_argument(
        "--theta0", type=finite_float(), default=0.3, metavar="RAD", help="initial beam angle (default 0.3)"
    )
    parser.add_argument(
        "--duration", type=JOB_RUN_S, default=15.0, metavar="S", help="seconds per run (default 15)"
    )
    parser.add_argument("--seed", type=seed(), default=0, help="seed of the samples and of every run's noise")
    parser.add_argument("--no-noise", action="store_true", help="switch the ball sensor's contact noise off")
    add_plant_options(parser)
    add_engine_options(
        parser, "mujoco", near="the fast engine did not hold or held within a margin of a band", grid=False
    )
    parser.add_argument(
        "--audit",
        type=count(0, 100_000),
        default=None,  # 32 with the fast engine; given with MuJoCo alone, refused
        metavar="N",
        help="with --engine screen or fast: N runs the fast engine decided alone run on MuJoCo too (default "
        "32); any that differs is reported, and fails a screened job",
    )
    add_params_options(parser)
    parser.add_argument(
        "--workers", type=WORKERS, default=1, help="local processes (default 1: this process)"
    )
    parser.add_argument(
        "--scheduler", metavar="ADDRESS", help="a Dask distributed scheduler to fan the runs out to"
    )
    add_served_options(parser)
    parser.add_argument("--out", metavar="DIR", help="write DIR/montecarlo.json and DIR/distributions.png")
    parser.add_argument("--overwrite", action="store_true", help="replace its own files in an existing --out")
    parser.add_argument("--json", action="store_true", help="print the whole result as JSON")
    add_controller_timeout(parser)


@dataclass(frozen=True)
class Options:
    """``montecarlo``'s options."""

    controller: str | None
    n: int
    x0: float
    theta0: float
    duration: float
    seed: int
    no_noise: bool
    plant: str
    ideal_sensors: bool
    engine: str | None
    audit: int | None
    workers: int
    scheduler: str | None
    controller_timeout: float | None
    parameters: ParamsOptions
    spread: SpreadOptions
    served: ServedOptions
    output: OutputOptions

    def job(self) -> ManyRunJob:
        return ManyRunJob.of("montecarlo", self, scheduler=self.scheduler, served=self.served)


def run(args: argparse.Namespace) -> int:
    return handle(options_from(Options, args))


def handle(o: Options) -> int:
    from twin.app.montecarlo import OUTPUT_FILES, MonteCarloSettings, run_montecarlo
    from twin.parameters import ParameterError
    from twin.physics import check_initial_state

    job = o.job()
    job.check_served()
    if (o.spread.spread is None) == (o.spread.calibration is None):
        raise ParameterError(
            "give one of --spread FILE or --calibration DIR (what to perturb, and by how much)"
        )
    base, spread = job.params_and_spread()
    assert spread is not None
    try:
        check_initial_state(base, o.x0, o.theta0, 0.0, 0.0)
    except ValueError as exc:
        raise ParameterError(f"--x0/--theta0: {exc}") from None
    job.check(base, OUTPUT_FILES)
    engine = resolve_engine(o.engine, o.plant, "mujoco", served=job.is_served, params=base)
    if engine == "mujoco":
        refuse_unused(
            [("--audit", o.audit)],
            "it re-runs the fast engine's runs on MuJoCo: with --engine screen or fast",
        )
    settings = MonteCarloSettings(
        controller=job.name,
        n=o.n,
        x0_m=o.x0,
        theta0_rad=o.theta0,
        duration_s=o.duration,
        noise=not o.no_noise,
        plant=o.plant,
        ideal_sensors=bool(o.ideal_sensors or backend(o.plant).ideal_converters),
        seed=o.seed,
        engine=engine,
        audit=32 if o.audit is None else o.audit,
    )
    with job.serving(base) as served:
        result = run_montecarlo(
            settings,
            base,
            spread,
            workers=o.workers,
            scheduler=o.scheduler,
            progress=progress_bar("montecarlo"),
            serve=served,
        )
    if (client := job.client_name(served)) is not None:
        result.settings = settings = replace(settings, controller=client)
    from twin.app.montecarlo_render import write_montecarlo  # matplotlib: after the runs

    job.write(write_montecarlo, result)
    if o.output.json:
        print(json.dumps(result.to_json()))
    else:
        s = result.summary
        ci = s["success_ci"]
        print(
            f"{settings.controller} from ({o.x0:g} m, {o.theta0:g} rad): held {s['held']} of {s['runs']}"
            + (
                f" ({100 * s['success_rate']:.1f} %, 95 % CI {100 * ci[0]:.1f}–{100 * ci[1]:.1f} %)"
                if ci
                else ""
            )
            + f", lost {s['lost']} ({result.wall_s:.1f} s)"
        )
        for name, dist in (("settling time (s)", s["settling_time_s"]), ("steady x (m)", s["steady_x_m"])):
            if dist:
                print(
                    f"  {name}: p5 {dist['p5']:g}, median {dist['p50']:g}, p95 {dist['p95']:g}, max {dist['max']:g}"
                )
        for run in s["worst"][:3]:
            if run["held"]:
                break
            changed = ", ".join(f"{k} = {v:.6g}" for k, v in run["parameters"].items())
            print(f"  worst: {run['reason']} (seed {run['seed']}): {changed}")
        if result.screening is not None:
            print(screen_summary(result.screening))
        if (out := o.output.out) is not None:
            print(f"wrote {Path(out) / 'montecarlo.json'} and {Path(out) / 'distributions.png'}")
    stopped = job.stopped(served, len(result.runs), settings.n)
    if stopped is not None:
        return stopped
    if not result.complete:
        done = f" after {len(result.runs)} of {settings.n} runs: the runs done are kept"
        return job.interrupted(done, "montecarlo.json")
    # The fast engine alone, asked for unconfirmed: its audit is reported, not failed.
    if job.audit_failed(result.screening) and settings.policy.screened:
        return 1
    return job.failures(result.runs)
