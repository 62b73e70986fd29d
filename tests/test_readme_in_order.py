"""The manual's recipes pasted in order, as a newcomer does: every code block of README.md and the manual's
pages (tests/test_readme_commands.py's ``PAGES``: README.md, then mkdocs.yml's nav in order) that is meant to be
pasted, top to bottom, in ONE working directory (a fresh copy of what the recipes read from a clone: ``docs/examples/``,
``examples/``, ``scripts/``), each shell line run by ``bash`` as typed, each Python block by ``python``, each
file the README names (``(here `requirements.toml`)``, ``Saved as `mypkg/ctrl.py```) written where it says.
A recipe that starts a server (``ballbeam serve``, ``--serve PORT``) runs in its own "terminal" while the rest
of its block runs in another, as the README tells. Each exits 0, or the code its comment documents (``# exit
1: …``, ``# 0 pass, 1 fail``), and no recipe refuses an output because an earlier one wrote it.

The design record and the protocol (docs/design.md, docs/protocol.md) and the generated pages hold no recipe to
paste (diagrams only); examples/*/README.md's are their own tests' (tests/test_c_controller.py,
tests/test_avr*.py, tests/test_fmi.py).

What is shrunk, and only through documented options appended to the line (the last of a repeated option
wins), so that the whole takes minutes on two cores: ``SHRUNK`` below, each with where the recipe runs at its
printed size. What is not run at all: ``SKIPPED``, each with its reason. The test prints every step's line,
exit code and seconds. A quick test plans the paste without running it: every shell and Python block is pasted,
or skipped whole for a reason in ``SKIPPED`` and counted in ``SKIPPED_BLOCKS``.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import socket
import subprocess
import sys
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import pytest
from test_readme_calibration import check_calibration
from test_readme_commands import (
    PAGES,
    README,
    RECORDS,
    Block,
    _expansions,
    code_blocks,
    logical_lines,
    page_name,
    shell_words,
)

ROOT = README.parent
COPIED = ("docs/examples", "examples", "scripts")  # what the recipes read or build, from a clone
STEP_TIMEOUT_S = 900.0  # a step that takes this long has hung (a loaded machine is slow, not this slow)

# A criteria file that keeps every check of `validate` but runs few, short runs (`--criteria`, documented).
QUICK_CRITERIA = """\
nominal_seeds = 1
duration_s = 6.0
region_x0 = [-0.2, 0.2, 2]
region_theta0 = [-0.3, 0.3, 2]
region_duration_s = 4.0
zeroing_counts = 1
latencies_s = [0.0]
free_runs_s = [0.01]
montecarlo_runs = 3
robust_rigs = 3
min_success_lower_bound = 0.1
"""
CRITERIA_FILE = "quick-criteria.toml"


@dataclass(frozen=True)
class Shrink:
    """Options appended to a recipe whose words contain all of ``match``; ``codes`` the exits it may then
    give besides its documented ones, and ``why``."""

    match: tuple[str, ...]
    options: tuple[str, ...]
    why: str
    codes: frozenset[int] = frozenset()


SHRUNK = (
    Shrink(
        ("ballbeam", "experiment", "--out", "data_file.mat"),
        ("--duration", "20"),
        "a 20 s log for README.md's two-parameter fit (docs/calibrate.md's recipe runs at its printed size)",
    ),
    Shrink(
        ("ballbeam", "sweep", "--out", "roa/"), ("--x0=-0.32:0.32:3", "--theta0=-0.7:0.7:3"), "3 × 3 starts"
    ),
    Shrink(("ballbeam", "montecarlo"), ("--n", "12"), "12 rigs (tests/test_montecarlo.py)"),
    Shrink(
        ("ballbeam", "run", "--realtime"),
        ("--duration", "6"),
        "6 s of wall clock, not 15: held within it (tests/test_realtime.py paces longer runs)",
    ),
    Shrink(
        ("ballbeam", "validate"), ("--criteria", CRITERIA_FILE), "few short runs (tests/test_validate.py)"
    ),
    Shrink(("ballbeam", "sweep", "--serve"), ("--x0=-0.3:0.3:2", "--theta0=-0.6:0.6:2"), "5 sessions"),
    Shrink(
        ("ballbeam", "sweep", "avr:examples/avr/bb_sf.elf"),
        ("--x0=-0.3:0.3:2", "--theta0=-0.6:0.6:2"),
        "2 × 2",
    ),
    Shrink(
        ("ballbeam", "certify"),
        ("--guarantee", "0.9", "--confidence", "0.9"),
        "22 runs (tests/test_certify.py)",
    ),
    Shrink(
        ("python", "scripts/train_policy.py"),
        ("--iterations", "1", "--directions", "2", "--top", "2", "--duration", "2"),
        "one iteration (tests/test_policy.py); its policy is untrained, so its validation may fail",
        frozenset({1}),
    ),
    Shrink(
        ("ballbeam", "run", "--rig", "udp://127.0.0.1:5752", "--sessions"),
        (),
        "the shrunk validation's few sessions may all be held",
        frozenset({0}),
    ),
    Shrink(
        ("ballbeam", "run", "--controller", "learned_policy:make_policy"),
        (),
        "the untrained policy of the shrunk training may lose the ball",
        frozenset({1}),
    ),
)

SKIPPED = (
    ("pip install", "installs the package: the test runs in the installed one (.ci/run runs the test line)"),
    ("python -m pytest", "the test suite itself"),
    (
        "ballbeam view",
        "serves a browser until it is closed: tests/test_docs_view_blocks.py runs it as pasted and ends it",
    ),
    (" PORT", "a placeholder: the next block runs the client on its port"),
    (
        "ballbeam shadow",
        "three terminals timed by the shadow's output (the controller started once it says `watching`): "
        "tests/test_readme_shadow.py runs the block as pasted; it writes shadow.jsonl alone",
    ),
)


def _skip_reason(block: Block) -> str | None:
    """Why a whole block is not run: the shadow's and the view's blocks are one recipe of several terminals."""
    for needle in ("ballbeam shadow", "ballbeam view --serve"):
        if needle in block.text:
            return next(why for n, why in SKIPPED if n in needle)
    return None


def _line_skip_reason(line: str) -> str | None:
    return next((why for needle, why in SKIPPED if needle in line), None)


def _documented_codes(line: str) -> frozenset[int]:
    """The exits a recipe's comment documents (``# exit 1: …``, ``exits 1 if …``, ``# 0 pass, 1 fail``); 0
    when it documents none."""
    comment = line.partition(" #")[2]
    codes = {int(c) for c in re.findall(r"\bexits? (\d)\b", comment)}
    codes |= {int(c) for c in re.findall(r"\b(\d) (?:pass|fail)\b", comment)}
    return frozenset(codes or {0})


def _shrunk(line: str) -> tuple[str, Shrink | None]:
    """The line with its shrinking options appended (after the last word, before the comment); a synopsis
    (``[--duration 15]``, ``twin|reference``) as its shortest command, its optional groups left out."""
    words = shell_words(line)
    if words[0] == "ballbeam" and _expansions(words[1:]) != [words[1:]]:
        words = ["ballbeam", *_expansions(words[1:])[0]]
        line = shlex.join(words)
    for shrink in SHRUNK:
        if all(m in words for m in shrink.match):
            if not shrink.options:
                return line, shrink
            assert not {"&&", ";", "(", ")"} & set(words), f"shrinking a compound line: {line}"
            return shlex.join([*words, *shrink.options]), shrink
    return line, None


def _served_port(line: str) -> int | None:
    """The UDP port a recipe serves on (``ballbeam serve --port P``, ``--serve P``), or None."""
    words = shell_words(line)
    if words[:2] == ["ballbeam", "serve"] and "--port" in words:
        return int(words[words.index("--port") + 1])
    if "--serve" in words:
        return int(words[words.index("--serve") + 1].rpartition(":")[2])
    return None


def _bound(port: int) -> bool:
    """Whether something holds UDP 127.0.0.1:``port`` (the server is listening)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return True
    return False


