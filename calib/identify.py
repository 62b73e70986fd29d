"""Dynamic identification from closed-loop rig logs: windowed prediction error with free window states.

What the rig records is the ball channel (last sample of each block), the angle channel (block mean) and
the DAC command of each 20 ms tick. The plant is open-loop unstable and the logs are closed-loop, so the
recorded volts cannot be replayed open-loop over a whole log. The log is cut into short windows (1 s by
default); each window's initial state (x, θ, ẋ, θ̇) is a free parameter (multiple shooting without
continuity constraints), and the chosen rig parameters are shared by all windows. The model is the smooth
one: the reference equations (twin.reference.EquationCoefficients) integrated by RK4 in numpy across all
windows at once, with ideal converters — quantization is treated as noise, because a quantizer inside the
fitted loop breaks finite-difference Jacobians. What the sensors do that matters is modelled:

* angle channel: the block-mean volts turned back into the mean counter value (twin.sensors.
  angle_counter_mean: the AD561 and ADC levels inverted, which removes the ADC's rounding of each level,
  a bias of up to 0.44 mrad that eq 6.2.10 keeps), modelled as the mean of θ over the 20 ms block
  (trapezoid over the sub-steps) minus the encoder's zeroing error (leaving the block mean out biases the
  pivot damping);
* ball channel: the sensor's static curve (``ball_sensor.curve_*``) at x delayed by the RC time constant,
  read through the software's eq 6.3.1, with an optional gain and offset relative to it;
* command: the amplifier 9.6·(u − 2.5) within ±12 V, switched ``daq.output_latency_s`` after the tick.

The loss is robust (``soft_l1``: quadratic within 2 σ, linear beyond), so the ball channel's contact-noise
outliers do not pull the fit. Residuals are in units of the channels' nominal noise. Intervals come from the
Gauss-Newton covariance at the optimum, scaled by the residuals' robust spread and inflated for their
correlation in time (AR(1) effective sample size), because the white-noise assumption is optimistic here.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.optimize
import scipy.sparse
import scipy.stats

from calib.logs import RigLog
from twin.converters import ball_position_m
from twin.parameters import Parameters
from twin.reference import EquationCoefficients
from twin.sensors import angle_count_step_rad, angle_counter_mean

__all__ = [
    "FITTABLE",
    "Calibration",
    "CalibrationError",
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
CONFIDENCE = 0.95
# Residuals stay correlated over seconds (a still beam reads the same encoder level; the reference model's
# small errors against the rig): the intervals treat each 5 s of log as one independent cluster.
CLUSTER_S = 5.0


class CalibrationError(ValueError):
    """The fit cannot be set up as asked (unknown parameter, logs of different periods, …)."""


@dataclass(frozen=True)
class FitSpec:
    """A parameter the fit can estimate, with its physical bounds and typical size."""

    name: str
    unit: str
    lower: float
    upper: float
    scale: float
    meaning: str


FITTABLE: dict[str, FitSpec] = {
    s.name: s
    for s in (
        FitSpec(
            "motor.resistance_ohm", "Ω", 1.0, 50.0, 10.0, "armature resistance (drifts with temperature)"
        ),
        FitSpec("beam.inertia_pivot_kgm2", "kg·m²", 1e-3, 2e-2, 4e-3, "beam inertia about the pivot"),
        FitSpec("beam.pivot_damping_nm_s_per_rad", "N·m·s/rad", 0.0, 0.05, 1e-3, "pivot viscous friction"),
        FitSpec("beam.pivot_friction_nm", "N·m", 0.0, 0.05, 1e-3, "pivot Coulomb friction"),
        FitSpec(
            "angle_sensor.zeroing_error_rad",
            "rad",
            -0.1,
            0.1,
            0.01,
            "beam angle at which the counter was zeroed",
        ),
        FitSpec(
            "track.contact_spacing_m",
            "m",
            0.002,
            0.0166,
            0.01,
            "wire contact spacing d (sets r* = √(r² − d²/4))",
        ),
        FitSpec("daq.output_latency_s", "s", 0.0, 0.018, 0.005, "delay from a block's end to the DAC update"),
        FitSpec("ball_reading.gain", "-", 0.5, 1.5, 1.0, "ball reading's gain relative to the sensor curve"),
        FitSpec(
            "ball_reading.offset_m", "m", -0.05, 0.05, 0.005, "ball reading's offset relative to the curve"
        ),
    )
}
# Measurement-model parameters that are not twin parameters: they are folded into the sensor curve.
_READING = ("ball_reading.gain", "ball_reading.offset_m")


@dataclass(frozen=True)
class FittedValue:
    value: float
    ci_low: float
    ci_high: float
    initial: float
    unit: str


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

    def to_json(self) -> dict[str, object]:
        return {
            "params": {
                name: {
                    "value": v.value,
                    "ci_low": v.ci_low,
                    "ci_high": v.ci_high,
                    "initial": v.initial,
                    "unit": v.unit,
                }
                for name, v in self.values.items()
            },
            "correlation": {
                "names": list(self.values),
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
            "ci_inflation": round(self.ci_inflation, 3),
            "ci_level": CONFIDENCE,
        }


def _get(params: Parameters, name: str) -> float:
    if name == "ball_reading.gain":
        return 1.0
    if name == "ball_reading.offset_m":
        return 0.0
    group, field_name = name.split(".")
    return float(getattr(getattr(params, group), field_name))


def apply_values(base: Parameters, values: dict[str, float]) -> Parameters:
    """``base`` with fitted values; a ball-reading gain/offset is folded into the sensor's curve so that the
    software's eq 6.3.1 reads g·(what it read before) + b."""
    plain = {k: v for k, v in values.items() if k not in _READING}
    out = base.with_overrides(plain, origin="calibration") if plain else base
    gain, offset = values.get("ball_reading.gain", 1.0), values.get("ball_reading.offset_m", 0.0)
    if gain != 1.0 or offset != 0.0:
        sw = out.software
        volts = np.asarray(out.ball_sensor.curve_volts_v)
        read = ball_position_m(volts, sw)
        new_volts = ((gain * read + offset) - sw.ball_offset_m) / sw.ball_gain_m_per_v
        out = out.with_overrides({"ball_sensor.curve_volts_v": new_volts.tolist()}, origin="calibration")
    return out


