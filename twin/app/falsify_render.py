"""A falsification's figure and its folder: rendering and writing only, the numbers come from
``twin.app.falsify`` (imported here, never the other way round)."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from twin.app.falsify import OUTPUT_FILES, FalsifyResult  # noqa: E402
from twin.outputs import atomic_directory  # noqa: E402

__all__ = ["render_falsify", "write_falsify"]


def write_falsify(result: FalsifyResult, out_dir: str | Path, *, overwrite: bool = False) -> Path:
    """``falsify.json`` and ``falsify.png`` into ``out_dir``, atomically (its other files are kept)."""
    with atomic_directory(out_dir, OUTPUT_FILES, overwrite=overwrite) as tmp:
        (tmp / "falsify.json").write_text(json.dumps(result.to_json(), indent=1) + "\n")
        render_falsify(result, tmp / "falsify.png")
    return Path(out_dir)


def render_falsify(result: FalsifyResult, path: Path) -> None:
    """The search's trace (each run's least robustness, in order) and its runs over the starts."""
    runs = result.runs
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), dpi=110)
    objective = np.array([max(r["objective"], -1.0) for r in runs]) if runs else np.zeros(0)
    index = np.arange(1, len(runs) + 1)
    axes[0].scatter(index, objective, s=10, c=np.array([r["batch"] for r in runs]), cmap="viridis")
    axes[0].plot(
        index, np.minimum.accumulate(objective) if runs else objective, color="k", lw=1, label="least so far"
    )
    axes[0].axhline(0.0, color="r", lw=0.8)
    axes[0].set_xlabel("run")
    axes[0].set_ylabel("least robustness (the requirement's unit)")
    axes[0].legend(fontsize=8)
    x = [1e3 * r["x0_m"] for r in runs]
    th = [r["theta0_rad"] for r in runs]
    sc = axes[1].scatter(x, th, s=12, c=objective, cmap="coolwarm_r")
    fig.colorbar(sc, ax=axes[1], label="least robustness")
    bad = [r for r in runs if r["objective"] < 0]
    if bad:
        axes[1].scatter(
            [1e3 * r["x0_m"] for r in bad], [r["theta0_rad"] for r in bad], marker="x", c="k", s=30
        )
    axes[1].set_xlabel("x0 (mm)")
    axes[1].set_ylabel("θ0 (rad)")
    out = result.to_json()
    head = (
        f"counterexample after {out['runs_to_first_violation']} runs"
        if out["found"]
        else f"no violation in {out['runs_spent']} runs"
    )
    fig.suptitle(f"{result.settings.controller}, {result.spec.source}: {head}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
