"""The region-of-attraction map of a sweep (matplotlib) and the sweep's folder: rendering and writing only,
the numbers come from ``twin.app.sweep``.

``write_sweep`` writes ``sweep.json`` (one record per point: ``x0_m``, ``theta0_rad``, ``seed`` and every
field of the verdict; the claims; the settings) and ``map.png`` into a directory, atomically. This module
imports the sweep's types, never the other way round (tests/test_import_graph.py)."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import ListedColormap  # noqa: E402
from matplotlib.patches import Patch, Rectangle  # noqa: E402

from twin.app.sweep import CLAIMS, OUTPUT_FILES, SweepResult, summarize  # noqa: E402
from twin.outputs import atomic_directory  # noqa: E402
from twin.rigs.backends import DEFAULT_PLANT  # noqa: E402

__all__ = ["render_map", "write_sweep"]


def write_sweep(result: SweepResult, out_dir: str | Path, *, overwrite: bool = False) -> Path:
    """``sweep.json`` and ``map.png`` into ``out_dir`` (``twin.outputs.atomic_directory``: a failure leaves
    the old ones; the folder's other files are kept)."""
    with atomic_directory(out_dir, OUTPUT_FILES, overwrite=overwrite) as tmp:
        (tmp / "sweep.json").write_text(json.dumps(result.to_json(), indent=1) + "\n")
        render_map(result, tmp / "map.png")
    return Path(out_dir)


def _engine_words(result: SweepResult) -> str:
    """Who decided the map's starts, for its title."""
    s = result.settings
    if s.plant != DEFAULT_PLANT:
        return f"plant {s.plant}"
    if result.screening is not None:
        return f"screened (MuJoCo decided {100 * result.screening['mujoco_fraction']:.0f} %)"
    return "FAST ENGINE ALONE (not confirmed)" if s.policy.stand_alone else "MuJoCo twin"


def render_map(result: SweepResult, path: Path) -> None:
    """The map: settling time (colour) where held, grey where kept but not held, dark red where lost;
    the claims' rectangles dashed, their corner states marked; --locate's boundary crossings dotted."""
    s = result.settings
    xs, ths = s.x0.values(), s.theta0.values()
    nx, nt = len(xs), len(ths)
    settle = np.full((nt, nx), np.nan)
    # 0 lost, 1 kept but not held, 2 held without a settling time, 3 held as --refine inferred it (not run)
    background = np.full((nt, nx), np.nan)
    for k, p in enumerate(result.points):
        if not p:
            continue
        i, j = divmod(k, nt)
        if p["ball_lost"]:
            background[j, i] = 0
        elif not p["held"]:
            background[j, i] = 1
        elif p.get("inferred"):
            background[j, i] = 3
        elif p["settling_time_s"] is None:  # a limit cycle wider than the settling band (|x0| small)
            background[j, i] = 2
        else:
            settle[j, i] = p["settling_time_s"]
    dx = (xs[1] - xs[0]) / 2 if nx > 1 else 0.01
    dt = (ths[1] - ths[0]) / 2 if nt > 1 else 0.01
    extent = (xs[0] - dx, xs[-1] + dx, ths[0] - dt, ths[-1] + dt)
    fig, ax = plt.subplots(figsize=(7.5, 6.6), dpi=120)
    colours = ["#7f1d1d", "#c8c8c8", "#f2c4de", "#9fd8a8"]
    ax.imshow(
        background, origin="lower", extent=extent, aspect="auto", cmap=ListedColormap(colours), vmin=0, vmax=3
    )
    image = ax.imshow(settle, origin="lower", extent=extent, aspect="auto", cmap="viridis")
    fig.colorbar(image, ax=ax, label="settling time (s), held starts")
    for claim in CLAIMS:
        if s.controller not in claim.applies_to:
            continue
        (xlo, xhi), (tlo, thi) = claim.x0_m, claim.theta0_rad
        rectangle = (xlo, tlo), xhi - xlo, thi - tlo
        ax.add_patch(Rectangle(*rectangle, fill=False, ls="-", lw=2.4, ec="white"))  # visible on any colour
        ax.add_patch(Rectangle(*rectangle, fill=False, ls="--", lw=1.0, ec="black", label="thesis's claim"))
        cx, ct = zip(*claim.corners, strict=True)
        ax.plot(cx, ct, "w*", ms=12, mec="black", label="thesis's corner states")
    if result.boundary and result.boundary["crossings"]:
        at = np.array([c["at"] for c in result.boundary["crossings"]])
        ax.plot(
            at[:, 0],
            at[:, 1],
            "o",
            ms=2.2,
            mfc="black",
            mec="white",
            mew=0.4,
            label=f"boundary, to 1/{2 ** result.boundary['bisections']} of a grid step",
        )
    decided = np.array(
        [[xs[k // nt], ths[k % nt]] for k, p in enumerate(result.points) if p.get("engine") == "mujoco"]
    )
    if result.screening is not None and len(decided):
        ax.plot(
            decided[:, 0], decided[:, 1], ".", ms=1.6, color="white", label="decided by MuJoCo (screened)"
        )
    summary = summarize(result.points)
    ax.set_title(
        f"{s.controller}: held {summary['held']}, not held {summary['not_held']}, lost {summary['lost']} "
        f"of {summary['points']}\n{s.duration_s:g} s runs, noise {'on' if s.noise else 'off'}, "
        f"{'ideal sensors' if s.ideal_sensors else 'full I/O chain'}, {_engine_words(result)}"
        + ("" if result.complete else " — INCOMPLETE"),
        fontsize=10,
    )
    ax.set_xlabel("initial ball position x0 (m)")
    ax.set_ylabel("initial beam angle θ0 (rad)")
    handles = [
        Patch(color=colours[0], label="ball lost"),
        Patch(color=colours[1], label="kept, not held (or the controller failed)"),
        Patch(color=colours[2], label="held, cycling wider than the settling band"),
        *(
            [Patch(color=colours[3], label="held (inferred by --refine, not run)")]
            if result.refinement
            else []
        ),
        *ax.get_legend_handles_labels()[0],
    ]
    ax.legend(
        handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.11), ncol=3, fontsize=8, frameon=False
    )
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
