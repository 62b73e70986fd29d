"""The same law in three forms from the thesis's starts — Python (double), the C client on the PC (double), the
firmware on a simulated ATmega328P (float) — with each difference's cause measured (twin.app.firmware_forms).

Builds examples/c and examples/avr with their Makefiles (gcc, avr-gcc), then writes docs/firmware/forms.json and
docs/firmware/forms.md, and puts forms.md in docs/validation/firmware.md between its firmware-forms markers
(tests/test_avr_forms.py checks they agree).

python scripts/firmware_forms.py [--duration S] [--workers N] [--validation]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

from twin.app.firmware_forms import AVR_DIR, C_DIR, compare, render
from twin.outputs import write_atomic

OUT = Path(__file__).resolve().parents[1] / "docs" / "firmware"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=15.0, help="each run (s; validate's nominal: 15)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--validation", action="store_true", help="also each form's default validate battery")
    args = parser.parse_args()
    for folder in (C_DIR, AVR_DIR):
        subprocess.run(["make", "-s", "-C", str(folder)], check=True)
    result = compare(
        AVR_DIR / "bb_sf.elf",
        C_DIR / "bb_sf",
        duration_s=args.duration,
        workers=args.workers,
        progress=lambda stage: print(f"firmware forms: {stage}", file=sys.stderr, flush=True),
        validation=args.validation,
    )
    result["settings"]["image"] = "examples/avr/bb_sf.elf"
    OUT.mkdir(parents=True, exist_ok=True)
    write_atomic(OUT / "forms.json", json.dumps(result, indent=1) + "\n", overwrite=True)
    write_atomic(OUT / "forms.md", render(result), overwrite=True)
    readme = OUT.parent / "validation" / "firmware.md"  # the manual's page of the table
    text = readme.read_text()
    begin, end = "<!-- firmware-forms -->\n", "<!-- /firmware-forms -->"
    head, _, rest = text.partition(begin)
    _, _, tail = rest.partition(end)
    write_atomic(readme, head + begin + render(result) + end + tail, overwrite=True)
    print(render(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
