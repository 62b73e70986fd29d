"""``ballbeam compare``: the twin's prediction of recorded logs, windowed and in closed loop."""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path

from twin.app.catalogue import one_line
from twin.app.commands.common import (
    ParamsOptions,
    add_controller_timeout,
    add_params_options,
    compare_params,
    controller_help,
    hardware_controller,
    inputs,
    options_from,
    progress_bar,
    refuse_part_rig,
    write_out,
)
from twin.app.options import finite_float, seed
from twin.outputs import check_output_folder

HELP = (
    "the twin's prediction of recorded logs: windowed prediction and, with --controller, the closed loop "
    "from the first block; report, figures, JSON (exit 0 conforms, 1 not, 2 bad input)"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "logs", nargs="+", metavar="LOG", help="data_file.mat or .csv logs (rig, run, serve, experiment)"
    )
    parser.add_argument(
        "--out", required=True, metavar="DIR", help="write report.md, comparison.json and PNGs here"
    )
    parser.add_argument("--overwrite", action="store_true", help="replace its own files in an existing --out")
    parser.add_argument(
        "--calibration",
        metavar="DIR",
        help="the parameters of a calibration (its params.toml; not with --params)",
    )
    parser.add_argument(
        "--controller",
        metavar="NAME|MODULE:CLASS",
        help="the hardware controller that ran: the twin then runs it from each log's first block. "
        + controller_help(firmware=False),
    )
    parser.add_argument(
        "--window",
        type=finite_float(0, unit="s"),  # its minimum, 2 ticks, follows from the logs' period
        default=1.0,
        metavar="S",
        help="window whose fitted state starts the next prediction (default 1 s, as calibrate)",
    )
    parser.add_argument(
        "--horizon",
        type=finite_float(0, lo_open=True, unit="s"),
        default=0.5,
        metavar="S",
        help="seconds predicted and scored from each window's start (default 0.5: two e-folding times of the "
        "open-loop plant's unstable pole, 3.8 /s)",
    )
    parser.add_argument(
        "--min-fit",
        type=finite_float(hi=100.0, unit="%"),
        default=90.0,
        metavar="PCT",
        help="conformance: the prediction's fit %% on each channel at least this (default 90)",
    )
    parser.add_argument(
        "--max-floor-ratio",
        type=finite_float(0, lo_open=True),
        default=20.0,
        metavar="K",
        help="conformance: the prediction's residual RMS at most K × the channel's noise floor (default 20)",
    )
    parser.add_argument("--seed", type=seed(), default=0, help="seed of the closed-loop twin's sensor noise")
    parser.add_argument("--json", action="store_true", help="print comparison.json")
    add_params_options(parser)
    add_controller_timeout(parser)


@dataclass(frozen=True)
class Options:
    """``compare``'s options."""

    logs: list[str]
    out: str
    overwrite: bool
    calibration: str | None
    controller: str | None
    window: float
    horizon: float
    min_fit: float
    max_floor_ratio: float
    seed: int
    json: bool
    controller_timeout: float | None
    parameters: ParamsOptions


def run(args: argparse.Namespace) -> int:
    return handle(options_from(Options, args))


def handle(o: Options) -> int:
    from calib.compare import OUTPUT_FILES, Criterion, compare
    from calib.logs import check_period, read_log, rig_log
    from twin.engine import ControllerError
    from twin.parameters import ParameterError
    from twin.plant import NumericalError

    params, source = compare_params(o.parameters, o.calibration)
    refuse_part_rig(params, "compare", "judge its logs (ballbeam judge) or calibrate it (calibrate --log)")
    criterion = Criterion(min_fit_percent=o.min_fit, max_floor_ratio=o.max_floor_ratio)
    factory = None if o.controller is None else hardware_controller(o.controller, params)
    check_output_folder(
        "--out",
        o.out,
        OUTPUT_FILES,
        overwrite=o.overwrite,
        inputs=inputs(
            params=o.parameters.params,
            rig_file=o.parameters.rig_file,
            logs=o.logs,
            calibration=o.calibration,
            controller=o.controller,
        ),
    )
    logs = [(path, read_log(path)) for path in o.logs]
    rigs = [rig_log(log, path) for path, log in logs]  # every log checked before the work
    for rig in rigs:  # a log at another period (or in ms) is the log's fault, not the window's
        check_period(rig, params.period_s)
    period_s = min(r.period_s for r in rigs)
    if o.window < 2 * period_s:
        raise ParameterError(
            f"--window = {o.window:g}: at least 2 ticks of the logs' {period_s * 1e3:g} ms period "
            f"({2 * period_s:g} s)"
        )
    if not period_s <= o.horizon <= o.window:
        raise ParameterError(
            f"--horizon = {o.horizon:g}: from one tick ({period_s:g} s) to the window ({o.window:g} s)"
        )
    bar = progress_bar("compare", unit="step")
    try:
        result = compare(
            logs,
            params,
            params_source=source,
            controller=factory,
            controller_name=o.controller or "",
            window_s=o.window,
            horizon_s=o.horizon,
            criterion=criterion,
            seed=o.seed,
            progress=bar,
        )
    except ControllerError as exc:
        print(f"ballbeam compare: the controller failed: {exc}", file=sys.stderr)
        return 1
    except NumericalError as exc:
        print(f"ballbeam compare: {one_line(exc)}", file=sys.stderr)
        return 1
    from calib.compare_render import write_comparison  # matplotlib: after the run

    write_out(o.out, o.overwrite, write_comparison, result)
    if o.json:
        print(json.dumps(result.to_json()))
        return 0 if result.passed else 1
    wp = result.windowed
    print(
        f"{wp.n_windows} windows of {wp.window_s:g} s; each window predicted {wp.horizon_s:g} s ahead from the "
        "previous window's fitted end state (scored), and fitted to itself (shown apart)"
    )
    for lw in wp.logs:
        for d in lw.dropped:
            print(f"warning: {lw.path}: the window from {d.start_s:.2f} s left out ({d.reason}): not scored")
    for c in ("ball", "angle"):
        pred, fitted = wp.predicted[c], wp.fitted[c]
        unit, scale = ("mm", 1e3) if c == "ball" else ("mrad", 1e3)
        print(
            f"{c:<6} predicted fit {pred.fit_percent:7.2f} %  RMS {scale * pred.rms:.3g} {unit} "
            f"= {pred.floor_ratio:.1f} × floor {scale * pred.floor:.3g} {unit}  "
            f"whiteness {pred.outside}/{len(pred.acf) - 1} lags outside  (fitted {fitted.fit_percent:.2f} %)"
        )
    for cl in result.closed_loop:
        tracked = ", ".join(
            f"{c} until {'the end' if t is None else f'{t:.2f} s'}" for c, t in cl.tracked_s.items()
        )
        print(f"closed loop {cl.path} ({cl.controller}): tracks the log: {tracked}")
        print(
            f"  verdict  log: {cl.verdict_log.reason}; twin: {cl.verdict_twin.reason} (measured), "
            f"{cl.verdict_twin_true.reason} (true state); agree: {'yes' if cl.verdicts_agree else 'no'}"
        )
    crit = result.criterion
    if result.passed:
        print(
            f"conforms: fit ≥ {crit.min_fit_percent:g} % and RMS ≤ {crit.max_floor_ratio:g} × floor on both channels"
        )
    else:
        print(f"does not conform: {'; '.join(result.failures)}")
    print(f"wrote {Path(o.out) / 'report.md'}, comparison.json and the figures")
    return 0 if result.passed else 1
