"""Every ``ballbeam`` command in the code blocks of README.md and the manual's pages (``PAGES``: README.md,
then the pages of mkdocs.yml's nav in order) parses with the command's own parser (nothing runs).

A command is read as a shell reads it: ``\\`` continuations joined, comments dropped, words split by
``shlex``. A synopsis line (``[--duration 15]``, ``torque|voltage``, ``…``) is parsed twice: with every
optional group left out and with every group in (the first of each ``a|b``), so both ends of what it
documents are commands the parser takes.
"""

import re
import shlex
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from twin.app.cli import build_parser, join_negative_numbers

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
SHELL_BLOCKS = ("", "bash", "sh", "shell", "console")


def _nav_pages(entries: object) -> list[str]:
    """The Markdown files of an mkdocs nav, in order."""
    if isinstance(entries, str):
        return [entries]
    if isinstance(entries, list):
        return [page for entry in entries for page in _nav_pages(entry)]
    if isinstance(entries, dict):
        return [page for value in entries.values() for page in _nav_pages(value)]
    return []


# The design record and the protocol's specification: their code blocks are diagrams and layouts, no recipe
# (tests/test_readme_in_order.py checks they hold none).
RECORDS = ("design.md", "protocol.md")


def manual_pages() -> list[Path]:
    """README.md, then every page of the manual in mkdocs.yml's nav order (the order a newcomer reads them in),
    the records left out."""
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))
    pages = [page for page in _nav_pages(config["nav"]) if page not in RECORDS]
    return [README, *(ROOT / config["docs_dir"] / page for page in pages)]


PAGES = manual_pages()


def page_name(path: Path) -> str:
    return str(path.relative_to(ROOT))


def manual_text() -> str:
    """Every page's text, in order (for checks of what the manual says, wherever it says it)."""
    return "\n".join(path.read_text(encoding="utf-8") for path in PAGES)


def manual_commands() -> list[tuple[str, int, list[str]]]:
    """(page, line number, words) of every ``ballbeam`` invocation of every page, in order."""
    return [
        (page_name(path), number, words)
        for path in PAGES
        for number, words in _commands(path.read_text(encoding="utf-8"))
    ]


@dataclass(frozen=True)
class Block:
    """A fenced code block: its language (``""`` when none), the line number of its first line inside the
    fence, and its lines."""

    language: str
    first_line: int
    lines: tuple[str, ...]

    @property
    def text(self) -> str:
        return "".join(line + "\n" for line in self.lines)

    @property
    def shell(self) -> bool:
        return self.language in SHELL_BLOCKS


def code_blocks(text: str) -> list[Block]:
    """Every fenced code block of a Markdown text, in order (indented fences too: a block in a list item)."""
    blocks: list[Block] = []
    lines: list[str] = []
    language, first, inside = "", 0, False
    for number, line in enumerate(text.splitlines(), start=1):
        fence = re.match(r"^\s*```(\w*)", line)
        if fence and not inside:
            language, first, lines, inside = fence.group(1), number + 1, [], True
        elif fence:
            blocks.append(Block(language, first, tuple(lines)))
            inside = False
        elif inside:
            lines.append(line)
    return blocks


def logical_lines(block: Block) -> list[tuple[int, str]]:
    """(line number, logical line) of a shell block, continuations joined as a shell does."""
    out: list[tuple[int, str]] = []
    pending, start = "", 0
    for number, line in enumerate(block.lines, start=block.first_line):
        if not pending:
            start = number
        if line.endswith("\\"):
            pending += line[:-1]  # backslash-newline vanishes; the next line's indent stays (a word break)
            continue
        out.append((start, pending + line))
        pending = ""
    return out


def _shell_lines(text: str) -> list[tuple[int, str]]:
    """(line number, logical line) of every shell code block."""
    return [line for block in code_blocks(text) if block.shell for line in logical_lines(block)]


SEPARATORS = ("&&", ";", "||", "(", ")")


def shell_words(line: str) -> list[str]:
    """A logical line's words as a shell splits them, comments dropped; ``&&``, ``;`` and a subshell's
    parentheses are words of their own."""
    lexer = shlex.shlex(line, posix=True, punctuation_chars="&;()")
    lexer.whitespace_split = True
    lexer.commenters = "#"
    return list(lexer)


def _commands(text: str) -> list[tuple[int, list[str]]]:
    """The ``ballbeam`` invocations: the words after ``ballbeam`` up to the end or a ``&&``, ``;``, ``|``."""
    found = []
    for number, line in _shell_lines(text):
        words = shell_words(line)
        for i, word in enumerate(words):
            if word == "ballbeam" and (i == 0 or words[i - 1] in SEPARATORS):
                rest = words[i + 1 :]
                end = next((k for k, w in enumerate(rest) if w in SEPARATORS), len(rest))
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
    commands = [words for _, _, words in manual_commands()]
    assert len(commands) >= 12
    assert {"view", "run", "sweep", "montecarlo", "validate", "calibrate", "experiment"} <= {
        c[0] for c in commands if c
    }
    calibrate = next(
        c for page, _, c in manual_commands() if page == "docs/calibrate.md" and c[0] == "calibrate"
    )
    assert (
        "--fit" in calibrate and "angle_sensor.zeroing_error_rad" in calibrate[calibrate.index("--fit") + 1]
    )


@pytest.mark.quick
def test_the_readme_and_every_page_with_a_recipe_are_read() -> None:
    """The pages read are README.md and the nav's pages; each page that holds commands is one of them."""
    assert PAGES[0] == README and len(PAGES) == len(set(PAGES)) and all(p.is_file() for p in PAGES)
    pages = {page for page, _, _ in manual_commands()}
    assert {"README.md", "docs/watch.md", "docs/validate.md", "docs/calibrate.md", "docs/connect.md"} <= pages
    readme = [words[0] for page, _, words in manual_commands() if page == "README.md"]
    assert {"view", "calibrate", "validate"} <= set(readme)  # the three jobs, one command each


@pytest.mark.parametrize(
    "page,number,words",
    manual_commands(),
    ids=lambda v: f"line{v}" if isinstance(v, int) else (" ".join(v)[:40] if isinstance(v, list) else v),
)
def test_every_readme_command_parses(
    page: str, number: int, words: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    for argv in _expansions(words):
        error = _parse_error(argv, capsys)
        assert error is None, f"{page} line {number}: ballbeam {' '.join(argv)}: {error}"


@pytest.mark.quick
def test_a_split_list_is_caught(capsys: pytest.CaptureFixture[str]) -> None:
    """The pasted-command failure the README once had: a ``\\`` inside the --fit list splits it in two."""
    text = "```bash\nballbeam calibrate log.mat --fit motor.resistance_ohm,\\\n    beam.inertia_pivot_kgm2\n```\n"
    [(number, words)] = _commands(text)
    assert number == 2 and words[-1] == "beam.inertia_pivot_kgm2"
    assert _parse_error(words, capsys) is not None
