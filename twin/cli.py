"""The ``ballbeam`` command."""

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


def _load_params(path: str | None) -> Parameters:
    return Parameters.from_file(path) if path else Parameters()


def _cmd_linearize(args: argparse.Namespace) -> int:
    params = _load_params(args.params)
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
    params = _load_params(args.params)
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
    from twin.log import save_csv, save_mat
    from twin.runner import run_closed_loop

    params = _load_params(args.params)
    for name, value in (("--x0", args.x0), ("--theta0", args.theta0), ("--duration", args.duration)):
        if not math.isfinite(value):
            raise ParameterError(f"{name} = {value!r} is not a finite number")
    if args.duration <= 0:
        raise ParameterError(f"--duration = {args.duration!r} must be positive")
    for path in (args.log, args.plot):
        if path and Path(path).exists() and not args.overwrite:
            raise ParameterError(f"{path}: exists; not overwritten (pass --overwrite)")
    controller = registry.make(args.controller, params)
    result = run_closed_loop(
        controller,
        x0_m=args.x0,
        theta0_rad=args.theta0,
        duration_s=args.duration,
        seed=args.seed,
        noise=not args.no_noise,
        params=params,
    )
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
        **result.metrics,
    }
    if args.json:
        print(json.dumps(summary))
    else:
        for key, value in summary.items():
            print(f"{key:<22} {value}")
    return 0


def _cmd_view(args: argparse.Namespace) -> int:
    from twin.viewer import ViewerError, serve

    params = _load_params(args.params)
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise ParameterError(f"--duration = {args.duration!r} must be a positive number of seconds")
    try:
        stats = serve(
            host=args.host,
            port=args.port,
            controller=args.controller,
            speed=args.speed,
            seed=args.seed,
            duration_s=args.duration,
            params=params,
        )
    except ViewerError as exc:
        print(f"ballbeam view: error: {exc}", file=sys.stderr)
        return 2
    if args.duration is not None and stats:
        print(json.dumps(stats))
    return 0


def build_parser() -> argparse.ArgumentParser:
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
    lin.add_argument("--params", metavar="FILE", help="parameter file (TOML or JSON) overriding the defaults")
    lin.add_argument("--json", action="store_true", help="print JSON")
    lin.set_defaults(func=_cmd_linearize)

    from controllers.registry import NAMES

    run = sub.add_parser("run", help="run a controller on the twin in closed loop and report the verdict")
    run.add_argument("--controller", required=True, choices=NAMES)
    run.add_argument("--x0", type=float, required=True, metavar="M", help="initial ball position (m)")
    run.add_argument("--theta0", type=float, required=True, metavar="RAD", help="initial beam angle (rad)")
    run.add_argument(
        "--duration", type=float, default=15.0, metavar="S", help="simulated seconds (default 15)"
    )
    run.add_argument("--seed", type=int, default=0, help="seed of the sensor noise (default 0)")
    run.add_argument("--no-noise", action="store_true", help="switch the ball sensor's contact noise off")
    run.add_argument("--log", metavar="FILE", help="save the run: .mat (thesis data_file format) or .csv")
    run.add_argument("--plot", metavar="FILE", help="save a PNG of the run")
    run.add_argument("--overwrite", action="store_true", help="replace existing --log/--plot files")
    run.add_argument("--params", metavar="FILE", help="parameter file (TOML or JSON) overriding the defaults")
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
    view.add_argument(
        "--params", metavar="FILE", help="parameter file (TOML or JSON) overriding the defaults"
    )
    view.set_defaults(func=_cmd_view)

    par = sub.add_parser("params", help="list every parameter with its unit and source")
    par.add_argument("--params", metavar="FILE", help="parameter file (TOML or JSON) overriding the defaults")
    par.add_argument("--json", action="store_true", help="print JSON")
    par.set_defaults(func=_cmd_params)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except (ValueError, FileExistsError) as exc:  # bad input (ParameterError is a ValueError): no traceback
        print(f"ballbeam: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into e.g. head
        return 0


if __name__ == "__main__":
    sys.exit(main())
