"""``ballbeam linearize``: the continuous-time A, B at the origin (the twin's or the reference model's)."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from twin.app.commands.common import ParamsOptions, add_params_options, load_params, options_from

if TYPE_CHECKING:
    import numpy as np

    from twin.parameters import Parameters

HELP = "continuous-time A, B at the origin"


def _reference(params: Parameters, input: str) -> tuple[np.ndarray, np.ndarray]:
    from twin.linearize import hold_control, linearize_reference
    from twin.parts import is_thesis_rig, rig_parts
    from twin.reference import ReferenceModel

    parts = rig_parts(params)
    if is_thesis_rig(parts):
        return ReferenceModel(params).linearize(input)  # type: ignore[arg-type]
    # a rig of other parts: its DriveLaw's model, about the control that holds the level beam
    control_of = parts.actuator.control_of
    rest = parts.actuator.rest_command(params)
    return linearize_reference(params, hold_control(params, control_of(params)(rest) if control_of else rest))


def _twin(params: Parameters, input: str) -> tuple[np.ndarray, np.ndarray]:
    from twin.linearize import linearize_mujoco  # imports MuJoCo only when needed

    return linearize_mujoco(params, input)  # type: ignore[arg-type]


# Each --source's linearization, by name: the table is the choice (no name is compared).
SOURCES: dict[str, Callable[[Parameters, str], tuple[np.ndarray, np.ndarray]]] = {
    "twin": _twin,
    "reference": _reference,
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--input", choices=("torque", "voltage"), default="torque")
    parser.add_argument(
        "--source",
        choices=tuple(SOURCES),
        default="twin",
        help="the MuJoCo twin (reduced to its 4 slow modes) or the analytic reference model",
    )
    add_params_options(parser)
    parser.add_argument("--json", action="store_true", help="print JSON")


@dataclass(frozen=True)
class Options:
    """``linearize``'s options."""

    input: str
    source: str
    json: bool
    parameters: ParamsOptions


def run(args: argparse.Namespace) -> int:
    return handle(options_from(Options, args))


def handle(o: Options) -> int:
    import numpy as np

    from twin.linearize import LinearizationError
    from twin.parts import is_thesis_rig, rig_parts
    from twin.reference import STATE_NAMES

    params = load_params(o.parameters)
    parts = rig_parts(params)
    thesis = is_thesis_rig(parts)
    if not thesis and o.input == "torque":
        raise ValueError(
            f"--input torque: a rig of other parts ({parts.actuator.name} through {parts.beam_drive.name}) is "
            "linearized in its actuator's control; give --input voltage (the control: "
            f"{parts.actuator.control_unit})"
        )
    try:
        a, b = SOURCES[o.source](params, o.input)
    except LinearizationError as exc:
        print(f"ballbeam linearize: the {o.source} model cannot be linearized here: {exc}", file=sys.stderr)
        return 1
    result = {
        "state": list(STATE_NAMES),
        "input": o.input,
        "source": o.source,
        "A": a.tolist(),
        "B": b.tolist(),
    }
    if o.json:
        print(json.dumps(result))
    else:
        unit = "N·m" if o.input == "torque" else parts.actuator.control_unit
        where = "the origin" if thesis else "the level beam, the ball at the track's centre"
        print(f"Continuous-time linearization at {where} ({o.source}, input: {o.input} [{unit}])")
        print("state:", ", ".join(STATE_NAMES))
        with np.printoptions(precision=6, suppress=True, linewidth=120):
            print("A =\n", a)
            print("B =\n", b)
            print("eigenvalues of A:", np.linalg.eigvals(a))
    return 0
