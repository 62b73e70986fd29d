"""Run every named controller from the chapter 4 starts (x0 = ±0.2 m, θ0 = 0.3 rad) and the hardware
experiments' starts, and write which settle, in what time, with what peak voltage, and which fail.

    python scripts/controller_report.py --out out/controllers [--duration 15] [--seed 0]

Each row is what ``ballbeam run --controller NAME --x0 X --theta0 T --seed S --json`` prints.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from controllers import registry
from controllers import thesis_numbers as T
from twin.runner import run_closed_loop

CHAPTER4_STARTS = [(0.2, 0.3), (-0.2, 0.3)]


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

    starts = CHAPTER4_STARTS + list(T.HARDWARE_STARTS.values())
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
                {"controller": name, "x0_m": x0, "theta0_rad": theta0, "seed": args.seed, **result.metrics}
            )
            m = result.metrics
            print(
                f"{name:22s} ({x0:+.2f}, {theta0:+.2f}): "
                f"{'LOST' if m['ball_lost'] else ('settled' if m['settled'] else 'not settled')}"
            )
    (args.out / "controllers.json").write_text(json.dumps(rows, indent=1) + "\n")

    lines = [
        "# Named controllers on the twin (noise on)",
        "",
        f"Duration {args.duration:g} s, seed {args.seed}. *settled*: |x| < 5 mm and |θ| < 0.02 rad over the last "
        "2 s. *t_s*: last time |x| exceeded 2 % of |x0| (at least 4 mm); — when it never stays inside.",
        "",
        "| controller | x0 (m) | θ0 (rad) | verdict | t_s (s) | peak V | peak θ (rad) | final x (mm) | lost at (s) |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        verdict = "**fails: ball lost**" if r["ball_lost"] else ("settled" if r["settled"] else "not settled")
        lines.append(
            f"| {r['controller']} | {r['x0_m']:+.2f} | {r['theta0_rad']:+.2f} | {verdict} | "
            f"{_fmt(r['settling_time_s'], 2)} | {r['peak_motor_voltage_v']:.1f} | {r['peak_theta_rad']:.2f} | "
            f"{1e3 * r['final_x_m']:.1f} | {_fmt(r['ball_lost_time_s'], 2)} |"
        )
    (args.out / "controllers.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out / 'controllers.md'} and controllers.json")


if __name__ == "__main__":
    main()
