"""Screenshots of the live view of each preset rig, taken by headless Chromium (Debian's) via Playwright.

python scripts/preset_screenshots.py [--out docs/img] [--preset NAME ...] [--controller rig-lqg] [--wait 12]
                                     [--overwrite]

Each preset's view (``ballbeam view --rig-file PRESET --controller CONTROLLER``) runs in a process of its own on a
free port of 127.0.0.1. A preset with a documented start (``STARTS``: the start docs/rigs.md says rig-lqg holds the
ball from) is started there, as a person would (the x0 and θ0 boxes, then Reset); the thesis from the view's own
default. Once the run has gone ``--wait`` seconds, the page at 1400 × 900 is saved as OUT/rig-PRESET.png. A file
that exists is refused (nothing is taken) unless ``--overwrite``.
"""

from __future__ import annotations

import argparse
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from playwright.sync_api import sync_playwright

from twin.app.browser import CHROMIUM_ARGS, find_chromium
from twin.parts.description import PRESETS

DEFAULT_PRESETS = ("thesis", "open-ball-and-beam", "arduino-stepper-ultrasonic")
VIEWPORT_PX = (1400, 900)  # as docs/view.png: every plot and the rig visible
ANNOUNCE_S = 120.0  # the view designs its controller (rig-lqg: a linearization) before it announces itself
# (x0 m, θ0 rad) each preset's run starts from: docs/rigs.md's (tests/test_presets.py holds the ball from it).
STARTS: dict[str, tuple[float, float]] = {
    "open-ball-and-beam": (0.05, 0.0),
    "arduino-stepper-ultrasonic": (0.05, 0.0),
    "quanser-bb01": (0.1, 0.0),
}
# The panel's number boxes in their order (twin.viewer.gui: speed, x0, θ0, flick, setpoint, drift).
X0_BOX, THETA0_BOX = 1, 2


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _start_view(preset: str, controller: str, port: int, duration_s: float, log: Path) -> subprocess.Popen:
    """``ballbeam view`` of ``preset`` in the background, its output to ``log`` (a full pipe would stall it),
    returned once it announced its address."""
    command = [sys.executable, "-m", "twin.app.cli", "view", "--rig-file", preset, "--controller", controller]
    command += ["--port", str(port), "--duration", str(duration_s)]
    with open(log, "w", encoding="utf-8") as out:
        proc = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT, text=True)
    deadline = time.monotonic() + ANNOUNCE_S
    while time.monotonic() < deadline and proc.poll() is None:
        if "ballbeam view: http://" in log.read_text(encoding="utf-8"):
            return proc
        time.sleep(0.2)
    proc.kill()
    proc.wait(timeout=20)
    sys.exit(f"preset_screenshots: the view of {preset!r} did not start:\n{log.read_text(encoding='utf-8')}")


def _shoot(chromium: str, port: int, wait_s: float, start: tuple[float, float] | None, out: Path) -> None:
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium, args=list(CHROMIUM_ARGS))
        page = browser.new_page(viewport={"width": VIEWPORT_PX[0], "height": VIEWPORT_PX[1]})
        page.goto(f"http://127.0.0.1:{port}")
        page.get_by_text("Connected").wait_for(timeout=30000)
        page.wait_for_function("() => document.body.innerText.includes('run 1 ·')", timeout=60000)
        if start is not None:  # type the start into its boxes, then Reset: run 2 starts there
            boxes = page.locator("input[inputmode=decimal]")
            for index, value in ((X0_BOX, start[0]), (THETA0_BOX, start[1])):
                boxes.nth(index).fill(f"{value:g}")
                boxes.nth(index).press("Enter")
            time.sleep(1.0)  # the loop applies the values between ticks
            page.get_by_role("button", name="Reset").click()
            page.wait_for_function("() => document.body.innerText.includes('run 2 ·')", timeout=60000)
        time.sleep(wait_s)
        page.mouse.move(
            VIEWPORT_PX[0] // 2, VIEWPORT_PX[1] - 5
        )  # off the controls: no hover hint in the shot
        time.sleep(0.5)
        # The software-WebGL notice is about this headless browser, not about the rig.
        page.evaluate(
            "() => document.querySelectorAll('.mantine-Notification-root').forEach(n => n.remove())"
        )
        page.screenshot(path=str(out))
        browser.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/img"), help="folder (default docs/img)")
    parser.add_argument(
        "--preset",
        action="append",
        choices=PRESETS,
        help=f"a preset to take (repeatable; default {', '.join(DEFAULT_PRESETS)})",
    )
    parser.add_argument(
        "--controller", default="rig-lqg", help="the controller each view runs (default rig-lqg)"
    )
    parser.add_argument(
        "--wait", type=float, default=12.0, help="seconds of running before the shot (default 12)"
    )
    parser.add_argument("--overwrite", action="store_true", help="replace screenshots that exist")
    args = parser.parse_args()
    presets = tuple(args.preset or DEFAULT_PRESETS)
    targets = {name: args.out / f"rig-{name}.png" for name in presets}
    existing = [str(path) for path in targets.values() if path.exists()]
    if existing and not args.overwrite:
        sys.exit(f"preset_screenshots: {', '.join(existing)} exist: pass --overwrite to replace them")
    chromium = find_chromium()
    if chromium is None:
        sys.exit("preset_screenshots: Debian's chromium is not installed (apt-get install chromium)")
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        for name, path in targets.items():
            port = _free_port()
            proc = _start_view(name, args.controller, port, args.wait + 120.0, Path(tmp) / f"{name}.log")
            try:
                _shoot(chromium, port, args.wait, STARTS.get(name), path)
            finally:
                proc.terminate()
                proc.wait(timeout=20)
            print(f"wrote {path}")


if __name__ == "__main__":
    main()
