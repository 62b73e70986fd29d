"""``ballbeam params``: every parameter with its unit and source."""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass

from twin.app.commands.common import ParamsOptions, add_params_options, load_params, options_from

HELP = "list every parameter with its unit and source"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_params_options(parser)
    parser.add_argument("--json", action="store_true", help="print JSON")


@dataclass(frozen=True)
class Options:
    """``params``'s options."""

    json: bool
    parameters: ParamsOptions


def run(args: argparse.Namespace) -> int:
    return handle(options_from(Options, args))


def handle(o: Options) -> int:
    from twin.parameters import Parameters

    params = load_params(o.parameters)
    if o.json:
        print(json.dumps(params.to_dict(), indent=2))
    else:
        for row in Parameters.describe():
            group, name = row["name"].split(".")
            value = getattr(getattr(params, group), name)
            print(f"{row['name']:<40} {value!r:>22} {row['unit']:<10} {row['source']}")
    return 0
