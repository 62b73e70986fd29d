"""The ``ballbeam`` command."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Sequence

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


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ballbeam", description="Digital twin of the two-wire ball-and-beam rig.")
    sub = parser.add_subparsers(dest="command", required=True)

    lin = sub.add_parser("linearize", help="continuous-time A, B at the origin")
    lin.add_argument("--input", choices=("torque", "voltage"), default="torque")
    lin.add_argument("--source", choices=("twin", "reference"), default="twin",
                     help="the MuJoCo twin (reduced to its 4 slow modes) or the analytic reference model")
    lin.add_argument("--params", metavar="FILE", help="parameter file (TOML or JSON) overriding the defaults")
    lin.add_argument("--json", action="store_true", help="print JSON")
    lin.set_defaults(func=_cmd_linearize)

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
    except ParameterError as exc:
        print(f"ballbeam: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into e.g. head
        return 0


if __name__ == "__main__":
    sys.exit(main())
