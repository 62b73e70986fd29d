"""``ballbeam experiment``: an identification experiment on the twin, its log saved."""

from __future__ import annotations

import argparse
from dataclasses import dataclass

from twin.app.commands.common import (
    LOG_SUFFIXES,
    MAX_RUN_S,
    ParamsOptions,
    add_params_options,
    inputs,
    load_params,
    log_bytes,
    options_from,
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


@dataclass(frozen=True)
class Options:
    """``experiment``'s options."""

    name: str
    out: str
    duration: float
    seed: int
    overwrite: bool
    parameters: ParamsOptions


def run(args: argparse.Namespace) -> int:
    return handle(options_from(Options, args))


def handle(o: Options) -> int:
    from calib.experiments import EXPERIMENTS, run_experiment
    from twin.parameters import ParameterError

    params = load_params(o.parameters)
    if o.name not in EXPERIMENTS:
        raise ParameterError(f"unknown experiment {o.name!r}; known: {', '.join(EXPERIMENTS)}")
    out = check_outputs(
        [("--out", o.out, LOG_SUFFIXES, log_bytes(o.out, o.duration, params))],
        overwrite=o.overwrite,
        inputs=inputs(params=o.parameters.params, rig_file=o.parameters.rig_file),
    )["--out"]
    result = run_experiment(o.name, params, duration_s=o.duration, seed=o.seed)
    save_log(result.log, "--out", o.out, out, o.overwrite)
    print(
        f"{o.name}: {o.duration:g} s, {result.log.k} ticks, ball lost: {result.verdict.ball_lost}; "
        f"wrote {o.out}"
    )
    return 0 if not result.verdict.ball_lost else 1
