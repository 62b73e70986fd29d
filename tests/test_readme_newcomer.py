"""What a newcomer pasting the README met, one test each: the recipes' output folders do not
collide, a file path given as ``--controller`` is refused naming the module to give, the README's controller
example is importable as ``mypkg.ctrl:MyController``, the Gymnasium snippet prints what it shows, ``run
--realtime`` warns when it did not keep real time, and the README pins what a firmware's summary and a
controller FMU's steps mean. The manual's pages count as the README (tests/test_readme_commands.py's ``PAGES``);
tests/test_readme_in_order.py pastes every recipe in order."""

from __future__ import annotations

import contextlib
import io
import json
import struct
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from cli_checks import refused
from test_readme_commands import README, code_blocks, manual_commands, manual_text

from twin.app.cli import main
from twin.interface import DaqSample
from twin.realtime import OVERRUN_WARNING_SHARE, TickTiming, overrun_warning

ROOT = README.parent
TEXT = manual_text()


def _python_block(needle: str) -> str:
    (code,) = [b.text for b in code_blocks(TEXT) if b.language == "python" and needle in b.text]
    return code


@pytest.fixture
def user_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """A folder holding the README's controller example saved as it says (``mypkg/ctrl.py``), as the current
    folder; the module path and the imported modules restored afterwards."""
    assert "Saved as `mypkg/ctrl.py`" in TEXT
    (tmp_path / "mypkg").mkdir()
    (tmp_path / "mypkg" / "ctrl.py").write_text(_python_block("class MyController"), encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", list(sys.path))
    yield tmp_path
    for name in [m for m in sys.modules if m.split(".")[0] in ("mypkg", "slowctl")]:
        del sys.modules[name]


@pytest.mark.quick
def test_the_readmes_output_folders_and_files_do_not_collide() -> None:
    """Pasted in order, no command writes an ``--out`` another already wrote (unless it says ``--overwrite``)."""
    seen: dict[str, str] = {}
    for page, number, words in manual_commands():
        if "--out" not in words or "--overwrite" in words:
            continue
        out = words[words.index("--out") + 1].rstrip("/")
        assert out not in seen, f"{seen[out]} and {page}:{number} both write --out {out}"
        seen[out] = f"{page}:{number}"
    assert {"roa", "roa-c", "report", "report-c"} <= set(seen)


@pytest.mark.quick
@pytest.mark.parametrize(
    "spec,dotted",
    [
        ("mypkg/ctrl.py:MyController", "mypkg.ctrl:MyController"),
        ("./mypkg/ctrl.py:MyController", "mypkg.ctrl:MyController"),
        ("mypkg/ctrl:MyController", "mypkg.ctrl:MyController"),
        ("./ctrl.py", "ctrl:MyController"),
        ("mypkg/ctrl.py", "mypkg.ctrl:MyController"),
        (".ctrl:MyController", "e.g. ctrl:MyController"),
    ],
)
def test_a_file_path_as_the_controller_is_refused_naming_the_module_to_give(
    user_folder: Path, spec: str, dotted: str, capsys: pytest.CaptureFixture[str]
) -> None:
    line = refused(capsys, ["run", "--controller", spec, "--x0", "0.1", "--theta0", "0", "--duration", "0.1"])
    assert spec in line and "file path" in line and dotted in line and str(user_folder) in line, line
    assert "TypeError" not in line and "no module named" not in line


def test_the_readmes_controller_is_found_in_the_current_folder_and_imports_without_running(
    user_folder: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["run", "--controller", "mypkg.ctrl:MyController", "--x0", "0.14", "--theta0", "-0.2", "--json"]
    code = main([*argv, "--seed", "1"])  # as the example runs it: 15 s, seed 1
    out = capsys.readouterr()
    summary = json.loads(out.out)
    assert summary["controller"] == "mypkg.ctrl:MyController" and summary["ball_lost"] is False
    assert code == 0, out.err
    assert "True held" not in out.out + out.err  # the example's own run is the script's, not the import's


@pytest.mark.quick
def test_overruns_above_the_stated_share_are_a_warning() -> None:
    def timing(overruns: int) -> TickTiming:
        return TickTiming(100, 20.0, 0.1, 30.0, 45.0, 25.0, 31.0, overruns)

    assert OVERRUN_WARNING_SHARE == 0.01 and "above 1 % of ticks overrun" in TEXT
    assert overrun_warning(timing(1)) is None
    text = overrun_warning(timing(63))
    assert text is not None and "63 of 100 ticks overran (63 %, above 1 %)" in text, text
    assert "longest compute 31.0 ms" in text and "the verdict" in text


SLOW_CONTROLLER = """
import time
from twin.interface import Controller

class Slow(Controller):
    name = "slow"
    def start(self, sample):
        pass
    def update(self, sample):
        time.sleep(0.03)  # longer than the 20 ms period: every tick overruns
        return 2.5
"""


def test_run_realtime_that_overruns_warns_and_keeps_the_verdicts_exit(
    user_folder: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (user_folder / "slowctl.py").write_text(SLOW_CONTROLLER, encoding="utf-8")
    argv = ["run", "--controller", "slowctl:Slow", "--x0", "0", "--theta0", "0", "--duration", "0.3"]
    code = main([*argv, "--realtime", "--json"])
    out = capsys.readouterr()
    summary = json.loads(out.out)
    assert code == 1  # a 0.3 s run is shorter than the verdict's window: not held, as without --realtime
    assert summary["realtime"]["overruns"] >= 0.5 * summary["realtime"]["ticks"]
    assert "real time not kept" in summary["realtime_warning"]
    assert "ballbeam run: warning: real time not kept" in out.err and "Traceback" not in out.err


def test_the_gymnasium_snippet_prints_what_it_shows() -> None:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(_python_block("gymnasium.make("), "docs/learn.md", "exec"), {"__name__": "__main__"})
    first, second = out.getvalue().splitlines()
    words = first.replace("[", " ").replace("]", " ").split()
    assert len(words) == 7 and words[-2:] == ["False", "False"], first  # 4 volts, the reward, two flags
    assert all(abs(float(v)) <= 5.0 for v in words[:4]) and 0.05 <= float(words[4]) <= 1.0, first
    assert second == "64 (64, 2)"


def test_every_figure_of_a_firmwares_summary_is_in_the_readmes_table(
    capsys: pytest.CaptureFixture[str],
) -> None:
    elf = ROOT / "examples" / "avr" / "bb_sf.elf"
    argv = ["run", "--controller", f"avr:{elf}", "--x0", "0.14", "--theta0", "-0.2", "--duration", "0.5"]
    main([*argv, "--json"])
    figures = json.loads(capsys.readouterr().out)["firmware"]
    table = TEXT[TEXT.index("| `update_cycles_max`") : TEXT.index("`validate` adds a `target` check")]
    missing = [name for name in figures if f"`{name}`" not in table]
    assert not missing, f"docs/firmware.md's firmware table lacks {missing}"


def test_a_controller_fmu_steps_at_the_times_the_readme_states(monkeypatch: pytest.MonkeyPatch) -> None:
    """Its first step (on the start block) at 0, the one answering block k at (k + 1)·T, a running sum of T."""
    from twin.childproc import Child
    from twin.fmi.controller import FmuController
    from twin.fmi.host import REQUEST

    assert "`doStep(0, T)`" in TEXT and "`doStep((k + 1)·T, T)`" in TEXT
    sent: list[tuple[float, ...]] = []
    write = Child.write

    def record(self: Child, data: bytes) -> None:
        if len(data) == REQUEST.size:
            sent.append(struct.unpack("<4d", data))
        write(self, data)

    monkeypatch.setattr(Child, "write", record)
    controller = FmuController(ROOT / "examples" / "fmu" / "BbStateFeedback.fmu", period_s=0.02)
    try:
        controller.start(DaqSample(-0.01, 0.5, 0.1))
        for k in range(3):
            controller.update(DaqSample(0.02 * k, 0.5, 0.1))
    finally:
        controller.close()
    expected, t = [], 0.0
    for _ in range(4):
        expected.append((t, 0.02))
        t += 0.02
    assert [(s[0], s[1]) for s in sent] == expected


@pytest.mark.quick
def test_the_readme_says_what_a_pythonfmu3_controller_must_register() -> None:
    """FMPy wants an FMI 3.0 unit's independent variable; pythonfmu3 adds none, the twin's unit registers it."""
    line = 'Float64("time", causality=Fmi3Causality.independent'
    assert line in " ".join(TEXT.split())
    assert line in (ROOT / "twin" / "fmi" / "ballbeam_fmu.py").read_text(encoding="utf-8")
