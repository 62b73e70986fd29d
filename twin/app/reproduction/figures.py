"""The closed-loop figures as PNG: each figure claim's declared runs, drawn (no evaluation here).

One PNG per figure id (``fig_4_4.png`` …), titled with the thesis's caption; the panels are those
``closed_loop.FIGURE_SHOW`` names for it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from twin.app.reproduction.claims import Claim
from twin.app.reproduction.closed_loop import FIGURE_SHOW, ZEROING_ERRORS_RAD, zeroing_runs
from twin.app.reproduction.scenarios import Trace, run

__all__ = ["CAPTIONS", "png_name", "write_figures"]

CAPTIONS = {  # the thesis's captions, as printed
    "Fig 4.4": "System Response with x(0)=0.2 m and θ(0)=0.3 rad (State-feedback)",
    "Fig 4.5": "System Response with x(0)=-0.2 m and θ(0)=0.3 rad (State-feedback)",
    "Fig 4.8": "System Response with x(0)=0.2 m and θ(0)=0.3 rad (Control law partitioning)",
    "Fig 4.9": "System Response with x(0)=-0.2 m and θ(0)=0.3 rad (Control law partitioning)",
    "Fig 4.11": "System Response with x(0)=0.2 m and θ(0)=0.3 rad (Sliding Mode)",
    "Fig 4.12": "System Response with x(0)=-0.2 m and θ(0)=0.3 rad (Sliding Mode)",
    "Fig 5.3": "x(0)=0.2 m, θ(0)=0.3 rad. with state feedback",
    "Fig 5.4": "x(0)=-0.2 m, θ(0)=0.3 rad. with state feedback",
    "Fig 5.5": "Observer error with x(0)=-0.2 m, θ(0)=0.3 rad. with state feedback",
    "Fig 5.8": "x(0)=0.2 m, θ(0)=0.3 rad. with control law partitioning",
    "Fig 5.9": "x(0)=-0.2 m, θ(0)=0.3 rad. with control law partitioning",
    "Fig 5.10": "Observer error with x(0)=-0.2 m, θ(0)=0.3 rad. with control law partitioning",
    "Fig 7.1": "Sliding Mode Controller, required torque versus time",
    "Fig 7.2": "Control Law Partitioning, required torque versus time",
    "Fig 7.3": "State Feedback, required torque versus time",
    "Fig 7.4": "Sliding Mode Controller, required torque versus time",
    "Fig 7.5": "Control Law Partitioning, required torque versus time",
    "Fig 7.6": "State Feedback, required torque versus time",
    "Fig 7.7": "State feedback Required Torque versus time",
    "Fig 7.8": "Voltage: State feedback [-0.25m, 0.2 rad]",
    "Fig 7.9": "Ball Position: State feedback [-0.25m, 0.2 rad]",
    "Fig 7.10": "Beam Angle: State feedback [-0.25m, 0.2 rad]",
    "Fig 7.11": "Voltage: State feedback [0.33 m, 0.68 rad.]",
    "Fig 7.12": "Position: State feedback [0.33 m, 0.68 rad.]",
    "Fig 7.13": "Beam Angle: State feedback [0.33 m, 0.68 rad.]",
    "Fig 7.14": "Voltage: Control law partitioning [-0.26m, 0.3 rad]",
    "Fig 7.15": "Position: Control law partitioning [-0.26m, 0.3 rad]",
    "Fig 7.16": "Beam Angle: Control law partitioning [-0.26m, 0.3 rad]",
    "Fig 7.17": "Voltage: Control law partitioning [0.33 m, 0.7 rad]",
    "Fig 7.18": "Position: Control law partitioning [0.33 m, 0.7 rad]",
    "Fig 7.19": "Beam Angle: Control law partitioning [0.33 m, 0.7 rad]",
    "Fig 7.20": "Initialization Error",
}
PANELS: dict[str, tuple[str, Any]] = {  # panel → (y label, what to plot of a trace)
    "x": ("x (m)", lambda tr: tr.x),
    "theta": ("θ (rad)", lambda tr: tr.theta),
    "torque": ("torque at the beam (N·m)", lambda tr: tr.torque),
    "volts": ("motor voltage (V)", lambda tr: tr.volts),
}


def png_name(fig_id: str) -> str:
    return "fig_" + fig_id.split()[1].replace(".", "_") + ".png"


def _save(fig: Any, out_dir: Path, fig_id: str) -> None:
    fig.suptitle(f"{fig_id}: {CAPTIONS[fig_id]}", fontsize=10)
    fig.tight_layout()
    fig.savefig(out_dir / png_name(fig_id), dpi=90)
    plt.close(fig)


def _responses(traces: list[Trace], show: tuple[str, ...]) -> Any:
    fig, axes = plt.subplots(len(show), 1, figsize=(7, 2.2 * len(show) + 0.6), sharex=True, squeeze=False)
    for ax, what in zip(axes[:, 0], show, strict=True):
        label, values = PANELS[what]
        for tr in traces:
            ax.plot(tr.t, values(tr), label=tr.scenario.label, lw=0.9)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    axes[-1, 0].set_xlabel("time (s)")
    return fig


def _observer_error(traces: list[Trace]) -> Any:
    fig, axes = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    for tr in traces:
        err = tr.state[:, 2:] - tr.estimate[:, 2:]
        for i in range(2):
            axes[i].plot(tr.t, err[:, i], label=tr.scenario.label)
    axes[0].set_ylabel("ẋ − ẋ_est (m/s)")
    axes[1].set_ylabel("θ̇ − θ̇_est (rad/s)")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.set_yscale("symlog", linthresh=0.1)
    axes[0].legend(fontsize=7)
    axes[1].set_xlabel("time (s)")
    return fig


def _zeroing() -> Any:
    fig, axes = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True)
    for label, runs in zeroing_runs().items():
        style = "-o" if "twin" in label else "--x"
        steady = [run(s).verdict for s in runs]
        axes[0].plot(
            ZEROING_ERRORS_RAD,
            [np.nan if v.steady_x_m is None else v.steady_x_m for v in steady],
            style,
            label=label,
        )
        axes[1].plot(
            ZEROING_ERRORS_RAD,
            [np.nan if v.steady_theta_rad is None else v.steady_theta_rad for v in steady],
            style,
            label=label,
        )
    axes[0].set_ylabel("steady ball position (m)")
    axes[1].set_ylabel("steady beam angle (rad)")
    axes[1].set_xlabel("zeroing error e (rad): beam angle at which the counter was zeroed")
    for ax in axes:
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    return fig


def write_figures(claims: tuple[Claim, ...], out_dir: Path) -> list[Path]:
    """One PNG per figure claim, from its (cached) runs."""
    for claim in claims:
        show = FIGURE_SHOW.get(claim.id)
        if show is None:
            continue
        if show == ("zeroing",):
            fig = _zeroing()
        else:
            traces = [run(s) for s in claim.scenarios]
            fig = _observer_error(traces) if show == ("observer error",) else _responses(traces, show)
        _save(fig, out_dir, claim.id)
    return sorted(out_dir.glob("fig_*.png"))
