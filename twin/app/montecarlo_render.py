"""The distributions of a Monte Carlo study (matplotlib) and the study's folder: rendering and writing only,
the numbers come from ``twin.app.montecarlo`` (imported here, never the other way round)."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from twin.app.montecarlo import OUTPUT_FILES, MonteCarloResult  # noqa: E402
from twin.outputs import atomic_directory  # noqa: E402

__all__ = ["render_distributions", "write_montecarlo"]


def write_montecarlo(result: MonteCarloResult, out_dir: str | Path, *, overwrite: bool = False) -> Path:
    """``montecarlo.json`` and ``distributions.png`` into ``out_dir``, atomically
    (``twin.outputs.atomic_directory``: the folder's other files are kept)."""
    with atomic_directory(out_dir, OUTPUT_FILES, overwrite=overwrite) as tmp:
        (tmp / "montecarlo.json").write_text(json.dumps(result.to_json(), indent=1) + "\n")
        render_distributions(result, tmp / "distributions.png")
    return Path(out_dir)


def render_distributions(result: MonteCarloResult, path: Path) -> None:
    """Histograms of the held runs' settling times and of every kept run's steady offset."""
    done = [r for r in result.runs if r]
    s = result.summary
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), dpi=110)
    settle = [r["settling_time_s"] for r in done if r["held"] and r["settling_time_s"] is not None]
    offset = [1e3 * r["steady_x_m"] for r in done if r["steady_x_m"] is not None]
    axes[0].hist(settle, bins=30, color="#1f77b4")
    axes[0].set_xlabel("settling time (s), held runs")
    axes[1].hist(offset, bins=30, color="#2ca02c")
    axes[1].set_xlabel("steady ball offset (mm)")
    for ax in axes:
        ax.set_ylabel("runs")
    rate = "–" if s.get("success_rate") is None else f"{100 * s['success_rate']:.1f} %"
    ci = s.get("success_ci")
    fig.suptitle(
        f"{result.settings.controller}: held {s.get('held')} of {s.get('runs')} ({rate}"
        + (f", 95 % CI {100 * ci[0]:.1f}–{100 * ci[1]:.1f} %" if ci else "")
        + f"), lost {s.get('lost')}",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
