"""What refining a robust map costs, per rig (what ``ballbeam sweep --rigs N --refine`` does) against
refining on the probability contour (jointly on every rig's class, or on the held count), computed from a
finished robust map's per-rig classes (``robust.json``'s ``rig_classes``) without running anything.

    python scripts/refinement_cost.py OUT/robust.json [--step N]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "robust_json", type=Path, help="a robust map's robust.json (sweep --rigs N --out DIR)"
    )
    parser.add_argument(
        "--step", type=int, default=None, help="the coarse step (default: the map's own, or 8)"
    )
    args = parser.parse_args(argv)
    from twin.app.robust import refinement_costs

    try:
        doc = json.loads(args.robust_json.read_text())
        settings, rig_classes = doc["settings"], doc["rig_classes"]
        nx, nt = int(settings["x0"]["n"]), int(settings["theta0"]["n"])
        step = args.step or int(settings.get("refine") or 8)
        costs = refinement_costs(rig_classes, nx, nt, step)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        print(f"refinement_cost: {args.robust_json}: not a complete robust map ({exc})", file=sys.stderr)
        return 2
    print(f"{len(rig_classes)} rigs × {nx} × {nt} starts, coarse step {step}")
    brute = costs.pop("brute_force")
    print(f"  brute force: {brute} runs")
    for way, figures in costs.items():
        print(
            f"  {way:>10}: {figures['runs']:>7} runs ({100 * figures['runs'] / brute:.1f} %), "
            f"per-start held counts {'equal' if figures['counts_equal'] else 'DIFFER'}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
