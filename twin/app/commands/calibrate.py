"""``ballbeam calibrate``: fit the twin's parameters to logs recorded on a rig."""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path

from twin.app.commands.common import (
    ParamsOptions,
    add_params_options,
    check_overwrite,
    inputs,
    load_params,
    options_from,
    progress_bar,
    refuse_part_rig,
    write_out,
)
from twin.app.options import finite_float
from twin.outputs import check_output_folder

HELP = (
    "fit the twin's parameters to logs recorded on a rig (exit 0 converged and adequate; 1 not "
    "converged, model mismatch, weak excitation or a parameter the logs do not identify; 2 a log refused)"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("logs", nargs="*", metavar="LOG", help="data_file.mat or .csv logs of the same rig")
    parser.add_argument(
        "--log",
        metavar="SERIAL.csv",
        help="a part-built rig's serial log (what its sketch prints; with --rig-file and --columns)",
    )
    parser.add_argument(
        "--columns",
        metavar="MAP",
        help="the serial log's column map, e.g. 'time=ms, distance=mm, pulse=us' or a preset map's name",
    )
    parser.add_argument(
        "--fit",
        required=True,
        metavar="NAME,NAME,…",
        help="parameters to fit, e.g. motor.resistance_ohm,beam.inertia_pivot_kgm2 (docs/calibrate.md)",
    )
    parser.add_argument("--out", metavar="DIR", help="write params.toml, calibration.json and report.md here")
    parser.add_argument("--overwrite", action="store_true", help="replace its own files in an existing --out")
    parser.add_argument(
        "--window",
        type=finite_float(0, unit="s"),  # its minimum, 2 ticks, follows from the logs' period
        default=1.0,
        metavar="S",
        help="window length (default 1 s; at least 2 ticks of the logs)",
    )
    parser.add_argument("--json", action="store_true", help="print calibration.json")
    add_params_options(parser)


@dataclass(frozen=True)
class Options:
    """``calibrate``'s options."""

    logs: list[str]
    log: str | None
    columns: str | None
    fit: str
    out: str | None
    overwrite: bool
    window: float
    json: bool
    parameters: ParamsOptions


def run(args: argparse.Namespace) -> int:
    return handle(options_from(Options, args))


def handle(o: Options) -> int:
    from calib.identify import FITTABLE, calibrate
    from calib.logs import check_period, load_rig_log
    from calib.report import OUTPUT_FILES, write_report
    from twin.parameters import ParameterError

    check_overwrite(o.overwrite, [("--out", o.out)])
    start = load_params(o.parameters)
    if o.log is not None or not o.logs:
        return _serial(o, start)
    refuse_part_rig(start, "calibrate LOG …", "give its board's serial log as --log SERIAL.csv --columns MAP")
    fit = [name.strip() for name in o.fit.split(",") if name.strip()]
    unknown = [n for n in fit if n not in FITTABLE]
    if not fit or unknown:
        raise ParameterError(f"--fit {o.fit!r}: choose from {', '.join(FITTABLE)}")
    if o.out is not None:
        check_output_folder(
            "--out",
            o.out,
            OUTPUT_FILES,
            overwrite=o.overwrite,
            inputs=inputs(params=o.parameters.params, rig_file=o.parameters.rig_file, logs=o.logs),
        )
    logs = [load_rig_log(path) for path in o.logs]
    for log in logs:  # a log at another period (or in ms) is the log's fault, not the window's
        check_period(log, start.daq.period_s)
    period_s = min(log.period_s for log in logs)
    if o.window < 2 * period_s:  # a window is fitted from its ticks' differences: at least two
        raise ParameterError(
            f"--window = {o.window:g}: at least 2 ticks of the logs' {period_s * 1e3:g} ms period "
            f"({2 * period_s:g} s)"
        )

    # A bar per stage over its evaluation budget: the ETA is an upper bound (a fit stops when it converges). It
    # goes to stderr, with --json too (the JSON is stdout's): a 1-hour log's fit is minutes of work.
    progress = progress_bar("calibrate", unit="evaluation")
    cal = calibrate(logs, fit, start, window_s=o.window, progress=progress)
    write_out(o.out, o.overwrite, write_report, cal)
    if o.json:
        print(json.dumps(cal.to_json()))
    else:
        for name, v in cal.values.items():
            print(
                f"{name:<36} {v.value:12.6g}  [{v.ci_low:.6g}, {v.ci_high:.6g}]  (start {v.initial:.6g}) {v.unit}"
            )
        for name in cal.not_identifiable:  # the problem on stderr says why and the value it keeps
            print(f"{name:<36} not identifiable by these logs: kept at its start value")
        print(f"converged: {cal.converged} ({cal.message}); {cal.wall_s:.1f} s")
        for warning in cal.warnings:
            print(f"warning: {warning}")
        if o.out is not None:
            print(f"wrote {Path(o.out) / 'params.toml'}, calibration.json, report.md")
    # A fit that did not converge, or whose residuals or information say it cannot be trusted (model
    # mismatch, weak excitation, a parameter the logs do not identify: kept at its start value in
    # params.toml), exits 1: its files are written for inspection, its message is on stderr.
    for problem in cal.problems:
        print(f"calibrate: {problem}", file=sys.stderr)
    return 0 if cal.trustworthy else 1


def _serial(o: Options, start: object) -> int:
    """A part-built rig's serial log (``calib.part_identify``): the fitted rig as ``rig.toml``."""
    from calib.part_identify import calibrate_part_rig, write_outputs
    from calib.serial_log import read_serial_log
    from twin.parameters import ParameterError, Parameters

    assert isinstance(start, Parameters)
    if o.log is None or o.logs or o.columns is None:
        raise ParameterError("calibrate: give LOG… (the thesis rig), or --log SERIAL.csv with --columns MAP")
    log = read_serial_log(o.log, o.columns, start)
    cal = calibrate_part_rig(
        log, [n.strip() for n in o.fit.split(",") if n.strip()], start, window_s=o.window
    )
    if o.json:
        print(json.dumps(cal.to_json()))
    else:
        for name, v in cal.values.items():
            print(
                f"{name:<32} {v.value:12.6g}  [{v.ci_low:.6g}, {v.ci_high:.6g}]  (start {v.initial:.6g}) {v.unit}"
            )
        for name in cal.not_identifiable:
            print(f"{name:<32} not identifiable by these logs: kept at its start value")
        for channel, a in cal.adequacy.items():  # each in the board's unit (mm, V, counts)
            print(
                f"{channel} channel: RMS {a.rms:.3g} {a.unit} = {a.ratio:.2f} × floor {a.floor:.3g} {a.unit}, "
                f"ρ(1) {a.lag1:.2f}"
            )
        print(f"converged: {cal.converged} ({cal.message}); {cal.wall_s:.1f} s")
    if o.out is not None:
        name = o.parameters.rig_file or "calibrated"
        written = write_outputs(cal, o.out, f"{Path(name).stem} (calibrated)")
        print(f"wrote {', '.join(str(p) for p in written)}")
    for problem in cal.problems:
        print(f"calibrate: {problem}", file=sys.stderr)
    return 0 if cal.trustworthy else 1
