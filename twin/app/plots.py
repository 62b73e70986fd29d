"""Figures of a closed-loop run (matplotlib, no display needed): rendering, in the application layer (the
core computes the run, ``twin.engine.RunResult``, and draws nothing)."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from twin import converters  # noqa: E402
from twin.engine import RunResult  # noqa: E402
from twin.outputs import atomic_output  # noqa: E402
from twin.parameters import SoftwareCalibration  # noqa: E402

__all__ = ["plot_run", "run_figure"]


def run_figure(
    result: RunResult, title: str | None = None, *, software: SoftwareCalibration | None = None
) -> Figure:
    """Ball position and beam angle (true, measured, the controller's estimate) and motor volts against time.

    Measured = the logged ADC volts (datam1, datam2) through the software's converters (eq 6.3.1, eq 6.2.10)
    with ``software`` (the run's calibration; the thesis's by default). The estimate (x1, x2) is drawn
    where the controller logged one: a controller without an estimate logs NaN, drawn as nothing, and the
    measured trace stays."""
    log = result.log
    sw = software or SoftwareCalibration()
    measured_x = np.asarray(converters.ball_position_m(log.datam1, sw), dtype=float)
    measured_theta = np.asarray(converters.beam_angle_rad(log.datam2, sw), dtype=float)
    fig, axes = plt.subplots(3, 1, figsize=(8, 7.5), sharex=True)
    for ax, true, measured, estimate, label, unit in (
        (axes[0], log.true_x_m, measured_x, log.x1, "eq 6.3.1", "ball x (m)"),
        (axes[1], log.true_theta_rad, measured_theta, log.x2, "eq 6.2.10", "beam θ (rad)"),
    ):
        ax.plot(log.true_time_s, true, label="true")
        ax.plot(log.timem, measured, ".", ms=2, label=f"measured ({label})")
        if np.isfinite(estimate).any():
            ax.plot(log.timem, estimate, lw=0.8, label="estimate")
        ax.set_ylabel(unit)
        ax.legend(loc="upper right", fontsize=8)
    ax = axes[2]
    ax.plot(log.true_time_s, log.motor_volts_v)
    ax.set_ylabel("motor (V)")
    ax.set_xlabel("time (s)")
    fig.suptitle(title or f"{result.controller}: {'held' if result.verdict.held else result.verdict.reason}")
    fig.tight_layout()
    return fig


def plot_run(
    result: RunResult,
    path: str | Path,
    title: str | None = None,
    *,
    overwrite: bool = True,
    software: SoftwareCalibration | None = None,
) -> None:
    """``run_figure`` as one PNG.

    The file is written atomically (``twin.outputs.atomic_output``): a failed write leaves an existing file as
    it was; without ``overwrite`` an existing file is refused (``FileExistsError``)."""
    fig = run_figure(result, title, software=software)
    try:
        with atomic_output(path, overwrite=overwrite) as fh:
            fig.savefig(fh, dpi=110, format=Path(path).suffix[1:].lower() or "png")
    finally:
        plt.close(fig)
