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

Five signals are statistics over the trailing window (``WINDOWED`` and ``rail_share``): at the last tick they
are the verdict's final-window mean, peak-to-peak and saturated share. On a finite run ``eventually always P``
is P at the last tick (its robustness too), so the verdict's checks are formulas
(docs/examples/requirements.toml); a run shorter than the window has windows of what there is.

Every formula is checked when its file is loaded, before any run (``parse_requirements``: bounds below 0 or
reversed, numbers not finite, division by other than a non-zero number, sqrt/exp/pow, nesting; then
``check_timing`` against the run's period and duration), and each robustness is stated finite (``stated``):
whatever a command writes is valid JSON that ``run --replay`` reads back.
"""

from __future__ import annotations

import functools
import logging
import math
import re
import tomllib
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.parameters import ParameterError, read_input_file

if TYPE_CHECKING:
    from twin.log import RunLog
    from twin.parameters import Parameters

__all__ = [
    "ROBUSTNESS_LIMIT",
    "SIGNALS",
    "Requirement",
    "Spec",
    "check_timing",
    "load_requirements",
    "load_spec",
    "margins",
    "named",
    "parse_requirements",
    "robustness",
    "run_signals",
    "stated",
    "violated",
]

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
    # Over the trailing window (the verdict's final window, twin.verdict.Criteria.window_s): at the last tick
    # these are the verdict's steady state, limit cycle and saturated share, bit for bit.
    "x_mean_m": ("m", "mean of x_m over the trailing window (the ticks within window_s before)"),
    "theta_mean_rad": ("rad", "mean of theta_rad over the trailing window"),
    "x_pp_m": ("m", "peak-to-peak of x_m over the trailing window"),
    "theta_pp_rad": ("rad", "peak-to-peak of theta_rad over the trailing window"),
    "rail_share": ("0…1", "share of the ticks since release with the motor at its rails"),
}
# The signals computed from the others over the trailing window, only when a formula names them.
WINDOWED: dict[str, tuple[str, Callable[[np.ndarray], Any]]] = {
    "x_mean_m": ("x_m", np.mean),
    "theta_mean_rad": ("theta_rad", np.mean),
    "x_pp_m": ("x_m", np.ptp),
    "theta_pp_rad": ("theta_rad", np.ptp),
}
MAX_REQUIREMENTS = 100
MAX_FORMULA_CHARS = 2000
# Operators and parentheses nested deeper than this are refused: rtamt's parser and monitor recurse per level.
MAX_NESTING = 40
# A robustness beyond ±this (±inf: e.g. `eventually` over a window where the run has no tick, or a bound no
# number reaches) or undefined (NaN: inf − inf, a run with no tick) is stated as ±this, NaN as −this (it
# counts as violated): JSON has no infinities, and every file a command writes is one its reader accepts.
ROBUSTNESS_LIMIT = 1e100
# Arithmetic whose result can fail on a run's values (a negative under sqrt, an overflowing exp): refused
# when the file is loaded, rather than after the run. Division is allowed by a non-zero number only.
REFUSED_FUNCTIONS = {"Sqrt": "sqrt", "Exp": "exp", "Pow": "pow"}


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
            shown = (
                repr(formula) if isinstance(formula, (int, float, bool)) else f"a {type(formula).__name__}"
            )
            raise ParameterError(f"{where}: requirement {name!r} = {shown[:80]}: a formula in quotes")
        if len(formula) > MAX_FORMULA_CHARS:
            raise ParameterError(
                f"{where}: requirement {name!r}: a formula of at most {MAX_FORMULA_CHARS} characters"
            )
        requirement = Requirement(str(name), formula.strip())
        depth = _paren_depth(requirement.formula)
        if depth > MAX_NESTING:
            raise ParameterError(
                f"{where}: requirement {name!r}: parentheses nested {depth} deep; at most {MAX_NESTING}"
            )
        try:
            spec = _monitor(requirement, 0.02)
        except RecursionError:
            raise ParameterError(
                f"{where}: requirement {name!r}: operators nested too deep; at most {MAX_NESTING}"
            ) from None
        except Exception as exc:  # noqa: BLE001 - rtamt's parser raises its own types
            raise ParameterError(f"{where}: requirement {name!r}: {_say(exc)}") from None
        problem = _shape_problem(spec.ast.specs[0], 1)
        if problem:
            raise ParameterError(f"{where}: requirement {name!r}: {problem}")
        out.append(requirement)
    return tuple(out)


def _paren_depth(formula: str) -> int:
    depth = deepest = 0
    for char in formula:
        depth += (char == "(") - (char == ")")
        deepest = max(deepest, depth)
    return deepest


def _shape_problem(node: Any, depth: int) -> str | None:
    """What makes a parsed formula unfit to judge whatever the run (None: nothing): nesting deeper than
    ``MAX_NESTING``, a number that is not finite, a division by other than a non-zero number, a function
    whose value can fail on a run (``REFUSED_FUNCTIONS``), a time bound below 0 or above its other end."""
    kind = type(node).__name__
    if depth > MAX_NESTING:
        return f"operators nested deeper than {MAX_NESTING}"
    if kind == "Constant" and not math.isfinite(float(node.val)):
        return f"the number {node.val} is not finite"
    if kind in REFUSED_FUNCTIONS:
        return (
            f"{REFUSED_FUNCTIONS[kind]}(…) can fail on a run's values (a negative under sqrt or pow, an "
            "exp that overflows): write the comparison without it (sqrt(a) <= c as a <= c*c)"
        )
    if kind == "Division":
        divisor = node.children[1]
        if type(divisor).__name__ != "Constant":
            return (
                f"divides by {divisor.name}, which a run can make 0: divide by a number only "
                "(a / y <= c as a <= c * y for y > 0)"
            )
        if float(divisor.val) == 0.0:
            return f"divides by {divisor.name}: division by zero"
    if hasattr(node, "begin_unit"):  # a timed operator: its interval [begin, end]
        begin, end = _bound_s(node.begin, node.begin_unit), _bound_s(node.end, node.end_unit)
        if begin < 0 or end < 0:
            return f"{_interval(node)}: a time bound below 0 s (time runs from the tick judged on)"
        if begin > end:
            return (
                f"{_interval(node)}: the lower bound {float(begin):g} s is above the upper {float(end):g} s"
            )
    for child in node.children:
        problem = _shape_problem(child, depth + 1)
        if problem:
            return problem
    return None


# rtamt's time units in its own integer base (nanoseconds); a bound without a unit is in seconds.
_UNIT_NS = {"s": 10**9, "ms": 10**6, "us": 10**3, "ns": 1}


def _bound_s(value: Any, unit: str) -> Fraction:
    return Fraction(value) * _UNIT_NS[unit or "s"] / _UNIT_NS["s"]


def _interval(node: Any) -> str:
    """A timed operator as written, its bounds in seconds: ``eventually[0:5]``."""
    operator = type(node).__name__.removeprefix("Timed").lower()
    begin, end = _bound_s(node.begin, node.begin_unit), _bound_s(node.end, node.end_unit)
    return f"{operator}[{float(begin):g}:{float(end):g}]"


# The past-time operators: they look back from the tick judged, not ahead.
_LOOKING_BACK = {"TimedOnce", "TimedHistorically", "TimedSince"}


def _horizon_problem(node: Any, period_ns: Fraction, duration_s: float, ahead: Fraction) -> str | None:
    """The first timed operator whose bounds are not whole DAQ periods or that looks (with the operators it
    is nested in) past the run's end; ``ahead``: how far its parents already look, in seconds."""
    if hasattr(node, "begin_unit"):
        for value, unit in ((node.begin, node.begin_unit), (node.end, node.end_unit)):
            ticks = Fraction(value) * _UNIT_NS[unit or "s"] / period_ns
            if ticks.denominator != 1:
                period_s = float(period_ns / _UNIT_NS["s"])
                low, high = math.floor(ticks) * period_s, math.ceil(ticks) * period_s
                return (
                    f"{_interval(node)}: {float(_bound_s(value, unit)):g} s is not a whole number of DAQ periods "
                    f"({period_s:g} s): the nearest are {low:.10g} and {high:.10g} s"
                )
        if type(node).__name__ not in _LOOKING_BACK:
            ahead += _bound_s(node.end, node.end_unit)
        if ahead > Fraction(duration_s):
            return (
                f"{_interval(node)}: looks {float(ahead):g} s ahead (with the operators around it), past "
                f"the run's {duration_s:g} s"
            )
    for child in node.children:
        problem = _horizon_problem(child, period_ns, duration_s, ahead)
        if problem:
            return problem
    return None


def check_timing(
    requirements: tuple[Requirement, ...], where: str, period_s: float, duration_s: float
) -> None:
    """Refuse (``ParameterError`` naming ``where``, the requirement and the bound) a formula whose time bounds
    are not whole DAQ periods of ``period_s`` or look past a run of ``duration_s``: checked before a run, as
    rtamt's monitor refuses the one and pads the other beyond the run with ±inf (and memory)."""
    # rtamt's own arithmetic: the period in its nanoseconds, exactly as it converts a float period
    period_ns = Fraction(float(period_s) * _UNIT_NS["s"])
    for r in requirements:
        problem = _horizon_problem(_monitor(r, 0.02).ast.specs[0], period_ns, duration_s, Fraction(0))
        if problem:
            raise ParameterError(f"{where}: requirement {r.name!r}: {problem}")


@dataclass(frozen=True)
class Spec:
    """A requirements file: its requirements and, from its optional ``[validate]`` table, which of them each
    of validate's checks asks of its runs (``check = ["name", …]``; a check not listed asks all)."""

    requirements: tuple[Requirement, ...]
    checks: Mapping[str, tuple[str, ...]]
    source: str

    def asked(self, check: str) -> tuple[Requirement, ...]:
        names = self.checks.get(check)
        return self.requirements if names is None else tuple(r for r in self.requirements if r.name in names)


def load_spec(path: str | Path, checks: tuple[str, ...] = ()) -> Spec:
    """A requirements file (see the module's doc); ``checks``: the names its ``[validate]`` table may use."""
    raw = read_input_file(path, "requirements file", "a few kB")
    try:
        data = tomllib.loads(raw.decode("utf-8-sig"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ParameterError(f"{path}: not a TOML requirements file: {exc}") from None
    except RecursionError:
        raise ParameterError(
            f"{path}: tables or arrays nested too deep for a requirements file (one [requirements] table "
            'of name = "formula")'
        ) from None
    requirements = parse_requirements(data, str(path))
    extra = sorted(set(data) - {"requirements", "validate"})
    if extra:
        raise ParameterError(
            f"{path}: unknown table {extra[0]!r}; a requirements file has [requirements], [validate]"
        )
    names = {r.name for r in requirements}
    table = data.get("validate", {})
    if not isinstance(table, dict):
        raise ParameterError(f'{path}: [validate] is a table of check = ["requirement", …]')
    asked: dict[str, tuple[str, ...]] = {}
    for check, listed in table.items():
        if checks and check not in checks:
            raise ParameterError(
                f"{path}: [validate] {check!r} is not a check; the checks: {', '.join(checks)}"
            )
        if not isinstance(listed, list) or not all(isinstance(n, str) for n in listed):
            raise ParameterError(f"{path}: [validate] {check} = {listed!r}: a list of requirement names")
        unknown = [n for n in listed if n not in names]
        if unknown:
            raise ParameterError(
                f"{path}: [validate] {check}: no requirement {unknown[0]!r} in [requirements]"
            )
        asked[check] = tuple(listed)
    return Spec(requirements, asked, str(path))


def load_requirements(path: str | Path) -> tuple[Requirement, ...]:
    """The requirements of a TOML file (see the module's doc)."""
    return load_spec(path).requirements


def _say(exc: BaseException) -> str:
    """rtamt's complaint in one line: an unknown name as such, a syntax error without its token list."""
    if isinstance(exc, KeyError):
        return f"unknown signal {exc}; the signals: {', '.join(SIGNALS)}"
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text.replace("RTAMT Exception: ", "").split(" expecting ")[0]


def _monitor(requirement: Requirement, period_s: float) -> Any:
    """rtamt's discrete-time monitor of one formula over ``SIGNALS`` sampled every ``period_s`` (parsed once per
    process: a parse costs ~90 ms, an evaluation of 750 ticks ~2 ms, and rtamt's offline evaluation keeps no
    state between runs). A name that is not a signal is rtamt's ``KeyError``."""
    return _parsed(requirement.formula, float(period_s))


@functools.lru_cache(maxsize=256)
def _parsed(formula: str, period_s: float) -> Any:
    with warnings.catch_warnings():  # rtamt's generated parser imports typing.io (deprecated)
        warnings.simplefilter("ignore", DeprecationWarning)
        import rtamt  # type: ignore[import-untyped]

    spec = rtamt.StlDiscreteTimeSpecification()
    for name in SIGNALS:
        spec.declare_var(name, "float")
    spec.set_sampling_period(period_s, "s", 0.1)
    spec.spec = formula
    previous = logging.root.manager.disable
    logging.disable(logging.WARNING)  # rtamt warns on the root logger before its KeyError
    try:
        spec.parse()
    finally:
        logging.disable(previous)
    return spec


def named(requirements: tuple[Requirement, ...]) -> set[str]:
    """The signals the formulas name."""
    words = set(re.findall(r"[A-Za-z_][A-Za-z0-9_]*", " ".join(r.formula for r in requirements)))
    return words & set(SIGNALS)


def run_signals(
    log: RunLog, params: Parameters, setpoint_m: float = 0.0, names: set[str] | None = None
) -> dict[str, np.ndarray]:
    """The signals of a run the twin recorded (its log has the true state), at its released ticks. The
    trailing-window signals (``WINDOWED``) are computed only when in ``names`` (None: all); the others are
    zeros then (a formula that names them gets them)."""
    from twin.converters import ball_position_m, beam_angle_rad
    from twin.verdict import Criteria, at_rail

    t_all = np.asarray(log.true_time_s, dtype=float)
    released = t_all >= 0.0
    t = t_all[released]
    sw = params.software
    motor = np.asarray(log.motor_volts_v, dtype=float)[released]
    lost = np.asarray(log.ball_lost, dtype=bool)[released]
    rails = at_rail(motor, params.amplifier.rail_v).astype(float)
    out = {
        "time": t - t[0] if t.size else t,
        "x_m": np.asarray(log.true_x_m, dtype=float)[released],
        "xdot_m_s": np.asarray(log.true_xdot_m_s, dtype=float)[released],
        "theta_rad": np.asarray(log.true_theta_rad, dtype=float)[released],
        "thetadot_rad_s": np.asarray(log.true_thetadot_rad_s, dtype=float)[released],
        "x_meas_m": np.asarray(ball_position_m(np.asarray(log.datam1, dtype=float), sw))[released],
        "theta_meas_rad": np.asarray(beam_angle_rad(np.asarray(log.datam2, dtype=float), sw))[released],
        "setpoint_m": np.full(t.size, float(setpoint_m)),
        "motor_v": motor,
        "dac_v": np.asarray(log.aout, dtype=float)[released],
        "at_rail": rails,
        "lost": np.maximum.accumulate(lost).astype(float),
        "rail_share": np.cumsum(rails) / np.arange(1, t.size + 1),
    }
    # The window's first tick for each tick, by the verdict's own test (t ≥ t_i − window_s).
    first = np.searchsorted(t, t - Criteria().window_s, side="left")
    for name, (source, statistic) in WINDOWED.items():
        if names is not None and name not in names:
            out[name] = np.zeros(t.size)
            continue
        x = out[source]
        out[name] = np.array([statistic(x[j : i + 1]) for i, j in enumerate(first.tolist())], dtype=float)
    return out


def robustness(
    requirements: tuple[Requirement, ...], signals: Mapping[str, np.ndarray], period_s: float
) -> dict[str, float]:
    """Each requirement's robustness at time 0 over ``signals`` (``run_signals``) as ``stated`` (a run with no
    tick: −``ROBUSTNESS_LIMIT``, nothing to judge)."""
    times = np.asarray(signals["time"], dtype=float)
    if not times.size:
        return {r.name: stated(math.nan) for r in requirements}
    # rtamt keys its samples by time: whole periods from 0 (the ticks' times carry the physics' rounding)
    data = {"time": (np.round(times / period_s) * period_s).tolist()}
    data.update({name: np.asarray(signals[name], dtype=float).tolist() for name in SIGNALS})
    out = {}
    for r in requirements:
        try:
            values = _monitor(r, period_s).evaluate(data)
        except (ArithmeticError, ValueError) as exc:  # what parse_requirements cannot rule out
            raise ParameterError(f"requirement {r.name!r} = {r.formula!r}: on this run: {exc}") from None
        out[r.name] = stated(float(values[0][1]))
    return out


def stated(value: float) -> float:
    """A robustness as it is stated (``ROBUSTNESS_LIMIT``): finite, NaN as −limit."""
    if math.isnan(value):
        return -ROBUSTNESS_LIMIT
    return min(max(value, -ROBUSTNESS_LIMIT), ROBUSTNESS_LIMIT)


def margins(
    requirements: tuple[Requirement, ...], log: RunLog, params: Parameters, setpoint_m: float = 0.0
) -> dict[str, float]:
    """Each requirement's robustness over the run of ``log`` (``run_signals`` then ``robustness``)."""
    signals = run_signals(log, params, setpoint_m, named(requirements))
    return robustness(requirements, signals, params.period_s)


def violated(values: Mapping[str, float]) -> list[str]:
    """The requirements whose robustness is negative (or NaN)."""
    return [name for name, value in values.items() if not value >= 0]
