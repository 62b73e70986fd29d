"""``ballbeam params``: every parameter with its unit and source; with ``--rig-file``, the rig's parameters part by
part, with their bounds."""

from __future__ import annotations

import argparse
import dataclasses
import json
from dataclasses import dataclass
from typing import TYPE_CHECKING

from twin.app.commands.common import ParamsOptions, add_params_options, load_params, options_from

if TYPE_CHECKING:
    from twin.parameters import Parameters

HELP = "list every parameter with its unit and source (a rig's, part by part, with --rig-file)"


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
        values = params.to_dict()
        if o.parameters.rig_file:  # the rig's parts' own groups too, at their defaults where not set
            from twin.parts import rig_parts

            for part in rig_parts(params):
                values.update({g: dataclasses.asdict(params.group(g)) for g in part.groups})
        print(json.dumps(values, indent=2))
    elif o.parameters.rig_file:
        _print_rig(params)
    else:
        import twin.parts  # noqa: F401  # registers every built-in part's parameter group

        for row in Parameters.describe():
            group, name = row["name"].split(".")
            value = getattr(params.group(group), name)
            print(f"{row['name']:<40} {value!r:>22} {row['unit']:<10} {row['source']}")
    return 0


def _print_rig(params: Parameters) -> None:
    """The rig's parameters under each role and its part, then the groups no part owns."""
    from twin.parameters import GROUPS
    from twin.parts.description import describe_rig
    from twin.parts.thesis import NOT_PART_GROUPS

    place = None
    for row in describe_rig(params):
        if (row["role"], row["part"]) != place:
            place = (row["role"], row["part"])
            print(f"[{row['role']}] part = {row['part']!r}")
        bounds = f" ({row['bounds']})" if row["bounds"] else ""
        print(f"  {row['name']:<40} {row['value']:>22} {row['unit']}{bounds}; {row['source']}")
    for group in NOT_PART_GROUPS:
        print(f"[{group}] ({NOT_PART_GROUPS[group]})")
        values = params.group(group)
        for f in dataclasses.fields(GROUPS[group]):
            print(
                f"  {group}.{f.name:<33} {getattr(values, f.name)!r:>22} {f.metadata['unit']}; {f.metadata['source']}"
            )
