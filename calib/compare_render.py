"""The comparison's figures (matplotlib), Markdown and folder: rendering and writing only, the numbers come
from ``calib.compare.Comparison`` (imported here, never the other way round)."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from calib.compare import (  # noqa: E402
    CHANNELS,
    MAX_LAG,
    OUTPUT_FILES,
    ChannelScore,
    ClosedLoopPrediction,
    Comparison,
    LogWindows,
    WindowedPrediction,
)
from twin.outputs import atomic_directory  # noqa: E402

__all__ = ["render_figures", "render_markdown", "write_comparison"]

# Channel → (axis label, display scale from SI).
_LABEL = {"ball": ("ball x (mm)", 1e3), "angle": ("beam θ (mrad)", 1e3)}
# Logs shown one after another on a common axis, this far apart (s).
_GAP_S = 1.0
# The closed-loop figure shows at most this many logs (the JSON and the report list all).
_MAX_CLOSED_LOOP_ROWS = 4


def _offsets(logs: list[LogWindows]) -> list[float]:
    """Each log's time offset on the common axis: the logs one after another."""
    out, at = [], 0.0
    for lw in logs:
        out.append(at - float(lw.t_s[0, 0]))
        at += float(lw.t_s[-1, -1] - lw.t_s[0, 0]) + _GAP_S
    return out


