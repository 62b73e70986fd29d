"""Requirements as signal temporal logic over a run's signals: each a named formula, each run's robustness (how
far from violation, in the signal's units; negative: violated) from rtamt's discrete-time monitor.

A requirements file is TOML::

    [requirements]
    kept     = "always (abs(x_m) <= 0.3)"
    settles  = "eventually[0:5] always (abs(x_m - setpoint_m) <= 0.01)"
    no_stops = "always (abs(theta_rad) <= 0.75)"

The signals (``SIGNALS``) are sampled at the DAQ's ticks from release on: the true state at each block's end,
what the software measured (the block's readings through the rig software's calibration), the setpoint, the
motor and DAC volts, whether the motor is at its rails and whether the ball is lost. Time in a formula is seconds
from the first released tick; the 1 kHz physics between ticks is not seen by the monitor (a requirement on an
excursion shorter than a period is checked at the ticks only). The robustness is the formula's at time 0.
"""

from __future__ import annotations

import logging
import math
import tomllib
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.parameters import ParameterError, read_input_file

if TYPE_CHECKING:
    from twin.log import RunLog
    from twin.parameters import Parameters

__all__ = ["SIGNALS", "Requirement", "load_requirements", "parse_requirements", "robustness", "run_signals"]

# The signals a formula may name: unit and meaning.
SIGNALS: Mapping[str, tuple[str, str]] = {
    "x_m": ("m", "true ball position along the beam"),
    "xdot_m_s": ("m/s", "true ball velocity"),
    "theta_rad": ("rad", "true beam angle"),
    "thetadot_rad_s": ("rad/s", "true beam rate"),
    "x_meas_m": ("m", "ball position the software measured (eq 6.3.1)"),
    "theta_meas_rad": ("rad", "beam angle the software measured (eq 6.2.10)"),
    "setpoint_m": ("m", "the ball setpoint"),
    "motor_v": ("V", "volts across the motor"),
    "dac_v": ("V", "the DAC command"),
    "at_rail": ("0/1", "1 while the motor is at the amplifier's rails"),
    "lost": ("0/1", "1 from the tick the ball is lost on"),
}
MAX_REQUIREMENTS = 100
MAX_FORMULA_CHARS = 2000


@dataclass(frozen=True)
class Requirement:
    name: str
    formula: str


def parse_requirements(data: Any, where: str) -> tuple[Requirement, ...]:
    """The ``[requirements]`` table of a parsed file, each formula parsed once to be refused here (a
    ``ParameterError`` naming ``where``, the requirement and what is wrong) rather than in a run."""
    table = data.get("requirements") if isinstance(data, dict) else None
    if not isinstance(table, dict) or not table:
        raise ParameterError(f'{where}: no [requirements] table of name = "formula" entries')
    if len(table) > MAX_REQUIREMENTS:
        raise ParameterError(f"{where}: {len(table)} requirements; at most {MAX_REQUIREMENTS}")
    out = []
    for name, formula in table.items():
        if not isinstance(formula, str) or not formula.strip():
            raise ParameterError(f"{where}: requirement {name!r} = {formula!r}: a formula in quotes")
        if len(formula) > MAX_FORMULA_CHARS:
            raise ParameterError(
                f"{where}: requirement {name!r}: a formula of at most {MAX_FORMULA_CHARS} characters"
            )
        requirement = Requirement(str(name), formula.strip())
        try:
            _monitor(requirement, 0.02)
        except Exception as exc:  # noqa: BLE001 - rtamt's parser raises its own types
            raise ParameterError(f"{where}: requirement {name!r}: {_say(exc)}") from None
        out.append(requirement)
    return tuple(out)


def load_requirements(path: str | Path) -> tuple[Requirement, ...]:
    """The requirements of a TOML file (see the module's doc)."""
    raw = read_input_file(path, "requirements file", "a few kB")
    try:
        data = tomllib.loads(raw.decode("utf-8-sig"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ParameterError(f"{path}: not a TOML requirements file: {exc}") from None
    return parse_requirements(data, str(path))


def _say(exc: BaseException) -> str:
    """rtamt's complaint in one line: an unknown name as such, a syntax error without its token list."""
    if isinstance(exc, KeyError):
        return f"unknown signal {exc}; the signals: {', '.join(SIGNALS)}"
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text.replace("RTAMT Exception: ", "").split(" expecting ")[0]


def _monitor(requirement: Requirement, period_s: float) -> Any:
    """rtamt's discrete-time monitor of one formula over ``SIGNALS`` sampled every ``period_s``. A name that is
    not a signal is rtamt's ``KeyError`` (after a warning on the root logger, which is kept quiet here)."""
    with warnings.catch_warnings():  # rtamt's generated parser imports typing.io (deprecated)
        warnings.simplefilter("ignore", DeprecationWarning)
        import rtamt  # type: ignore[import-untyped]

    spec = rtamt.StlDiscreteTimeSpecification()
    for name in SIGNALS:
        spec.declare_var(name, "float")
    spec.set_sampling_period(period_s, "s", 0.1)
    spec.spec = requirement.formula
    previous = logging.root.manager.disable
    logging.disable(logging.WARNING)
    try:
        spec.parse()
    finally:
        logging.disable(previous)
    return spec


def run_signals(log: RunLog, params: Parameters, setpoint_m: float = 0.0) -> dict[str, np.ndarray]:
    """The signals of a run the twin recorded (its log has the true state), at its released ticks."""
    from twin.converters import ball_position_m, beam_angle_rad
    from twin.verdict import at_rail

    t = np.asarray(log.true_time_s, dtype=float)
    released = t >= 0.0
    sw = params.software
    motor = np.asarray(log.motor_volts_v, dtype=float)[released]
    lost = np.asarray(log.ball_lost, dtype=bool)[released]
    return {
        "time": t[released] - t[released][0] if released.any() else t[released],
        "x_m": np.asarray(log.true_x_m, dtype=float)[released],
        "xdot_m_s": np.asarray(log.true_xdot_m_s, dtype=float)[released],
        "theta_rad": np.asarray(log.true_theta_rad, dtype=float)[released],
        "thetadot_rad_s": np.asarray(log.true_thetadot_rad_s, dtype=float)[released],
        "x_meas_m": np.asarray(ball_position_m(np.asarray(log.datam1, dtype=float), sw))[released],
        "theta_meas_rad": np.asarray(beam_angle_rad(np.asarray(log.datam2, dtype=float), sw))[released],
        "setpoint_m": np.full(int(released.sum()), float(setpoint_m)),
        "motor_v": motor,
        "dac_v": np.asarray(log.aout, dtype=float)[released],
        "at_rail": at_rail(motor, params.amplifier.rail_v).astype(float),
        "lost": np.maximum.accumulate(lost).astype(float),
    }


def robustness(
    requirements: tuple[Requirement, ...], signals: Mapping[str, np.ndarray], period_s: float
) -> dict[str, float]:
    """Each requirement's robustness at time 0 over ``signals`` (``run_signals``); NaN for a run with no tick."""
    times = np.asarray(signals["time"], dtype=float)
    if not times.size:
        return {r.name: math.nan for r in requirements}
    # rtamt keys its samples by time: whole periods from 0 (the ticks' times carry the physics' rounding)
    data = {"time": (np.round(times / period_s) * period_s).tolist()}
    data.update({name: np.asarray(signals[name], dtype=float).tolist() for name in SIGNALS})
    out = {}
    for r in requirements:
        values = _monitor(r, period_s).evaluate(data)
        out[r.name] = float(values[0][1])
    return out
