"""The calibration report's figures (matplotlib) and Markdown: rendering only, the numbers come from
``calib.identify.Calibration``."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from calib.identify import CONFIDENCE, Calibration  # noqa: E402

__all__ = ["render_figures", "render_markdown"]


def render_figures(cal: Calibration, out: Path) -> None:
    """fit.png, residuals.png and (two or more fitted parameters) correlation.png into ``out``."""
    tr = cal.traces
    t = tr["t_s"]
    fig, axes = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    for ax, key, unit, scale in (
        (axes[0], "ball", "ball x (mm)", 1e3),
        (axes[1], "angle", "beam θ (mrad)", 1e3),
    ):
        suffix = "m" if key == "ball" else "rad"
        ax.plot(t, scale * tr[f"y_{key}_{suffix}"], ".", ms=2, color="k", label="measured")
        ax.plot(t, scale * tr[f"before_{key}_{suffix}"], lw=0.8, label="simulated, starting parameters")
        ax.plot(t, scale * tr[f"after_{key}_{suffix}"], lw=0.8, label="simulated, fitted parameters")
        ax.set_ylabel(unit)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[1].set_xlabel("time over the windows (s)")
    fig.suptitle("Measured and simulated readings (each window started from its fitted state)")
    fig.tight_layout()
    fig.savefig(out / "fit.png", dpi=100)
    plt.close(fig)

    fig, axes = plt.subplots(2, 2, figsize=(10, 6))
    for row, (key, suffix, unit) in enumerate((("ball", "m", "mm"), ("angle", "rad", "mrad"))):
        res = 1e3 * (tr[f"after_{key}_{suffix}"] - tr[f"y_{key}_{suffix}"])
        axes[row, 0].plot(t, res, lw=0.6)
        axes[row, 0].set_ylabel(f"{key} residual ({unit})")
        lim = np.percentile(np.abs(res), 99) if res.size else 1.0
        axes[row, 1].hist(res[np.abs(res) <= lim], bins=60)
        axes[row, 1].set_xlabel(f"{key} residual ({unit}), central 99 %")
    axes[1, 0].set_xlabel("time over the windows (s)")
    fig.tight_layout()
    fig.savefig(out / "residuals.png", dpi=100)
    plt.close(fig)

    names = cal.correlation_names
    if names:
        fig, ax = plt.subplots(figsize=(1.2 + 0.9 * len(names), 1.0 + 0.8 * len(names)))
        im = ax.imshow(cal.correlation, vmin=-1, vmax=1, cmap="RdBu_r")
        ax.set_xticks(range(len(names)), names, rotation=60, ha="right", fontsize=7)
        ax.set_yticks(range(len(names)), names, fontsize=7)
        for i in range(len(names)):
            for j in range(len(names)):
                ax.text(j, i, f"{cal.correlation[i, j]:+.2f}", ha="center", va="center", fontsize=7)
        fig.colorbar(im)
        fig.tight_layout()
        fig.savefig(out / "correlation.png", dpi=100)
        plt.close(fig)


def render_markdown(cal: Calibration) -> str:
    lines = [
        "# Calibration",
        "",
        f"{cal.n_windows} windows, {cal.n_ticks} ticks; converged: **{cal.converged}** ({cal.message}); "
        f"{cal.wall_s:.1f} s.",
        "",
        f"| parameter | fitted | {CONFIDENCE:.0%} interval | start | unit |",
        "| --- | --- | --- | --- | --- |",
    ]
    for name, v in cal.values.items():
        lines.append(
            f"| {name} | {v.value:.6g} | [{v.ci_low:.6g}, {v.ci_high:.6g}] | {v.initial:.6g} | {v.unit} |"
        )
    lines += [
        "",
        f"Intervals: {cal.interval_method}; the plain white-noise intervals would be "
        f"×{1 / cal.ci_inflation:.2f} as wide."
        if cal.ci_inflation > 0
        else f"Intervals: {cal.interval_method}.",
        "",
        "Before: the starting parameters with every window's state fitted to convergence; after: the fit.",
        "",
        "| residual | before | after |",
        "| --- | --- | --- |",
    ]
    for key in cal.rms_after:
        lines.append(f"| {key} | {cal.rms_before[key]:.4g} | {cal.rms_after[key]:.4g} |")
    if cal.adequacy:
        lines += [
            "",
            "## Model adequacy",
            "",
            "| channel | residual RMS | noise floor | RMS / floor | ρ(1…5) | white band ±1.96/√N |",
            "| --- | --- | --- | --- | --- | --- |",
        ]
        for a in cal.adequacy.values():
            rho = ", ".join(f"{r:+.2f}" for r in a.autocorrelation)
            lines.append(
                f"| {a.channel} | {a.rms:.3g} {a.unit} | {a.floor:.3g} {a.unit} | {a.ratio:.2f} | {rho} | "
                f"±{a.band:.3f} |"
            )
        lines.append("")
        lines.append(f"Normalized information matrix's condition number: {cal.information_condition:.3g}.")
    lines += ["", "## Problems", ""]
    lines += [f"- **{p}**" for p in cal.problems] or ["- none"]
    lines += ["", "## Warnings", ""]
    lines += [f"- {w}" for w in cal.warnings] or ["- none"]
    lines += [
        "",
        "![measured and simulated](fit.png)",
        "",
        "![residuals](residuals.png)",
        "",
        "![correlation](correlation.png)",
        "",
    ]
    return "\n".join(lines)
