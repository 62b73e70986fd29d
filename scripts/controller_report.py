"""Run every named controller from the chapter 4 starts (x0 = ±0.2 m, θ0 = 0.3 rad) and the hardware
experiments' starts, and write the verdict of each run: held or not (and why), settling time, steady
offset, limit cycle, peak voltage, share of time at the rails.

    python scripts/controller_report.py --out out/controllers [--duration 15] [--seed 0]

Each row is what ``ballbeam run --controller NAME --x0 X --theta0 T --seed S --json`` prints.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from controllers import registry
from controllers import thesis_numbers as T
from twin.outputs import write_atomic
from twin.parameters import Parameters
from twin.rigs.sim import run_closed_loop
from twin.verdict import Criteria


def _fmt(value: object, digits: int = 3) -> str:
    if value is None:
        return "—"
    if isinstance(value, float):
        return f"{value:.{digits}f}"
    return str(value)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, type=Path)
    parser.add_argument("--duration", type=float, default=15.0)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    starts = [*T.CHAPTER4_STARTS, *T.HARDWARE_STARTS.values()]
    rows = []
    for name in registry.NAMES:
        for x0, theta0 in starts:
            result = run_closed_loop(
                registry.make(name),
                x0_m=x0,
                theta0_rad=theta0,
                duration_s=args.duration,
                seed=args.seed,
                noise=True,
            )
            rows.append(
                {
                    "controller": name,
                    "x0_m": x0,
                    "theta0_rad": theta0,
                    "seed": args.seed,
                    **result.verdict.to_json(),
                }
            )
            print(f"{name:22s} ({x0:+.2f}, {theta0:+.2f}): {result.verdict.reason}")
    write_atomic(args.out / "controllers.json", json.dumps(rows, indent=1) + "\n", overwrite=True)

    c, free_run_ms = Criteria(), 1e3 * Parameters().start.free_run_s
    lines = [
        "# Named controllers on the twin (noise on)",
        "",
        f"Duration {args.duration:g} s, seed {args.seed}, default start timing (the first command "
        f"{free_run_ms:g} ms after release). The verdict and its bands are the README's (*held*: ball kept, "
        f"offset within ±{1e3 * c.offset_band_m:g} mm and the limit cycle within {1e3 * c.limit_cycle_band_m:g} mm "
        f"p-p over the final {c.window_s:g} s). *t_s*: last time |x − steady| exceeded "
        f"max({100 * c.settling_fraction:g} % |x0|, {1e3 * c.settling_floor_m:g} mm), from release; — when that "
        "is inside the final window.",
        "",
        "| controller | x0 (m) | θ0 (rad) | verdict | t_s (s) | steady x (mm) | x p-p (mm) | peak V | at rails "
        "| peak θ (rad) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        verdict = "held" if r["held"] else f"**{r['reason']}**"
        steady = _fmt(None if r["steady_x_m"] is None else 1e3 * r["steady_x_m"], 1)
        pp = _fmt(None if r["limit_cycle_x_pp_m"] is None else 1e3 * r["limit_cycle_x_pp_m"], 1)
        lines.append(
            f"| {r['controller']} | {r['x0_m']:+.2f} | {r['theta0_rad']:+.2f} | {verdict} | "
            f"{_fmt(r['settling_time_s'], 2)} | {steady} | {pp} | {r['peak_motor_voltage_v']:.1f} | "
            f"{100 * r['saturated_fraction']:.0f} % | {r['peak_theta_rad']:.2f} |"
        )
    write_atomic(args.out / "controllers.md", "\n".join(lines) + "\n", overwrite=True)
    print(f"wrote {args.out / 'controllers.md'} and controllers.json")


if __name__ == "__main__":
    main()
