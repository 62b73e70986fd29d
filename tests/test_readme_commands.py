"""Every ``ballbeam`` command in README.md's code blocks parses with the command's own parser (nothing runs).

A command is read as a shell reads it: ``\\`` continuations joined, comments dropped, words split by
``shlex``. A synopsis line (``[--duration 15]``, ``torque|voltage``, ``…``) is parsed twice: with every
optional group left out and with every group in (the first of each ``a|b``), so both ends of what it
documents are commands the parser takes.
"""

import re
import shlex
from pathlib import Path

import pytest

from twin.app.cli import build_parser, join_negative_numbers

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
SHELL_BLOCKS = ("", "bash", "sh", "shell", "console")


def _shell_lines(text: str) -> list[tuple[int, str]]:
    """(line number, logical line) of every shell code block, continuations joined as a shell does."""
    out: list[tuple[int, str]] = []
    in_block, shell, pending, start = False, False, "", 0
    for number, line in enumerate(text.splitlines(), start=1):
        fence = re.match(r"^\s*```(\w*)", line)
        if fence:
            in_block, shell = not in_block, fence.group(1) in SHELL_BLOCKS
            continue
        if not (in_block and shell):
            continue
        if not pending:
            start = number
        if line.endswith("\\"):
            pending += line[:-1]  # backslash-newline vanishes; the next line's indent stays (a word break)
            continue
        out.append((start, pending + line))
        pending = ""
    return out


def _commands(text: str) -> list[tuple[int, list[str]]]:
    """The ``ballbeam`` invocations: the words after ``ballbeam`` up to the end or a ``&&``, ``;``, ``|``."""
    found = []
    for number, line in _shell_lines(text):
        lexer = shlex.shlex(line, posix=True, punctuation_chars="&;")
        lexer.whitespace_split = True
        lexer.commenters = "#"
        words = list(lexer)
        for i, word in enumerate(words):
            if word == "ballbeam" and (i == 0 or words[i - 1] in ("&&", ";", "||")):
                rest = words[i + 1 :]
                end = next((k for k, w in enumerate(rest) if w in ("&&", ";", "||")), len(rest))
                found.append((number, rest[:end]))
    return found


def _expansions(words: list[str]) -> list[list[str]]:
    """A literal command as it is; a synopsis without its optional groups and with all of them."""
    line = " ".join(words)
    if not re.search(r"[\[\]|…]|\.\.\.", line):
        return [words]
    least = re.sub(r"\[[^\[\]]*\]", " ", line)
    most = re.sub(r"[\[\]]", " ", line)
    out = []
    for variant in (least, most):
        variant = re.sub(r"(\S+?)\|\S+", r"\1", variant)  # a|b: the first alternative
        variant = re.sub(r"…|\.\.\.", " ", variant)
        out.append(variant.split())
    return out


def _parse_error(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str | None:
    parser = build_parser()
    try:
        parser.parse_args(join_negative_numbers(argv, parser))
    except SystemExit as exc:
        if exc.code not in (0, None):  # 0: --help / --version, which parse
            return capsys.readouterr().err.strip().splitlines()[-1]
    return None


@pytest.mark.quick
def test_the_readme_has_its_commands() -> None:
    """The extraction sees the commands it is meant to check (the test is not vacuous)."""
    commands = [words for _, words in _commands(README.read_text(encoding="utf-8"))]
    assert len(commands) >= 12
    assert {"view", "run", "sweep", "montecarlo", "validate", "calibrate", "experiment"} <= {
        c[0] for c in commands if c
    }
    calibrate = next(c for c in commands if c and c[0] == "calibrate")
    assert (
        "--fit" in calibrate and "angle_sensor.zeroing_error_rad" in calibrate[calibrate.index("--fit") + 1]
    )


@pytest.mark.parametrize(
    "number,words",
    _commands(README.read_text(encoding="utf-8")),
    ids=lambda v: f"line{v}" if isinstance(v, int) else " ".join(v)[:40],
)
def test_every_readme_command_parses(
    number: int, words: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    for argv in _expansions(words):
        error = _parse_error(argv, capsys)
        assert error is None, f"README.md line {number}: ballbeam {' '.join(argv)}: {error}"


@pytest.mark.quick
def test_a_split_list_is_caught(capsys: pytest.CaptureFixture[str]) -> None:
    """The pasted-command failure the README once had: a ``\\`` inside the --fit list splits it in two."""
    text = "```bash\nballbeam calibrate log.mat --fit motor.resistance_ohm,\\\n    beam.inertia_pivot_kgm2\n```\n"
    [(number, words)] = _commands(text)
    assert number == 2 and words[-1] == "beam.inertia_pivot_kgm2"
    assert _parse_error(words, capsys) is not None