@dataclass
class Server:
    """A recipe running in its own terminal."""

    where: str
    line: str
    expected: frozenset[int]
    proc: subprocess.Popen[bytes]
    log: Path
    began: float


@dataclass
class Step:
    where: str
    shown: str
    code: int
    expected: frozenset[int]
    seconds: float
    note: str = ""


class Newcomer:
    """One working directory and the terminals' output, step by step."""

    def __init__(self, work: Path, terminal: Path) -> None:
        self.work, self.terminal = work, terminal
        bindir = str(Path(sys.executable).parent)  # `ballbeam` and `python` of this environment
        self.env = {
            **os.environ,
            "PATH": bindir + os.pathsep + os.environ.get("PATH", ""),
            "MPLBACKEND": "Agg",
        }
        self.env.pop("PYTHONPATH", None)  # the installed package, as after `pip install .`
        self.steps: list[Step] = []
        self.count = 0

    def _log(self) -> Path:
        self.count += 1
        return self.terminal / f"{self.count:03d}.txt"

    def start(self, line: str) -> tuple[subprocess.Popen[bytes], Path]:
        log = self._log()
        with open(log, "wb") as out:
            proc = subprocess.Popen(
                ["bash", "-c", line], cwd=self.work, env=self.env, stdout=out, stderr=subprocess.STDOUT
            )
        return proc, log

    def run(self, where: str, line: str, expected: frozenset[int], stdin: str | None = None) -> Step:
        log = self._log()
        began = time.monotonic()
        with open(log, "wb") as out:
            done = subprocess.run(
                ["bash", "-c", line] if stdin is None else [sys.executable, "-"],
                cwd=self.work,
                env=self.env,
                input=None if stdin is None else stdin.encode(),
                stdout=out,
                stderr=subprocess.STDOUT,
                timeout=STEP_TIMEOUT_S,
                check=False,
            )
        step = Step(where, line, done.returncode, expected, time.monotonic() - began, note=str(log))
        self.steps.append(step)
        return step

    def finish(self, server: Server) -> None:
        code = server.proc.wait(STEP_TIMEOUT_S)
        seconds = time.monotonic() - server.began
        self.steps.append(Step(server.where, server.line, code, server.expected, seconds, str(server.log)))

    def output(self, step: Step) -> str:
        return Path(step.note).read_text(errors="replace")[-3000:]


