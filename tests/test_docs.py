"""The generated docs are what the code computes now: rows of the committed JSON are recomputed (a sample
of the long runs, every summary in full). Regenerate with ``python scripts/regenerate_docs.py``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from controllers import registry
from twin.app.sweep import CLAIMS, Grid, SweepResult, SweepSettings, _judge, summarize
from twin.parameters import Parameters
from twin.rigs.batch import run_batch
from twin.rigs.sim import run_closed_loop

DOCS = Path(__file__).resolve().parent.parent / "docs"
MAPS = ("appendix-sf", "appendix-clp")


def _sweep(name: str) -> dict:
    return json.loads((DOCS / "validation" / name / "sweep.json").read_text())


def _result(data: dict) -> SweepResult:
    s = data["settings"]
    settings = SweepSettings(
        **{**s, "x0": Grid(**s["x0"]), "theta0": Grid(**s["theta0"])}  # type: ignore[arg-type]
    )
    return SweepResult(settings, data["points"], data["complete"], data["corners"])


@pytest.mark.parametrize("name", MAPS)
def test_the_maps_summaries_and_claims_follow_from_their_points(name: str) -> None:
    data = _sweep(name)
    assert data["complete"] and data["settings"]["controller"] == name
    assert data["summary"] == summarize(data["points"])
    result = _result(data)
    judged = [_judge(c, result, Parameters()) for c in CLAIMS if name in c.applies_to]
    assert json.loads(json.dumps(judged)) == data["claims"]


@pytest.mark.quick
def test_the_claims_summary_follows_from_both_maps() -> None:
    sf, clp = (_sweep(name)["points"] for name in MAPS)
    claims = json.loads((DOCS / "validation" / "claims.json").read_text())
    kept = {name: sum(not p["ball_lost"] for p in pts) for name, pts in zip(MAPS, (sf, clp), strict=True)}
    assert claims["kept"] == kept
    assert claims["only_clp"] == sum(
        a["ball_lost"] and not b["ball_lost"] for a, b in zip(sf, clp, strict=True)
    )
    assert claims["clp_larger"] == (kept["appendix-clp"] > kept["appendix-sf"])


@pytest.mark.slow
@pytest.mark.parametrize("name", MAPS)
def test_a_sample_of_each_map_is_what_the_engine_computes_now(name: str) -> None:
    data = _sweep(name)
    s = data["settings"]
    points = data["points"][:: len(data["points"]) // 12][:12]
    results = run_batch(
        registry,
        name,
        x0_m=np.array([p["x0_m"] for p in points]),
        theta0_rad=np.array([p["theta0_rad"] for p in points]),
        seeds=np.array([p["seed"] for p in points], dtype=np.int64),
        duration_s=s["duration_s"],
        noise=s["noise"],
        plant=s["plant"],
        ideal_sensors=s["ideal_sensors"],
    )
    for point, result in zip(points, results, strict=True):
        assert {k: point[k] for k in result.verdict.to_json()} == result.verdict.to_json(), point


@pytest.mark.slow
def test_a_sample_of_the_controller_report_is_what_the_engine_computes_now() -> None:
    rows = json.loads((DOCS / "controllers" / "controllers.json").read_text())
    names = list(dict.fromkeys(r["controller"] for r in rows))
    assert names == list(registry.NAMES)
    per = len(rows) // len(names)
    for i, name in enumerate(names):
        row = rows[i * per + i % per]  # a different start for each controller
        result = run_closed_loop(
            registry.make(name),
            x0_m=row["x0_m"],
            theta0_rad=row["theta0_rad"],
            duration_s=15.0,
            seed=row["seed"],
        )
        assert {k: row[k] for k in result.verdict.to_json()} == result.verdict.to_json(), (name, row)
