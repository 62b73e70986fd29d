"""The report's Markdown, rendered from evaluated entries (no evaluation here)."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

from twin.app.reproduction.claims import SEVERITY, UNEXPLAINED, VERDICTS, Entry

__all__ = ["render"]


def _cell(value: object, limit: int = 160) -> str:
    text = value if isinstance(value, str) else json.dumps(value, ensure_ascii=False)
    text = text.replace("|", "\\|").replace("\n", " ")
    return text if len(text) <= limit else text[: limit - 1] + "…"


def render(entries: list[Entry], pngs: list[Path]) -> str:
    counts = Counter(e.verdict for e in entries)
    lines = [
        "# Reproduction of the thesis's numbers",
        "",
        f"{len(entries)} claims: " + ", ".join(f"{counts[v]} {v}" for v in VERDICTS if counts[v]) + ".",
        "",
        "Each claim is recomputed from the project's models and checked; its verdict follows from the check and "
        "from diagnostic hypotheses that are themselves recomputed (`twin/app/reproduction/claims.py`).",
        "",
    ]
    lines += [f"- *{v}*: {meaning}" for v, (_, meaning) in VERDICTS.items()]
    lines.append("")
    for verdict in (*SEVERITY, UNEXPLAINED):
        chosen = [e for e in entries if e.verdict == verdict]
        if chosen:
            lines += [f"## {VERDICTS[verdict][0]}", ""]
            lines += [f"- **{e.id}** ({e.quantity}): {e.explanation}" for e in chosen]
            lines.append("")
    lines += [
        "## All claims",
        "",
        "| id | quantity | thesis | recomputed | rel. error | check | verdict |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for e in entries:
        d = e.as_dict()
        rel = "—" if d["rel_error"] is None else f"{d['rel_error']:.3g}"
        lines.append(
            f"| {e.id} | {_cell(e.quantity)} | {_cell(d['thesis'])} | {_cell(d['recomputed'])} | {rel} | "
            f"{_cell(e.check)} | {e.verdict} |"
        )
    if pngs:
        lines += [
            "",
            "## Figures",
            "",
            "Each figure shows the thesis's model (as the thesis simulated it) and "
            "the twin; its title is the thesis's caption.",
            "",
        ]
        lines += [f"![{p.stem}]({p.name})" for p in pngs]
    return "\n".join(lines) + "\n"
