"""Screenshot of the live view as a person sees it, taken by headless Chromium (Debian's) via Playwright.

python scripts/screenshot.py [--out docs/view.png] [--wait 8]
"""

from __future__ import annotations

import argparse
import socket
import subprocess
import sys
import time
from pathlib import Path

from playwright.sync_api import sync_playwright

from twin.app.browser import CHROMIUM_ARGS, find_chromium


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/view.png"))
    parser.add_argument("--wait", type=float, default=8.0, help="seconds of running before the shot")
    parser.add_argument("--controller", default="lqi")
    parser.add_argument(
        "--setpoint-steps", type=int, default=8, help="setpoint slider steps (0.01 m each) to the right"
    )
    args = parser.parse_args()
    chromium = find_chromium()
    if chromium is None:
        sys.exit("screenshot: Debian's chromium is not installed (apt-get install chromium)")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "twin.app.cli",
            "view",
            "--port",
            str(port),
            "--controller",
            args.controller,
            "--duration",
            str(args.wait + 60),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        assert server.stdout is not None  # stdout=PIPE
        for line in server.stdout:
            if line.startswith("ballbeam view:"):
                break
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium, args=list(CHROMIUM_ARGS))
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.goto(f"http://127.0.0.1:{port}")
            page.get_by_text("Connected").wait_for(timeout=30000)
            time.sleep(2.0)
            if args.setpoint_steps:  # move the setpoint with the keyboard, as a person would
                page.get_by_role("slider").nth(4).focus()
                for _ in range(args.setpoint_steps):
                    page.keyboard.press("ArrowRight")
            time.sleep(args.wait)
            # The software-WebGL notice is about this headless browser, not about the twin.
            page.evaluate(
                "() => document.querySelectorAll('.mantine-Notification-root').forEach(n => n.remove())"
            )
            args.out.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(args.out))
            browser.close()
    finally:
        server.terminate()
        server.wait(timeout=20)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
