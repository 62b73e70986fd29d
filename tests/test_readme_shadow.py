"""The manual's three-terminal ``ballbeam shadow`` recipe (docs/watch.md) run as printed: a served twin with a
warm motor, the shadow at the nominal parameters, a controller — each command read from the page's block, the controller
started as a user would, once the shadow says it is watching and then some seconds more (switching
terminals: longer than the shadow's ``--idle``). The shadow scores the session's windows and raises the
drift alarm the README shows (its documented exit for an alarm, 1)."""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "docs" / "watch.md"  # where the recipe lives
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
CLI = [sys.executable, "-m", "twin.app.cli"]


def recipe() -> list[list[str]]:
    """The commands of the page's block that begins ``# three terminals``, as a shell splits them."""
    text = README.read_text(encoding="utf-8")
    block = re.search(r"```bash\n(# three terminals[^\n]*\n.*?)```", text, re.S)
    assert block is not None, "docs/watch.md: the shadow's three-terminal block"
    lines = [line for line in block.group(1).splitlines() if line and not line.startswith("#")]
    commands = [shlex.split(line) for line in lines]
    assert [c[:2] for c in commands] == [["ballbeam", "serve"], ["ballbeam", "shadow"], ["ballbeam", "run"]]
    return [[*CLI, *c[1:]] for c in commands]


@pytest.mark.slow
def test_the_readmes_shadow_recipe_works_as_pasted(tmp_path: Path, manual_wire_port: int) -> None:
    serve_cmd, shadow_cmd, run_cmd = recipe()
    idle_s = 5.0  # the shadow's --idle default, which the recipe leaves as it is
    assert "--idle" not in shadow_cmd
    procs: list[subprocess.Popen[str]] = []
    try:
        serve = subprocess.Popen(
            serve_cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=ENV
        )
        procs.append(serve)
        assert serve.stdout is not None
        assert serve.stdout.readline().startswith(f"serving on udp://127.0.0.1:{manual_wire_port}")
        with open(tmp_path / "shadow.err", "w") as err:
            shadow = subprocess.Popen(
                shadow_cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=err, text=True, env=ENV
            )
            procs.append(shadow)
            assert shadow.stdout is not None
            head = []
            for line in shadow.stdout:  # the band is measured first: minutes on a loaded machine
                head.append(line)
                if line.startswith("watching "):
                    break
            assert head and head[-1].startswith("watching "), "".join(head)
            time.sleep(idle_s + 1.0)  # the user switches to the third terminal
            run = subprocess.run(run_cmd, cwd=tmp_path, capture_output=True, text=True, env=ENV, timeout=300)
            assert run.returncode in (0, 1), run.stderr
            rest = shadow.stdout.read()
            code = shadow.wait(300)
        serve.wait(60)
    finally:
        for proc in procs:
            proc.kill()
    out = "".join(head) + rest
    summary = out.strip().splitlines()[-2]  # then "wrote shadow.jsonl"
    scored = re.search(r"(\d+) windows scored", summary)
    assert scored is not None and int(scored.group(1)) >= 25, out
    assert summary.startswith("1 session(s) watched") and "went silent" not in out, out
    assert "DRIFT ALARM at" in out and code == 1, out  # the served motor is warm: the alarm, exit 1
    assert "shadow: measuring the band" in (tmp_path / "shadow.err").read_text()
    assert (tmp_path / "shadow.jsonl").is_file()
