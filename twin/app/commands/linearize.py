"""``ballbeam linearize``: the continuous-time A, B at the origin (the twin's or the reference model's)."""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from twin.app.commands.common import ParamsOptions, add_params_options, load_params, options_from

if TYPE_CHECKING:
    import numpy as np

    from twin.parameters import Parameters

HELP = "continuous-time A, B at the origin"


def _reference(params: Parameters, input: str) -> tuple[np.ndarray, np.ndarray]:
    from twin.reference import ReferenceModel

    return ReferenceModel(params).linearize(input)  # type: ignore[arg-type]


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

    from twin.reference import STATE_NAMES

    params = load_params(o.parameters)
    a, b = SOURCES[o.source](params, o.input)
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
        unit = "N·m" if o.input == "torque" else "V"
        print(f"Continuous-time linearization at the origin ({o.source}, input: {o.input} [{unit}])")
        print("state:", ", ".join(STATE_NAMES))
        with np.printoptions(precision=6, suppress=True, linewidth=120):
            print("A =\n", a)
            print("B =\n", b)
            print("eigenvalues of A:", np.linalg.eigvals(a))
    return 0
