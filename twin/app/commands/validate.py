"""``ballbeam validate``: the standard battery before hardware, one report."""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path

from twin.app.commands.common import (
    SERVED_CONTROLLER,
    WORKERS,
    OutputOptions,
    ParamsOptions,
    ServedOptions,
    SpreadOptions,
    add_controller_timeout,
    add_engine_options,
    add_params_options,
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
from twin.app.options import seed

HELP = (
    "the standard battery before hardware: nominal starts, region, sensitivities, saturation, "
    "Monte Carlo; one report, exit 0 pass / 1 fail"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--controller", metavar="NAME|MODULE:CLASS|avr:FILE.elf", help=controller_help() + SERVED_CONTROLLER
    )
    add_spread_options(parser, "for the robust-region and Monte Carlo checks")
    parser.add_argument(
        "--criteria",
        metavar="FILE",
        help="TOML overriding the pass criteria (see the report; the defaults are the rig's: docs/validate.md)",
    )
    parser.add_argument(
        "--spec",
        metavar="FILE",
        help="requirements in signal temporal logic (TOML; docs/examples/requirements.toml): the nominal, "
        "saturation, region and sensitivity checks ask them of their runs instead of the verdict's fields",
    )
    parser.add_argument("--seed", type=seed(), default=0, help="base seed of every run's noise")
    add_engine_options(parser, "screen", near="near a class change of the region check's map")
    add_params_options(parser)
    parser.add_argument(
        "--workers", type=WORKERS, default=1, help="local processes (default 1: this process)"
    )
    add_served_options(parser)
    parser.add_argument(
        "--out", metavar="DIR", help="write DIR/report.md, DIR/validation.json, DIR/region.png"
    )
    parser.add_argument("--overwrite", action="store_true", help="replace its own files in an existing --out")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    add_controller_timeout(parser)


# validate judges the twin itself: its runs are MuJoCo's (or the fast engine's, screened).
PLANT = "twin"


@dataclass(frozen=True)
class Options:
    """``validate``'s options."""

    controller: str | None
    criteria: str | None
    spec: str | None
    seed: int
    engine: str | None
    band: int | None
    workers: int
    controller_timeout: float | None
    parameters: ParamsOptions
    spread: SpreadOptions
    served: ServedOptions
    output: OutputOptions

    def job(self) -> ManyRunJob:
        return ManyRunJob.of("validate", self, served=self.served, criteria=self.criteria, spec=self.spec)


def run(args: argparse.Namespace) -> int:
    return handle(options_from(Options, args))


def handle(o: Options) -> int:
    from twin.app.validate import (
        OUTPUT_FILES,
        check_criteria_for,
        default_criteria,
        load_criteria,
        validate,
    )
    from twin.parameters import ParameterError

    job = o.job()
    job.check_served()
    params, spread = job.params_and_spread()
    # the rig's own defaults (the thesis's on the thesis's rig); a file overrides them field by field
    criteria = load_criteria(o.criteria, params) if o.criteria else default_criteria(params)
    spec = None
    if o.spec is not None:
        from twin.app.validate import SPEC_CHECKS
        from twin.requirements import check_timing, load_spec

        spec = load_spec(o.spec, SPEC_CHECKS)
        for asking in SPEC_CHECKS:  # each check's runs are as long as the criteria say
            duration = criteria.region_duration_s if asking == "region" else criteria.duration_s
            check_timing(spec.asked(asking), o.spec, params.period_s, duration)
    try:
        check_criteria_for(criteria, params)
    except ParameterError as exc:
        raise ParameterError(f"{o.criteria or 'the default criteria'}: {exc}") from None
    job.check(params, OUTPUT_FILES)
    settings_engine = resolve_engine(o.engine, PLANT, "screen", served=job.is_served, params=params)
    band = resolve_band(o.band, settings_engine, PLANT)
    with job.serving(params) as served:
        report = validate(
            job.name,
            params,
            criteria,
            spread=spread,
            seed=o.seed,
            workers=o.workers,
            progress=progress_bar("validate"),
            serve=served,
            spec=spec,
            engine=settings_engine,
            band=band,
        )
    if (client := job.client_name(served)) is not None:
        report.controller = client
    from twin.app.validate_render import write_validation  # matplotlib: after the runs

    job.write(write_validation, report)
    if o.output.json:
        print(json.dumps(report.to_json()))
    else:
        mark = {True: "pass", False: "FAIL", None: "not run"}
        for check in report.checks:
            shown = "stopped" if check.measured.startswith("interrupted") else mark[check.passed]
            shown = "n/a" if check.measured.startswith("not applicable") else shown
            print(f"{shown:<8} {check.name}: {check.measured}  [{check.criterion}]")
        print(f"{report.controller}: {'PASS' if report.passed else 'FAIL'} ({report.wall_s:.0f} s)")
        if o.output.out is not None:
            print(f"wrote {Path(o.output.out) / 'report.md'}")
    if served is not None and served.stopped:
        print(f"ballbeam validate: {served.stopped}: the checks done so far are reported", file=sys.stderr)
        return 1
    if not report.complete:
        done = ": the checks done and the runs of the stage interrupted are reported"
        return job.interrupted(done, "validation.json")
    screened = report.region.screening if report.region is not None else None
    if screened is not None:
        if not o.output.json:  # the JSON holds it (the region's "screening")
            print(f"region: {screen_summary(screened)}")
        if job.audit_failed(screened):
            return 1
    return 0 if report.passed else 1
