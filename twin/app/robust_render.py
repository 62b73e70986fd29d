"""The robust map of a sweep over many rigs (matplotlib) and its folder: rendering and writing only, the
numbers come from ``twin.app.robust`` (imported here, never the other way round)."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from twin.app.robust import OUTPUT_FILES, RobustResult  # noqa: E402
from twin.outputs import atomic_directory  # noqa: E402

__all__ = ["render_robust", "write_robust"]


def write_robust(result: RobustResult, out_dir: str | Path, *, overwrite: bool = False) -> Path:
    """``robust.json`` and ``robust.png`` into ``out_dir`` (atomically, as every job's folder)."""
    with atomic_directory(out_dir, OUTPUT_FILES, overwrite=overwrite) as tmp:
        (tmp / "robust.json").write_text(json.dumps(result.to_json(), indent=1) + "\n")
        render_robust(result, tmp / "robust.png")
    return Path(out_dir)


def render_robust(result: RobustResult, path: Path) -> None:
    """The share of rigs that hold each start (colour); the starts every rig holds (white contour) and the
    robust region, whose lower bound reaches the level (red contour)."""
    s = result.settings
    xs, ths = s.x0.values(), s.theta0.values()
    nx, nt = len(xs), len(ths)
    rate = np.full((nt, nx), np.nan)
    robust = np.zeros((nt, nx))
    for k, p in enumerate(result.points):
        i, j = divmod(k, nt)
        rate[j, i] = np.nan if p["rate"] is None else p["rate"]
        robust[j, i] = 1.0 if p["robust"] else (0.5 if p["held"] == result.rigs else 0.0)
    dx = (xs[1] - xs[0]) / 2 if nx > 1 else 0.01
    dt = (ths[1] - ths[0]) / 2 if nt > 1 else 0.01
    fig, ax = plt.subplots(figsize=(7.5, 6.6), dpi=120)
    image = ax.imshow(
        rate,
        origin="lower",
        extent=(xs[0] - dx, xs[-1] + dx, ths[0] - dt, ths[-1] + dt),
        aspect="auto",
        cmap="viridis",
        vmin=0,
        vmax=1,
    )
    fig.colorbar(image, ax=ax, label=f"share of the {result.rigs} rigs that hold the start")
    if nx > 1 and nt > 1:
        ax.contour(xs, ths, robust, levels=[0.25, 0.75], colors=["white", "red"], linewidths=[1.0, 2.0])
    m = result.summary
    ax.set_title(
        f"{s.controller}: {result.rigs} rigs from {Path(result.source).name}\n"
        f"held by every rig {m['held_by_every_rig']} of {m['starts']} (white); lower bound ≥ {result.level:g} "
        f"at {result.confidence:g}: {m['robust']} (red)"
        + (f"; nominal rig holds {m['nominal_held']}" if "nominal_held" in m else "")
        + (
            f"\nscreened: MuJoCo decided {100 * result.screening['mujoco_fraction']:.0f} % of the runs"
            if result.screening is not None
            else "\nFAST ENGINE ALONE (not confirmed)"
            if s.policy.stand_alone
            else ""
        ),
        fontsize=9,
    )
    ax.set_xlabel("initial ball position x0 (m)")
    ax.set_ylabel("initial beam angle θ0 (rad)")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
