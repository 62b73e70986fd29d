"""A run to repeat: the counterexample (or least robust run) of ``falsify.json``, or a certification's failing
run (``certify.json``): every input needed to repeat it bit for bit (``ballbeam run --replay``, ``ballbeam view
--replay``).

The file keeps the run as ``{"controller", "x0_m", "theta0_rad", "seed", "noise", "duration_s", "parameters"
(the changes from the defaults by dotted name), "requirements" (name: formula), "robustness"}`` and, when the
run had them, ``flick_time_s``, ``flick_speed_m_s`` and ``setpoint_m``; a malformed file is refused naming the
file and the field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from twin.app.options import MAX_RUN_S
from twin.parameters import ParameterError, Parameters, load_json, read_input_file
from twin.requirements import Requirement, Spec, parse_requirements

__all__ = ["Replay", "load_replay", "refuse_given", "replay_entry"]

# Where a run to repeat sits in each kind of file, in order of preference.
RUN_KEYS = ("counterexample", "least_robust")


@dataclass(frozen=True)
class Replay:
    controller: str
    x0_m: float
    theta0_rad: float
    seed: int
    noise: bool
    duration_s: float
    params: Parameters
    requirements: tuple[Requirement, ...]
    robustness: dict[str, float]  # as the file states it
    source: str
    flick: tuple[float, float] | None = None  # (time after release, s; speed, m/s)
    setpoint_m: float | None = None


def load_replay(path: str | Path) -> Replay:
    """The run a falsify.json or certify.json names (its counterexample, else its least robust run)."""
    raw = read_input_file(path, "replay file", "a falsification's falsify.json is a few hundred kB")
    try:
        data = load_json(raw.decode("utf-8-sig"))
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise ParameterError(f"{path}: not a JSON file: {exc}") from None
    run = next((data[k] for k in RUN_KEYS if isinstance(data, dict) and data.get(k)), None)
    if not isinstance(run, dict):
        raise ParameterError(
            f"{path}: no run to repeat (expected {' or '.join(RUN_KEYS)}: falsify --out's file)"
        )

    def field(name: str, kind: type | tuple[type, ...], check: Any = None) -> Any:
        value = run.get(name)
        ok = isinstance(value, kind) and not (kind is not bool and isinstance(value, bool))
        if ok and isinstance(value, float):
            ok = math.isfinite(value)
        if not ok or (check is not None and not check(value)):
            raise ParameterError(f"{path}: {name} = {value!r} is not what a run needs")
        return value

    number = (int, float)
    parameters = field("parameters", dict)
    try:
        params = Parameters().with_overrides(parameters, origin=f"{path}: parameters")
    except ParameterError as exc:
        raise ParameterError(str(exc)) from None
    formulas = field("requirements", dict)
    requirements = parse_requirements({"requirements": formulas}, f"{path}: requirements")
    robustness = field("robustness", dict)
    optional = {}
    for name in ("flick_time_s", "flick_speed_m_s", "setpoint_m"):
        if run.get(name) is not None:
            optional[name] = float(field(name, number))
    flick = None
    if "flick_time_s" in optional:
        flick = (optional["flick_time_s"], optional.get("flick_speed_m_s", 0.0))
    return Replay(
        controller=field("controller", str, lambda v: 0 < len(v) < 4096),
        x0_m=float(field("x0_m", number)),
        theta0_rad=float(field("theta0_rad", number)),
        seed=field("seed", int, lambda v: 0 <= v < 2**63),
        noise=field("noise", bool),
        duration_s=float(field("duration_s", number, lambda v: 0 < v <= MAX_RUN_S)),
        params=params,
        requirements=requirements,
        robustness={str(k): float(v) for k, v in robustness.items() if isinstance(v, (int, float))},
        source=str(path),
        flick=flick,
        setpoint_m=optional.get("setpoint_m"),
    )


def as_json(replay: Replay) -> dict[str, Any]:
    """What a summary says of a replayed run's source."""
    return {"file": replay.source, "robustness_stated": replay.robustness}


def refuse_given(options: list[tuple[str, Any]]) -> None:
    """Refuse the options (option, value; None: not given) that a replay brings itself."""
    given = [option for option, value in options if value is not None and value is not False]
    if given:
        raise ParameterError(f"--replay brings the run's own {', '.join(given)}: drop them")


def replay_entry(
    controller: str, run: dict[str, Any], noise: bool, duration_s: float, spec: Spec
) -> dict[str, Any]:
    """A job's run as the file keeps it (``load_replay`` reads it back): ``run`` is its record with the run's
    ``parameters`` (``Parameters.changed``) and each requirement's robustness."""
    return {
        "controller": controller,
        "x0_m": run["x0_m"],
        "theta0_rad": run["theta0_rad"],
        "seed": run["seed"],
        "noise": noise,
        "duration_s": duration_s,
        "parameters": run["parameters"],
        "requirements": {r.name: r.formula for r in spec.requirements},
        "robustness": run["requirements"],
        "ball_lost": run["ball_lost"],
    }
