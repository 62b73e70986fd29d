"""``ballbeam judge``: the verdict of a recorded log from its measured signals."""

from __future__ import annotations

import argparse
import json

from twin.app.commands.common import add_params_options, load_params
from twin.app.options import finite_float

HELP = (
    "the verdict of a recorded log (a rig's data_file.mat or CSV) from its measured signals only "
    "(exit 0 held, 1 lost or not held, 2 bad input)"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "log", metavar="LOG.mat|LOG.csv", help="the log: timem, datam1, datam2, aout are read"
    )
    parser.add_argument(
        "--setpoint", type=finite_float(unit="m"), metavar="M", help="judge the ball about this position (m)"
    )
    add_params_options(parser)
    parser.add_argument("--json", action="store_true", help="print the verdict as JSON")


def run(args: argparse.Namespace) -> int:
    from calib.logs import load_judged_log
    from twin.physics import check_on_track
    from twin.verdict import evaluate_measured

    params = load_params(args)
    if args.setpoint is not None:
        check_on_track(params, "--setpoint", args.setpoint)
    log = load_judged_log(args.log, params.daq.period_s)  # checked as every command checks a rig log
    verdict = evaluate_measured(log, params, x_ref_m=args.setpoint or 0.0)
    summary = {
        "log": args.log,
        "source": "measured",
        "ticks": log.k,
        **({} if args.setpoint is None else {"setpoint_m": args.setpoint}),
        **verdict.to_json(),
    }
    if args.json:
        print(json.dumps(summary))
    else:
        for key, value in summary.items():
            print(f"{key:<26} {value}")
    return 0 if verdict.held else 1