def _file_named_around(text_lines: list[str], block: Block) -> str | None:
    """The file a block is to be saved as: ``(here `NAME`):`` on the line before its fence, or a paragraph
    right after it that begins ``Saved as `NAME```."""
    before = "\n".join(text_lines[max(block.first_line - 4, 0) : block.first_line - 2])  # up to the fence
    after = "\n".join(
        text_lines[block.first_line + len(block.lines) : block.first_line + len(block.lines) + 3]
    )
    for pattern, where in ((r"\(here `([^`]+)`\):\s*$", before), (r"^\s*Saved as `([^`]+)`", after)):
        found = re.search(pattern, where, flags=re.M)
        if found:
            return found.group(1)
    return None


def _paste_block(me: Newcomer, block: Block, text_lines: list[str], page: str) -> None:
    where = f"{page}:{block.first_line}"
    name = _file_named_around(text_lines, block)
    if name is not None:
        path = me.work / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(block.text, encoding="utf-8")
    if block.language == "python":
        me.run(where, f"python <<'EOF' ({where})", frozenset({0}), stdin=block.text)
        return
    if not block.shell:
        return
    reason = _skip_reason(block)
    if reason is not None:
        me.steps.append(Step(where, block.lines[0], -1, frozenset(), 0.0, f"skipped: {reason}"))
        return
    servers: list[Server] = []
    for number, raw in logical_lines(block):
        where = f"{page}:{number}"
        line = raw.strip()
        reason = _line_skip_reason(line)
        if reason is not None:
            me.steps.append(Step(where, line, -1, frozenset(), 0.0, f"skipped: {reason}"))
            continue
        line, shrink = _shrunk(line)
        expected = _documented_codes(raw) | (shrink.codes if shrink else frozenset())
        port = _served_port(line)
        if port is not None:  # the server's terminal: the rest of the block is the client's
            assert not _bound(port), f"{where}: UDP port {port} is taken before the recipe serves on it"
            began = time.monotonic()
            proc, log = me.start(line)
            while not _bound(port) and proc.poll() is None and time.monotonic() < began + 120:
                time.sleep(0.1)
            servers.append(Server(where, line, expected, proc, log, began))
            continue
        me.run(where, line, expected)
    for server in servers:
        try:
            me.finish(server)
        finally:
            server.proc.kill()


def _newcomers_folder(work: Path) -> None:
    for part in COPIED:
        shutil.copytree(ROOT / part, work / part, symlinks=True)  # copy2: make sees the built files as built
    (work / CRITERIA_FILE).write_text(QUICK_CRITERIA, encoding="utf-8")


# The blocks no test can paste, counted (page, the reason's needle): installs and the test suite itself, the
# live view (it serves until closed), the shadow's three terminals and the view's wire recipe (each run by the
# test its reason names).
SKIPPED_BLOCKS = Counter(
    {
        ("README.md", "pip install"): 1,
        ("docs/index.md", "pip install"): 1,
        ("README.md", "ballbeam view"): 1,
        ("docs/watch.md", "ballbeam view"): 1,
        ("docs/watch.md", "ballbeam shadow"): 1,
        ("docs/connect.md", "ballbeam view"): 1,
    }
)


