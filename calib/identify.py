"""Dynamic identification from closed-loop rig logs: multiple shooting on the smooth model.

What the rig records is the ball channel (last sample of each block), the angle channel (block mean) and
the DAC command of each 20 ms tick. The plant is open-loop unstable and the logs are closed-loop, so the
recorded volts cannot be replayed open-loop over a whole log. The log is cut into short windows (1 s by
default); each window's initial state (x, θ, ẋ, θ̇) is a free parameter, and the chosen rig parameters are
shared by all windows (multiple shooting). The state is continuous, so each window's end must meet the next
window's start (soft continuity residuals, ``CONTINUITY_SIGMA``): without them every window's velocities are
nuisance parameters fitted to one second of data, and the pivot damping came out 5–27 % high on twin logs.

The model is the smooth one: the reference equations (twin.reference.EquationCoefficients) integrated by RK4
in numpy across all windows at once, with ideal converters — quantization is treated as noise, because a
quantizer inside the fitted loop breaks finite-difference Jacobians. What the sensors do that matters is
modelled:

* angle channel: the block-mean volts turned back into the mean counter value (twin.sensors.
  angle_counter_mean: the AD561 and ADC levels inverted, which removes the ADC's rounding of each level,
  a bias of up to 0.44 mrad that eq 6.2.10 keeps), modelled as the mean of θ over the 20 ms block
  (trapezoid over the sub-steps) minus the encoder's zeroing error (leaving the block mean out biases the
  pivot damping);
* ball channel: the sensor's static curve (twin.sensors.wiper_static_v) at x delayed by the RC time
  constant, read through the software's eq 6.3.1, with an optional gain and offset relative to it;
* command: the amplifier 9.6·(u − 2.5) within ±12 V (twin.output_stage.amplifier_volts), switched
  ``daq.output_latency_s`` after the tick, into the motor law (twin.dcmotor.torque_nm).

The loss is robust (``soft_l1``: quadratic within 2 σ, linear beyond), so the ball channel's contact-noise
outliers do not pull the fit. Residuals are in units of the channels' nominal noise. The Jacobian is taken by
forward differences with the columns that share no residual perturbed together, all in one batched
simulation. Intervals come from the cluster-robust (sandwich) covariance with 5 s of log per cluster and
Student's t, because the residuals are correlated in time and the white-noise intervals are optimistic;
the model's own resolution (``MODEL_RESOLUTION``, derived by a coverage study) is added to them.
"""

from __future__ import annotations

import dataclasses
import math
import time
import tomllib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import scipy.ndimage
import scipy.optimize
import scipy.sparse
import scipy.sparse.linalg
import scipy.stats

from calib.adequacy import ChannelAdequacy, channel_adequacy
from calib.logs import DAC_STEP_V, RigLog, check_period
from twin.converters import ball_position_m
from twin.dcmotor import torque_nm
from twin.log import LogError
from twin.output_stage import amplifier_volts
from twin.parameters import READING, Amplifier, Parameters, declaration, within_bounds
from twin.reference import EquationCoefficients, rk4_step
from twin.sensors import angle_count_step_rad, angle_counter_mean, wiper_static_v

__all__ = [
    "FITTABLE",
    "Calibration",
    "CalibrationError",
    "DroppedWindow",
    "FitSpec",
    "FittedValue",
    "WindowProblem",
    "calibrate",
]

# Nominal noise of the two channels, the unit of the residuals: the ball reading's ADC step is 0.17 mm and
# Table 6.3's curve carries sub-millimetre error; the angle reading is one encoder count (3.5 mrad)
# averaged over the block, 1 mrad as a uniform quantization's standard deviation.
SIGMA_BALL_M = 0.5e-3
SIGMA_ANGLE_RAD = 1.0e-3
# soft_l1's transition, in σ: residuals beyond 2 σ count linearly (contact-noise outliers).
ROBUST_SCALE = 2.0
# Bounds of the window states (x m, θ rad, ẋ m/s, θ̇ rad/s) and their typical sizes (optimizer scaling).
STATE_BOUNDS = (np.array([-0.5, -1.0, -5.0, -30.0]), np.array([0.5, 1.0, 5.0, 30.0]))
STATE_SCALE = np.array([0.05, 0.05, 0.2, 0.5])
# How far a window's end may miss the next window's start (x m, θ rad, ẋ m/s, θ̇ rad/s): what the DAC's
# 11.7 mV steps and unmodelled friction can push the state in a second — the rig's state is continuous.
CONTINUITY_SIGMA = np.array([0.2e-3, 0.5e-3, 5e-3, 20e-3])
CONFIDENCE = 0.95
# The smooth model's own resolution: what the fit misses beyond its statistical interval (quantization
# treated as noise, the smooth model against a MuJoCo twin or another simulator), added to the statistical
# half-widths in quadrature as (relative to the value, absolute). Derived, not chosen: the coverage study
# (scripts/calib_coverage.py --derive) fits logs of rigs drawn from a spread on the twin and on an
# independent simulator and writes the smallest floors that put 95 % of its fits' truths inside their
# intervals; held-out seeds check them (docs/design.md, "Coverage of the 95 % intervals").
RESOLUTION_FILE = Path(__file__).resolve().parent / "resolution.toml"


def _resolution_file(path: Path = RESOLUTION_FILE) -> tuple[dict[str, tuple[float, float]], dict[str, float]]:
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    floors = {name: (float(f["relative"]), float(f["absolute"])) for name, f in data["floors"].items()}
    return floors, {k: float(v) for k, v in data["scope"].items()}


# MODEL_RESOLUTION: per parameter (relative, absolute). RESOLUTION_SCOPE: what the study's rigs spanned that
# the fit does not fit — its ball sensors' contact losses up to ``contact_loss_rate_hz_max`` per second.
MODEL_RESOLUTION, RESOLUTION_SCOPE = _resolution_file()
# Residuals stay correlated over seconds (a still beam reads the same encoder level; the reference model's
# small errors against the rig): the intervals treat each 5 s of log as one independent cluster.
CLUSTER_S = 5.0
# A fit's progress: (evaluations done, evaluation budget, stage).
Progress = Callable[[int, int, str], None]


# Windows the smooth model cannot be trusted on are dropped before the fit (a warning names them):
# * a window holding a stretch of RAILED_TICKS or more consecutive ticks with the amplifier at a rail (a
#   command within one DAC step of it or beyond): for 100 ms the loop is open (the command carries no
#   feedback), and a real amplifier's output there follows its current limit and supply sag, which §6.4's
#   clipped line does not model. Single railed ticks are common and harmless: 7.8 % of the recommended
#   experiment's ticks on the independent rig, in runs of 1–4 but for one of 6; a fit of a log railed 33 % of
#   the time in runs of 1–4 (a clipping that the model reproduces exactly) recovers every parameter within
#   its interval (docs/design.md);
# * the ball lost, and everything after it in that log (``_ball_lost_from``).
RAILED_TICKS = 5
# The ball is lost from the first tick whose reading is within a ball radius of ±track.half_length_m (it is
# against a stop or leaving the wires), or from where the log's last LOST_TICKS or more readings sit at the
# open wiper's volts (±LOST_BAND_V: a few ADC steps of noise) after a jump of more than LOST_JUMP_M in one
# tick: the ball left the spring and the open wiper reads as a ball near the centre. A contact loss lasts
# ``ball_sensor.dropout_mean_duration_s`` (0.5 ms), never 10 ticks; 0.05 m in 20 ms is 2.5 m/s, beyond what a
# ball rolling the whole 0.65 m beam at the stops' 43° reaches (1.9 m/s); the windows from
# LOST_MARGIN_TICKS before it go too (the ball leaving one wire first).
LOST_TICKS = 10
LOST_BAND_V = 0.05
LOST_JUMP_M = 0.05
LOST_MARGIN_TICKS = 5


