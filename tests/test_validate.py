"""``ballbeam validate``: every check is computed from runs that equal their single runs, the criteria are
data that a file can change, and the exit code is the verdict."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from controllers import registry
from controllers import thesis_numbers as T
from twin.app.cli import main
from twin.app.sweep import point_seeds
from twin.app.validate import ValidationCriteria, load_criteria, validate
from twin.parameters import ParameterError, Parameters
from twin.rigs.sim import run_closed_loop

QUICK = ValidationCriteria(
    nominal_seeds=1,
    duration_s=4.0,
    region_x0=(-0.2, 0.2, 3),
    region_theta0=(-0.3, 0.3, 3),
    region_duration_s=4.0,
    zeroing_counts=1,
    latencies_s=(0.0,),
    free_runs_s=(0.04,),
)
QUICK_TOML = """
nominal_seeds = 1
duration_s = 4.0
region_x0 = [-0.2, 0.2, 3]
region_theta0 = [-0.3, 0.3, 3]
region_duration_s = 4.0
zeroing_counts = 1
latencies_s = [0.0]
free_runs_s = [0.04]
"""


@pytest.mark.slow
def test_the_checks_come_from_the_runs() -> None:
    report = validate("appendix-clp", Parameters(), QUICK)
    names = [c.name for c in report.checks]
    assert names[:3] == ["nominal", "saturation", "region"] and "monte carlo" in names
    nominal = report.checks[0]
    starts = [*T.CHAPTER4_STARTS, *T.HARDWARE_STARTS.values()]
    assert len(nominal.rows) == len(starts)
    seeds = point_seeds(0, len(starts))
    for row, (x, th), seed in zip(nominal.rows, starts, seeds, strict=True):
        single = run_closed_loop(
            registry.make("appendix-clp"), x0_m=x, theta0_rad=th, duration_s=4.0, seed=int(seed)
        )
        assert row["held"] == single.verdict.held and row["seed"] == seed
    held = sum(r["held"] for r in nominal.rows)
    assert nominal.passed == (held == len(starts)) and nominal.measured == f"held {held} of {len(starts)}"
    worst = max(r["saturated_fraction"] for r in nominal.rows)
    assert report.checks[1].passed == (worst <= 0.2)
    # No spread: the robust region and Monte Carlo are not run, and they do not fail the report.
    assert [c.passed for c in report.checks[-2:]] == [None, None]
    assert [c.name for c in report.checks[-2:]] == ["robust region", "monte carlo"]
    assert report.passed == all(c.passed is not False for c in report.checks)


@pytest.mark.slow
def test_the_robust_region_is_each_required_start_on_the_spreads_rigs() -> None:
    """With a spread: every required start of the region grid on the same rigs (twin.app.robust's draw and
    seeds); each start's count of rigs keeping the ball equals single runs on those rigs, and its bound is
    the exact binomial interval's low end, as Monte Carlo's."""
    import scipy.stats

    from twin.app.montecarlo import load_spread, sample_parameters
    from twin.app.robust import rig_point_seeds

    base = Parameters()
    spread = load_spread(Path(__file__).parents[1] / "docs" / "examples" / "spread.toml", base)
    criteria = replace(
        QUICK,
        region_x0=(-0.3, 0.3, 4),  # ±0.3, ±0.1: the required box (±0.2) holds the inner two
        region_theta0=(-0.7, 0.7, 3),
        robust_rigs=6,
        montecarlo_runs=6,
        min_success_lower_bound=0.5,
    )
    report = validate("appendix-sf", base, criteria, spread=spread)
    check = next(c for c in report.checks if c.name == "robust region")
    rows = sorted(check.rows, key=lambda r: (r["x0_m"], r["theta0_rad"]))
    assert [(round(r["x0_m"], 6), r["theta0_rad"]) for r in rows] == [(-0.1, 0.0), (0.1, 0.0)]
    rigs, _ = sample_parameters(base, spread, 6, 0)
    for k, row in enumerate(rows):  # the grid's order: x0 by x0, θ0 within
        kept = 0
        for m, rig in enumerate(rigs):
            seed = int(rig_point_seeds(0, m, len(rows))[k])
            single = run_closed_loop(
                registry.make("appendix-sf", rig),
                x0_m=row["x0_m"],
                theta0_rad=0.0,
                duration_s=4.0,
                seed=seed,
                params=rig,
            )
            kept += not single.verdict.ball_lost
        low = scipy.stats.binomtest(kept, 6).proportion_ci(0.95, method="exact").low
        assert row["kept"] == kept and row["kept_lower_bound"] == pytest.approx(low, abs=1e-6)
    assert check.passed == all(r["kept_lower_bound"] >= 0.5 for r in rows)


@pytest.mark.quick
def test_criteria_files(tmp_path: Path) -> None:
    path = tmp_path / "criteria.toml"
    path.write_text(QUICK_TOML)
    assert load_criteria(path) == QUICK
    for text, message in [
        ("nominal_seed = 1\n", "unknown criterion 'nominal_seed'"),
        ("nominal_seeds = 1.5\n", "must be a int"),
        ("latencies_s = 3\n", "must be a list of numbers"),
        ("duration_s = 'long'\n", "must be a float"),
    ]:
        path.write_text(text)
        with pytest.raises(ParameterError, match=message):
            load_criteria(path)


@pytest.mark.slow
def test_the_exit_code_is_the_verdict(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    criteria = tmp_path / "criteria.toml"
    criteria.write_text(QUICK_TOML + "max_saturated_fraction = 0.0\n")  # no tick at the rails allowed
    out = tmp_path / "report"
    code = main(
        ["validate", "--controller", "appendix-sf", "--criteria", str(criteria), "--out", str(out), "--json"]
    )
    data = json.loads(capsys.readouterr().out)
    saturation = next(c for c in data["checks"] if c["name"] == "saturation")
    assert code == (0 if data["passed"] else 1)
    assert saturation["passed"] == (saturation["measured"] == "at most 0.0 %")
    assert (out / "report.md").read_text().startswith("# Validation of `appendix-sf`")
    assert json.loads((out / "validation.json").read_text()) == data


def test_ctrl_c_keeps_the_checks_done(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    import twin.app.fanout as fanout

    criteria = tmp_path / "criteria.toml"
    criteria.write_text(QUICK_TOML)
    real, calls = fanout.run_chunk, []

    def interrupted(chunk):
        calls.append(chunk)
        if len(calls) == 2:  # the nominal runs are done; Ctrl-C during the region
            raise KeyboardInterrupt
        return real(chunk)

    monkeypatch.setattr(fanout, "run_chunk", interrupted)
    out = tmp_path / "report"
    code = main(["validate", "--controller", "appendix-sf", "--criteria", str(criteria), "--out", str(out)])
    assert code == 130 and "interrupted" in capsys.readouterr().err
    data = json.loads((out / "validation.json").read_text())
    assert not data["complete"] and not data["passed"]
    # The stage interrupted is reported, not judged, with the runs it finished (none here: its one batch).
    assert [c["name"] for c in data["checks"]] == ["nominal", "saturation", "region"]
    region = data["checks"][2]
    assert region["passed"] is None and region["measured"].startswith("interrupted after 0 of ")
    assert "interrupted" in (out / "report.md").read_text()


@pytest.mark.quick
def test_the_progress_bar_restarts_for_each_stage(capsys: pytest.CaptureFixture[str]) -> None:
    from twin.app.commands.common import progress_bar as _progress_bar

    update = _progress_bar("validate")
    for done, total in [(0, 3), (2, 3), (3, 3), (0, 5), (5, 5), (0, 5), (4, 5)]:
        update(done, total)
    err = capsys.readouterr().err
    assert "3/3" in err and "5/5" in err  # each finished stage's bar is drawn full
    assert err.count(" 0/3 ") == 1 and err.count(" 0/5 ") == 2  # a new bar for each stage, from zero


@pytest.mark.quick
def test_the_report_file_is_the_rendering_of_the_checks_done(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    """An interrupted validation (Ctrl-C after the nominal runs): report.md is ``render_markdown`` of the
    report the job kept, a row per check done with its result, and says it was interrupted."""
    import twin.app.fanout as fanout
    import twin.app.validate_render as validate_render

    real_chunk, calls = fanout.run_chunk, []

    def interrupted(chunk):
        calls.append(chunk)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real_chunk(chunk)

    rendered = []
    real_render = validate_render.render_markdown

    def spy(report):
        rendered.append((report, real_render(report)))
        return rendered[-1][1]

    monkeypatch.setattr(fanout, "run_chunk", interrupted)
    monkeypatch.setattr(validate_render, "render_markdown", spy)
    criteria = tmp_path / "criteria.toml"
    criteria.write_text(QUICK_TOML)
    out = tmp_path / "report"
    assert (
        main(["validate", "--controller", "appendix-sf", "--criteria", str(criteria), "--out", str(out)])
        == 130
    )
    capsys.readouterr()
    ((report, text),) = rendered
    assert (out / "report.md").read_text() == text
    assert not report.complete and "**interrupted**" in text and "**Verdict: FAIL**" in text
    rows = [line for line in text.splitlines() if line.startswith("| ") and not line.startswith("| check")]
    for check in report.checks:
        mark = {True: "pass", False: "**FAIL**", None: "not run"}[check.passed]
        assert any(line.startswith(f"| {check.name} | {mark} |") for line in rows), check.name
    nominal = next(c for c in report.checks if c.name == "nominal")
    runs = [line for line in rows if line.startswith(("| +", "| -")) and not line.startswith("| --")]
    assert len(runs) == len(nominal.rows) == 6  # the thesis's six starts, one seed
