"""``ballbeam judge``: the verdict of a recorded log from its measured signals."""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass

from twin.app.commands.common import ParamsOptions, add_params_options, load_params, options_from
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


@dataclass(frozen=True)
class Options:
    """``judge``'s options."""

    log: str
    setpoint: float | None
    json: bool
    parameters: ParamsOptions


def run(args: argparse.Namespace) -> int:
    return handle(options_from(Options, args))


def handle(o: Options) -> int:
    from calib.logs import load_judged_log
    from twin.parts.measured import measured_channels
    from twin.physics import check_on_track
    from twin.verdict import evaluate_measured

    params = load_params(o.parameters)
    if o.setpoint is not None:
        check_on_track(params, "--setpoint", o.setpoint)
    channels = measured_channels(params)  # a rig of other parts: its parts' conversions (refused if none)
    log = load_judged_log(o.log, params)  # checked as every command checks a rig log
    verdict = evaluate_measured(log, params, x_ref_m=o.setpoint or 0.0, channels=channels)
    summary = {
        "log": o.log,
        "source": "measured",
        "ticks": log.k,
        **({} if o.setpoint is None else {"setpoint_m": o.setpoint}),
        **verdict.to_json(),
    }
    if o.json:
        print(json.dumps(summary))
    else:
        for key, value in summary.items():
            print(f"{key:<26} {value}")
    return 0 if verdict.held else 1
