"""``ballbeam params``: every parameter with its unit and source."""

from __future__ import annotations

import argparse
import json

from twin.app.commands.common import add_params_options, load_params

HELP = "list every parameter with its unit and source"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_params_options(parser)
    parser.add_argument("--json", action="store_true", help="print JSON")


def run(args: argparse.Namespace) -> int:
    from twin.parameters import Parameters

    params = load_params(args)
    if args.json:
        print(json.dumps(params.to_dict(), indent=2))
    else:
        for row in Parameters.describe():
            group, name = row["name"].split(".")
            value = getattr(getattr(params, group), name)
            print(f"{row['name']:<40} {value!r:>22} {row['unit']:<10} {row['source']}")
    return 0
