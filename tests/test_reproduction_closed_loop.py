"""The closed-loop claims of the reproduction (twin/app/reproduction/closed_loop.py), one test id per claim.

Slow: each claim runs its declared scenarios (cached across the claims of this process). The verdict must be
the one the committed docs/reproduction/reproduction.json holds (else the docs are stale) and follow from the
claim's own check on the runs' verdicts.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from twin.app.reproduction import closed_loop
from twin.app.reproduction.claims import VERDICTS, Claim, evaluate
from twin.app.reproduction.figures import png_name, write_figures
from twin.app.reproduction.markdown import render
from twin.app.reproduction.scenarios import run

ROOT = Path(__file__).resolve().parent.parent
COMMITTED = {
    e["id"]: e for e in json.loads((ROOT / "docs/reproduction/reproduction.json").read_text("utf-8"))
}

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("claim", closed_loop.CLAIMS, ids=lambda c: c.id)
def test_closed_loop_claim(claim: Claim) -> None:
    entry = evaluate(claim, None)
    assert entry.verdict in VERDICTS
    json.dumps(entry.as_dict())
    passed = claim.check(claim.printed, claim.recompute(None)).passed.all()
    assert passed == (entry.verdict == claim.confirmed)
    for scenario in claim.scenarios:  # every declared run is the engine's, with its verdict
        assert run(scenario).verdict.duration_s > 0
    assert COMMITTED[claim.id]["verdict"] == entry.verdict, "docs/reproduction is stale"


def test_figures_and_markdown(tmp_path: Path) -> None:
    pngs = write_figures(closed_loop.CLAIMS, tmp_path)
    assert {p.name for p in pngs} == {png_name(i) for i in closed_loop.FIGURE_SHOW}
    for p in pngs:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and p.stat().st_size > 5000
    md = render([evaluate(c, None) for c in closed_loop.CLAIMS[:3]], pngs)
    assert "![fig_4_4](fig_4_4.png)" in md
