"""Recompute every numeric result of the thesis's chapters 3–5 and 7 and report where it contradicts itself.

    python scripts/reproduce_thesis.py --out DIR [--quick]

Writes DIR/reproduction.json (a list of {id, quantity, thesis, recomputed, rel_error, verdict, explanation}),
DIR/reproduction.md (the same as a table, with a summary) and the figures as PNG.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from controllers.reproduction.report import write_report


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, type=Path)
    parser.add_argument("--quick", action="store_true", help="shorter runs and coarser grids (for tests)")
    args = parser.parse_args()
    start = time.perf_counter()
    entries = write_report(args.out, quick=args.quick)
    print(f"{len(entries)} entries in {time.perf_counter() - start:.0f} s → {args.out / 'reproduction.md'}")


if __name__ == "__main__":
    main()
