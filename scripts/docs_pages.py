"""The manual's measured tables rendered from the committed JSON, between their ``<!-- marker -->`` and
``<!-- /marker -->`` lines on the pages under docs/validation/ (no figure of a JSON file is typed by hand).

The measuring scripts write the JSON and the table together (``scripts/screen_agreement.py --write-docs``,
``scripts/bench.py --only-falsify --write-docs``, ``scripts/firmware_forms.py``); this renders every table again
from the JSON alone, and ``--check`` says which page is stale (exit 1) without writing: tests/test_docs_site.py
runs it. The reference pages (parameters, commands) are generated when the site is built (docs/hooks.py).

python scripts/docs_pages.py [--check]
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
VALIDATION = REPO / "docs" / "validation"


@dataclass(frozen=True)
class Table:
    """A table of a page: its marker, the JSON it is rendered from, and the renderer."""

    page: Path
    marker: str
    data: Path
    render: Callable[[Any], str]


def tables() -> list[Table]:
    from twin.app.falsify_render import render_table
    from twin.app.firmware_forms import render as render_forms
    from twin.app.screening import render_agreement

    return [
        Table(
            VALIDATION / "engines.md", "screen-table", VALIDATION / "screen_agreement.json", render_agreement
        ),
        Table(VALIDATION / "engines.md", "falsify-table", VALIDATION / "falsify_bench.json", render_table),
        Table(
            VALIDATION / "firmware.md",
            "firmware-forms",
            REPO / "docs" / "firmware" / "forms.json",
            render_forms,
        ),
    ]


def with_table(text: str, marker: str, table: str, page: Path) -> str:
    """``text`` with the block between the marker's two lines replaced by ``table``."""
    begin, end = f"<!-- {marker} -->\n", f"<!-- /{marker} -->"
    head, found, rest = text.partition(begin)
    if not found or end not in rest:
        raise ValueError(f"{page}: no {begin.strip()} … {end} markers to write the table between")
    _, _, tail = rest.partition(end)
    return head + begin + table + end + tail


def rendered() -> dict[Path, str]:
    """Each page's text with every one of its tables rendered from its JSON."""
    pages: dict[Path, str] = {}
    for table in tables():
        text = pages.get(table.page) or table.page.read_text(encoding="utf-8")
        data = json.loads(table.data.read_text(encoding="utf-8"))
        pages[table.page] = with_table(text, table.marker, table.render(data), table.page)
    return pages


def stale() -> list[Path]:
    """The pages whose tables are not their JSON rendered."""
    return [page for page, text in rendered().items() if page.read_text(encoding="utf-8") != text]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="exit 1 naming each stale page; write nothing")
    args = parser.parse_args()
    if args.check:
        old = stale()
        for page in old:
            print(
                f"{page.relative_to(REPO)}: a table is not its JSON rendered (python scripts/docs_pages.py)"
            )
        return 1 if old else 0
    from twin.outputs import write_atomic

    for page, text in rendered().items():
        write_atomic(page, text, overwrite=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
