"""``ballbeam view --serve`` in a real headless Chromium with the C controller on the wire: the page says the
rig waits for a client with the ball held, then shows the C client's session connected and the ball
balanced from the view's start; Reset ends the client's session with STOP 0 (its exit status 0) and the
next session waits."""

import math
import os
import re
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from test_c_controller import build_bb_sf

from twin.app.browser import CHROMIUM_ARGS, find_chromium

CHROMIUM = find_chromium()
sync_api = (
    pytest.importorskip("playwright.sync_api")
    if not os.environ.get("CI")
    else __import__("playwright.sync_api", fromlist=["sync_playwright"])
)
if CHROMIUM is None:
    if os.environ.get("CI"):
        raise RuntimeError("CI must install Debian's chromium for the browser tests (.ci/run does)")
    pytest.skip("Debian chromium is not installed", allow_module_level=True)
ROOT = Path(__file__).resolve().parent.parent


def _free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def bb_sf(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """examples/c/bb_sf built with the Makefile's flags (as tests/test_c_controller.py builds it)."""
    return build_bb_sf(tmp_path_factory.mktemp("c"))


def _text(page) -> str:
    return page.evaluate("() => document.body.innerText")


def _ball(page) -> list[float]:
    return page.evaluate(
        "() => { const n = window.__viserMutable.nodeRefFromName['/ball'];"
        " return [n.position.x, n.position.y, n.position.z]; }"
    )


def _wait_text(page, needle: str, timeout_ms: int = 30000) -> None:
    page.wait_for_function("(s) => document.body.innerText.includes(s)", arg=needle, timeout=timeout_ms)


@pytest.mark.slow
@pytest.mark.realtime
def test_the_c_controller_balances_the_served_view_in_the_browser(bb_sf: Path, tmp_path: Path) -> None:
    udp, http = _free_port(socket.SOCK_DGRAM), _free_port(socket.SOCK_STREAM)
    log_path = tmp_path / "view.log"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    with open(log_path, "w") as log:
        view = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "twin.app.cli",
                "view",
                "--serve",
                f"127.0.0.1:{udp}",
                "--port",
                str(http),
                "--duration",
                "300",
            ],
            stdout=log,
            stderr=subprocess.STDOUT,
            text=True,
            env=env,
        )
    client = None
    try:
        deadline = time.time() + 60
        while "serving the twin on udp://" not in log_path.read_text():
            assert view.poll() is None and time.time() < deadline, log_path.read_text()
            time.sleep(0.2)
        assert f"serving the twin on udp://127.0.0.1:{udp}" in log_path.read_text()
        with sync_api.sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=CHROMIUM, args=list(CHROMIUM_ARGS))
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.goto(f"http://127.0.0.1:{http}")
            page.get_by_text("Connected").wait_for(timeout=30000)
            page.wait_for_function(
                "() => window.__viserMutable && window.__viserMutable.nodeRefFromName['/ball']", timeout=30000
            )
            # No client yet: the wire entry is the controller, the rig is held at the view's start.
            _wait_text(page, f"waiting for a client on udp://127.0.0.1:{udp}")
            assert f"controller: wire client (udp://127.0.0.1:{udp})" in _text(page)
            time.sleep(1.0)
            held = _ball(page)
            # x0 = 0.15 m on the beam at θ0 = 0.1 rad: x·cos θ − (h* + r*)·sin θ from the pivot.
            assert abs(held[0] - (0.15 * math.cos(0.1) - 0.021957 * math.sin(0.1))) < 0.003
            assert "t = -0.01 s" in _text(page)
            time.sleep(1.0)
            assert _ball(page) == held and "waiting for a client" in _text(page)

            client = subprocess.Popen(
                [str(bb_sf), "udp", "127.0.0.1", str(udp), "--timeout", "30", "--name", "bb_sf pytest"],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
            _wait_text(page, "client bb_sf pytest at 127.0.0.1:")
            assert "· connected" in _text(page)
            page.wait_for_function(
                "() => { const m = /t = ([0-9.]+) s/.exec(document.body.innerText);"
                " return m && parseFloat(m[1]) > 6.0; }",
                timeout=60000,
            )
            text = _text(page)
            assert "ball on the beam" in text and "run failed" not in text
            ball = _ball(page)
            assert abs(ball[0]) < 0.03, ball  # balanced near the centre from 0.15 m
            counts = re.search(r"late (\d+) · missing (\d+) · watchdog trips (\d+)", text)
            assert counts is not None, text
            assert int(counts.group(3)) == 0 and int(counts.group(2)) < 10, counts.group(0)

            page.get_by_role("button", name="Reset").click()  # the run is replaced: STOP 0 to the client
            out, err = client.communicate(timeout=30)
            assert client.returncode == 0, err  # bb_sf: 0 = the session ended as the server said (STOP 0)
            _wait_text(page, f"waiting for a client on udp://127.0.0.1:{udp}")
            browser.close()
    finally:
        if client is not None and client.poll() is None:
            client.kill()
        view.terminate()
        view.wait(timeout=20)
