"""``ballbeam experiment``: an identification experiment on the twin, its log saved."""

from __future__ import annotations

import argparse

from twin.app.commands.common import (
    LOG_SUFFIXES,
    MAX_RUN_S,
    add_params_options,
    inputs,
    load_params,
    log_bytes,
    save_log,
)
from twin.app.options import finite_float, seed
from twin.outputs import check_outputs

HELP = "run an identification experiment on the twin and save its log"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("name", metavar="NAME", help="square (recommended), dither or sweep")
    parser.add_argument(
        "--out", required=True, metavar="LOG.mat", help="the log: .mat (thesis format) or .csv"
    )
    parser.add_argument(
        "--duration",
        type=finite_float(5, MAX_RUN_S, unit="s", why="the log keeps every tick in memory"),
        default=60.0,
        metavar="S",
        help=f"seconds, 5…{MAX_RUN_S:g} (default 60)",
    )
    parser.add_argument("--seed", type=seed(), default=0, help="seed of the dither and the sensor noise")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    add_params_options(parser)


def run(args: argparse.Namespace) -> int:
    from calib.experiments import EXPERIMENTS, run_experiment
    from twin.parameters import ParameterError

    params = load_params(args)
    if args.name not in EXPERIMENTS:
        raise ParameterError(f"unknown experiment {args.name!r}; known: {', '.join(EXPERIMENTS)}")
    out = check_outputs(
        [("--out", args.out, LOG_SUFFIXES, log_bytes(args.out, args.duration, params))],
        overwrite=args.overwrite,
        inputs=inputs(args),
    )["--out"]
    result = run_experiment(args.name, params, duration_s=args.duration, seed=args.seed)
    save_log(result.log, "--out", args.out, out, args.overwrite)
    print(
        f"{args.name}: {args.duration:g} s, {result.log.k} ticks, ball lost: {result.verdict.ball_lost}; "
        f"wrote {args.out}"
    )
    return 0 if not result.verdict.ball_lost else 1
