"""The reproduction: every claim evaluated once, written as JSON, Markdown and figures."""

from __future__ import annotations

import json
from pathlib import Path

from twin.app.reproduction import closed_loop, numbers
from twin.app.reproduction.claims import Claim, Entry, evaluate
from twin.app.reproduction.figures import write_figures
from twin.app.reproduction.markdown import render
from twin.app.reproduction.models import Model
from twin.parameters import Parameters

__all__ = ["all_claims", "collect", "write_report"]


def all_claims() -> tuple[Claim, ...]:
    return (*numbers.CLAIMS, *closed_loop.CLAIMS)


def collect(params: Parameters | None = None, claims: tuple[Claim, ...] | None = None) -> list[Entry]:
    model = Model(params)
    return [evaluate(c, model) for c in (all_claims() if claims is None else claims)]


def write_report(out_dir: Path, figures: bool = True) -> list[Entry]:
    out_dir.mkdir(parents=True, exist_ok=True)
    entries = collect()
    pngs = write_figures(closed_loop.CLAIMS, out_dir) if figures else []
    (out_dir / "reproduction.json").write_text(
        json.dumps([e.as_dict() for e in entries], indent=1, ensure_ascii=False) + "\n", encoding="utf-8"
    )
    (out_dir / "reproduction.md").write_text(render(entries, pngs), encoding="utf-8")
    return entries
