"""Assemble the reproduction: the numbers of chapters 3–5 and the closed-loop figures of chapters 4, 5, 7."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

from controllers.reproduction import Entry

__all__ = ["collect", "write_report"]


def collect(out_dir: Path, quick: bool = False) -> list[Entry]:
    from controllers.reproduction import figures, numbers

    return list(numbers.entries()) + list(figures.entries(out_dir, quick=quick))


def _cell(value: object, limit: int = 160) -> str:
    text = json.dumps(value) if not isinstance(value, str) else value
    text = text.replace("|", "\\|").replace("\n", " ")
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _markdown(entries: list[Entry], out_dir: Path) -> str:
    counts = Counter(e.verdict for e in entries)
    lines = [
        "# Reproduction of the thesis's numbers",
        "",
        f"{len(entries)} entries: " + ", ".join(f"{n} {v}" for v, n in sorted(counts.items())) + ".",
        "",
        "Verdicts: *agrees* (within 1 % or the printed rounding), *misprint* (a typo; the thesis elsewhere uses "
        "the right value), *inconsistent* (does not follow from the thesis's own model; cause given), *fails* "
        "(a printed design that does not do what the thesis says), *holds* (a claim confirmed), *unexplained*.",
        "",
    ]
    for verdict, heading in (
        ("misprint", "Misprints"),
        ("inconsistent", "Inconsistencies"),
        ("fails", "Printed designs and claims that fail"),
        ("unexplained", "Unexplained"),
    ):
        chosen = [e for e in entries if e.verdict == verdict]
        if chosen:
            lines += [f"## {heading}", ""]
            lines += [f"- **{e.id}** ({e.quantity}): {e.explanation}" for e in chosen]
            lines.append("")
    lines += [
        "## All entries",
        "",
        "| id | quantity | thesis | recomputed | rel. error | verdict | explanation |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for e in entries:
        d = e.as_dict()
        rel = "—" if d["rel_error"] is None else f"{d['rel_error']:.3g}"
        lines.append(
            f"| {e.id} | {_cell(e.quantity)} | {_cell(d['thesis'])} | {_cell(d['recomputed'])} | {rel} | "
            f"{e.verdict} | {_cell(e.explanation, 400)} |"
        )
    pngs = sorted(out_dir.glob("*.png"))
    if pngs:
        lines += [
            "",
            "## Figures",
            "",
            "Each figure shows the thesis's model (as the thesis simulated it) and the "
            "twin; its title is the thesis's caption.",
            "",
        ]
        lines += [f"![{p.stem}]({p.name})" for p in pngs]
    return "\n".join(lines) + "\n"


def write_report(out_dir: Path, quick: bool = False) -> list[Entry]:
    out_dir.mkdir(parents=True, exist_ok=True)
    entries = collect(out_dir, quick=quick)
    (out_dir / "reproduction.json").write_text(json.dumps([e.as_dict() for e in entries], indent=1) + "\n")
    (out_dir / "reproduction.md").write_text(_markdown(entries, out_dir))
    return entries
