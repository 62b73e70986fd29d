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

__all__ = ["render_falsify", "render_table", "write_falsify"]

# The bench's problems (scripts/bench.py, (k)) as the manual's table names them.
PROBLEMS = {
    "corner": "start box across appendix-sf's region at a corner (x0 −0.05…0.105 m, θ0 −0.70…0 rad)",
    "spread_tail": "appendix-sf from (0.12 m, −0.535 rad) over docs/examples/spread.toml's rigs",
}


def write_falsify(result: FalsifyResult, out_dir: str | Path, *, overwrite: bool = False) -> Path:
    """``falsify.json`` and ``falsify.png`` into ``out_dir``, atomically (its other files are kept)."""
    with atomic_directory(out_dir, OUTPUT_FILES, overwrite=overwrite) as tmp:
        (tmp / "falsify.json").write_text(json.dumps(result.to_json(), indent=1, allow_nan=False) + "\n")
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


def render_table(bench: dict[str, float]) -> str:
    """The manual's falsifier-against-sampling table from the bench's (k) figures (``bench.py --only-falsify``)."""
    seeds = int(bench["seeds"])
    budget = int(bench["budget"])
    lines = [
        f"| problem (5 s runs, noise off) | violating share (brute force) | falsifier: median runs (found of {seeds}) "
        f"| uniform: median runs (found of {seeds}) | uniform ÷ falsifier |",
        "|---|---|---|---|---|",
    ]
    for key, what in PROBLEMS.items():
        uniform = bench[f"{key}_uniform_median_runs"]
        shown = f"> {budget}" if uniform > budget else f"{uniform:g}"
        found = bench[f"{key}_uniform_found_of_{seeds}"]
        lines.append(
            f"| {what} | {100 * bench[f'{key}_violating_share']:.2f} % (uniform's expected median "
            f"{bench[f'{key}_uniform_expected_median_runs']:.0f}) | {bench[f'{key}_falsifier_median_runs']:g} "
            f"({bench[f'{key}_falsifier_found_of_{seeds}']:.0f}) | {shown} ({found:.0f}) "
            f"| {'≥ ' if uniform > budget else ''}{bench[f'{key}_uniform_over_falsifier']:.1f}× |"
        )
    lines.append("")
    lines.append(
        f"A search without a violation counts {budget} + 1. A falsification of budget 500 at 10 s took "
        f"{bench['falsify_over_batch']:.2f}× the time of a 500-run batch ({bench['falsify_500_s']:.1f} s against "
        f"{bench['batch_500_s']:.1f} s, interleaved, the best of two)."
    )
    return "\n".join(lines) + "\n"
