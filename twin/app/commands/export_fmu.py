"""``ballbeam export-fmu``: the rig as an FMI 3.0 (or 2.0) co-simulation unit (twin.fmi)."""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path

from twin.app.commands.common import (
    ParamsOptions,
    add_params_options,
    inputs,
    load_params,
    options_from,
    package_version,
    params_source,
)

HELP = "export the rig as an FMI 3.0 (or 2.0) co-simulation unit (.fmu) for Simulink, OpenModelica, FMPy"

# The unit is about 1 MB (pythonfmu3's libraries for two platforms and the scripts).
_FMU_BYTES = 1 << 20


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", required=True, metavar="FILE.fmu", help="the unit to write (atomically)")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    parser.add_argument(
        "--calibration",
        metavar="DIR",
        help="a calibration's values (calibrate --out): the unit's parameters start at them, their standard "
        "uncertainties in the descriptions",
    )
    parser.add_argument(
        "--fmi",
        type=int,
        choices=(3, 2),
        default=3,
        help="the FMI version: 3 (default; pythonfmu3) or 2 (pythonfmu: most importers in labs read 2.0)",
    )
    add_params_options(parser)
    parser.add_argument("--json", action="store_true", help="print what was written as JSON")


@dataclass(frozen=True)
class Options:
    """``export-fmu``'s options."""

    out: str
    overwrite: bool
    calibration: str | None
    fmi: int
    json: bool
    parameters: ParamsOptions


def run(args: argparse.Namespace) -> int:
    return handle(options_from(Options, args))


def handle(o: Options) -> int:
    from twin.app.commands.common import compare_params
    from twin.fmi.export import check_rig, export_fmu, rig_description
    from twin.outputs import check_outputs

    paths = check_outputs(
        [("--out", o.out, (".fmu",), _FMU_BYTES)],
        overwrite=o.overwrite,
        inputs=inputs(params=o.parameters.params, rig_file=o.parameters.rig_file, calibration=o.calibration),
    )
    uncertainty: dict[str, float] = {}
    if o.calibration is not None:
        params, source = compare_params(o.parameters, o.calibration)
        uncertainty = _uncertainties(Path(o.calibration) / "calibration.json")
    else:
        params = load_params(o.parameters)
        source = params_source(o.parameters) or "the defaults (thesis values)"
    check_rig(params, source)
    description = rig_description(params, version=package_version(), source=source, uncertainty=uncertainty)
    out = export_fmu(paths["--out"], description, overwrite=o.overwrite, fmi_version=o.fmi)
    summary = {
        "fmu": str(out),
        "fmi": f"{o.fmi}.0",
        "bytes": out.stat().st_size,
        "version": description["version"],
        "source": source,
    }
    print(json.dumps(summary) if o.json else f"wrote {out} ({summary['bytes']} bytes): parameters {source}")
    return 0


def _uncertainties(path: Path) -> dict[str, float]:
    """Each fitted parameter's standard uncertainty in a calibration.json (none when it has none)."""
    from twin.parameters import ParameterError

    try:
        fitted = json.loads(path.read_text())["params"]
        return {name: float(entry["sd"]) for name, entry in fitted.items()}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        print(f"ballbeam export-fmu: {path}: no uncertainties read ({type(exc).__name__})", file=sys.stderr)
        if isinstance(exc, OSError):
            raise ParameterError(f"--calibration: {path}: {exc.strerror or exc}") from None
        return {}
