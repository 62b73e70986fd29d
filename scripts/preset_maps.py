"""Each preset's 41 × 41 map, screened and confirmed by MuJoCo, against MuJoCo's brute force.

    python scripts/preset_maps.py --out DIR [--preset NAME ...] [--controller rig-lqg] [--n 41] [--duration 10]

For every preset the fast engine can screen (``twin.screen.kernel_refusal`` is None; or those named), the map of
``ballbeam sweep --rig-file PRESET --controller rig-lqg`` over the rig's own track and travel
(``twin.app.sweep.rig_grids``): screened (``--engine screen``: the fast engine runs every start, MuJoCo every
start near a class change and an audit sample) and brute force (``--engine mujoco``: MuJoCo runs every start, the
same seeds). Per preset it writes DIR/PRESET.json (the classes of both maps, where they differ, what the
screening ran, each map's CPU and wall seconds) and DIR/PRESET.png (the screened map, ``ballbeam sweep``'s
picture). DIR must not exist or be empty; each file is written atomically (a preset finished is kept if a later
one fails). CPU seconds are this process's and its workers' (``resource.getrusage``), after a one-start warm-up
of each engine.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import tempfile
import time
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np

import twin.parts  # noqa: F401  (registers the parts)
from twin.app.sweep import Grid, SweepResult, SweepSettings, rig_grids, run_sweep, verdict_class
from twin.outputs import write_atomic
from twin.parts.description import PRESETS, preset
from twin.screen import kernel_refusal


def _cpu_s() -> float:
    """CPU seconds (user + system) of this process and its finished children."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def _timed(settings: SweepSettings, params: Any, workers: int) -> tuple[SweepResult, float, float]:
    cpu, wall = _cpu_s(), time.perf_counter()
    result = run_sweep(settings, params, workers=workers)
    return result, _cpu_s() - cpu, time.perf_counter() - wall


def screenable(names: list[str] | None = None) -> list[str]:
    """The presets named (default: every one) that the fast engine can screen; the others are reported."""
    out = []
    for name in names or list(PRESETS):
        refusal = kernel_refusal(preset(name))
        if refusal is None:
            out.append(name)
        else:
            print(f"{name}: not screened ({refusal})", file=sys.stderr)
    return out


def preset_map(
    name: str, controller: str, n: int, duration_s: float, workers: int
) -> tuple[dict[str, Any], SweepResult]:
    """The preset's screened map and brute force compared: the JSON's content, and the screened result."""
    params = preset(name)
    x0, theta0 = rig_grids(params, n)
    base = SweepSettings(controller, x0, theta0, duration_s)
    for engine in ("fast", "mujoco"):  # the kernel loaded from numba's cache, MuJoCo's model built: not timed
        run_sweep(
            replace(base, x0=Grid(0.0, 0.0, 1), theta0=Grid(0.0, 0.0, 1), duration_s=0.1, engine=engine),
            params,
        )
    screened, screened_cpu, screened_wall = _timed(replace(base, engine="screen"), params, workers)
    brute, brute_cpu, brute_wall = _timed(replace(base, engine="mujoco"), params, workers)
    a = np.array([verdict_class(p) for p in screened.points]).reshape(x0.n, theta0.n)
    b = np.array([verdict_class(p) for p in brute.points]).reshape(x0.n, theta0.n)
    xs, ths = x0.values(), theta0.values()
    differ = [
        {
            "x0_m": float(xs[i]),
            "theta0_rad": float(ths[j]),
            "screened": str(a[i, j]),
            "brute_force": str(b[i, j]),
        }
        for i, j in np.argwhere(a != b).tolist()
    ]
    # every start MuJoCo ran in the screened map is brute force's record (the same seed)
    same_records = all(s == {**r, "engine": "mujoco"} for s, r in zip(screened.points, brute.points, strict=True)
                       if s.get("engine") == "mujoco")  # fmt: skip
    report = {
        "preset": name,
        "controller": controller,
        "grid": {"x0": asdict(x0), "theta0": asdict(theta0)},
        "duration_s": duration_s,
        "complete": screened.complete and brute.complete,
        "starts": int(a.size),
        "classes_equal": int((a == b).sum()),
        "classes_differ": differ,
        "mujoco_records_equal_brute_force": same_records,
        "screening": screened.screening,
        "screened": {"cpu_s": round(screened_cpu, 1), "wall_s": round(screened_wall, 1)},
        "brute_force": {"cpu_s": round(brute_cpu, 1), "wall_s": round(brute_wall, 1)},
        "classes": {
            "screened": [[str(c) for c in row] for row in a],
            "brute_force": [[str(c) for c in row] for row in b],
        },
        "summary": {"screened": screened.to_json()["summary"], "brute_force": brute.to_json()["summary"]},
        "load_1min": round(os.getloadavg()[0], 2),
    }
    return report, screened


def write_preset(out: Path, name: str, report: dict[str, Any], screened: SweepResult) -> None:
    """DIR/NAME.json and DIR/NAME.png, each atomically (the picture rendered aside, then moved in)."""
    from twin.app.sweep_render import render_map  # matplotlib: after the runs

    with tempfile.TemporaryDirectory() as tmp:
        picture = Path(tmp) / "map.png"
        render_map(screened, picture)
        write_atomic(out / f"{name}.png", picture.read_bytes())
    write_atomic(out / f"{name}.json", json.dumps(report, indent=1) + "\n")


def check_out(out: Path) -> None:
    """Refuse an existing file, or a folder with anything in it; create the folder."""
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise SystemExit(f"--out {out}: exists and is not an empty folder; give a new one")
    out.mkdir(parents=True, exist_ok=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out", required=True, type=Path, help="a new (or empty) folder for the JSON and PNGs"
    )
    parser.add_argument("--preset", action="append", choices=PRESETS, help="only this preset (repeatable)")
    parser.add_argument("--controller", default="rig-lqg")
    parser.add_argument("--n", type=int, default=41, help="starts along each axis (default 41)")
    parser.add_argument("--duration", type=float, default=10.0, help="seconds per run (default 10)")
    parser.add_argument("--workers", type=int, default=1, help="local processes per map (default 1)")
    args = parser.parse_args(argv)
    check_out(args.out)
    for name in screenable(args.preset):
        report, screened = preset_map(name, args.controller, args.n, args.duration, args.workers)
        write_preset(args.out, name, report, screened)
        print(
            f"{name}: {report['classes_equal']} of {report['starts']} classes equal brute force; screened "
            f"{report['screened']['cpu_s']} CPU s ({report['screening']['mujoco_runs']} MuJoCo runs), brute force "
            f"{report['brute_force']['cpu_s']} CPU s",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
