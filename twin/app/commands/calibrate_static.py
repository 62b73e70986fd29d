"""``ballbeam calibrate-static``: a sensor's static curve fitted from a measured table."""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from twin.app.commands.common import (
    ParamsOptions,
    add_params_options,
    check_overwrite,
    inputs,
    load_params,
    options_from,
)
from twin.outputs import check_outputs, writing

if TYPE_CHECKING:
    from twin.parameters import Parameters

PARAMS_OUT_SUFFIXES = (".toml",)

HELP = "fit a sensor's static curve from a measured table (CSV)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "table",
        metavar="TABLE.csv",
        help=(
            "columns position_m,volts_v (ball) or di,volts_v (angle); or a table the package ships: "
            "thesis:table_6_3 (Table 6.3), thesis:eq_6_2_4 (eq 6.2.4's three points)"
        ),
    )
    parser.add_argument(
        "--sensor",
        metavar="PART",
        choices=("vl53l0x", "hcsr04", "gp2y0a21", "potentiometer", "as5600"),
        help=(
            "fit this part's static curve instead (vl53l0x, hcsr04, gp2y0a21, potentiometer, as5600): TABLE is then "
            "a ruler table, columns distance_mm|distance_cm|distance_m|angle_deg|angle_rad, reading_<mm|us|counts|v> "
            "and optional sd_<unit>, n (rows of one true value are pooled); --out writes a rig-description table"
        ),
    )
    parser.add_argument("--out", metavar="FILE.toml", help="write the fitted parameters as a parameter file")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    parser.add_argument("--json", action="store_true", help="print JSON")
    add_params_options(parser)


@dataclass(frozen=True)
class Options:
    """``calibrate-static``'s options."""

    table: str
    sensor: str | None
    out: str | None
    overwrite: bool
    json: bool
    parameters: ParamsOptions


def run(args: argparse.Namespace) -> int:
    return handle(options_from(Options, args))


def handle(o: Options) -> int:
    from calib.static import calibrate, load_table
    from calib.static_render import render_lines, render_toml
    from twin.outputs import atomic_output

    check_overwrite(o.overwrite, [("--out", o.out)])
    params = load_params(o.parameters)
    paths = check_outputs(
        [("--out", o.out, PARAMS_OUT_SUFFIXES, 0)],
        overwrite=o.overwrite,
        inputs=inputs(params=o.parameters.params, rig_file=o.parameters.rig_file, table=o.table),
    )
    if o.sensor is not None:
        return _sensor(o, params, paths)
    result = calibrate(load_table(table_path(o.table)), params)
    print(json.dumps(result.to_json(), indent=2) if o.json else "\n".join(render_lines(result)))
    if o.out is not None and "--out" in paths:
        with writing("--out", o.out), atomic_output(paths["--out"], overwrite=o.overwrite) as fh:
            fh.write(render_toml(result).encode("utf-8"))
    return 0


def _sensor(o: Options, params: Parameters, paths: dict[str, Path]) -> int:
    """``--sensor PART``: the part's static curve from a ruler table (``calib.sensor_static``); exit 0 whether
    or not the part's model holds the table (the verdict is printed)."""
    from calib.sensor_static import fit_static, load_ruler_table, render_lines, write_static_fit

    assert o.sensor is not None
    fit = fit_static(o.sensor, load_ruler_table(Path(o.table)), params)
    print(json.dumps(fit.to_json(), indent=2) if o.json else "\n".join(render_lines(fit)))
    if o.out is not None and "--out" in paths:
        with writing("--out", o.out):
            write_static_fit(fit, paths["--out"], overwrite=o.overwrite)
    return 0


def table_path(spec: str) -> Path:
    """``spec`` as a path; ``thesis:NAME`` is a table the package ships (``calib/tables/NAME.csv``: the
    thesis's measurements, found without a clone of the repository)."""
    from calib.static import TABLES_DIR
    from twin.parameters import ParameterError

    if not spec.startswith("thesis:"):
        return Path(spec)
    shipped = Path(TABLES_DIR)
    names = sorted(p.stem for p in shipped.glob("*.csv"))
    name = spec.removeprefix("thesis:")
    if name not in names:
        raise ParameterError(f"TABLE {spec!r}: the package ships {', '.join('thesis:' + n for n in names)}")
    return shipped / f"{name}.csv"