def _window_lines(t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Windows (nw, W) as one line broken between windows (a NaN after each)."""
    pad = np.full((t.shape[0], 1), np.nan)
    return np.hstack([t, pad]).ravel(), np.hstack([y, pad]).ravel()


def render_figures(result: Comparison, out: Path) -> None:
    """prediction.png, residuals.png, autocorrelation.png, windows.png and (with a controller) closed_loop.png."""
    wp = result.windowed
    offsets = _offsets(wp.logs)
    xlabel = "time over the logs (s)" if len(wp.logs) > 1 else "log time (s)"
    _save(_prediction_figure(wp, offsets, xlabel), out / "prediction.png")
    _save(_residuals_figure(wp, offsets, xlabel), out / "residuals.png")
    _save(_autocorrelation_figure(wp), out / "autocorrelation.png")
    _save(_windows_figure(wp, offsets, xlabel), out / "windows.png")
    loops = result.closed_loop[:_MAX_CLOSED_LOOP_ROWS]
    if loops:
        _save(_closed_loop_figure(loops), out / "closed_loop.png")


def _save(fig: Figure, path: Path) -> None:
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)  # pyplot keeps every open figure alive


def _prediction_figure(wp: WindowedPrediction, offsets: list[float], xlabel: str) -> Figure:
    """Per channel: the readings, each window's fitted line and its prediction from the previous window."""
    fig, axes = plt.subplots(2, 1, figsize=(11, 6.5), sharex=True)
    for ax, c in zip(axes, CHANNELS, strict=True):
        label, scale = _LABEL[c]
        for i, (lw, off) in enumerate(zip(wp.logs, offsets, strict=True)):
            t = lw.t_s + off
            first = i == 0  # one legend entry per line kind, not one per log
            ax.plot(
                t.ravel(),
                scale * lw.measured[c].ravel(),
                ".",
                ms=2,
                color="k",
                label="measured" if first else None,
            )
            ax.plot(
                *_window_lines(t, scale * lw.fitted[c]),
                lw=0.6,
                color="tab:gray",
                alpha=0.7,
                label="fitted (start state fitted to the window)" if first else None,
            )
            ax.plot(
                *_window_lines(t, scale * lw.predicted[c]),
                lw=1.1,
                color="tab:red",
                label=f"predicted {wp.horizon_s:g} s from the previous window's estimate" if first else None,
            )
        ax.set_ylabel(label)
        s = wp.predicted[c]
        ax.set_title(
            f"{c}: predicted fit {s.fit_percent:.1f} %, fitted {wp.fitted[c].fit_percent:.1f} %", fontsize=9
        )
    axes[0].legend(loc="upper right", fontsize=7)
    axes[1].set_xlabel(xlabel)
    return fig


def _residuals_figure(wp: WindowedPrediction, offsets: list[float], xlabel: str) -> Figure:
    """Per channel: the prediction's residual against time (with ± the noise floor) and its histogram."""
    fig, axes = plt.subplots(2, 2, figsize=(11, 6), gridspec_kw={"width_ratios": (3, 1)})
    for row, c in enumerate(CHANNELS):
        label, scale = _LABEL[c]
        s = wp.predicted[c]
        residual = []
        for lw, off in zip(wp.logs, offsets, strict=True):
            e = lw.predicted[c] - lw.measured[c]
            if c == "ball":
                e = np.where(lw.dropout, np.nan, e)
            axes[row, 0].plot(*_window_lines(lw.t_s + off, scale * e), lw=0.7, color="tab:red")
            residual.append(e[np.isfinite(e)])
        for sign in (-1, 1):
            axes[row, 0].axhline(sign * scale * s.floor, color="tab:blue", lw=0.8, ls="--")
        axes[row, 0].set_ylabel(f"{c} residual ({label.split('(')[1]}")
        res = scale * np.concatenate(residual) if residual else np.zeros(0)
        axes[row, 1].hist(res, bins=50, color="tab:red")
        axes[row, 1].set_xlabel(f"RMS {scale * s.rms:.3g}, floor {scale * s.floor:.3g}")
    axes[0, 0].set_title(
        "prediction residual (dashed: ± the noise floor; ball dropouts left out)", fontsize=9
    )
    axes[1, 0].set_xlabel(xlabel)
    return fig


def _autocorrelation_figure(wp: WindowedPrediction) -> Figure:
    """Per channel: the predicted and the fitted residuals' autocorrelation with their whiteness bands."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    lags = np.arange(MAX_LAG + 1)
    for ax, c in zip(axes, CHANNELS, strict=True):
        for s, colour, what, shift in (
            (wp.predicted[c], "tab:red", "predicted", -0.15),
            (wp.fitted[c], "tab:gray", "fitted", 0.15),
        ):
            ax.vlines(
                lags + shift,
                0,
                s.acf,
                color=colour,
                lw=2,
                label=f"{what} ({s.outside}/{MAX_LAG} lags outside)",
            )
            ax.axhspan(-s.band, s.band, color=colour, alpha=0.12)
        ax.axhline(0, color="k", lw=0.5)
        ax.set_xlabel(f"lag (ticks of {1e3 * wp.window_s / wp.ticks_per_window:g} ms)")
        ax.set_title(f"{c} residual autocorrelation (band ±1.96/√N)", fontsize=9)
        ax.legend(fontsize=7)
    return fig


def _windows_figure(wp: WindowedPrediction, offsets: list[float], xlabel: str) -> Figure:
    """Per channel: each window's RMS error against its start time, where a drift shows."""
    fig, axes = plt.subplots(2, 1, figsize=(11, 5.5), sharex=True)
    for ax, c in zip(axes, CHANNELS, strict=True):
        label, scale = _LABEL[c]
        for i, (lw, off) in enumerate(zip(wp.logs, offsets, strict=True)):
            t = lw.t_s[:, 0] + off
            first = i == 0  # one legend entry per line kind, not one per log
            ax.plot(
                t,
                scale * wp.window_rms(lw, "predicted")[c],
                "o-",
                ms=3,
                color="tab:red",
                label="predicted" if first else None,
            )
            ax.plot(
                t,
                scale * wp.window_rms(lw, "fitted")[c],
                "o-",
                ms=2,
                lw=0.6,
                color="tab:gray",
                label="fitted" if first else None,
            )
        ax.axhline(scale * wp.predicted[c].floor, color="tab:blue", ls="--", lw=0.8, label="noise floor")
        ax.set_ylabel(f"RMS per window ({label.split('(')[1]}")
    axes[0].set_title("error per window against time (drift)", fontsize=9)
    axes[0].legend(fontsize=7)
    axes[1].set_xlabel(f"window start, {xlabel}")
    return fig


def _closed_loop_figure(loops: list[ClosedLoopPrediction]) -> Figure:
    """One row per log: its readings and the closed-loop twin's, and where the twin leaves the band."""
    fig, axes = plt.subplots(len(loops), 2, figsize=(11, 2.8 * len(loops)), squeeze=False)
    for row, cl in enumerate(loops):
        for col, c in enumerate(CHANNELS):
            label, scale = _LABEL[c]
            ax = axes[row, col]
            ax.plot(cl.t_s, scale * cl.measured[c], lw=0.8, color="k", label="log")
            ax.plot(cl.t_s, scale * cl.twin[c], lw=0.8, color="tab:red", label="twin, closed loop")
            tracked = cl.tracked_s[c]
            if tracked is not None:
                ax.axvline(
                    tracked, color="tab:blue", ls="--", lw=0.8, label=f"leaves ±{scale * cl.bands[c]:g}"
                )
            ax.set_ylabel(label)
            ax.set_title(f"{Path(cl.path).name}: {c}", fontsize=8)
            ax.legend(fontsize=7)
    for col in range(2):
        axes[-1, col].set_xlabel("time from release (s)")
    return fig


def _dropped_text(wp: WindowedPrediction) -> str:
    """The windows calibration's screen left out (railed, the ball lost), counted by reason."""
    reasons: dict[str, int] = {}
    for lw in wp.logs:
        for d in lw.dropped:
            reasons[d.reason] = reasons.get(d.reason, 0) + 1
    return ", ".join(f"{n} window(s) {r}" for r, n in sorted(reasons.items()))


def _score_row(what: str, c: str, s: ChannelScore) -> str:
    _, scale = _LABEL[c]
    unit = "mm" if c == "ball" else "mrad"
    return (
        f"| {c} | {what} | {s.fit_percent:.2f} | {scale * s.rms:.3g} {unit} | {scale * s.floor:.3g} {unit} | "
        f"{s.floor_ratio:.2f} | {s.outside}/{MAX_LAG} | {s.samples} |"
    )


def _fmt(value: float | None, scale: float = 1.0, digits: int = 3) -> str:
    return "—" if value is None else f"{scale * value:.{digits}g}"


def render_markdown(result: Comparison) -> str:
    wp = result.windowed
    crit = result.criterion
    lines = [
        "# The twin against the log",
        "",
        f"Logs: {', '.join(result.logs)}; parameters: {result.params_source}; {result.wall_s:.1f} s.",
        "",
        f"**{'Conforms' if result.passed else 'Does not conform'}**: on each channel the prediction's fit ≥ "
        f"{crit.min_fit_percent:g} % and its residual RMS ≤ {crit.max_floor_ratio:g} × the noise floor, no "
        "predicted window diverged."
        + ("" if result.passed else " Failed: " + "; ".join(result.failures) + "."),
        "",
        "## Windowed prediction",
        "",
        f"{wp.n_windows} windows of {wp.window_s:g} s ({wp.ticks_per_window} ticks). **Fitted**: each window's start "
        "state (x, θ, ẋ, θ̇) fitted to that window's readings at the given parameters (no parameter fitted; "
        f"windows not joined). **Predicted**: the first {wp.horizon_s:g} s of window k from window k − 1's fitted "
        f"end state with window k's logged commands: no reading of the predicted span entered it "
        f"({wp.n_predicted} predicted windows; the first window of each log has no predecessor"
        + (
            f", nor has a window after one left out: {_dropped_text(wp)}"
            if any(lw.dropped for lw in wp.logs)
            else ""
        )
        + "). The scores and the criterion are the predictions'; the fitted rows overstate what the model "
        "predicts.",
        "",
        "| channel | | fit % | residual RMS | noise floor | RMS / floor | lags outside ±1.96/√N | samples |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for c in CHANNELS:
        lines.append(_score_row("predicted", c, wp.predicted[c]))
        lines.append(_score_row("fitted", c, wp.fitted[c]))
    q = wp.predicted
    lines += [
        "",
        "Fit % = 100·(1 − ‖y − ŷ‖/‖y − mean(y)‖) over the scored ticks (MATLAB's `compare`). Noise floor = the larger "
        "of the reading's quantization (ball: the ADC step through eq 6.3.1 /√12 = "
        f"{1e3 * q['ball'].quantization:.3g} mm; angle: one encoder count /√12 = "
        f"{1e3 * q['angle'].quantization:.3g} mrad) and the log's tick-to-tick scatter (1.4826·MAD of the "
        f"second difference /√6: ball {1e3 * q['ball'].scatter:.3g} mm, angle {1e3 * q['angle'].scatter:.3g} mrad). "
        f"{wp.dropouts} ball ticks are contact dropouts (more than 3 mm from the median of the five about them) and "
        "are left out of the ball's scores. Whiteness: a prediction's residual grows over the horizon, so it "
        "is correlated; the fitted residual's autocorrelation is the model's one-window error.",
        "",
        f"Divergent predicted windows: {wp.diverged}. State fit: {wp.fit_message}",
        "",
        "![measured, fitted and predicted](prediction.png)",
        "",
        "![residuals](residuals.png)",
        "",
        "![autocorrelation](autocorrelation.png)",
        "",
        "![error per window](windows.png)",
        "",
    ]
    if result.closed_loop:
        lines += [
            "## Closed loop from the first block",
            "",
            "The twin (MuJoCo, the hardware sensor chain, the given parameters) started at rest from the log's first "
            "block (x and θ: the volts through the twin's sensor chain inverted) runs the controller for the log's "
            "duration. It tracks the log while its readings (eq 6.3.1, eq 6.2.10, a 3-tick median against "
            "dropouts) stay within the bands. Verdicts: the log's and the twin's measured (`ballbeam judge`), "
            "the twin's from its true state.",
            "",
            "| log | controller | x0 (mm) | θ0 (mrad) | ball tracked until (s) | beam tracked until (s) | log | twin "
            "(measured) | twin (true state) | agree |",
            "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
        ]
        for cl in result.closed_loop:
            lines.append(
                f"| {cl.path} | {cl.controller} | {1e3 * cl.x0_m:.1f} | {1e3 * cl.theta0_rad:.1f} | "
                f"{_fmt(cl.tracked_s['ball'], digits=4) if cl.tracked_s['ball'] is not None else 'end'} | "
                f"{_fmt(cl.tracked_s['angle'], digits=4) if cl.tracked_s['angle'] is not None else 'end'} | "
                f"{cl.verdict_log.reason} | {cl.verdict_twin.reason} | {cl.verdict_twin_true.reason} | "
                f"{'yes' if cl.verdicts_agree else 'no'} |"
            )
        lines += [
            "",
            "| log | | steady x (mm) | steady θ (mrad) | x limit cycle (mm p-p) | settling (s) |",
            "| --- | --- | --- | --- | --- | --- |",
        ]
        for cl in result.closed_loop:
            for what, v in (("log", cl.verdict_log), ("twin", cl.verdict_twin)):
                lines.append(
                    f"| {cl.path} | {what} | {_fmt(v.steady_x_m, 1e3)} | {_fmt(v.steady_theta_rad, 1e3)} | "
                    f"{_fmt(v.limit_cycle_x_pp_m, 1e3)} | {_fmt(v.settling_time_s)} |"
                )
        lines += ["", "![closed loop](closed_loop.png)", ""]
    return "\n".join(lines)


def write_comparison(result: Comparison, out_dir: str | Path, *, overwrite: bool = False) -> Path:
    """comparison.json, report.md and the figures into ``out_dir`` (atomically: ``twin.outputs``)."""
    with atomic_directory(out_dir, OUTPUT_FILES, overwrite=overwrite) as tmp:
        (tmp / "comparison.json").write_text(json.dumps(result.to_json(), indent=2) + "\n")
        render_figures(result, tmp)
        (tmp / "report.md").write_text(render_markdown(result))
    return Path(out_dir)
