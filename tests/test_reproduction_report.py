"""The reproduction report's files: JSON entries with the agreed fields, the Markdown table and summary."""

import json

from controllers.reproduction import Entry, figures, report


def test_report_writes_json_and_markdown(tmp_path, monkeypatch) -> None:
    # The figures are exercised in test_reproduction_figures.py; here one stands in for them.
    fake = Entry("Fig 4.4", "SF continuous from (0.2, 0.3)", "2.5–3 s", {"twin": 2.44}, None, "agrees", "ok")
    monkeypatch.setattr(figures, "entries", lambda out_dir, quick=False: [fake])
    (tmp_path / "fig_4_4.png").write_bytes(b"\x89PNG")
    entries = report.write_report(tmp_path, quick=True)
    rows = json.loads((tmp_path / "reproduction.json").read_text())
    assert len(rows) == len(entries) >= 60
    for row in rows:
        assert set(row) == {"id", "quantity", "thesis", "recomputed", "rel_error", "verdict", "explanation"}
    ids = {row["id"] for row in rows}
    for needed in ("Table 3.1 r*", "eq 3.2.8 A", "eq 3.4.8 Φ", "§4.2 K", "§5.2.1 G", "Fig 4.4"):
        assert needed in ids
    md = (tmp_path / "reproduction.md").read_text()
    assert "## Misprints" in md and "## Inconsistencies" in md and "| Table 3.1 r* |" in md
    assert "![fig_4_4](fig_4_4.png)" in md
