"""Screenshot of the live view as a person sees it, taken by headless Chromium (Debian's) via Playwright.

python scripts/screenshot.py [--out docs/view.png] [--wait 8]
"""

from __future__ import annotations

import argparse
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

from playwright.sync_api import sync_playwright

ARGS = [
    "--no-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/view.png"))
    parser.add_argument("--wait", type=float, default=8.0, help="seconds of running before the shot")
    parser.add_argument("--controller", default="appendix-clp")
    args = parser.parse_args()
    chromium = shutil.which("chromium")
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
        for line in server.stdout:
            if line.startswith("ballbeam view:"):
                break
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium, args=ARGS)
            page = browser.new_page(viewport={"width": 1400, "height": 860})
            page.goto(f"http://127.0.0.1:{port}")
            page.get_by_text("Connected").wait_for(timeout=30000)
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
