"""Progress counts whole runs done, as their batches come back (what an interrupt keeps: a batch running is
lost), never fractions of a batch's ticks, and changes no number; a job of stages (validate) reports one
count over all its stages with the stage named, so that its ETA is the whole job's."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from test_validate import QUICK

from twin.app.commands.common import progress_bar as _progress_bar
from twin.app.fanout import Runs, Stages, run_starts
from twin.app.montecarlo import MonteCarloSettings, load_spread, run_montecarlo
from twin.app.sweep import point_seeds
from twin.app.validate import validate
from twin.parameters import Parameters

SPREAD = Path(__file__).resolve().parent.parent / "docs" / "examples" / "spread.toml"
# Two seconds of each run.
RUNS = Runs("appendix-sf", Parameters(), 2.0, True, "twin", False)


def _recorder() -> tuple[list[tuple[int, int, str]], object]:
    calls: list[tuple[int, int, str]] = []

    def progress(done: int, total: int, stage: str = "") -> None:
        calls.append((done, total, stage))

    return calls, progress


def test_progress_counts_the_runs_of_each_batch_as_it_comes_back() -> None:
    """64 runs in two batches of 32: the count is 0, 32, 64 (nothing in between: no run of a batch is done
    before the batch is), and the records equal those of the same job without progress."""
    n = 64
    starts = np.column_stack([np.linspace(-0.2, 0.2, n), np.zeros(n)])
    seeds = point_seeds(3, n)
    calls, progress = _recorder()
    records, complete = run_starts(RUNS, starts, seeds, progress=progress)  # type: ignore[arg-type]
    plain, _ = run_starts(RUNS, starts, seeds)
    assert complete and records == plain
    assert calls == [(0, n, ""), (32, n, ""), (n, n, "")]


def test_a_monte_carlo_counts_whole_runs() -> None:
    """``montecarlo --n 64``: two batches of 32; the bar showed fractions of ticks over one batch of all."""
    calls, progress = _recorder()
    settings = MonteCarloSettings("appendix-sf", 64, -0.2, 0.3, duration_s=1.0, seed=0)
    result = run_montecarlo(settings, Parameters(), load_spread(SPREAD, Parameters()), progress=progress)  # type: ignore[arg-type]
    assert result.complete
    assert [d for d, _, _ in calls] == [0, 32, 64]


def test_a_robust_map_counts_whole_runs() -> None:
    """A brute-force robust map is one job of every start on every rig (12 runs, one batch): its count is
    whole runs, never goes back, and changes no number."""
    from twin.app.robust import run_robust
    from twin.app.sweep import Grid, SweepSettings

    settings = SweepSettings("appendix-sf", Grid(-0.2, 0.2, 3), Grid(0.0, 0.3, 2), duration_s=1.0)
    spread = load_spread(SPREAD, Parameters())
    calls, progress = _recorder()
    result = run_robust(settings, Parameters(), spread, 2, progress=progress)  # type: ignore[arg-type]
    assert result.to_json() | {"wall_s": 0} == run_robust(settings, Parameters(), spread, 2).to_json() | {
        "wall_s": 0
    }
    done = [d for d, _, _ in calls]
    assert done == sorted(done) and done[-1] == 12 and all(total == 12 for _, total, _ in calls)
    assert set(done) == {0, 12}


@pytest.mark.quick
def test_stages_count_over_the_whole_job() -> None:
    calls, progress = _recorder()
    stages = Stages(progress, {"nominal": 4, "region": 9, "monte carlo": 0})  # type: ignore[arg-type]
    first, second = stages.stage("nominal"), stages.stage("region")
    assert first is not None and second is not None
    first(0, 4)
    first(4, 4)
    second(0, 11)  # the region's corner states: 11 runs, not the 9 planned
    second(11, 11)
    assert calls == [
        (0, 13, "nominal (stage 1 of 3)"),
        (4, 13, "nominal (stage 1 of 3)"),
        (4, 15, "region (stage 2 of 3)"),
        (15, 15, "region (stage 2 of 3)"),
    ]
    assert Stages(None, {"nominal": 1}).stage("nominal") is None


def test_validate_names_its_stages_and_counts_all_their_runs() -> None:
    c = dataclasses.replace(
        QUICK,
        duration_s=1.0,
        region_duration_s=1.0,
        montecarlo_runs=3,
        robust_rigs=3,
        min_success_lower_bound=0.25,
    )
    calls, progress = _recorder()
    report = validate(
        "appendix-sf", Parameters(), c, spread=load_spread(SPREAD, Parameters()), progress=progress
    )  # type: ignore[arg-type]
    assert report.complete
    labels = list(dict.fromkeys(stage for _, _, stage in calls))
    assert labels == [
        "nominal (stage 1 of 5)",
        "region (stage 2 of 5)",
        "sensitivity (stage 3 of 5)",
        "robust region (stage 4 of 5)",
        "monte carlo (stage 5 of 5)",
    ]
    done = [d for d, _, _ in calls]
    assert done == sorted(done)
    assert report.region is not None
    rows = {check.name: len(check.rows) for check in report.checks}
    sensitivity = sum(n for name, n in rows.items() if name.startswith("sensitivity"))
    robust = 3 * rows["robust region"]  # every required start (all 9 of QUICK's grid) on 3 rigs
    runs = rows["nominal"] + len(report.region.points) + len(report.region.corners) + sensitivity + robust + 3
    assert all(total == runs for _, total, stage in calls if not stage.startswith(("nominal", "region")))
    assert done[-1] == runs  # the count ends at every run of every stage


@pytest.mark.quick
def test_the_bar_shows_the_stage_and_one_total(capsys: pytest.CaptureFixture[str]) -> None:
    update = _progress_bar("validate")
    for done, total, stage in [
        (0, 10, "nominal (stage 1 of 2)"),
        (4, 10, "nominal (stage 1 of 2)"),
        (4, 12, "region (stage 2 of 2)"),
        (12, 12, "region (stage 2 of 2)"),
    ]:
        update(done, total, stage)
    err = capsys.readouterr().err
    assert "validate: nominal (stage 1 of 2)" in err and "validate: region (stage 2 of 2)" in err
    assert "12/12" in err and err.count(" 0/") == 1  # one bar for the whole job, drawn full at its end
