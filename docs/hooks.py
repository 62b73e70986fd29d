"""MkDocs hook: the reference pages generated at build time, so they cannot go stale.

``reference/cli.md`` gets every ``ballbeam`` command's ``--help`` (from the parser ``twin.app.cli`` builds) and
``reference/parameters.md`` the parameter table (``Parameters.describe``, what ``ballbeam params`` prints), each
in place of its ``<!-- generated: … -->`` marker. tests/test_docs_site.py builds the site strictly and reads
these functions.
"""

from __future__ import annotations

import argparse
import os
from typing import Any

COMMANDS_MARKER = "<!-- generated: commands -->"
PARAMETERS_MARKER = "<!-- generated: parameters -->"
HELP_COLUMNS = "100"  # argparse wraps to the terminal's width: a fixed one keeps the page the same everywhere


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def parameters_markdown() -> str:
    """The parameter table: name, default, unit, source, one row per parameter (the parts' own groups too:
    importing twin.parts registers them)."""
    import twin.parts  # noqa: F401  # registers every built-in part's parameter group
    from twin.parameters import Parameters

    rows = ["| parameter | default | unit | source |", "| --- | --- | --- | --- |"]
    for row in Parameters.describe():
        cells = (f"`{row['name']}`", f"`{row['default']}`", row["unit"], row["source"])
        rows.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    return "\n".join(rows) + "\n"


def commands_markdown() -> str:
    """Each command's ``--help``, as ``ballbeam COMMAND --help`` prints it, under a heading of its own."""
    from twin.app.cli import build_parser

    previous = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = HELP_COLUMNS
    try:
        parser = build_parser()
        (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        helps = {choice.dest: choice.help for choice in sub._choices_actions}
        parts = ["```text\n" + parser.format_help().rstrip() + "\n```\n"]
        for name, command in sub.choices.items():
            usage = command.format_help().rstrip()
            parts.append(f"## `ballbeam {name}`\n\n{helps.get(name) or ''}\n\n```text\n{usage}\n```\n")
    finally:
        if previous is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = previous
    return "\n".join(parts)


def on_page_markdown(markdown: str, page: Any, **_: Any) -> str:
    if COMMANDS_MARKER in markdown:
        markdown = markdown.replace(COMMANDS_MARKER, commands_markdown())
    if PARAMETERS_MARKER in markdown:
        markdown = markdown.replace(PARAMETERS_MARKER, parameters_markdown())
    return markdown
