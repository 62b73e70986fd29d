"""Regenerate every generated file under docs/ with the code as it is now (one command).

    python scripts/regenerate_docs.py [--skip-maps] [--skip-screenshot] [--workers N]

- docs/reproduction/   scripts/reproduce_thesis.py (every thesis claim, its computed verdict, the figures)
- docs/controllers/    scripts/controller_report.py (every named controller from the thesis's starts)
- docs/validation/     scripts/validation_maps.py (regions of attraction, chapter 7 claims; ~15 min here)
- docs/view.png        scripts/screenshot.py (needs Debian's chromium)

The tests check that the committed JSON is what the code computes now (tests/test_docs.py and the
reproduction's tests), so a change that moves a number fails until this is run and committed.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _run(*args: str) -> None:
    print("$", " ".join(args), flush=True)
    subprocess.run([sys.executable, *args], cwd=ROOT, check=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--skip-maps", action="store_true", help="leave docs/validation as it is (slow)")
    parser.add_argument("--skip-screenshot", action="store_true", help="leave docs/view.png as it is")
    parser.add_argument("--workers", type=int, default=1, help="local processes for the maps")
    args = parser.parse_args()
    _run("scripts/reproduce_thesis.py", "--out", "docs/reproduction")
    _run("scripts/controller_report.py", "--out", "docs/controllers")
    if not args.skip_maps:
        _run("scripts/validation_maps.py", "--out", "docs/validation", "--workers", str(args.workers))
    if not args.skip_screenshot and shutil.which("chromium"):
        _run("scripts/screenshot.py", "--out", "docs/view.png")


if __name__ == "__main__":
    main()