@dataclass(frozen=True)
class Planned:
    """A shell or Python block of a page, and the reason it is not pasted (None: it is)."""

    page: str
    block: Block
    skipped: str | None


def paste_plan() -> list[Planned]:
    """Every shell and Python block of the manual, in paste order: pasted, or skipped whole (the block's own
    reason, or every line of it skipped) with the needle of its reason."""
    plan = []
    for path in PAGES:
        for block in code_blocks(path.read_text(encoding="utf-8")):
            if block.language != "python" and not block.shell:
                continue
            needle = None
            if block.shell:
                needle = next(
                    (n for n in ("ballbeam shadow", "ballbeam view --serve") if n in block.text), None
                )
                lines = [line.strip() for _, line in logical_lines(block)]
                if needle is None and all(_line_skip_reason(line) for line in lines):
                    needle = next(n for n, _ in SKIPPED if n in lines[0])
            plan.append(Planned(page_name(path), block, needle))
    return plan


@pytest.mark.quick
def test_every_block_is_pasted_or_skipped_for_a_counted_reason() -> None:
    """The doc blocks: each shell and Python block is pasted by the in-order run below, or is one of the
    counted blocks that cannot be (none skipped otherwise)."""
    plan = paste_plan()
    skipped = Counter(
        (p.page, "ballbeam view" if p.skipped == "ballbeam view --serve" else p.skipped)
        for p in plan
        if p.skipped
    )
    assert skipped == SKIPPED_BLOCKS, skipped
    pasted = [p for p in plan if not p.skipped]
    print(
        f"\n{len(plan)} shell and Python blocks: {len(pasted)} pasted, {sum(skipped.values())} skipped (counted)"
    )
    assert len(pasted) >= 20 and {p.page for p in pasted} >= {
        "README.md",
        "docs/validate.md",
        "docs/connect.md",
    }


@pytest.mark.slow
def test_the_readme_recipes_run_in_order_in_one_folder(tmp_path: Path, manual_wire_port: int) -> None:
    work, terminal = tmp_path / "clone", tmp_path / "terminal"
    work.mkdir()
    terminal.mkdir()
    _newcomers_folder(work)
    me = Newcomer(work, terminal)
    began = time.monotonic()
    plan = paste_plan()
    ran_blocks = 0
    for path in PAGES:
        text = path.read_text(encoding="utf-8")
        text_lines = text.splitlines()
        for block in code_blocks(text):
            before = len([s for s in me.steps if s.code >= 0])
            _paste_block(me, block, text_lines, page_name(path))
            ran_blocks += len([s for s in me.steps if s.code >= 0]) > before
    total = time.monotonic() - began
    print(f"\n{len(me.steps)} steps of {ran_blocks} blocks in {total:.0f} s")
    for s in me.steps:
        print(
            f"{s.where:<24} {s.code:>3} {s.seconds:6.1f} s  {s.shown[:110]}  {s.note if s.code < 0 else ''}"
        )
    failed = [s for s in me.steps if s.code >= 0 and s.code not in s.expected]
    assert not failed, "\n\n".join(
        f"{s.where}: {s.shown}\nexit {s.code}, expected {sorted(s.expected)}:\n{me.output(s)}" for s in failed
    )
    assert ran_blocks == len([p for p in plan if not p.skipped])  # every planned block ran a step
    ran = [s for s in me.steps if s.code >= 0]
    assert len(ran) >= 40, [s.shown for s in ran]  # the extraction is not vacuous
    assert {"roa", "roa-c", "report", "report-c", "cal", "cmp", "cmp_run", "fz", "cert"} <= {
        p.name for p in work.iterdir()
    }
    check_calibration(work)  # docs/calibrate.md's recipe, run above as printed, fitted the twin's own values


@pytest.mark.quick
def test_the_docs_hold_no_recipe_to_paste() -> None:
    """docs/*.md's code blocks outside the manual's pages are diagrams (the design record, the protocol, the
    generated pages): a recipe added there (a shell block, a command line) must join a page the in-order run
    above pastes."""
    pasted = set(PAGES)
    records = {ROOT / "docs" / name for name in RECORDS}
    assert records and not records & pasted
    for path in sorted((ROOT / "docs").rglob("*.md")):
        if path in pasted:
            continue
        for block in code_blocks(path.read_text(encoding="utf-8")):
            assert block.language not in ("bash", "sh", "shell", "console", "python"), (
                path,
                block.first_line,
            )
            commands = [
                line for line in block.lines if line.lstrip().startswith(("ballbeam ", "$ ", "python "))
            ]
            assert not commands, (path, block.first_line, commands)
