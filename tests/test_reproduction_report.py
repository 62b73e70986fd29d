"""The reproduction's report files: JSON entries with the agreed fields and the Markdown (number claims only)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

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


@pytest.mark.quick
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


@pytest.mark.quick
def test_every_figure_has_a_caption_and_its_own_file_name() -> None:
    from twin.app.reproduction.figures import CAPTIONS, png_name

    assert png_name("Fig 6.16") == "fig_6_16.png"
    names = [png_name(fig_id) for fig_id in CAPTIONS]
    assert len(set(names)) == len(names) and all(CAPTIONS.values())


@pytest.mark.quick
def test_the_chapter_4_state_feedback_is_a_stable_loop_on_the_thesis_model() -> None:
    from twin.app.reproduction.scenarios import closed_loop_eigenvalues, thesis_params

    eigenvalues = closed_loop_eigenvalues("thesis-sf-continuous")
    assert eigenvalues.shape == (4,) and max(eigenvalues.real) < 0.0
    assert thesis_params(zeroing_error_rad=0.01).angle_sensor.zeroing_error_rad == 0.01
    assert thesis_params(continuous=True).daq.period_s < thesis_params().daq.period_s
