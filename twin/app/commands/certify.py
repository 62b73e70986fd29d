"""``ballbeam certify``: every requirement holds with probability ≥ P at confidence C over rigs drawn from a
spread or calibration, or the run that violates one (``twin.app.certify``)."""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from twin.app.commands.common import (
    JOB_RUN_S,
    OutputOptions,
    ParamsOptions,
    SpreadOptions,
    add_controller_timeout,
    add_job_outputs,
    add_params_options,
    add_requirements_job,
    check_start_box,
    interrupted,
    options_from,
    progress_bar,
)
from twin.app.commands.job import ManyRunJob
from twin.app.options import SpanType, count, finite_float, seed

HELP = (
    "a guarantee: every requirement holds with probability ≥ P at confidence C over rigs from a spread or "
    "calibration and starts from a box (exact binomial bound), or the run that violates one; exit 0 pass"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_requirements_job(parser, "each must hold", "the rigs drawn (one of them is required)")
    parser.add_argument(
        "--x0",
        type=SpanType("--x0"),
        default=(-0.2, 0.2),
        metavar="A:B",
        help="the starts' ball positions (m), drawn uniformly (default -0.2:0.2)",
    )
    parser.add_argument(
        "--theta0",
        type=SpanType("--theta0"),
        default=(-0.3, 0.3),
        metavar="A:B",
        help="the starts' beam angles (rad), drawn uniformly (default -0.3:0.3)",
    )
    parser.add_argument(
        "--guarantee",
        type=finite_float(0, 1, lo_open=True),
        default=0.99,
        metavar="P",
        help="the probability stated (default 0.99)",
    )
    parser.add_argument(
        "--confidence",
        type=finite_float(0, 1, lo_open=True),
        default=0.99,
        metavar="C",
        help="its confidence (default 0.99: 459 runs without a violation for P = 0.99)",
    )
    parser.add_argument(
        "--duration", type=JOB_RUN_S, default=15.0, metavar="S", help="seconds per run (default 15)"
    )
    parser.add_argument("--no-noise", action="store_true", help="switch the ball sensor's contact noise off")
    parser.add_argument("--seed", type=seed(), default=0, help="seed of the rigs, starts and noise drawn")
    parser.add_argument(
        "--batch",
        type=count(1, 100_000),
        default=64,
        metavar="N",
        help="runs per batch (a violation ends the job after its batch; default 64)",
    )
    add_params_options(parser)
    add_job_outputs(parser, "DIR/certify.json")
    add_controller_timeout(parser)


@dataclass(frozen=True)
class Options:
    """``certify``'s options (a statement is made here: no client is served)."""

    controller: str
    spec: str
    x0: tuple[float, float]
    theta0: tuple[float, float]
    guarantee: float
    confidence: float
    duration: float
    no_noise: bool
    seed: int
    batch: int
    workers: int
    scheduler: str | None
    controller_timeout: float | None
    parameters: ParamsOptions
    spread: SpreadOptions
    output: OutputOptions

    def job(self) -> ManyRunJob:
        return ManyRunJob.of("certify", self, scheduler=self.scheduler, spec=self.spec)


def run(args: argparse.Namespace) -> int:
    return handle(options_from(Options, args))


def handle(o: Options) -> int:
    from twin.app.certify import OUTPUT_FILES, CertifySettings, certify, runs_needed
    from twin.parameters import ParameterError
    from twin.requirements import check_timing, load_spec

    job = o.job()
    if (o.spread.spread is None) == (o.spread.calibration is None):
        raise ParameterError(
            "give one of --spread FILE or --calibration DIR (the rigs the statement is over)"
        )
    base, spread = job.params_and_spread()
    assert spread is not None
    spec = load_spec(o.spec)
    check_timing(spec.requirements, o.spec, base.period_s, o.duration)
    x, th = o.x0, o.theta0
    check_start_box(base, x, th)
    runs_needed(o.guarantee, o.confidence)  # refused here if it cannot be stated
    job.check(base, OUTPUT_FILES)
    settings = CertifySettings(
        o.controller,
        x,
        th,
        o.guarantee,
        o.confidence,
        o.duration,
        not o.no_noise,
        o.seed,
        o.batch,
    )
    result = certify(
        settings,
        base,
        spec,
        spread,
        workers=o.workers,
        scheduler=o.scheduler,
        progress=progress_bar("certify"),
    )
    job.write(_write, result)
    out = result.to_json()
    if o.output.json:
        print(json.dumps(out))
    else:
        print(out["statement"])
        for name, r in out["requirements"].items():
            sd = f", noise sd {r['noise_sd']:.3g}" if "noise_reruns" in r else ""
            print(f"  {name}: {r['status']}, least robustness {r['least_robustness']:+.4g}{sd}")
        if result.counterexample is not None and o.output.out is not None:
            from twin.app.replay import replay_command

            print(f"repeat it: {replay_command(Path(o.output.out) / 'certify.json', o.controller)}")
    if result.outcome == "interrupted":
        return interrupted("certify", ": no statement")
    return 0 if result.outcome == "pass" else 1


def _write(result: Any, out_dir: str, *, overwrite: bool = False) -> None:
    from twin.app.certify import OUTPUT_FILES
    from twin.outputs import atomic_directory

    with atomic_directory(out_dir, OUTPUT_FILES, overwrite=overwrite) as tmp:
        (tmp / "certify.json").write_text(json.dumps(result.to_json(), indent=1) + "\n")
