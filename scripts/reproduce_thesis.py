"""Recompute every claim of the thesis's chapters 3–5 and 7 and report which ones hold.

    python scripts/reproduce_thesis.py [--out docs/reproduction] [--no-figures]

Writes DIR/reproduction.json (one entry per claim: id, where, quantity, thesis, recomputed, rel_error, verdict,
check, findings, unexplained, explanation), DIR/reproduction.md and the figures as PNG.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from twin.app.reproduction.report import write_report

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "reproduction")
    parser.add_argument("--no-figures", action="store_true", help="JSON and Markdown only")
    args = parser.parse_args()
    start = time.perf_counter()
    entries = write_report(args.out, figures=not args.no_figures)
    print(f"{len(entries)} claims in {time.perf_counter() - start:.0f} s → {args.out / 'reproduction.md'}")


if __name__ == "__main__":
    main()
