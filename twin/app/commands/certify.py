"""``ballbeam certify``: every requirement holds with probability ≥ P at confidence C over rigs drawn from a
spread or calibration, or the run that violates one (``twin.app.certify``)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from twin.app.commands.common import (
    JOB_RUN_S,
    add_controller_timeout,
    add_job_outputs,
    add_params_options,
    add_requirements_job,
    check_job,
    check_start_box,
    interrupted,
    params_and_spread,
    progress_bar,
    write_out,
)
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


def run(args: argparse.Namespace) -> int:
    from twin.app.certify import OUTPUT_FILES, CertifySettings, certify, runs_needed
    from twin.parameters import ParameterError
    from twin.requirements import check_timing, load_spec

    args.serve = None
    if (args.spread is None) == (args.calibration is None):
        raise ParameterError(
            "give one of --spread FILE or --calibration DIR (the rigs the statement is over)"
        )
    base, spread = params_and_spread(args)
    assert spread is not None
    spec = load_spec(args.spec)
    check_timing(spec.requirements, args.spec, base.daq.period_s, args.duration)
    x, th = args.x0, args.theta0
    check_start_box(base, x, th)
    runs_needed(args.guarantee, args.confidence)  # refused here if it cannot be stated
    check_job(args, base, OUTPUT_FILES)
    settings = CertifySettings(
        args.controller,
        x,
        th,
        args.guarantee,
        args.confidence,
        args.duration,
        not args.no_noise,
        args.seed,
        args.batch,
    )
    result = certify(
        settings,
        base,
        spec,
        spread,
        workers=args.workers,
        scheduler=args.scheduler,
        progress=progress_bar("certify"),
    )
    write_out(args, _write, result)
    out = result.to_json()
    if args.json:
        print(json.dumps(out))
    else:
        print(out["statement"])
        for name, r in out["requirements"].items():
            sd = f", noise sd {r['noise_sd']:.3g}" if "noise_reruns" in r else ""
            print(f"  {name}: {r['status']}, least robustness {r['least_robustness']:+.4g}{sd}")
        if result.counterexample is not None and args.out is not None:
            from twin.app.replay import replay_command

            print(f"repeat it: {replay_command(Path(args.out) / 'certify.json', args.controller)}")
    if result.outcome == "interrupted":
        return interrupted("certify", ": no statement")
    return 0 if result.outcome == "pass" else 1


def _write(result: Any, out_dir: str, *, overwrite: bool = False) -> None:
    from twin.app.certify import OUTPUT_FILES
    from twin.outputs import atomic_directory

    with atomic_directory(out_dir, OUTPUT_FILES, overwrite=overwrite) as tmp:
        (tmp / "certify.json").write_text(json.dumps(result.to_json(), indent=1) + "\n")
