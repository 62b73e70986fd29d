"""The live view in a real headless Chromium: the page connects, the ball moves, reset and a controller
change take effect in the twin; the server listens on 127.0.0.1 only; a taken port is an error."""

import os
import re
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
sync_api = pytest.importorskip("playwright.sync_api") if not os.environ.get("CI") else __import__(
    "playwright.sync_api", fromlist=["sync_playwright"])
if CHROMIUM is None:
    if os.environ.get("CI"):
        raise RuntimeError("CI must install Debian's chromium for the browser tests (.ci/run does)")
    pytest.skip("Debian chromium is not installed", allow_module_level=True)

CHROMIUM_ARGS = ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--no-first-run", "--disable-quic"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start_view(port: int, *extra: str) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-m", "twin.cli", "view", "--port", str(port), "--duration", "90",
                             *extra], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    deadline = time.time() + 60
    for line in proc.stdout:
        if line.startswith("ballbeam view: http://"):
            return proc
        if time.time() > deadline:
            break
    proc.kill()
    raise AssertionError("ballbeam view did not announce its address")


def _listening_addresses(port: int) -> set[str]:
    """Local IPv4 addresses with a socket listening on ``port`` (from /proc/net/tcp)."""
    found = set()
    for line in Path("/proc/net/tcp").read_text().splitlines()[1:]:
        local, state = line.split()[1], line.split()[3]
        addr_hex, port_hex = local.split(":")
        if int(port_hex, 16) == port and state == "0A":  # 0A = LISTEN
            found.add(socket.inet_ntoa(bytes.fromhex(addr_hex)[::-1]))
    return found


@pytest.fixture(scope="module")
def view():
    port = _free_port()
    proc = _start_view(port)
    yield port
    proc.terminate()
    proc.wait(timeout=20)


def _page_text(page) -> str:
    return page.evaluate("() => document.body.innerText")


def _sim_time(page) -> float:
    return float(re.search(r"t = ([0-9.]+) s", _page_text(page)).group(1))


def _ball_position(page) -> list[float]:
    return page.evaluate("() => { const n = window.__viserMutable.nodeRefFromName['/ball'];"
                         " return [n.position.x, n.position.y, n.position.z]; }")


def test_page_shows_the_running_twin_and_its_controls(view: int) -> None:
    assert _listening_addresses(view) == {"127.0.0.1"}
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 1400, "height": 900})
        page.goto(f"http://127.0.0.1:{view}")
        page.get_by_text("Connected").wait_for(timeout=30000)
        page.wait_for_function("() => window.__viserMutable && window.__viserMutable.nodeRefFromName['/ball']",
                               timeout=30000)
        assert page.get_by_text("Share").count() == 0  # the public share button is hidden

        # The ball node moves over time (started at x0 = 0.15 m, θ0 = 0.1 rad).
        first = _ball_position(page)
        time.sleep(1.0)
        second = _ball_position(page)
        assert max(abs(a - b) for a, b in zip(first, second)) > 1e-3

        # Reset: the twin restarts from its initial state; simulated time drops back.
        page.wait_for_function("() => /t = ([3-9]|[1-9][0-9])\\./.test(document.body.innerText)", timeout=30000)
        before = _sim_time(page)
        page.get_by_role("button", name="Reset").click()
        page.wait_for_function(f"() => {{ const m = /t = ([0-9.]+) s/.exec(document.body.innerText);"
                               f" return m && parseFloat(m[1]) < {before} - 1.0; }}", timeout=15000)
        assert _sim_time(page) < before

        # Controller change: the twin now runs the chosen controller.
        assert "controller: appendix-clp" in _page_text(page)
        page.get_by_role("combobox", name="Controller").click()
        page.get_by_role("option", name="lqr", exact=True).click()
        page.wait_for_function("() => document.body.innerText.includes('controller: lqr')", timeout=15000)

        # A second browser watches too; when it leaves, the first keeps receiving the running twin.
        other = browser.new_page(viewport={"width": 1400, "height": 900})
        other.goto(f"http://127.0.0.1:{view}")
        other.wait_for_function("() => document.body.innerText.includes('controller: lqr')", timeout=15000)
        other.close()
        before = _sim_time(page)
        page.wait_for_function(f"() => {{ const m = /t = ([0-9.]+) s/.exec(document.body.innerText);"
                               f" return m && parseFloat(m[1]) > {before} + 1.0; }}", timeout=15000)
        browser.close()


def test_a_taken_port_is_reported_not_changed() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        out = subprocess.run([sys.executable, "-m", "twin.cli", "view", "--port", str(port), "--duration", "1"],
                             capture_output=True, text=True, timeout=60)
    assert out.returncode == 2
    assert f"port {port} on 127.0.0.1 is taken" in out.stderr