@dataclass(frozen=True)
class _Windows:
    command_v: np.ndarray  # (nw, W): the command acting during each tick (written at the previous tick)
    previous_v: np.ndarray  # (nw, W): the command before it (acts until the latency has passed)
    y_ball_m: np.ndarray  # (nw, W): eq 6.3.1 of the ball channel at each tick's end
    y_angle_rad: np.ndarray  # (nw, W): eq 6.2.10 of the angle channel (block mean)
    start_guess: np.ndarray  # (nw, 4): state at each window's start from the readings
    period_s: float


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
    ) -> None:
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
        self.base = base
        self.fit = list(fit)
        self.substeps = substeps
        self.windows = self._cut(logs, window_s)
        self.n_windows, self.W = self.windows.command_v.shape
        self.n_global = len(self.fit)

    # --- setup -------------------------------------------------------------------------------------------
    def _cut(self, logs: Sequence[RigLog], window_s: float) -> _Windows:
        p = self.base
        period = float(logs[0].period_s)
        w = max(2, int(round(window_s / period)))
        parts: dict[str, list[np.ndarray]] = {k: [] for k in ("cmd", "prev", "yb", "ya", "s0")}
        curve_x, curve_v = np.asarray(p.ball_sensor.curve_position_m), np.asarray(p.ball_sensor.curve_volts_v)
        for log in logs:
            yb = np.asarray(ball_position_m(log.ball_v, p.software))
            # The angle channel in counts (the level table inverted), then radians from the zeroing angle.
            counts = np.asarray(angle_counter_mean(log.angle_v, p))
            ya = (counts - p.angle_sensor.counter_zero_count) * angle_count_step_rad(p)
            x_est = np.interp(log.ball_v, curve_v, curve_x)  # the curve inverted: a better first guess
            th_est = ya + p.angle_sensor.zeroing_error_rad
            n = len(log.time_s)
            for i0 in range(1, n - w, w):  # tick i0 ends where the window starts; i0 − 1 gives the slope
                idx = np.arange(i0 + 1, i0 + w + 1)
                parts["cmd"].append(log.command_v[idx - 1])
                parts["prev"].append(log.command_v[idx - 2])
                parts["yb"].append(yb[idx])
                parts["ya"].append(ya[idx])
                xd = (x_est[i0 + 1] - x_est[i0 - 1]) / (2 * period)
                thd = (th_est[i0 + 1] - th_est[i0 - 1]) / (2 * period)
                parts["s0"].append(np.array([x_est[i0], th_est[i0], xd, thd]))
        if not parts["cmd"]:
            raise CalibrationError(f"the logs are shorter than one window ({w} ticks)")
        return _Windows(
            command_v=np.array(parts["cmd"]),
            previous_v=np.array(parts["prev"]),
            y_ball_m=np.array(parts["yb"]),
            y_angle_rad=np.array(parts["ya"]),
            start_guess=np.clip(np.array(parts["s0"]), STATE_BOUNDS[0], STATE_BOUNDS[1]),
            period_s=period,
        )

    def initial_vector(self) -> np.ndarray:
        g = [_get(self.base, n) for n in self.fit]
        return np.concatenate([np.array(g, dtype=float), self.windows.start_guess.ravel()])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo = [FITTABLE[n].lower for n in self.fit] + list(np.tile(STATE_BOUNDS[0], self.n_windows))
        hi = [FITTABLE[n].upper for n in self.fit] + list(np.tile(STATE_BOUNDS[1], self.n_windows))
        return np.array(lo), np.array(hi)

    def scale(self) -> np.ndarray:
        return np.concatenate([[FITTABLE[n].scale for n in self.fit], np.tile(STATE_SCALE, self.n_windows)])

    def sparsity(self) -> scipy.sparse.csr_matrix:
        """Rows: the window's ball then angle residuals; columns: global parameters, then window states."""
        nw, W, ng = self.n_windows, self.W, self.n_global
        m = scipy.sparse.lil_matrix((2 * nw * W, ng + 4 * nw), dtype=np.int8)
        for w in range(nw):
            for channel in range(2):
                rows = slice(channel * nw * W + w * W, channel * nw * W + (w + 1) * W)
                m[rows, :ng] = 1
                m[rows, ng + 4 * w : ng + 4 * w + 4] = 1
        return m.tocsr()

    # --- the model --------------------------------------------------------------------------------------
    def parameters(self, z: np.ndarray) -> Parameters:
        return apply_values(
            self.base, dict(zip(self.fit, (float(v) for v in z[: self.n_global]), strict=True))
        )

    def predict(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Predicted (ball reading m, angle reading rad) of every tick of every window."""
        values = dict(zip(self.fit, (float(v) for v in z[: self.n_global]), strict=True))
        p = self.base.with_overrides({k: v for k, v in values.items() if k not in _READING}, origin="fit")
        gain, offset = values.get("ball_reading.gain", 1.0), values.get("ball_reading.offset_m", 0.0)
        q = EquationCoefficients.from_params(p)
        acc = q.accelerations
        k_tau, k_b = p.motor.torque_per_volt_nm_per_v, p.motor.backemf_at_beam_v_s_per_rad
        amp = p.amplifier
        win = self.windows
        s = z[self.n_global :].reshape(self.n_windows, 4).copy()
        x, th, xd, thd = s[:, 0], s[:, 1], s[:, 2], s[:, 3]
        h = win.period_s / self.substeps
        latency = p.daq.output_latency_s
        v_new = np.clip(amp.gain_v_per_v * (win.command_v - amp.zero_command_v), -amp.rail_v, amp.rail_v)
        v_old = np.clip(amp.gain_v_per_v * (win.previous_v - amp.zero_command_v), -amp.rail_v, amp.rail_v)
        # The new command's share of each sub-step: the part of [k·h, (k+1)·h) after the latency.
        share = np.clip((np.arange(1, self.substeps + 1) * h - latency) / h, 0.0, 1.0)

        def f(x_, th_, xd_, thd_, v_):
            xdd, thdd = acc(x_, th_, xd_, thd_, k_tau * (v_ - k_b * thd_))
            return xd_, thd_, xdd, thdd

        tau_rc = p.ball_sensor.rc_resistance_ohm * p.ball_sensor.rc_capacitance_f
        curve_x, curve_v = np.asarray(p.ball_sensor.curve_position_m), np.asarray(p.ball_sensor.curve_volts_v)
        pred_b = np.empty((self.n_windows, self.W))
        pred_a = np.empty((self.n_windows, self.W))
        for j in range(self.W):
            mean_th = 0.5 * th
            for k in range(self.substeps):
                v = v_old[:, j] + share[k] * (v_new[:, j] - v_old[:, j])
                a1 = f(x, th, xd, thd, v)
                a2 = f(
                    x + 0.5 * h * a1[0], th + 0.5 * h * a1[1], xd + 0.5 * h * a1[2], thd + 0.5 * h * a1[3], v
                )
                a3 = f(
                    x + 0.5 * h * a2[0], th + 0.5 * h * a2[1], xd + 0.5 * h * a2[2], thd + 0.5 * h * a2[3], v
                )
                a4 = f(x + h * a3[0], th + h * a3[1], xd + h * a3[2], thd + h * a3[3], v)
                x = x + h / 6.0 * (a1[0] + 2 * a2[0] + 2 * a3[0] + a4[0])
                th = th + h / 6.0 * (a1[1] + 2 * a2[1] + 2 * a3[1] + a4[1])
                xd = xd + h / 6.0 * (a1[2] + 2 * a2[2] + 2 * a3[2] + a4[2])
                thd = thd + h / 6.0 * (a1[3] + 2 * a2[3] + 2 * a3[3] + a4[3])
                mean_th = mean_th + (th if k < self.substeps - 1 else 0.5 * th)
            pred_a[:, j] = mean_th / self.substeps - p.angle_sensor.zeroing_error_rad
            wiper = np.interp(x - tau_rc * xd, curve_x, curve_v)
            pred_b[:, j] = gain * ball_position_m(wiper, p.software) + offset
        return pred_b, pred_a

    def residuals(self, z: np.ndarray) -> np.ndarray:
        """Normalized residuals: ball channel rows, then angle channel rows (window-major)."""
        pred_b, pred_a = self.predict(z)
        rb = (pred_b - self.windows.y_ball_m) / SIGMA_BALL_M
        ra = (pred_a - self.windows.y_angle_rad) / SIGMA_ANGLE_RAD
        r = np.concatenate([rb.ravel(), ra.ravel()])
        return np.where(np.isfinite(r), r, 1e6)


def _solve(
    problem: WindowProblem,
    z0: np.ndarray,
    free: np.ndarray,
    *,
    max_nfev: int,
    progress: Callable[[str], None] | None,
) -> scipy.optimize.OptimizeResult:
    """least_squares over the ``free`` entries of z (the others held at z0)."""
    lo, hi = problem.bounds()
    scale = problem.scale()
    sparsity = problem.sparsity()[:, free]
    calls = [0]
    started = time.perf_counter()

    def fun(u: np.ndarray) -> np.ndarray:
        z = z0.copy()
        z[free] = u
        r = problem.residuals(z)
        calls[0] += 1
        if progress is not None and calls[0] % 10 == 0:
            cost = float(np.sum(np.sqrt(1 + (r / ROBUST_SCALE) ** 2) - 1))
            progress(
                f"evaluations {calls[0]:4d}  robust cost {cost:12.1f}  {time.perf_counter() - started:6.1f} s"
            )
        return r

    u0 = np.clip(z0[free], lo[free], hi[free])
    return scipy.optimize.least_squares(
        fun,
        u0,
        bounds=(lo[free], hi[free]),
        x_scale=scale[free],
        jac_sparsity=sparsity,
        loss="soft_l1",
        f_scale=ROBUST_SCALE,
        method="trf",
        tr_solver="lsmr",
        max_nfev=max_nfev,
        xtol=1e-8,
        ftol=1e-8,
        gtol=1e-8,
    )


def _rms(problem: WindowProblem, z: np.ndarray) -> dict[str, float]:
    pred_b, pred_a = problem.predict(z)
    eb, ea = pred_b - problem.windows.y_ball_m, pred_a - problem.windows.y_angle_rad
    return {
        "ball_m": float(np.sqrt(np.mean(eb**2))),
        "ball_m_median_abs": float(np.median(np.abs(eb))),
        "angle_rad": float(np.sqrt(np.mean(ea**2))),
    }


def calibrate(
    logs: Sequence[RigLog],
    fit: Sequence[str],
    start: Parameters | None = None,
    *,
    window_s: float = 1.0,
    max_nfev: int = 60,
    progress: Callable[[str], None] | None = None,
) -> Calibration:
    """Fit ``fit`` (names from ``FITTABLE``) to ``logs`` from ``start`` (default: the thesis's values)."""
    started = time.perf_counter()
    base = start or Parameters()
    problem = WindowProblem(logs, base, fit, window_s=window_s)
    z0 = problem.initial_vector()
    n_g = problem.n_global
    states = np.arange(n_g, z0.size)
    # 1. The window states alone at the starting parameters: the "before" of the report.
    if progress:
        progress(
            f"{problem.n_windows} windows of {problem.W} ticks, {n_g} parameters: fitting the window states"
        )
    before = _solve(problem, z0, states, max_nfev=20, progress=progress)
    z_before = z0.copy()
    z_before[states] = before.x
    # 2. Everything together.
    if progress:
        progress("fitting the parameters and the window states together")
    every = np.arange(z0.size)
    result = _solve(problem, z_before, every, max_nfev=max_nfev, progress=progress)
    z = result.x

    # Intervals: the cluster-robust ("sandwich") covariance with a window as the cluster. Residuals within a
    # window are correlated (quantization that holds for many ticks, the model's own small errors), which
    # makes the plain Gauss-Newton covariance optimistic; the windows are independent of each other (each
    # has its own initial state). Bread: the loss-weighted Jacobian scipy returns; meat: each window's
    # gradient contribution Jᵀr with the robust loss's weights.
    jac = result.jac.toarray() if scipy.sparse.issparse(result.jac) else np.asarray(result.jac)
    r = problem.residuals(z)
    weights = 1.0 / np.sqrt(np.sqrt(1.0 + (r / ROBUST_SCALE) ** 2))  # √ρ′ of soft_l1
    rw = r * weights
    nw, W = problem.n_windows, problem.W
    bread = np.linalg.pinv(jac.T @ jac)
    meat = np.zeros_like(bread)
    per_cluster = max(1, int(round(CLUSTER_S / (W * problem.windows.period_s))))
    clusters = [range(c, min(c + per_cluster, nw)) for c in range(0, nw, per_cluster)]
    for members in clusters:
        rows = np.concatenate(
            [
                np.concatenate([np.arange(w * W, (w + 1) * W), nw * W + np.arange(w * W, (w + 1) * W)])
                for w in members
            ]
        )
        g = jac[rows].T @ rw[rows]
        meat += np.outer(g, g)
    n_c = len(clusters)
    cov = bread @ meat @ bread * n_c / max(n_c - 1, 1)
    # The same covariance assuming white residuals, to report how much the correlation widens the intervals.
    spread2 = float(rw @ rw) / max(r.size - z.size, 1)
    naive = np.sqrt(np.maximum(np.diag(bread)[:n_g] * spread2, 1e-300))
    cov_g = cov[:n_g, :n_g]
    std = np.sqrt(np.maximum(np.diag(cov_g), 0.0))
    inflation = float(np.median(std / naive)) if n_g else 1.0
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov_g / np.outer(std, std)
    corr = np.nan_to_num(corr)
    # Student's t with (clusters − 1) degrees of freedom: few clusters make the covariance itself uncertain.
    z_crit = float(scipy.stats.t.ppf(0.5 + CONFIDENCE / 2, max(n_c - 1, 1)))
    values: dict[str, FittedValue] = {}
    warnings: list[str] = []
    for i, name in enumerate(problem.fit):
        spec = FITTABLE[name]
        lo, hi = float(z[i] - z_crit * std[i]), float(z[i] + z_crit * std[i])
        values[name] = FittedValue(float(z[i]), lo, hi, float(z0[i]), spec.unit)
        if not np.isfinite(std[i]) or std[i] == 0.0:
            warnings.append(f"{name}: the data do not determine it (flat direction)")
        elif hi - lo > spec.upper - spec.lower:
            warnings.append(
                f"{name}: its {CONFIDENCE:.0%} interval is wider than its bounds: not identifiable here"
            )
        if abs(z[i] - spec.lower) < 1e-6 * spec.scale or abs(z[i] - spec.upper) < 1e-6 * spec.scale:
            warnings.append(
                f"{name} = {z[i]:.6g} {spec.unit} sits on its bound [{spec.lower:g}, {spec.upper:g}]"
            )
    for i in range(n_g):
        for j in range(i + 1, n_g):
            if abs(corr[i, j]) > 0.95:
                warnings.append(
                    f"{problem.fit[i]} and {problem.fit[j]} are correlated ({corr[i, j]:+.2f}): the logs barely "
                    "separate them; excite the rig differently (README: how to record a log)"
                )
    pred_b0, pred_a0 = problem.predict(z_before)
    pred_b1, pred_a1 = problem.predict(z)
    return Calibration(
        params=problem.parameters(z),
        values=values,
        correlation=corr,
        rms_before=_rms(problem, z_before),
        rms_after=_rms(problem, z),
        converged=bool(result.success),
        message=str(result.message),
        warnings=warnings,
        wall_s=time.perf_counter() - started,
        n_windows=problem.n_windows,
        n_ticks=problem.n_windows * problem.W,
        ci_inflation=inflation,
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
