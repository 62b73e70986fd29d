"""The reproduction's report files: JSON entries with the agreed fields and the Markdown (number claims only)."""

from __future__ import annotations

import json
from pathlib import Path

from twin.app.reproduction import numbers
from twin.app.reproduction.markdown import render
from twin.app.reproduction.report import collect

FIELDS = {
    "id",
    "where",
    "quantity",
    "thesis",
    "recomputed",
    "rel_error",
    "verdict",
    "check",
    "findings",
    "unexplained",
    "explanation",
}


def test_entries_and_markdown(tmp_path: Path) -> None:
    entries = collect(claims=numbers.CLAIMS)
    rows = json.loads(json.dumps([e.as_dict() for e in entries]))
    assert len(rows) == len(numbers.CLAIMS) and all(set(r) == FIELDS for r in rows)
    png = tmp_path / "fig_4_4.png"
    md = render(entries, [png])
    for e in entries:
        assert f"| {e.id} |" in md
    found = {e.verdict for e in entries}
    for verdict in found:
        assert f"{sum(e.verdict == verdict for e in entries)} {verdict}" in md.splitlines()[2]
    assert "![fig_4_4](fig_4_4.png)" in md
