"""The ``ballbeam`` command (application layer: it sees the controllers and hands their catalogue down).

Exit codes: 0 success (for ``run``: the ball was held), 1 a run whose ball was lost or not held, or whose
controller failed, 2 bad input (arguments, parameter files, output paths), each with a one-line message
and no traceback.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from twin.parameters import ParameterError, Parameters
from twin.reference import STATE_NAMES, ReferenceModel


def _load_params(args: argparse.Namespace) -> Parameters:
    params = Parameters.from_file(args.params) if args.params else Parameters()
    overrides: dict[str, object] = {}
    for item in getattr(args, "set", None) or ():
        name, sep, text = item.partition("=")
        if not sep or "." not in name:
            raise ParameterError(f"--set {item!r}: expected GROUP.NAME=VALUE, e.g. start.free_run_s=0.02")
        overrides[name.strip()] = _parse_value(text.strip(), item)
    return params.with_overrides(overrides, origin="--set") if overrides else params


def _parse_value(text: str, item: str) -> object:
    """A --set value: true/false, a number, or a JSON list of numbers."""
    if text in ("true", "false"):
        return text == "true"
    try:
        value = json.loads(text)
    except json.JSONDecodeError:
        raise ParameterError(
            f"--set {item!r}: {text!r} is not a number, true/false or a list of numbers"
        ) from None
    return value


def _cmd_linearize(args: argparse.Namespace) -> int:
    params = _load_params(args)
    if args.source == "reference":
        a, b = ReferenceModel(params).linearize(args.input)
    else:
        from twin.linearize import linearize_mujoco  # imports MuJoCo only when needed

        a, b = linearize_mujoco(params, args.input)
    result = {
        "state": list(STATE_NAMES),
        "input": args.input,
        "source": args.source,
        "A": a.tolist(),
        "B": b.tolist(),
    }
    if args.json:
        print(json.dumps(result))
    else:
        unit = "N·m" if args.input == "torque" else "V"
        print(f"Continuous-time linearization at the origin ({args.source}, input: {args.input} [{unit}])")
        print("state:", ", ".join(STATE_NAMES))
        with np.printoptions(precision=6, suppress=True, linewidth=120):
            print("A =\n", a)
            print("B =\n", b)
            print("eigenvalues of A:", np.linalg.eigvals(a))
    return 0


def _cmd_params(args: argparse.Namespace) -> int:
    params = _load_params(args)
    if args.json:
        print(json.dumps(params.to_dict(), indent=2))
    else:
        for row in Parameters.describe():
            group, name = row["name"].split(".")
            value = getattr(getattr(params, group), name)
            print(f"{row['name']:<40} {value!r:>22} {row['unit']:<10} {row['source']}")
    return 0


def _cmd_run(args: argparse.Namespace) -> int:
    from controllers import registry
    from twin.engine import ControllerError, run_closed_loop
    from twin.log import save_csv, save_mat

    params = _load_params(args)
    for name, value in (("--x0", args.x0), ("--theta0", args.theta0), ("--duration", args.duration)):
        if not math.isfinite(value):
            raise ParameterError(f"{name} = {value!r} is not a finite number")
    if args.duration <= 0:
        raise ParameterError(f"--duration = {args.duration!r} must be positive")
    for path in (args.log, args.plot):
        if path and Path(path).exists() and not args.overwrite:
            raise ParameterError(f"{path}: exists; not overwritten (pass --overwrite)")
    controller = registry.make(args.controller, params)
    try:
        result = run_closed_loop(
            controller,
            x0_m=args.x0,
            theta0_rad=args.theta0,
            duration_s=args.duration,
            seed=args.seed,
            noise=not args.no_noise,
            params=params,
            plant=args.plant,
            ideal_sensors=args.ideal_sensors or args.plant == "reference",
        )
    except ControllerError as exc:
        print(f"ballbeam run: the controller failed: {exc}", file=sys.stderr)
        return 1
    if args.log:
        save = save_csv if Path(args.log).suffix.lower() == ".csv" else save_mat
        save(result.log, args.log, overwrite=args.overwrite)
    if args.plot:
        from twin.plots import plot_run

        plot_run(result, args.plot)
    summary = {
        "controller": args.controller,
        "x0_m": args.x0,
        "theta0_rad": args.theta0,
        "seed": args.seed,
        "noise": not args.no_noise,
        "plant": args.plant,
        "ideal_sensors": bool(args.ideal_sensors or args.plant == "reference"),
        "free_run_s": params.start.free_run_s,
        **result.verdict.to_json(),
    }
    if args.json:
        print(json.dumps(summary))
    else:
        for key, value in summary.items():
            print(f"{key:<26} {value}")
    return 0 if result.verdict.held else 1


def _cmd_view(args: argparse.Namespace) -> int:
    from controllers import registry
    from twin.viewer import ViewerError, serve

    params = _load_params(args)
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise ParameterError(f"--duration = {args.duration!r} must be a positive number of seconds")
    try:
        stats = serve(
            registry,
            host=args.host,
            port=args.port,
            controller=args.controller,
            speed=args.speed,
            seed=args.seed,
            duration_s=args.duration,
            params=params,
            plant=args.plant,
            ideal_sensors=args.ideal_sensors or args.plant == "reference",
        )
    except ViewerError as exc:
        print(f"ballbeam view: error: {exc}", file=sys.stderr)
        return 2
    if args.duration is not None and stats:
        print(json.dumps(stats))
    return 0


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from calib.identify import FITTABLE, calibrate
    from calib.logs import load_rig_log
    from calib.report import check_out_dir, write_report

    start = _load_params(args)
    fit = [name.strip() for name in args.fit.split(",") if name.strip()]
    unknown = [n for n in fit if n not in FITTABLE]
    if not fit or unknown:
        raise ParameterError(f"--fit {args.fit!r}: choose from {', '.join(FITTABLE)}")
    if args.out:
        check_out_dir(args.out, args.overwrite)
    logs = [load_rig_log(path) for path in args.logs]

    def progress(line: str) -> None:
        if not args.json:
            print(f"  {line}", file=sys.stderr, flush=True)

    cal = calibrate(logs, fit, start, window_s=args.window, progress=progress)
    if args.out:
        write_report(cal, args.out, overwrite=args.overwrite)
    if args.json:
        print(json.dumps(cal.to_json()))
    else:
        for name, v in cal.values.items():
            print(
                f"{name:<36} {v.value:12.6g}  [{v.ci_low:.6g}, {v.ci_high:.6g}]  (start {v.initial:.6g}) {v.unit}"
            )
        print(f"converged: {cal.converged} ({cal.message}); {cal.wall_s:.1f} s")
        for warning in cal.warnings:
            print(f"warning: {warning}")
        if args.out:
            print(f"wrote {args.out}/params.toml, calibration.json, report.md")
    return 0 if cal.converged else 1


def _cmd_calibrate_static(args: argparse.Namespace) -> int:
    from calib.static import calibrate, load_table, render_lines, render_toml

    params = _load_params(args)
    if args.out and Path(args.out).exists() and not args.overwrite:
        raise ParameterError(f"{args.out}: exists; not overwritten (pass --overwrite)")
    result = calibrate(load_table(args.table), params)
    print(json.dumps(result.to_json(), indent=2) if args.json else "\n".join(render_lines(result)))
    if args.out:
        _write_atomic(Path(args.out), render_toml(result))
    return 0


def _cmd_experiment(args: argparse.Namespace) -> int:
    from calib.experiments import EXPERIMENTS, run_experiment
    from twin.log import save_csv, save_mat

    params = _load_params(args)
    if args.name not in EXPERIMENTS:
        raise ParameterError(f"unknown experiment {args.name!r}; known: {', '.join(EXPERIMENTS)}")
    if not (math.isfinite(args.duration) and 5.0 <= args.duration <= 3600.0):
        raise ParameterError(f"--duration = {args.duration!r}: an experiment lasts 5…3600 s")
    out = Path(args.out)
    if out.exists() and not args.overwrite:
        raise ParameterError(f"{out}: exists; not overwritten (pass --overwrite)")
    result = run_experiment(args.name, params, duration_s=args.duration, seed=args.seed)
    save = save_csv if out.suffix.lower() == ".csv" else save_mat
    save(result.log, out, overwrite=args.overwrite)
    print(
        f"{args.name}: {args.duration:g} s, {result.log.k} ticks, ball lost: {result.verdict.ball_lost}; wrote {out}"
    )
    return 0 if not result.verdict.ball_lost else 1


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    tmp.replace(path)


def _add_params_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--params", metavar="FILE", help="parameter file (TOML or JSON) overriding the defaults"
    )
    parser.add_argument(
        "--set",
        action="append",
        metavar="GROUP.NAME=VALUE",
        help="override one parameter, e.g. --set start.free_run_s=0 (repeatable; applied after --params)",
    )


def _add_plant_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--plant",
        choices=("twin", "reference"),
        default="twin",
        help="the MuJoCo twin (default) or the analytic reference model (always with ideal sensors)",
    )
    parser.add_argument(
        "--ideal-sensors",
        action="store_true",
        help="ideal converters: exact x and θ in the volts the software expects, exact DAC (no quantization, "
        "wiper curve, RC filter or noise)",
    )


def build_parser() -> argparse.ArgumentParser:
    from controllers.registry import NAMES

    parser = argparse.ArgumentParser(
        prog="ballbeam", description="Digital twin of the two-wire ball-and-beam rig."
    )
    sub = parser.add_subparsers(dest="command", required=True)

    lin = sub.add_parser("linearize", help="continuous-time A, B at the origin")
    lin.add_argument("--input", choices=("torque", "voltage"), default="torque")
    lin.add_argument(
        "--source",
        choices=("twin", "reference"),
        default="twin",
        help="the MuJoCo twin (reduced to its 4 slow modes) or the analytic reference model",
    )
    _add_params_options(lin)
    lin.add_argument("--json", action="store_true", help="print JSON")
    lin.set_defaults(func=_cmd_linearize)

    run = sub.add_parser(
        "run",
        help="run a controller in closed loop and report the verdict (exit 0 held, 1 lost or not held)",
    )
    run.add_argument("--controller", required=True, choices=NAMES)
    run.add_argument("--x0", type=float, required=True, metavar="M", help="initial ball position (m)")
    run.add_argument("--theta0", type=float, required=True, metavar="RAD", help="initial beam angle (rad)")
    run.add_argument(
        "--duration", type=float, default=15.0, metavar="S", help="simulated seconds (default 15)"
    )
    run.add_argument("--seed", type=int, default=0, help="seed of the sensor noise (default 0)")
    run.add_argument("--no-noise", action="store_true", help="switch the ball sensor's contact noise off")
    _add_plant_options(run)
    run.add_argument("--log", metavar="FILE", help="save the run: .mat (thesis data_file format) or .csv")
    run.add_argument("--plot", metavar="FILE", help="save a PNG of the run")
    run.add_argument("--overwrite", action="store_true", help="replace existing --log/--plot files")
    _add_params_options(run)
    run.add_argument("--json", action="store_true", help="print the verdict as JSON")
    run.set_defaults(func=_cmd_run)

    view = sub.add_parser("view", help="live 3D view of the twin in the browser (viser)")
    view.add_argument(
        "--host", default="127.0.0.1", help="interface to serve on (default 127.0.0.1: this machine only)"
    )
    view.add_argument("--port", type=int, default=8080, help="port (default 8080); a taken port is an error")
    view.add_argument("--controller", default="appendix-clp", choices=NAMES)
    view.add_argument(
        "--speed", type=float, default=1.0, help="simulated seconds per wall second (default 1.0)"
    )
    view.add_argument("--seed", type=int, default=0, help="seed of the sensor noise (default 0)")
    view.add_argument(
        "--duration", type=float, metavar="S", help="stop after S wall-clock seconds (headless runs)"
    )
    _add_plant_options(view)
    _add_params_options(view)
    view.set_defaults(func=_cmd_view)

    cal = sub.add_parser(
        "calibrate", help="fit the twin's parameters to logs recorded on a rig (exit 0 converged, 1 not)"
    )
    cal.add_argument("logs", nargs="+", metavar="LOG", help="data_file.mat or .csv logs of the same rig")
    cal.add_argument(
        "--fit",
        required=True,
        metavar="NAME,NAME,…",
        help="parameters to fit, e.g. motor.resistance_ohm,beam.inertia_pivot_kgm2 (see README)",
    )
    cal.add_argument("--out", metavar="DIR", help="write params.toml, calibration.json and report.md here")
    cal.add_argument("--overwrite", action="store_true", help="replace an existing --out directory")
    cal.add_argument("--window", type=float, default=1.0, metavar="S", help="window length (default 1 s)")
    cal.add_argument("--json", action="store_true", help="print calibration.json")
    _add_params_options(cal)
    cal.set_defaults(func=_cmd_calibrate)

    stat = sub.add_parser("calibrate-static", help="fit a sensor's static curve from a measured table (CSV)")
    stat.add_argument(
        "table", metavar="TABLE.csv", help="columns position_m,volts_v (ball) or di,volts_v (angle)"
    )
    stat.add_argument("--out", metavar="FILE.toml", help="write the fitted parameters as a parameter file")
    stat.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    stat.add_argument("--json", action="store_true", help="print JSON")
    _add_params_options(stat)
    stat.set_defaults(func=_cmd_calibrate_static)

    exp = sub.add_parser("experiment", help="run an identification experiment on the twin and save its log")
    exp.add_argument("name", metavar="NAME", help="square (recommended), dither or sweep")
    exp.add_argument("--out", required=True, metavar="LOG.mat", help="the log: .mat (thesis format) or .csv")
    exp.add_argument("--duration", type=float, default=60.0, metavar="S", help="seconds (default 60)")
    exp.add_argument("--seed", type=int, default=0, help="seed of the dither and the sensor noise")
    exp.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    _add_params_options(exp)
    exp.set_defaults(func=_cmd_experiment)

    par = sub.add_parser("params", help="list every parameter with its unit and source")
    _add_params_options(par)
    par.add_argument("--json", action="store_true", help="print JSON")
    par.set_defaults(func=_cmd_params)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except (ValueError, FileExistsError, FileNotFoundError) as exc:  # bad input: no traceback
        print(f"ballbeam: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into e.g. head
        return 0


if __name__ == "__main__":
    sys.exit(main())