def _longest_run(flags: np.ndarray) -> int:
    """The longest stretch of consecutive True values."""
    edges = np.diff(np.concatenate([[0], flags.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return int((ends - starts).max()) if starts.size else 0


def _ball_lost_from(ball_v: np.ndarray, yb: np.ndarray, p: Parameters) -> int:
    """The first tick of a log from which the ball is lost (its length when never)."""
    n = int(ball_v.size)
    lost = n
    at_end = np.flatnonzero(np.abs(yb) >= p.track.half_length_m - p.ball.radius_m)
    if at_end.size:
        lost = int(at_end[0])
    open_wiper = np.abs(ball_v - p.ball_sensor.dropout_voltage_v) <= LOST_BAND_V
    if open_wiper[-1]:
        first = n - int(np.argmin(open_wiper[::-1])) if not open_wiper.all() else 0
        if n - first >= LOST_TICKS and first > 0 and abs(yb[first] - yb[first - 1]) > LOST_JUMP_M:
            lost = min(lost, first)
    return max(0, lost - LOST_MARGIN_TICKS) if lost < n else n


@dataclass(frozen=True)
class DroppedWindow:
    """A window left out of the fit, and why."""

    path: str
    start_s: float  # its first tick's time (timem)
    reason: str  # "railed" or "ball lost"


# Model adequacy (calib.adequacy), thresholds measured on fits whose model is right (twin logs and the
# independent rig with the fitted effects only: residual RMS 0.4–0.7× the floor, |ρ(1)| ≤ 0.26, the most a
# regulated beam sitting on one encoder level gives) and on the audit's mismatched cases (docs/design.md): a
# channel is mismatched when its residual RMS is over MISMATCH_RATIO × its floor, or when its residual is
# coloured, |ρ(1)| > COLOURED_LAG1, whatever its size: a missing effect acts through the dynamics and
# leaves a residual correlated over many ticks (a rail at 9 V the model puts at 12 V: angle 1.3× its floor
# but ρ(1) = 0.74, the damping 9 % off), where white excess is only contact noise heavier than the floor,
# which the intervals already carry.
MISMATCH_RATIO = 3.0
COLOURED_LAG1 = 0.5
# The ticks near the rails: within NEAR_RAILS_TICKS after a command beyond NEAR_RAILS_SHARE of the rail.
NEAR_RAILS_TICKS = 5
NEAR_RAILS_SHARE = 0.5
# Effects a mismatch is refitted with, freed one at a time, to name the one that explains it.
RAIL = "amplifier.rail_v"
# The rail's refit starts below the modelled rail: at the rail no command is clipped and the residual does
# not depend on it (a zero gradient); from below, the fit moves it up to where clipping stops mattering.
RAIL_START_SHARE = 0.75
DIAGNOSTIC_EFFECTS = {
    "beam.pivot_friction_nm": "Coulomb (dry) friction in the pivot",
    RAIL: "the amplifier saturating below its modelled rail",
}
# Weak excitation: a parameter whose statistical standard deviation exceeds its bound (relative, or absolute) is
# only loosely determined by the logs: measured on the independent rig (tests/independent_rig.py, seeds 1–3,
# 60 s, the damping at 1e-3 N·m·s/rad) for the recommended experiment (resistance ≤ 0.01 %, inertia 0.02 %,
# damping 0.27–0.37 %, zeroing 0.03 mrad) against regulation without setpoint moves or dither (0.02 %,
# 0.11–0.16 %, 2.0–3.2 %, 0.03–0.05 mrad), docs/design.md. A relative bound is taken of the larger of the
# value and the parameter's typical size (``FitSpec.scale``) when the value can be 0 (its search range
# reaches 0): the pivot damping's statistical deviation hardly depends on its value, and a rig whose damping
# is near 0 (the twin's: 0) would otherwise be "loosely determined" by any log — the manual's recipe on the
# twin, 2.3e-5 ± 0.79e-5 N·m·s/rad, is 34 % of its value and 0.79 % of its typical size 1e-3.
WEAK_EXCITATION: dict[str, tuple[str, float]] = {
    "motor.resistance_ohm": ("relative", 0.01),
    "beam.inertia_pivot_kgm2": ("relative", 0.01),
    "beam.pivot_damping_nm_s_per_rad": ("relative", 0.015),
    "angle_sensor.zeroing_error_rad": ("absolute", 0.3e-3),
}
# Two fitted values the logs barely separate: |correlation| beyond this (a warning; with one of them loose, the
# problem names the correlation, ``_excitation_problems``).
INSEPARABLE_CORRELATION = 0.95
INTERVAL_METHOD = (
    f"cluster-robust (sandwich) covariance, {CLUSTER_S:g} s clusters, Student's t, plus the model's resolution "
    "(derived by a coverage study) in quadrature"
)


class CalibrationError(ValueError):
    """The fit cannot be set up as asked (unknown parameter, logs of different periods, …)."""


@dataclass(frozen=True)
class FitSpec:
    """A quantity the fit can estimate: the range the fit searches (``lower`` … ``upper``), its typical size
    (``scale``) and its meaning. Its unit and physical bounds are the parameter's own declaration
    (``twin.parameters.declaration``: the field's metadata; the ball reading's gain and offset, which are no
    field, ``twin.parameters.READING``); the search range, narrower where the logs of a bench-top rig allow it,
    lies within the physical bounds (checked here)."""

    name: str
    lower: float
    upper: float
    scale: float
    meaning: str

    def __post_init__(self) -> None:
        outside = [v for v in (self.lower, self.upper) if not within_bounds(self.name, v)]
        if outside or not self.lower < self.upper:
            raise ValueError(
                f"{self.name}: the search range [{self.lower!r}, {self.upper!r}] is not an interval within its "
                "physical bounds (twin.parameters)"
            )

    @property
    def unit(self) -> str:
        return str(declaration(self.name)["unit"])


FITTABLE: dict[str, FitSpec] = {
    s.name: s
    for s in (
        FitSpec("motor.resistance_ohm", 1.0, 50.0, 10.0, "armature resistance (drifts with temperature)"),
        FitSpec("beam.inertia_pivot_kgm2", 1e-3, 2e-2, 4e-3, "beam inertia about the pivot"),
        FitSpec("beam.pivot_damping_nm_s_per_rad", 0.0, 0.05, 1e-3, "pivot viscous friction"),
        FitSpec("beam.pivot_friction_nm", 0.0, 0.05, 1e-3, "pivot Coulomb friction"),
        FitSpec(
            "angle_sensor.zeroing_error_rad",
            -0.1,
            0.1,
            0.01,
            "beam angle at which the counter was zeroed",
        ),
        FitSpec(
            "track.contact_spacing_m",
            0.002,
            0.0166,
            0.01,
            "wire contact spacing d (sets r* = √(r² − d²/4))",
        ),
        FitSpec("daq.output_latency_s", 0.0, 0.018, 0.005, "delay from a block's end to the DAC update"),
        FitSpec("ball_reading.gain", 0.5, 1.5, 1.0, "ball reading's gain relative to the sensor curve"),
        FitSpec("ball_reading.offset_m", -0.05, 0.05, 0.005, "ball reading's offset relative to the curve"),
        FitSpec("ball_sensor.dropout_rate_hz", 0.0, 1000.0, 5.0, "contact losses of the ball's wiper"),
        FitSpec(
            "amplifier.rail_v", 1.0, 30.0, 12.0, "the amplifier's output limit (supply sag, current limit)"
        ),
    )
}
# Estimated after the dynamic fit from the ball channel's outliers (it does not enter the smooth model).
DROPOUT = "ball_sensor.dropout_rate_hz"
# A ball reading this far from the fitted model is a contact-noise outlier (6 σ of the channel's noise).
OUTLIER_M = 3e-3


@dataclass(frozen=True)
class FittedValue:
    value: float
    ci_low: float
    ci_high: float
    initial: float
    unit: str
    # The standard uncertainty behind the interval (statistical and model resolution combined): what a Monte
    # Carlo study samples, with the correlations.
    sd: float = math.nan
    # The interval's statistical half-width alone (Student's t × the cluster-robust deviation), before the
    # model's resolution is added: what the coverage study derives the resolution from.
    statistical_half: float = math.nan


@dataclass
class Calibration:
    """The result: the fitted parameter set (loads with ``--params``) and how well it is known."""

    params: Parameters
    values: dict[str, FittedValue]
    correlation: np.ndarray
    rms_before: dict[str, float]
    rms_after: dict[str, float]
    converged: bool
    message: str
    warnings: list[str]
    wall_s: float
    n_windows: int
    n_ticks: int
    ci_inflation: float
    traces: dict[str, np.ndarray] = field(default_factory=dict)
    # What makes the result untrustworthy (model mismatch, weak excitation): calibrate exits 1 when any.
    problems: list[str] = field(default_factory=list)
    adequacy: dict[str, ChannelAdequacy] = field(default_factory=dict)
    dropped: list[DroppedWindow] = field(default_factory=list)
    information_condition: float = math.nan
    diagnosis: str = ""
    interval_method: str = INTERVAL_METHOD
    # The parameters asked for that the logs do not identify (name: why): left out of ``values`` and kept at
    # their start value in ``params``; each is also a problem (calibrate exits 1).
    not_identifiable: dict[str, str] = field(default_factory=dict)

    @property
    def trustworthy(self) -> bool:
        return self.converged and not self.problems

    @property
    def correlation_names(self) -> list[str]:
        """The values ``correlation`` is over: the smooth fit's (the dropout rate is estimated apart)."""
        return [name for name in self.values if name != DROPOUT]

    def to_json(self) -> dict[str, object]:
        return {
            "params": {
                name: {
                    "value": v.value,
                    "ci_low": v.ci_low,
                    "ci_high": v.ci_high,
                    "initial": v.initial,
                    "sd": v.sd,
                    "statistical_half": v.statistical_half,
                    "unit": v.unit,
                }
                for name, v in self.values.items()
            },
            "correlation": {
                "names": self.correlation_names,
                "matrix": np.round(self.correlation, 4).tolist(),
            },
            "rms_residual": {
                "before": {k: round(v, 7) for k, v in self.rms_before.items()},
                "after": {k: round(v, 7) for k, v in self.rms_after.items()},
            },
            "converged": self.converged,
            "message": self.message,
            "warnings": list(self.warnings),
            "wall_s": round(self.wall_s, 2),
            "windows": self.n_windows,
            "ticks": self.n_ticks,
            # JSON has no NaN: with no value identified there is no inflation to state
            "ci_inflation": round(self.ci_inflation, 3) if math.isfinite(self.ci_inflation) else None,
            "ci_level": CONFIDENCE,
            "interval_method": self.interval_method,
            "problems": list(self.problems),
            "adequacy": {k: a.to_json() for k, a in self.adequacy.items()},
            "dropped_windows": [
                {"log": d.path, "start_s": round(d.start_s, 4), "reason": d.reason} for d in self.dropped
            ],
            "information_condition": round(self.information_condition, 2)
            if math.isfinite(self.information_condition)
            else None,
            "diagnosis": self.diagnosis,
            "not_identifiable": {
                name: {"kept": _get(self.params, name), "unit": FITTABLE[name].unit, "reason": why}
                for name, why in self.not_identifiable.items()
            },
        }


def _get(params: Parameters, name: str) -> float:
    if name == "ball_reading.gain":
        return 1.0
    if name == "ball_reading.offset_m":
        return 0.0
    group, field_name = name.split(".")
    return float(getattr(getattr(params, group), field_name))


@dataclass(frozen=True)
class _Windows:
    command_v: np.ndarray  # (nw, W): the command acting during each tick (written at the previous tick)
    previous_v: np.ndarray  # (nw, W): the command before it (acts until the latency has passed)
    y_ball_m: np.ndarray  # (nw, W): eq 6.3.1 of the ball channel at each tick's end
    y_angle_rad: np.ndarray  # (nw, W): eq 6.2.10 of the angle channel (block mean)
    start_guess: np.ndarray  # (nw, 4): state at each window's start from the readings
    joined: np.ndarray  # (nw − 1,) bool: window w + 1 starts where window w ends (same log)
    period_s: float


@dataclass(frozen=True)
class _Batch:
    """The model's constants for a batch of parameter values, as (B, 1) columns."""

    q: EquationCoefficients[np.ndarray]
    k_tau: np.ndarray
    k_b: np.ndarray
    latency: np.ndarray  # (B,)
    zero: np.ndarray
    gain: np.ndarray
    offset: np.ndarray
    rail: np.ndarray  # (B, 1, 1): the amplifier's limit, volts


class WindowProblem:
    """The residual of a set of logs for the parameters ``fit`` (the rest from ``base``)."""

    def __init__(
        self,
        logs: Sequence[RigLog],
        base: Parameters,
        fit: Sequence[str],
        *,
        window_s: float = 1.0,
        substeps: int = 5,
        screen: bool = True,
        start: dict[str, float] | None = None,
    ) -> None:
        """``screen``: drop the windows the model cannot be trusted on (``RAILED_TICKS``, the ball lost),
        listed in ``dropped``. ``start``: where the fit starts for some of ``fit`` (default: ``base``'s
        values; the windows are screened with ``base`` whatever the start)."""
        unknown = [n for n in fit if n not in FITTABLE]
        if unknown:
            raise CalibrationError(f"cannot fit {unknown}: fittable parameters are {sorted(FITTABLE)}")
        if len(set(fit)) != len(fit):
            raise CalibrationError(f"--fit names a parameter twice: {list(fit)}")
        if not logs:
            raise CalibrationError("no log to fit")
        periods = {round(log.period_s, 9) for log in logs}
        if len(periods) != 1:
            raise CalibrationError(
                f"the logs have different tick periods {sorted(periods)} s: fit them separately"
            )
        for log in logs:
            try:
                check_period(log, base.daq.period_s)
            except LogError as exc:
                raise CalibrationError(str(exc)) from None
        self.base = base
        self.fit = list(fit)
        self.start = dict(start or {})
        # The ball channel's contact losses in the noise model (``_one_sided``); off for a first, symmetric
        # fit (``_fit``).
        self.one_sided = True
        self.substeps = substeps
        self.screen = screen
        self.dropped: list[DroppedWindow] = []
        self.windows = self._cut(logs, window_s)
        self.n_windows, self.W = self.windows.command_v.shape
        self.n_global = len(self.fit)

    # --- setup -------------------------------------------------------------------------------------------
    def _cut(self, logs: Sequence[RigLog], window_s: float) -> _Windows:
        p = self.base
        period = float(logs[0].period_s)
        w = max(2, int(round(window_s / period)))
        parts: dict[str, list[np.ndarray]] = {k: [] for k in ("cmd", "prev", "yb", "ya", "s0")}
        joined: list[bool] = []
        curve_x, curve_v = np.asarray(p.ball_sensor.curve_position_m), np.asarray(p.ball_sensor.curve_volts_v)
        amp = p.amplifier
        rail_command_v = amp.rail_v / amp.gain_v_per_v
        for log in logs:
            yb = np.asarray(ball_position_m(log.ball_v, p.software))
            # The angle channel in counts (the level table inverted), then radians from the zeroing angle.
            counts = np.asarray(angle_counter_mean(log.angle_v, p))
            ya = (counts - p.angle_sensor.counter_zero_count) * angle_count_step_rad(p)
            # First guesses of the window states: the curve inverted (volts → position; reading it the other
            # way round put every first guess at the state bound, ±0.5 m), through a 5-tick median so that a
            # contact-noise spike at a window's start does not throw its first guess off the track.
            x_est = scipy.ndimage.median_filter(
                np.interp(log.ball_v, curve_v, curve_x), size=5, mode="nearest"
            )
            th_est = (
                scipy.ndimage.median_filter(ya, size=3, mode="nearest") + p.angle_sensor.zeroing_error_rad
            )
            n = len(log.time_s)
            railed = np.abs(log.command_v - amp.zero_command_v) >= rail_command_v - DAC_STEP_V
            lost_from = _ball_lost_from(log.ball_v, yb, p) if self.screen else n
            kept_last = False
            for i0 in range(1, n - w, w):  # tick i0 ends where the window starts
                idx = np.arange(i0 + 1, i0 + w + 1)
                reason = ""
                if self.screen and idx[-1] >= lost_from:
                    reason = "ball lost"
                elif self.screen and _longest_run(railed[idx - 1]) >= RAILED_TICKS:
                    reason = "railed"
                if reason:
                    self.dropped.append(DroppedWindow(str(log.path), float(log.time_s[idx[0]]), reason))
                    kept_last = False
                    continue
                if parts["cmd"]:
                    joined.append(kept_last)
                kept_last = True
                parts["cmd"].append(log.command_v[idx - 1])
                parts["prev"].append(log.command_v[idx - 2])
                parts["yb"].append(yb[idx])
                parts["ya"].append(ya[idx])
                xd = (x_est[i0 + 1] - x_est[i0 - 1]) / (2 * period)
                thd = (th_est[i0 + 1] - th_est[i0 - 1]) / (2 * period)
                parts["s0"].append(np.array([x_est[i0], th_est[i0], xd, thd]))
        if not parts["cmd"] and self.dropped:
            raise CalibrationError(
                f"{logs[0].path}: every window was dropped ("
                + ", ".join(sorted({d.reason for d in self.dropped}))
                + "): 'aout' (command_v) at the amplifier's rails or 'datam1' (ball_v) at the track's end"
            )
        if not parts["cmd"]:
            raise CalibrationError(f"the logs are shorter than one window ({w} ticks)")
        return _Windows(
            command_v=np.array(parts["cmd"]),
            previous_v=np.array(parts["prev"]),
            y_ball_m=np.array(parts["yb"]),
            y_angle_rad=np.array(parts["ya"]),
            start_guess=np.clip(np.array(parts["s0"]), STATE_BOUNDS[0], STATE_BOUNDS[1]),
            joined=np.array(joined, dtype=bool),
            period_s=period,
        )

    def initial_vector(self) -> np.ndarray:
        g = [self.start[n] if n in self.start else _get(self.base, n) for n in self.fit]
        return np.concatenate([np.array(g, dtype=float), self.windows.start_guess.ravel()])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo = [FITTABLE[n].lower for n in self.fit] + list(np.tile(STATE_BOUNDS[0], self.n_windows))
        hi = [FITTABLE[n].upper for n in self.fit] + list(np.tile(STATE_BOUNDS[1], self.n_windows))
        return np.array(lo), np.array(hi)

    def scale(self) -> np.ndarray:
        return np.concatenate([[FITTABLE[n].scale for n in self.fit], np.tile(STATE_SCALE, self.n_windows)])

    def sparsity(self) -> scipy.sparse.csr_matrix:
        """Rows: ball then angle residuals (window-major), then 4 continuity residuals per joined pair of
        windows; columns: global parameters, then window states."""
        nw, W, ng = self.n_windows, self.W, self.n_global
        joins = np.flatnonzero(self.windows.joined)
        # Built as coordinates (a 1-hour log has 360 000 rows): each reading row touches the globals and its
        # window's 4 states, each continuity row the globals and the 8 states of the windows it joins.
        reading_window = np.tile(np.repeat(np.arange(nw), W), 2)
        n_read = reading_window.size
        read_rows = np.repeat(np.arange(n_read), ng + 4)
        read_cols = np.concatenate(
            [np.tile(np.arange(ng), (n_read, 1)), ng + 4 * reading_window[:, None] + np.arange(4)], axis=1
        ).ravel()
        join_rows = n_read + np.arange(4 * joins.size)
        join_window = np.repeat(joins, 4)
        cont_rows = np.repeat(join_rows, ng + 8)
        cont_cols = np.concatenate(
            [np.tile(np.arange(ng), (join_rows.size, 1)), ng + 4 * join_window[:, None] + np.arange(8)],
            axis=1,
        ).ravel()
        rows = np.concatenate([read_rows, cont_rows])
        cols = np.concatenate([read_cols, cont_cols])
        shape = (n_read + join_rows.size, ng + 4 * nw)
        return scipy.sparse.csr_matrix((np.ones(rows.size, dtype=np.int8), (rows, cols)), shape=shape)

    # --- the model --------------------------------------------------------------------------------------
    def parameters(self, z: np.ndarray) -> Parameters:
        return self.base.with_values(dict(zip(self.fit, (float(v) for v in z[: self.n_global]), strict=True)))

    def predict(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Predicted (ball reading m, angle reading rad) of every tick of every window."""
        pred_b, pred_a, _ = self.simulate(z[None, :])
        return pred_b[0], pred_a[0]

    def _batch_coefficients(self, zg: np.ndarray) -> _Batch:
        """The model's constants for each row of global parameter values, as (B, 1) arrays."""
        rows = []
        for values in zg:
            named = dict(zip(self.fit, (float(v) for v in values), strict=True))
            p = self.base.with_overrides({k: v for k, v in named.items() if k not in READING}, origin="fit")
            rows.append(
                (
                    EquationCoefficients.from_params(p),
                    p.motor.torque_per_volt_nm_per_v,
                    p.motor.backemf_at_beam_v_s_per_rad,
                    p.daq.output_latency_s,
                    p.angle_sensor.zeroing_error_rad,
                    named.get("ball_reading.gain", 1.0),
                    named.get("ball_reading.offset_m", 0.0),
                    p.amplifier.rail_v,
                )
            )

        def column(values: list[float]) -> np.ndarray:
            return np.array(values, dtype=float)[:, None]

        return _Batch(
            q=EquationCoefficients.stack([r[0] for r in rows]),
            k_tau=column([r[1] for r in rows]),
            k_b=column([r[2] for r in rows]),
            latency=np.array([r[3] for r in rows]),
            zero=column([r[4] for r in rows]),
            gain=column([r[5] for r in rows]),
            offset=column([r[6] for r in rows]),
            rail=np.array([r[7] for r in rows], dtype=float)[:, None, None],
        )

    def simulate(self, zs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For each row of ``zs`` (B, n): the predicted readings (B, nw, W) and each window's state at its
        end (B, nw, 4). All rows and windows advance together (one numpy batch)."""
        B, nw, W = zs.shape[0], self.n_windows, self.W
        cst = self._batch_coefficients(zs[:, : self.n_global])
        acc = cst.q.accelerations
        k_tau, k_b = cst.k_tau, cst.k_b
        p, win = self.base, self.windows
        s = zs[:, self.n_global :].reshape(B, nw, 4)
        x, th, xd, thd = (s[:, :, i].copy() for i in range(4))
        h = win.period_s / self.substeps
        # Ideal DAC (quantization is noise here, see the module's docstring), the twin's amplifier with each
        # row's rail (a fitted or diagnosed ``amplifier.rail_v``).
        line = _unclipped(p)
        v_new = np.clip(np.asarray(amplifier_volts(win.command_v, line)), -cst.rail, cst.rail)
        v_old = np.clip(np.asarray(amplifier_volts(win.previous_v, line)), -cst.rail, cst.rail)
        # The new command's share of each sub-step: the part of [k·h, (k+1)·h) after the latency.
        latency = cst.latency[:, None]
        share = np.clip(
            (np.arange(1, self.substeps + 1)[None, :] * h - latency) / h, 0.0, 1.0
        )  # (B, substeps)

        def f(x_: Any, th_: Any, xd_: Any, thd_: Any, v_: Any) -> tuple[Any, Any, Any, Any]:
            xdd, thdd = acc(x_, th_, xd_, thd_, torque_nm(v_, thd_, k_tau, k_b))
            return xd_, thd_, xdd, thdd

        tau_rc = p.ball_sensor.rc_resistance_ohm * p.ball_sensor.rc_capacitance_f
        pred_b = np.empty((B, nw, W))
        pred_a = np.empty((B, nw, W))
        for j in range(W):
            mean_th = 0.5 * th
            dv = v_new[:, :, j] - v_old[:, :, j]
            for k in range(self.substeps):
                v = v_old[:, :, j] + share[:, k : k + 1] * dv
                x, th, xd, thd = rk4_step(f, x, th, xd, thd, v, h)
                mean_th = mean_th + (th if k < self.substeps - 1 else 0.5 * th)
            pred_a[:, :, j] = mean_th / self.substeps - cst.zero
            # The sensor's static curve at x delayed by the RC filter. A diverged window (its state not
            # finite) reads NaN, which residuals_batch scores as a huge residual.
            delayed = x - tau_rc * xd
            finite = np.isfinite(delayed)
            wiper = wiper_static_v(np.where(finite, delayed, 0.0), p.ball_sensor)
            read = cst.gain * ball_position_m(np.asarray(wiper), p.software) + cst.offset
            pred_b[:, :, j] = np.where(finite, read, np.nan)
        return pred_b, pred_a, np.stack([x, th, xd, thd], axis=2)

    def residuals_batch(self, zs: np.ndarray) -> np.ndarray:
        """Normalized residuals for each row of ``zs``: ball channel rows, angle channel rows (window-major),
        then the continuity of the state between consecutive windows of a log (multiple shooting: the
        rig's state is continuous)."""
        pred_b, pred_a, end = self.simulate(zs)
        B = zs.shape[0]
        rb = (pred_b - self.windows.y_ball_m) / SIGMA_BALL_M
        if self.one_sided:
            rb = _one_sided(rb, self._toward_open(zs, pred_b))
        ra = (pred_a - self.windows.y_angle_rad) / SIGMA_ANGLE_RAD
        starts = zs[:, self.n_global :].reshape(B, self.n_windows, 4)
        joins = np.flatnonzero(self.windows.joined)
        rc = (end[:, joins] - starts[:, joins + 1]) / CONTINUITY_SIGMA
        r = np.concatenate([rb.reshape(B, -1), ra.reshape(B, -1), rc.reshape(B, -1)], axis=1)
        return np.where(np.isfinite(r), r, 1e6)

    def residuals(self, z: np.ndarray) -> np.ndarray:
        return self.residuals_batch(z[None, :])[0]

    def _toward_open(self, zs: np.ndarray, pred_b: np.ndarray) -> np.ndarray:
        """+1 where the open wiper reads above the model's reading, −1 below: the side a contact loss pulls
        each reading to (B, nw, W)."""
        named = {k: zs[:, i, None, None] for i, k in enumerate(self.fit)}
        gain = named.get("ball_reading.gain", 1.0)
        offset = named.get("ball_reading.offset_m", 0.0)
        p = self.base
        x_open = gain * ball_position_m(p.ball_sensor.dropout_voltage_v, p.software) + offset
        return np.where(x_open >= pred_b, 1.0, -1.0)


def _unclipped(p: Parameters) -> Amplifier:
    """``p``'s amplifier without its rail (the line 9.6·(u − 2.5)): the model clips each row at its own."""
    return dataclasses.replace(p.amplifier, rail_v=float(declaration("amplifier.rail_v")["le"]))


def _one_sided(rb: np.ndarray, toward_open: np.ndarray) -> np.ndarray:
    """The ball channel's residuals (model − reading, in σ) with contact losses in the noise model.

    A contact loss only ever pulls a reading toward the open wiper's volts, never away: beyond
    ``ROBUST_SCALE`` σ on that side the residual is taken as c·(1 + tanh((d − c)/c)), which levels off at 2c,
    so a pulled reading's weight in the fit falls to zero however far it was pulled (soft_l1 alone gives
    every outlier the same constant pull, and one-sided outliers then bias the fit: +0.1…0.2 % in the
    resistance at 10–30 losses per second, beyond its interval). On the other side, and within c,
    the residual is unchanged."""
    c = ROBUST_SCALE
    d = -rb * toward_open  # how far the reading sits beyond the model toward the open wiper, in σ
    pulled = c * (1.0 + np.tanh((d - c) / c))
    return np.where(d > c, -toward_open * pulled, rb)


def colored_jacobian(
    residuals_batch: Callable[[np.ndarray], np.ndarray],
    z0: np.ndarray,
    free: np.ndarray,
    pattern: scipy.sparse.coo_matrix,
    scale: np.ndarray,
    hi: np.ndarray,
) -> Callable[[np.ndarray], scipy.sparse.csr_matrix]:
    """The Jacobian of the residuals in the ``free`` entries of z (the others held at ``z0``) by forward
    differences, every group of columns that share no row of the sparsity ``pattern`` perturbed at once, all
    groups in one batched simulation (``residuals_batch``: one row of residuals per row of z); a step that
    would leave the upper bound ``hi`` is taken backwards."""
    rows, cols = pattern.row.astype(np.int64), pattern.col.astype(np.int64)
    groups = _color_columns(pattern.tocsc())
    n_groups = int(groups.max()) + 1

    def jac(u: np.ndarray) -> scipy.sparse.csr_matrix:
        step = 1.49e-8 * np.maximum(np.abs(u), scale[free])
        step = np.where(u + step > hi[free], -step, step)
        zs = np.tile(z0, (n_groups + 1, 1))
        zs[:, free] = u
        for g in range(n_groups):
            members = np.flatnonzero(groups == g)
            zs[g + 1, free[members]] += step[members]
        r = residuals_batch(zs)
        data = (r[groups[cols] + 1, rows] - r[0, rows]) / step[cols]
        return scipy.sparse.csr_matrix((data, (rows, cols)), shape=pattern.shape)

    return jac


def _solve(
    problem: WindowProblem,
    z0: np.ndarray,
    free: np.ndarray,
    *,
    max_nfev: int,
    progress: Progress | None,
    stage: str = "",
) -> scipy.optimize.OptimizeResult:
    """least_squares over the ``free`` entries of z (the others held at z0).

    The Jacobian stays sparse (its rows touch the globals and one or two windows' states): memory and
    each iteration's cost are linear in the log's length, and the trust-region steps are solved by LSMR. A
    dense Jacobian of a 1-hour log is 40 GiB, and the exact solver's SVD of a 60 s log's (6 236 × 244) took
    most of that fit's time."""
    lo, hi = problem.bounds()
    scale = problem.scale()
    pattern = problem.sparsity()[:, free].tocoo()
    calls = [0]

    def fun(u: np.ndarray) -> np.ndarray:
        z = z0.copy()
        z[free] = u
        r = problem.residuals(z)
        calls[0] += 1
        if progress is not None:
            progress(min(calls[0], max_nfev), max_nfev, stage)
        return r

    u0 = np.clip(z0[free], lo[free], hi[free])
    jac = colored_jacobian(problem.residuals_batch, z0, free, pattern, scale, hi)

    return scipy.optimize.least_squares(
        fun,
        u0,
        jac=jac,
        bounds=(lo[free], hi[free]),
        x_scale=scale[free],
        loss="soft_l1",
        f_scale=ROBUST_SCALE,
        method="trf",
        tr_solver="lsmr",
        tr_options={"atol": 1e-12, "btol": 1e-12},
        max_nfev=max_nfev,
        xtol=1e-8,
        ftol=1e-8,
        gtol=1e-8,
    )


def dropout_rate(
    problem: WindowProblem, z: np.ndarray, params: Parameters
) -> tuple[float, float, float, int]:
    """The wiper's contact-loss rate from the ball channel's outliers, by maximum likelihood.

    A contact loss that starts a time a before a block's end and lasts d (exponential, mean
    ``ball_sensor.dropout_mean_duration_s``, which must be known: rate and duration trade off) pulls the RC
    filter towards the open-wiper volts; the reading is an outlier (more than ``OUTLIER_M`` off the fitted
    model) when that pull exceeds the threshold. For a tick whose wiper sits Δv from the open-wiper volts, w(Δv)
    is the length of start times that make it an outlier, so P(outlier) = 1 − e^(−λ·w). Returns (λ, 95 % low,
    high, number of outlier ticks)."""
    s = params.ball_sensor
    tau, mu = s.rc_resistance_ohm * s.rc_capacitance_f, s.dropout_mean_duration_s
    pred_b, _ = problem.predict(z)
    y = problem.windows.y_ball_m
    outlier = (np.abs(y - pred_b) > OUTLIER_M).ravel()
    gain = params.software.ball_gain_m_per_v
    wiper = (pred_b.ravel() - params.software.ball_offset_m) / gain  # the volts eq 6.3.1 reads as the model
    delta_v = np.abs(wiper - s.dropout_voltage_v)
    threshold_v = OUTLIER_M / gain
    # w(Δv) on a grid: ages a up to 20 τ, durations at 200 quantiles of the exponential distribution.
    ages = np.linspace(0.0, 20 * tau, 801)
    durations = -mu * np.log1p(-(np.arange(200) + 0.5) / 200)
    a, d = ages[:, None], durations[None, :]
    pull = np.where(d >= a, 1.0 - np.exp(-a / tau), np.exp(-(a - d) / tau) * (1.0 - np.exp(-d / tau)))
    levels = np.geomspace(max(threshold_v, 1e-6), max(float(delta_v.max()), threshold_v) * 1.01, 60)
    w_table = np.array([np.trapezoid(np.mean(lv * pull > threshold_v, axis=1), ages) for lv in levels])
    w = np.interp(delta_v, levels, w_table, left=0.0)
    usable = w > 0

    def nll(rate: float) -> float:
        p = -np.expm1(-rate * w[usable])
        return float(-np.sum(np.where(outlier[usable], np.log(np.maximum(p, 1e-300)), -rate * w[usable])))

    spec = FITTABLE[DROPOUT]
    best = scipy.optimize.minimize_scalar(nll, bounds=(spec.lower, spec.upper), method="bounded")
    rate = float(best.x)
    ew = np.exp(-rate * w[usable])
    info = float(np.sum(w[usable] ** 2 * ew / np.maximum(1.0 - ew, 1e-300)))
    half = 1.96 / math.sqrt(info) if info > 0 else spec.upper
    return rate, max(0.0, rate - half), rate + half, int(outlier.sum())


def _color_columns(pattern: scipy.sparse.csc_matrix) -> np.ndarray:
    """Greedy grouping of columns that share no row (a proper coloring of the column-intersection graph)."""
    n = pattern.shape[1]
    rows_of = [set(pattern.indices[pattern.indptr[j] : pattern.indptr[j + 1]].tolist()) for j in range(n)]
    groups = np.full(n, -1)
    used: list[set[int]] = []
    for j in range(n):
        for g, taken in enumerate(used):
            if not (rows_of[j] & taken):
                groups[j] = g
                taken |= rows_of[j]
                break
        else:
            groups[j] = len(used)
            used.append(set(rows_of[j]))
    return groups


def _rms(problem: WindowProblem, pred_b: np.ndarray, pred_a: np.ndarray) -> dict[str, float]:
    eb, ea = pred_b - problem.windows.y_ball_m, pred_a - problem.windows.y_angle_rad
    return {
        "ball_m": float(np.sqrt(np.mean(eb**2))),
        "ball_m_median_abs": float(np.median(np.abs(eb))),
        "angle_rad": float(np.sqrt(np.mean(ea**2))),
    }


@dataclass(frozen=True)
class _Covariance:
    cov: np.ndarray  # (g, g) cluster-robust covariance of the global parameters
    naive_var: np.ndarray  # (g,) their variances if the residuals were white
    information: np.ndarray  # (g, g) the globals' Fisher information, the window states marginalized
    n_clusters: int
    # (g,) each global's sensitivity: the norm of its Jacobian column (0: the residuals do not depend on it)
    sensitivity: np.ndarray = field(default_factory=lambda: np.zeros(0))


def _row_windows(problem: WindowProblem) -> np.ndarray:
    """The window each residual row belongs to (a continuity row: the window it leaves)."""
    nw, W = problem.n_windows, problem.W
    joins = np.flatnonzero(problem.windows.joined)
    per_tick = np.repeat(np.arange(nw), W)
    return np.concatenate([per_tick, per_tick, np.repeat(joins, 4)])


def cluster_sandwich(
    jac: scipy.sparse.spmatrix, n_g: int, cluster: np.ndarray, rw: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The globals' block of the sandwich covariance H⁻¹·(Σ_c J_cᵀr_c r_cᵀJ_c)·H⁻¹ (H = JᵀJ, the first ``n_g``
    columns the globals, the rows' clusters ``cluster``, their weighted residuals ``rw``) without forming a dense
    matrix over the window states: the g columns of H⁻¹ by a sparse LU of H (normalized by its diagonal, which
    keeps it well scaled), then J·H⁻¹[:, :g] (rows × g) summed per cluster. Returns the covariance, H⁻¹'s global
    block, the globals' sensitivities (their Jacobian columns' norms: 0 where no residual depends on them) and
    the clusters' count. One home for the thesis rig's fit and a part-built rig's (``calib.part_identify``)."""
    J = scipy.sparse.csr_matrix(jac)
    H = (J.T @ J).tocsc()
    d = np.sqrt(np.maximum(H.diagonal(), 1e-300))
    Dinv = scipy.sparse.diags(1.0 / d)
    # A flat direction (a parameter the data do not touch) leaves H singular: a ridge of 1e-12 of the
    # normalized diagonal keeps the factorization and shows up as a huge variance.
    Hn = (Dinv @ H @ Dinv + 1e-12 * scipy.sparse.identity(H.shape[0])).tocsc()
    lu = scipy.sparse.linalg.splu(Hn)
    rhs = np.zeros((H.shape[0], n_g))
    rhs[np.arange(n_g), np.arange(n_g)] = 1.0 / d[:n_g]
    with np.errstate(over="ignore", invalid="ignore"):  # a flat direction: inf, refused as not identifiable
        X = lu.solve(rhs) / d[:, None]  # H⁻¹[:, :g]
    n_c = int(cluster.max()) + 1 if cluster.size else 1
    with np.errstate(over="ignore", invalid="ignore"):
        B = np.asarray(J @ X)  # (rows, g)
    G = np.zeros((n_c, n_g))  # no globals (the dropout rate alone is fitted apart): an empty covariance
    with np.errstate(over="ignore", invalid="ignore"):
        for k in range(n_g):
            G[:, k] = np.bincount(cluster, weights=B[:, k] * rw, minlength=n_c)
        cov = G.T @ G * n_c / max(n_c - 1, 1)
    return cov, X[:n_g], np.sqrt(np.maximum(H.diagonal()[:n_g], 0.0)), n_c


def _sandwich(problem: WindowProblem, jac: scipy.sparse.spmatrix, rw: np.ndarray) -> _Covariance:
    """``cluster_sandwich`` over clusters of ``CLUSTER_S`` of log, with the information matrix."""
    per_cluster = max(1, int(round(CLUSTER_S / (problem.W * problem.windows.period_s))))
    cluster = _row_windows(problem) // per_cluster
    cov, inv_block, sensitivity, n_c = cluster_sandwich(jac, problem.n_global, cluster, rw)
    with np.errstate(all="ignore"):
        information = np.linalg.pinv(0.5 * (inv_block + inv_block.T))
    return _Covariance(cov, np.diag(inv_block).copy(), information, n_c, sensitivity)


def _adequacy(problem: WindowProblem, z: np.ndarray) -> dict[str, ChannelAdequacy]:
    pred_b, pred_a = problem.predict(z)
    win = problem.windows
    return {
        "ball": channel_adequacy(
            pred_b - win.y_ball_m, channel="ball", unit="m", floor=SIGMA_BALL_M, outlier=OUTLIER_M
        ),
        "angle": channel_adequacy(
            pred_a - win.y_angle_rad, channel="angle", unit="rad", floor=SIGMA_ANGLE_RAD
        ),
    }


def _mismatched(adequacy: dict[str, ChannelAdequacy]) -> list[str]:
    """The channels whose residual says the model misses something (``MISMATCH_RATIO``, ``COLOURED_LAG1``)."""
    out = []
    for a in adequacy.values():
        if a.ratio > MISMATCH_RATIO or abs(a.lag1) > COLOURED_LAG1:
            out.append(a.channel)
    return out


@dataclass(frozen=True)
class _Fit:
    z_before: np.ndarray
    result: scipy.optimize.OptimizeResult
    sandwich: _Covariance
    rw: np.ndarray


def _fit(problem: WindowProblem, *, max_nfev: int, progress: Progress | None, stage: str = "") -> _Fit:
    z0 = problem.initial_vector()
    n_g = problem.n_global
    states = np.arange(n_g, z0.size)
    # 1. The window states alone at the starting parameters, fitted to convergence: the "before" of the
    # report is then the best the starting parameters can do (a few evaluations would leave the states
    # short and overstate what the fit did).
    before = _solve(problem, z0, states, max_nfev=max_nfev, progress=progress, stage=f"{stage}window states")
    z_before = z0.copy()
    z_before[states] = before.x
    # 2. Everything together, first with the symmetric loss, then with contact losses in the noise model
    # from there. The one-sided loss alone can settle where the model runs beside the readings and every
    # one of them counts as pulled toward the open wiper (a redescending loss's false minimum: on one of ten
    # logs of the independent rig, 2 703 ticks "pulled", the ball channel 3.1× its floor); the symmetric
    # loss has no such minimum and starts the one-sided one next to the right one.
    every = np.arange(z0.size)
    problem.one_sided = False
    try:
        symmetric = _solve(
            problem,
            z_before,
            every,
            max_nfev=max_nfev,
            progress=progress,
            stage=f"{stage}parameters and states",
        )
    finally:
        problem.one_sided = True
    result = _solve(
        problem, symmetric.x, every, max_nfev=max_nfev, progress=progress, stage=f"{stage}contact losses"
    )
    # Intervals: the cluster-robust ("sandwich") covariance, clusters of CLUSTER_S of log. Residuals within a
    # cluster are correlated (quantization that holds for many ticks, the model's own small errors), which
    # makes the plain Gauss-Newton covariance optimistic. Bread: the loss-weighted Jacobian scipy returns;
    # meat: each cluster's gradient contribution Jᵀr with the robust loss's weights.
    r = problem.residuals(result.x)
    rw = r / np.sqrt(np.sqrt(1.0 + (r / ROBUST_SCALE) ** 2))  # r·√ρ′ of soft_l1
    return _Fit(z_before, result, _sandwich(problem, result.jac, rw), rw)


def calibrate(
    logs: Sequence[RigLog],
    fit: Sequence[str],
    start: Parameters | None = None,
    *,
    window_s: float = 1.0,
    substeps: int = 5,
    max_nfev: int = 100,
    progress: Progress | None = None,
    diagnose: bool = True,
    screen: bool = True,
) -> Calibration:
    """Fit ``fit`` (names from ``FITTABLE``) to ``logs`` from ``start`` (default: the thesis's values).

    ``diagnose``: when the residuals say model mismatch, refit with the candidate effects
    (``DIAGNOSTIC_EFFECTS``) freed and name one that explains the residual. ``screen``: drop the windows
    the model cannot be trusted on (``WindowProblem``)."""
    started = time.perf_counter()
    base = start or Parameters()
    dynamic = [name for name in fit if name != DROPOUT]
    if DROPOUT in fit and DROPOUT not in FITTABLE:
        raise CalibrationError(f"cannot fit {DROPOUT}")
    below_rail = {RAIL: RAIL_START_SHARE * base.amplifier.rail_v} if RAIL in dynamic else None
    problem = WindowProblem(
        logs, base, dynamic, window_s=window_s, substeps=substeps, screen=screen, start=below_rail
    )
    warnings = _dropped_warnings(problem)
    fitted = _fit(problem, max_nfev=max_nfev, progress=progress)
    z = fitted.result.x
    intervals = _intervals(problem, fitted)
    warnings += intervals.warnings
    condition = _normalized_condition(fitted.sandwich.information)
    adequacy = _adequacy(problem, z)
    mismatched = _mismatched(adequacy)
    problems: list[str] = []
    # A mismatched model's standard deviations mean nothing: only an adequate fit is judged on excitation.
    if not mismatched:
        # A value the logs do not identify is its own problem (below), not a loosely determined one.
        known_std = np.where([n in intervals.unidentified for n in problem.fit], 0.0, intervals.std)
        problems += _excitation_problems(problem.fit, z, known_std, intervals.corr)
    warnings += _correlation_warnings(problem, intervals.corr)
    diagnosis = ""
    if mismatched:
        if diagnose:
            near_rails = {ch: rail_cluster(problem, z, ch) for ch in adequacy}
            diagnosis = _diagnose(
                logs, base, dynamic, adequacy, window_s, substeps, max_nfev, progress, near_rails
            )
        problems.append(_mismatch_problem(adequacy, mismatched, diagnosis))
    values = intervals.values
    params_fitted = problem.parameters(z)
    losses, params_with_losses = _fit_dropout(
        problem, z, params_fitted, base, warnings if DROPOUT in fit else []
    )
    unidentified = dict(intervals.unidentified)
    if DROPOUT in fit:
        values[DROPOUT], params_fitted = losses, params_with_losses
        reason = _unidentified(losses.ci_low, losses.ci_high, losses.sd, 1.0)
        if reason:
            unidentified[DROPOUT] = reason
    warnings += _beyond_scope(losses)
    correlation = intervals.corr
    if unidentified:
        values, correlation, params_fitted = _leave_out(problem, z, base, values, correlation, unidentified)
        problems.insert(0, _unidentified_problem(base, unidentified))
    pred_b0, pred_a0 = problem.predict(fitted.z_before)
    pred_b1, pred_a1 = problem.predict(z)
    return Calibration(
        params=params_fitted,
        values=values,
        correlation=correlation,
        rms_before=_rms(problem, pred_b0, pred_a0),
        rms_after=_rms(problem, pred_b1, pred_a1),
        converged=bool(fitted.result.success),
        message=str(fitted.result.message),
        warnings=warnings,
        wall_s=time.perf_counter() - started,
        n_windows=problem.n_windows,
        n_ticks=problem.n_windows * problem.W,
        ci_inflation=intervals.inflation,
        problems=problems,
        adequacy=adequacy,
        dropped=list(problem.dropped),
        information_condition=condition,
        diagnosis=diagnosis,
        not_identifiable=unidentified,
        traces={
            "t_s": np.arange(problem.n_windows * problem.W) * problem.windows.period_s,
            "y_ball_m": problem.windows.y_ball_m.ravel(),
            "y_angle_rad": problem.windows.y_angle_rad.ravel(),
            "before_ball_m": pred_b0.ravel(),
            "before_angle_rad": pred_a0.ravel(),
            "after_ball_m": pred_b1.ravel(),
            "after_angle_rad": pred_a1.ravel(),
        },
    )


def _dropped_warnings(problem: WindowProblem) -> list[str]:
    """One warning per reason windows were dropped before the fit, naming the logs and the first window."""
    warnings = []
    for reason, what in (
        ("railed", f"the amplifier at a rail for {RAILED_TICKS} ticks or more in a row"),
        ("ball lost", "the ball lost (at the track's end, or gone from the spring) from then on"),
    ):
        dropped = [d for d in problem.dropped if d.reason == reason]
        if dropped:
            where = ", ".join(sorted({d.path for d in dropped}))
            warnings.append(
                f"{len(dropped)} window(s) dropped, {what}: {where} from t = {dropped[0].start_s:.2f} s"
                + (f" (and {len(dropped) - 1} more)" if len(dropped) > 1 and reason == "railed" else "")
            )
    return warnings


@dataclass(frozen=True)
class _Intervals:
    """The fitted values with their intervals, and what the covariance says about them."""

    values: dict[str, FittedValue]
    corr: np.ndarray  # the globals' correlation matrix
    inflation: float  # median of the cluster-robust over the white-residual standard deviations
    warnings: list[str]  # per value, in the fit's order: unidentifiable, on a bound
    std: np.ndarray  # the globals' statistical (cluster-robust) standard deviations
    # The globals the logs do not identify (``_unidentified``): the reason for each, in the fit's order.
    unidentified: dict[str, str] = field(default_factory=dict)


def _intervals(problem: WindowProblem, fitted: _Fit) -> _Intervals:
    """Each fitted global's interval: the sandwich covariance with Student's t, the model's resolution
    (``MODEL_RESOLUTION``) added in quadrature."""
    z, z_before, sandwich, rw = fitted.result.x, fitted.z_before, fitted.sandwich, fitted.rw
    # The same covariance assuming white residuals, to report how much the correlation widens the intervals.
    spread2 = float(rw @ rw) / max(rw.size - z.size, 1)
    naive = np.sqrt(np.maximum(sandwich.naive_var * spread2, 1e-300))
    cov_g = sandwich.cov
    std = np.sqrt(np.maximum(np.diag(cov_g), 0.0))
    inflation = float(np.median(std / naive)) if problem.n_global else 1.0
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov_g / np.outer(std, std)
    corr = np.nan_to_num(corr)
    # Student's t with (clusters − 1) degrees of freedom: few clusters make the covariance itself uncertain.
    z_crit = float(scipy.stats.t.ppf(0.5 + CONFIDENCE / 2, max(sandwich.n_clusters - 1, 1)))
    values: dict[str, FittedValue] = {}
    warnings: list[str] = []
    unidentified: dict[str, str] = {}
    for i, name in enumerate(problem.fit):
        spec = FITTABLE[name]
        rel, absolute = MODEL_RESOLUTION.get(name, (0.0, 0.0))
        half = math.hypot(z_crit * std[i], max(rel * abs(float(z[i])), absolute))
        lo, hi = float(z[i] - half), float(z[i] + half)
        values[name] = FittedValue(
            float(z[i]),
            lo,
            hi,
            float(z_before[i]),
            spec.unit,
            sd=half / z_crit,
            statistical_half=z_crit * std[i],
        )
        reason = _unidentified(lo, hi, float(std[i]), float(sandwich.sensitivity[i]))
        if reason:
            unidentified[name] = reason
            continue
        if hi - lo > spec.upper - spec.lower:
            warnings.append(
                f"{name}: its {CONFIDENCE:.0%} interval is wider than its bounds: not identifiable here"
            )
        if abs(z[i] - spec.lower) < 1e-6 * spec.scale or abs(z[i] - spec.upper) < 1e-6 * spec.scale:
            warnings.append(
                f"{name} = {z[i]:.6g} {spec.unit} sits on its bound [{spec.lower:g}, {spec.upper:g}]"
            )
    return _Intervals(values, corr, inflation, warnings, std, unidentified)


def _leave_out(
    problem: WindowProblem,
    z: np.ndarray,
    base: Parameters,
    values: dict[str, FittedValue],
    corr: np.ndarray,
    unidentified: dict[str, str],
) -> tuple[dict[str, FittedValue], np.ndarray, Parameters]:
    """The values, correlation and parameters without the ``unidentified`` ones: those stay at their start
    value (``base``), so params.toml and calibration.json hold what the logs identify, as their readers
    (``--params``, ``--calibration``) take it."""
    kept = [i for i, name in enumerate(problem.fit) if name not in unidentified]
    at_start = z.copy()
    for i, name in enumerate(problem.fit):
        if name in unidentified:
            at_start[i] = _get(base, name)
    params = problem.parameters(at_start)
    if DROPOUT in values and DROPOUT not in unidentified:
        params = params.with_overrides({DROPOUT: values[DROPOUT].value}, origin="calibration")
    values = {name: v for name, v in values.items() if name not in unidentified}
    return values, corr[np.ix_(kept, kept)], params


def _unidentified_problem(base: Parameters, unidentified: dict[str, str]) -> str:
    """The problem of the parameters the logs do not identify, each with why and the value it keeps."""
    told = []
    for name, why in unidentified.items():
        hint = ": the logs' command never reaches the rails" if name == RAIL else ""
        told.append(f"{name}: {why}{hint}; kept at its start {_get(base, name):g} {FITTABLE[name].unit}")
    return (
        "not identifiable by these logs: "
        + "; ".join(told)
        + " — left out of params.toml's fit (record a log that exercises it, or drop it from --fit)"
    )


def _unidentified(lo: float, hi: float, std: float, sensitivity: float) -> str:
    """Why a fitted value is not identified by the logs ("" when it is): the residuals do not depend on it
    (zero sensitivity, e.g. a rail the command never reaches) or its interval is not finite."""
    if sensitivity == 0.0:
        return "the residuals do not depend on it (zero sensitivity)"
    if not (math.isfinite(lo) and math.isfinite(hi) and math.isfinite(std)) or std == 0.0:
        return f"its {CONFIDENCE:.0%} interval is [{lo:.6g}, {hi:.6g}] (a flat direction of the fit)"
    return ""


def _loosely_determined(name: str, value: float, std: float) -> str:
    """How a fitted value is only loosely determined by the logs (its statistical standard deviation ``std``
    beyond its ``WEAK_EXCITATION`` bound), as the weak-excitation problem shows it; "" when it is not. A
    relative bound is of max(|value|, ``FitSpec.scale``) when the value can be 0 (its search range reaches
    0), so that a value near 0 is not loose for being small."""
    bound = WEAK_EXCITATION.get(name)
    if bound is None:
        return ""
    kind, limit = bound
    spec = FITTABLE[name]
    if kind == "absolute":
        return f"{name} (standard deviation {std:.3g} {spec.unit})" if not std <= limit else ""
    can_vanish = spec.lower <= 0.0
    reference = max(abs(value), spec.scale) if can_vanish else abs(value)
    if reference > 0 and std <= limit * reference:
        return ""
    if reference > abs(value):
        shown = f"{std:.3g} {spec.unit}, {std / reference:.1%} of its typical size {reference:g} {spec.unit}"
    else:
        shown = f"{std / reference:.1%} of its value" if reference > 0 else f"{std:.3g} {spec.unit}"
    return f"{name} (standard deviation {shown})"


def _excitation_problems(names: Sequence[str], z: np.ndarray, std: np.ndarray, corr: np.ndarray) -> list[str]:
    """The problems of the values the logs determine only loosely (``_loosely_determined``), told apart by
    cause. A value's deviation with the other fitted values known is std·√(1 − R²), R² its multiple
    correlation with them (1 − 1/(C⁻¹)ᵢᵢ of the correlation matrix C): when that is within the bound and its
    strongest correlation is beyond ``INSEPARABLE_CORRELATION``, the logs do determine it and what they do not
    is its split from the value it is correlated with (the pivot's
    viscous and Coulomb friction both oppose the beam's speed) — more setpoint moves and dither, which the
    log already has, is not the remedy; the problem names the correlation. Otherwise: weak excitation (a
    regulation log's damping is loose through moderate correlations with all the others, +0.69 at most)."""
    inverse = np.linalg.pinv(corr) if corr.size else corr
    weak, inseparable = [], []
    for i, name in enumerate(names):
        shown = _loosely_determined(name, float(z[i]), float(std[i]))
        if not shown:
            continue
        others = [j for j in range(len(names)) if j != i]
        conditional = float(std[i]) / math.sqrt(max(float(inverse[i, i]), 1.0)) if others else float(std[i])
        j = max(others, key=lambda k: abs(float(corr[i, k]))) if others else i
        if (
            j == i
            or abs(corr[i, j]) <= INSEPARABLE_CORRELATION
            or _loosely_determined(name, float(z[i]), conditional)
        ):
            weak.append(shown)
            continue
        inseparable.append(
            f"not separable: the logs do not tell {name} from {names[j]} (correlation {corr[i, j]:+.2f}): "
            f"{shown[len(name) + 2 : -1]}, {conditional:.3g} {FITTABLE[name].unit} were the others known — "
            "a correlation, not a lack of excitation: leave one out of --fit (its value from --set, measured "
            "apart) or fit them from logs that separate their effects"
        )
    problems = inseparable
    if weak:
        problems.insert(
            0,
            "weak excitation: the logs determine "
            + ", ".join(weak)
            + " only loosely (docs/calibrate.md: How to record a log for calibration — move the setpoint and "
            "add the dither)",
        )
    return problems


def _correlation_warnings(problem: WindowProblem, corr: np.ndarray) -> list[str]:
    """A warning for each pair of fitted globals the logs barely separate (|correlation| > 0.95)."""
    warnings = []
    n_g = problem.n_global
    for i in range(n_g):
        for j in range(i + 1, n_g):
            if abs(corr[i, j]) > INSEPARABLE_CORRELATION:
                warnings.append(
                    f"{problem.fit[i]} and {problem.fit[j]} are correlated ({corr[i, j]:+.2f}): the logs barely "
                    "separate them; excite the rig differently (docs/calibrate.md: How to record a log for calibration)"
                )
    return warnings


def _mismatch_problem(adequacy: dict[str, ChannelAdequacy], mismatched: list[str], diagnosis: str) -> str:
    """The problem a model mismatch makes: the mismatched channels' statistics, and the diagnosis if any."""
    shown = "; ".join(
        f"{a.channel} residual {a.ratio:.1f}× its noise floor, lag-1 autocorrelation {a.lag1:+.2f}"
        for a in adequacy.values()
        if a.channel in mismatched
    )
    return f"model mismatch: {shown}: the fitted values are not to be trusted" + (
        f"; {diagnosis}" if diagnosis else "; no candidate effect explains it (docs/design.md)"
    )


def _fit_dropout(
    problem: WindowProblem, z: np.ndarray, params_fitted: Parameters, base: Parameters, warnings: list[str]
) -> tuple[FittedValue, Parameters]:
    """The ball channel's dropout rate, estimated apart on the smooth fit: its value and the fitted
    parameters with it (a warning appended when the logs hold too few outliers to tell it)."""
    rate, rate_lo, rate_hi, outliers = dropout_rate(problem, z, params_fitted)
    # Its interval is a likelihood interval (asymmetric); its width over 2·1.96 is the standard uncertainty.
    sd_rate = (rate_hi - rate_lo) / (2 * float(scipy.stats.norm.ppf(0.5 + CONFIDENCE / 2)))
    value = FittedValue(rate, rate_lo, rate_hi, base.ball_sensor.dropout_rate_hz, "1/s", sd=sd_rate)
    params_fitted = params_fitted.with_overrides({DROPOUT: rate}, origin="calibration")
    if outliers < 10:
        warnings.append(
            f"{DROPOUT}: only {outliers} outlier ticks in the logs: the rate is barely determined"
        )
    return value, params_fitted


def _beyond_scope(losses: FittedValue) -> list[str]:
    """A warning when the logs' contact losses are beyond those of the rigs the model's resolution was
    derived on (``RESOLUTION_SCOPE``): the one-sided loss leaves a bias that grows with their rate (on the
    independent rig at 30 per second the resistance came out +0.056 % against a ±0.031 % interval), so the
    intervals there are not shown to hold their 95 %."""
    top = RESOLUTION_SCOPE["contact_loss_rate_hz_max"]
    if losses.ci_low <= top:
        return []
    return [
        f"the ball sensor's contact losses, about {losses.value:.0f} per second ({losses.ci_low:.0f}…"
        f"{losses.ci_high:.0f}), are beyond the {top:g} per second of the rigs the intervals' model resolution "
        "was derived on (docs/design.md): the values are still fitted with the losses in the noise model, but "
        "their intervals may be too narrow"
    ]


def _normalized_condition(information: np.ndarray) -> float:
    """The condition number of the globals' Fisher information scaled to unit diagonal (a correlation-like
    matrix: 1 when the parameters are determined independently, large when a combination is not)."""
    d = np.sqrt(np.abs(np.diag(information)))
    if information.size == 0 or not np.all(d > 0):
        return math.inf if information.size else 1.0
    eig = np.linalg.eigvalsh(information / np.outer(d, d))
    return float(eig[-1] / eig[0]) if eig[0] > 0 else math.inf


def _near_rails(problem: WindowProblem) -> np.ndarray:
    """The ticks (nw, W) within ``NEAR_RAILS_TICKS`` of a command beyond ``NEAR_RAILS_SHARE`` of the
    amplifier's rail: where an amplifier that saturates below its modelled rail makes the model wrong."""
    p = problem.base
    volts = np.abs(np.asarray(amplifier_volts(problem.windows.command_v, _unclipped(p))))
    high = (volts >= NEAR_RAILS_SHARE * p.amplifier.rail_v).astype(np.int8)
    # Tick i is near when a command of ticks i − NEAR_RAILS_TICKS + 1 … i was high (a window's ticks only).
    after = scipy.ndimage.maximum_filter1d(
        high, NEAR_RAILS_TICKS, axis=1, origin=NEAR_RAILS_TICKS // 2, mode="constant", cval=0
    )
    return after.astype(bool)


def rail_cluster(problem: WindowProblem, z: np.ndarray, channel: str) -> tuple[float, float]:
    """(share of the channel's residual power, share of the ticks) in the ticks near the rails."""
    pred_b, pred_a = problem.predict(z)
    win = problem.windows
    e = pred_a - win.y_angle_rad if channel == "angle" else pred_b - win.y_ball_m
    if channel == "ball":
        e = np.where(np.abs(e) <= OUTLIER_M, e, 0.0)
    near = _near_rails(problem)
    power = float(np.sum(e * e))
    return (float(np.sum(e[near] ** 2)) / power if power > 0 else 0.0), float(near.mean())


def _diagnose(
    logs: Sequence[RigLog],
    base: Parameters,
    fit: list[str],
    adequacy: dict[str, ChannelAdequacy],
    window_s: float,
    substeps: int,
    max_nfev: int,
    progress: Progress | None,
    near_rails: dict[str, tuple[float, float]],
) -> str:
    """Refit with each candidate effect the fit left out freed, one at a time; name the one whose refit
    explains the residual best: every channel adequate again, or the worst channel's residual halved at least
    (the lowest worst residual wins). ``near_rails``: each channel's ``rail_cluster`` in the fit that
    mismatched, told beside a rail's diagnosis."""
    worst = max(adequacy.values(), key=lambda a: (a.channel in _mismatched(adequacy), a.ratio))
    found: list[tuple[float, str]] = []
    for name, effect in DIAGNOSTIC_EFFECTS.items():
        if name in fit:
            continue
        below_rail = {RAIL: RAIL_START_SHARE * base.amplifier.rail_v} if name == RAIL else None
        problem = WindowProblem(
            logs, base, [*fit, name], window_s=window_s, substeps=substeps, start=below_rail
        )
        refit = _fit(problem, max_nfev=max_nfev, progress=progress, stage=f"diagnosis ({name}): ")
        after = _adequacy(problem, refit.result.x)
        value = float(refit.result.x[problem.fit.index(name)])
        if _mismatched(after) and after[worst.channel].ratio >= 0.5 * worst.ratio:
            continue
        where = ""
        if name == RAIL:
            power, ticks = near_rails[worst.channel]
            where = (
                ""
                if power <= ticks
                else (
                    f" ({100 * power:.0f} % of the {worst.channel} residual's power in the {100 * ticks:.0f} % "
                    f"of ticks within {NEAR_RAILS_TICKS} ticks after a command beyond {NEAR_RAILS_SHARE:.0%} of the "
                    f"±{base.amplifier.rail_v:g} V rail)"
                )
            )
        found.append(
            (
                max(a.ratio for a in after.values()),
                f"likely {effect}: refitted with {name} free it is {value:.3g} {FITTABLE[name].unit} and the "
                f"{worst.channel} residual falls from {worst.ratio:.1f}× to {after[worst.channel].ratio:.1f}× its "
                f"floor, lag-1 autocorrelation {worst.lag1:+.2f} to {after[worst.channel].lag1:+.2f}{where}; "
                f"add {name} to --fit",
            )
        )
    return min(found)[1] if found else ""
