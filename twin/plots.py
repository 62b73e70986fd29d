"""Figures of a closed-loop run (matplotlib, no display needed)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from twin.engine import RunResult  # noqa: E402
from twin.outputs import atomic_output  # noqa: E402

__all__ = ["plot_run"]


def plot_run(
    result: RunResult, path: str | Path, title: str | None = None, *, overwrite: bool = True
) -> None:
    """Ball position (true, measured, estimated), beam angle, motor volts against time, as one PNG.

    The file is written atomically (``twin.outputs.atomic_output``): a failed write leaves an existing file as
    it was; without ``overwrite`` an existing file is refused (``FileExistsError``)."""
    log = result.log
    fig, axes = plt.subplots(3, 1, figsize=(8, 7.5), sharex=True)
    ax = axes[0]
    ax.plot(log.true_time_s, log.true_x_m, label="true")
    ax.plot(log.timem, log.x1, ".", ms=2, label="measured (eq 6.3.1) / estimate")
    ax.set_ylabel("ball x (m)")
    ax.legend(loc="upper right", fontsize=8)
    ax = axes[1]
    ax.plot(log.true_time_s, log.true_theta_rad, label="true")
    ax.plot(log.timem, log.x2, ".", ms=2, label="measured (eq 6.2.10)")
    ax.set_ylabel("beam θ (rad)")
    ax.legend(loc="upper right", fontsize=8)
    ax = axes[2]
    ax.plot(log.true_time_s, log.motor_volts_v)
    ax.set_ylabel("motor (V)")
    ax.set_xlabel("time (s)")
    fig.suptitle(title or f"{result.controller}: {'held' if result.verdict.held else result.verdict.reason}")
    fig.tight_layout()
    try:
        with atomic_output(path, overwrite=overwrite) as fh:
            fig.savefig(fh, dpi=110, format=Path(path).suffix[1:].lower() or "png")
    finally:
        plt.close(fig)
