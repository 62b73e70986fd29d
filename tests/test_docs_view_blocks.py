"""The manual's ``ballbeam view`` lines, run as pasted: the live view serves its page on http://127.0.0.1:8080
and Ctrl-C ends it cleanly. The in-order recipe test cannot paste them (they serve until closed), so this test
runs the one command they all are; ``view --serve`` is run by tests/test_wire_sessions.py, the install lines
by ``.ci/run`` itself."""

from __future__ import annotations

import shutil
import signal
import subprocess
import sys
import time
import urllib.request

import pytest
from test_readme_commands import manual_commands

URL = "http://127.0.0.1:8080"  # what the lines tell the reader to open


def _view_lines() -> list[tuple[str, int]]:
    return [(page, number) for page, number, words in manual_commands() if words == ["view"]]


@pytest.mark.quick
def test_the_manual_tells_the_reader_to_run_the_view_as_one_command() -> None:
    pages = {page for page, _ in _view_lines()}
    assert {"README.md", "docs/index.md", "docs/watch.md"} <= pages, _view_lines()


@pytest.mark.slow
def test_ballbeam_view_as_pasted_serves_its_page_and_ctrl_c_ends_it() -> None:
    ballbeam = shutil.which("ballbeam")
    command = [ballbeam, "view"] if ballbeam else [sys.executable, "-m", "twin.app.cli", "view"]
    view = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        page = ""
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and view.poll() is None:
            try:
                with urllib.request.urlopen(URL, timeout=5) as answer:
                    page = answer.read().decode("utf-8", "replace")
                break
            except OSError:
                time.sleep(0.5)
        assert "<html" in page.lower(), f"no page at {URL}; exit {view.poll()}"
        view.send_signal(signal.SIGINT)
        out, err = view.communicate(timeout=60)
    finally:
        if view.poll() is None:
            view.kill()
            view.communicate()
    assert view.returncode in (0, 130), (view.returncode, err[-2000:])
    assert "Traceback" not in err, err[-2000:]
    assert f"ballbeam view: {URL}" in out + err
