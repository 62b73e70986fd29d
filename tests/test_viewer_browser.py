"""The live view in a real headless Chromium: the page connects, the ball moves, reset and a controller
change take effect in the twin; the server listens on 127.0.0.1 only; a taken port is an error."""

import math
import os
import re
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from twin.app.browser import CHROMIUM_ARGS as BROWSER_ARGS
from twin.app.browser import find_chromium
from twin.log import load_mat
from twin.viewer import PLOT_AXIS_PX

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
CHROMIUM_ARGS = list(BROWSER_ARGS)

# Records every text the page draws on a canvas (uPlot draws its axis values there, not in the DOM): the
# text, where it was drawn, its width and alignment.
RECORD_CANVAS_TEXT = """
window.__drawnText = [];
const fillText = CanvasRenderingContext2D.prototype.fillText;
CanvasRenderingContext2D.prototype.fillText = function (text, x, y, maxWidth) {
  if (window.__drawnText.length > 4000) window.__drawnText.splice(0, 2000);
  window.__drawnText.push({text: String(text), x: x, width: this.measureText(String(text)).width,
                           align: this.textAlign, canvasWidth: this.canvas.width});
  return fillText.call(this, text, x, y, maxWidth);
};
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start_view(port: int, log_path: Path) -> subprocess.Popen:
    """``ballbeam view`` in the background, its output to a file (a full pipe would stall the server)."""
    log = open(log_path, "w")
    proc = subprocess.Popen(
        [sys.executable, "-m", "twin.app.cli", "view", "--port", str(port), "--duration", "400"],
        stdout=log,
        stderr=subprocess.STDOUT,
        text=True,
    )
    deadline = time.time() + 60
    while time.time() < deadline and proc.poll() is None:
        if "ballbeam view: http://" in log_path.read_text():
            return proc
        time.sleep(0.2)
    proc.kill()
    raise AssertionError(f"ballbeam view did not announce its address:\n{log_path.read_text()}")


def _listening_addresses(port: int) -> set[str]:
    """Local IPv4 addresses with a socket listening on ``port`` (from /proc/net/tcp)."""
    found = set()
    for line in Path("/proc/net/tcp").read_text().splitlines()[1:]:
        local, state = line.split()[1], line.split()[3]
        addr_hex, port_hex = local.split(":")
        if int(port_hex, 16) == port and state == "0A":  # 0A = LISTEN
            found.add(socket.inet_ntoa(bytes.fromhex(addr_hex)[::-1]))
    return found


# The page tests are ``realtime``: the software-rendered page must keep up with the running twin within
# Playwright's 30 s waits (a second of simulated time, a click on a menu the page is still drawing), which
# a busy-loop on each core made it miss (a click on the controller menu timed out); they run alone and a
# failure on an overloaded machine is a skip naming the load (tests/conftest.py).
@pytest.fixture(scope="module")
def view(tmp_path_factory):
    port = _free_port()
    proc = _start_view(port, tmp_path_factory.mktemp("view") / "server.log")
    yield port
    proc.terminate()
    proc.wait(timeout=20)


def _page_text(page) -> str:
    return page.evaluate("() => document.body.innerText")


def _sim_time(page) -> float:
    return float(re.search(r"t = ([0-9.]+) s", _page_text(page)).group(1))


def _ball_position(page) -> list[float]:
    return page.evaluate(
        "() => { const n = window.__viserMutable.nodeRefFromName['/ball'];"
        " return [n.position.x, n.position.y, n.position.z]; }"
    )


def _wait_ball_moved(page, reference: list[float], distance_m: float) -> None:
    page.wait_for_function(
        "([ref, d]) => { const p = window.__viserMutable.nodeRefFromName['/ball'].position;"
        " return Math.hypot(p.x - ref[0], p.y - ref[1], p.z - ref[2]) > d; }",
        arg=[reference, distance_m],
        timeout=30000,
    )


@pytest.mark.slow
@pytest.mark.realtime
def test_page_shows_the_running_twin_and_its_controls(view: int) -> None:
    assert _listening_addresses(view) == {"127.0.0.1"}
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 1100, "height": 800})
        page.goto(f"http://127.0.0.1:{view}")
        page.get_by_text("Connected").wait_for(timeout=30000)
        page.wait_for_function(
            "() => window.__viserMutable && window.__viserMutable.nodeRefFromName['/ball']", timeout=30000
        )
        assert page.get_by_text("Share").count() == 0  # the public share button is hidden

        # Pause, then Reset: the twin restarts from its initial state and waits (the status counts runs;
        # reading its clock would race with a software-rendered page that skips frames).
        page.wait_for_function("() => document.body.innerText.includes('run 1 ·')", timeout=30000)
        page.get_by_role("button", name="Pause").click()
        page.wait_for_function("() => document.body.innerText.includes('paused')", timeout=30000)
        page.get_by_role("button", name="Reset").click()
        page.wait_for_function("() => document.body.innerText.includes('run 2 ·')", timeout=30000)
        time.sleep(1.0)  # the page shows the new run's first frame
        start = _ball_position(page)
        # Ball back at x0 = 0.15 m on the beam at θ0 = 0.1 rad: x·cos θ − (h* + r*)·sin θ = 0.147 m from the pivot.
        assert abs(start[0] - (0.15 * math.cos(0.1) - 0.021957 * math.sin(0.1))) < 0.003

        # The ball node moves: flick it toward −x (the way the tilted beam rolls it), step 10 × 20 ms by hand,
        # then let the twin run again.
        page.get_by_role("button", name="Flick ◀").click()
        for _ in range(10):
            page.get_by_role("button", name="Step 20 ms").click()
        _wait_ball_moved(page, start, 0.01)  # 0.1 m/s × 0.2 s + gravity ≈ 2.9 cm before the controller reacts
        stepped = _ball_position(page)
        page.get_by_role("button", name="Start").click()
        _wait_ball_moved(page, stepped, 0.001)

        # Controller change: the twin now runs the chosen controller.
        assert "controller: appendix-clp" in _page_text(page)
        page.get_by_role("combobox", name="Controller").click()
        page.get_by_role("option", name="lqr", exact=True).click()
        page.wait_for_function("() => document.body.innerText.includes('controller: lqr')", timeout=30000)

        # A second browser watches too; when it leaves, the first keeps receiving the running twin.
        other = browser.new_page(viewport={"width": 1100, "height": 800})
        other.goto(f"http://127.0.0.1:{view}")
        other.wait_for_function("() => document.body.innerText.includes('controller: lqr')", timeout=90000)
        other.close()
        page.bring_to_front()  # a background tab is throttled by Chromium; the server is not the cause
        before = _sim_time(page)
        page.wait_for_function(
            f"() => {{ const m = /t = ([0-9.]+) s/.exec(document.body.innerText);"
            f" return m && parseFloat(m[1]) > {before} + 1.0; }}",
            timeout=30000,
        )
        browser.close()


def _number_input(page, index: int, value: str) -> None:
    """Type a value into the index-th number box of the panel (speed, x0, θ0, flick, setpoint) and press Enter."""
    box = page.get_by_role("textbox").nth(index)
    box.fill(value)
    box.press("Enter")


@pytest.mark.slow
@pytest.mark.realtime
def test_a_control_engineers_view(view: int, tmp_path: Path) -> None:
    """At 1400 × 900: every plot on screen and its negative axis values whole; a lost ball raises a banner
    and pauses, Reset restores the run; the record downloads as a .mat file the log loader reads."""
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        context = browser.new_context(viewport={"width": 1400, "height": 900}, accept_downloads=True)
        page = context.new_page()
        page.add_init_script(RECORD_CANVAS_TEXT)
        page.goto(f"http://127.0.0.1:{view}")
        page.get_by_text("Connected").wait_for(timeout=30000)
        page.get_by_role("combobox", name="Controller").click()
        page.get_by_role("option", name="appendix-clp", exact=True).click()
        page.wait_for_function(
            "() => document.body.innerText.includes('controller: appendix-clp')", timeout=30000
        )

        # Every plot lies inside the window.
        plots = [
            box for box in (c.bounding_box() for c in page.locator("canvas").all()) if box["width"] < 600
        ]
        assert len(plots) == 5, plots
        assert all(0 <= box["y"] and box["y"] + box["height"] <= 900 for box in plots), plots

        # A negative y-axis value is drawn whole: right-aligned at the axis, its left edge inside the space
        # uPlot gives the values (beyond the rotated axis label), so its minus sign shows.
        page.wait_for_function(
            "() => window.__drawnText.some(d => d.align === 'right' && /^[-−]/.test(d.text))", timeout=30000
        )
        drawn = page.evaluate("() => window.__drawnText")
        values = [d for d in drawn if d["align"] == "right"]
        negative = [d for d in values if d["text"][0] in "-−"]
        assert negative
        label_px = 18
        clipped = [d for d in values if d["x"] - d["width"] < label_px - 0.5]
        assert not clipped, clipped
        assert max(d["x"] for d in values) <= PLOT_AXIS_PX + label_px

        # Ball lost: from x0 = −0.3 m with the beam at +0.7 rad the ball rolls off the −x end at once.
        _number_input(page, 1, "-0.3")
        _number_input(page, 2, "0.7")
        page.wait_for_function("() => document.body.innerText.includes('apply on Reset')", timeout=30000)
        page.get_by_role("button", name="Reset").click()
        # Two alerts: the banner atop the panel and a notification that stays while the ball is lost (the
        # banner may be scrolled out of sight).
        alerts = page.get_by_role("alert").filter(has_text="Ball lost at t =")
        alerts.first.wait_for(timeout=30000)
        page.wait_for_function(
            "() => [...document.querySelectorAll('[role=alert]')].filter(e => e.innerText.includes('Ball lost at t ='))"
            ".length === 2",
            timeout=30000,
        )
        assert all("Press Reset to start again" in text for text in alerts.all_inner_texts())
        assert "paused" in _page_text(page)
        lost_at = _sim_time(page)
        time.sleep(1.0)
        assert _sim_time(page) == lost_at  # paused where the ball left

        # Reset from a start the controller holds: the banner goes, the run goes on.
        _number_input(page, 1, "0.15")
        _number_input(page, 2, "0.1")
        page.wait_for_function(
            "() => document.body.innerText.includes('x0 = +0.15 m, θ0 = +0.10 rad apply on Reset')",
            timeout=30000,
        )
        page.get_by_role("button", name="Reset").click()
        page.wait_for_function("() => document.body.innerText.includes('ball on the beam')", timeout=30000)
        assert "apply on Reset" not in _page_text(page)
        # Banner and notification both go (the notification leaves with a short animation: wait for it).
        page.get_by_role("alert").filter(has_text="Ball lost").first.wait_for(state="detached", timeout=30000)
        assert page.get_by_role("alert").filter(has_text="Ball lost").count() == 0
        page.wait_for_function(
            "() => { const m = /t = ([0-9.]+) s/.exec(document.body.innerText); return m && parseFloat(m[1]) > 1.5; }",
            timeout=60000,
        )
        page.get_by_role("button", name="Pause").click()
        page.wait_for_function("() => document.body.innerText.includes('paused')", timeout=30000)
        paused_at = _sim_time(page)

        # Record: the run so far as the thesis's .mat file.
        with page.expect_download(timeout=30000) as download:
            page.get_by_role("button", name="Download .mat").click()
        path = tmp_path / download.value.suggested_filename
        download.value.save_as(path)
        assert path.suffix == ".mat" and "appendix-clp" in path.name
        log = load_mat(path)
        assert abs(log.timem[-1] - paused_at) < 0.02 + 1e-9
        assert abs(log.true_x_m[0] - 0.15) < 1e-9 and abs(log.true_theta_rad[0] - 0.1) < 1e-9
        assert not log.ball_lost.any()
        assert abs(float(np.median(np.diff(log.timem))) - 0.02) < 1e-9
        browser.close()


@pytest.mark.slow
def test_a_taken_port_is_reported_not_changed() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        out = subprocess.run(
            [sys.executable, "-m", "twin.app.cli", "view", "--port", str(port), "--duration", "1"],
            capture_output=True,
            text=True,
            timeout=60,
        )
    assert out.returncode == 2
    assert f"port {port} on 127.0.0.1 is taken" in out.stderr
