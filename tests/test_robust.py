"""The robust region of attraction: every start on the same N drawn rigs, counted against single runs, its
exact bound, refinement per rig equal to brute force, the cluster equal to here, and clear refusals."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest
from cli_checks import refused

from controllers import registry
from twin.app.montecarlo import load_spread, sample_parameters
from twin.app.robust import lower_bound, refinement_costs, rig_point_seeds, run_robust
from twin.app.sweep import Grid, SweepSettings
from twin.parameters import Parameters
from twin.rigs.sim import run_closed_loop

ROOT = Path(__file__).resolve().parents[1]
SPREAD = ROOT / "docs" / "examples" / "spread.toml"
SMALL = SweepSettings("appendix-sf", Grid(-0.3, 0.3, 3), Grid(-0.6, 0.6, 3), duration_s=2.0, seed=4)


def test_every_count_is_the_single_runs_of_the_drawn_rigs() -> None:
    base = Parameters()
    spread = load_spread(SPREAD, base)
    result = run_robust(SMALL, base, spread, 3, nthread=2)
    rigs, _ = sample_parameters(base, spread, 3, SMALL.seed)  # the same rigs montecarlo would draw
    assert result.complete and len(result.rig_values) == 3
    assert result.rig_values[1]["motor.resistance_ohm"] == rigs[1].motor.resistance_ohm
    for k, point in enumerate(result.points):
        held = lost = 0
        for m, params in enumerate(rigs):
            verdict = run_closed_loop(
                registry.make("appendix-sf", params),
                x0_m=point["x0_m"],
                theta0_rad=point["theta0_rad"],
                duration_s=SMALL.duration_s,
                seed=int(rig_point_seeds(SMALL.seed, m, len(result.points))[k]),
                params=params,
            ).verdict
            held += verdict.held
            lost += verdict.ball_lost
        assert (point["held"], point["lost"], point["rigs"]) == (held, lost, 3)
        assert point["lower_bound"] == pytest.approx(lower_bound(held, 3, 0.95), abs=1e-6)


@pytest.mark.quick
def test_the_bound_is_clopper_pearsons() -> None:
    # k = n: the bound solves p^n = 1 − confidence; k = 0: 0; and it rises with k.
    assert lower_bound(59, 59, 0.95) == pytest.approx(0.05 ** (1 / 59))
    assert lower_bound(59, 59, 0.95) >= 0.95 > lower_bound(58, 58, 0.95)
    assert lower_bound(0, 10, 0.95) == 0.0
    assert lower_bound(5, 10, 0.95) < lower_bound(6, 10, 0.95) < 0.6


def test_a_refined_robust_map_is_the_brute_force_one() -> None:
    base = Parameters()
    spread = load_spread(SPREAD, base)
    settings = SweepSettings("appendix-sf", Grid(-0.32, 0.32, 9), Grid(-0.7, 0.7, 9), duration_s=5.0)
    brute = run_robust(settings, base, spread, 3, nthread=2)
    refined = run_robust(replace(settings, refine=4), base, spread, 3, nthread=2)
    assert [(p["held"], p["lost"]) for p in refined.points] == [(p["held"], p["lost"]) for p in brute.points]
    assert refined.refinement is not None and refined.runs < brute.runs == 3 * 81


@pytest.mark.slow
def test_a_dask_cluster_gives_the_local_robust_map() -> None:
    distributed = pytest.importorskip("distributed")
    base = Parameters()
    spread = load_spread(SPREAD, base)
    local = run_robust(SMALL, base, spread, 4).to_json()
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        remote = run_robust(SMALL, base, spread, 4, scheduler=cluster.scheduler_address).to_json()
    for doc in (local, remote):
        doc.pop("wall_s")
    assert remote == local


def test_the_command_writes_the_map_and_refuses_half_a_request(tmp_path: Path, capsys) -> None:
    from twin.app.cli import main

    out = tmp_path / "r"
    argv = [
        "sweep",
        "--controller",
        "appendix-sf",
        "--x0=-0.2:0.2:2",
        "--theta0=-0.2:0.2:2",
        "--duration",
        "1",
    ]
    assert main([*argv, "--spread", str(SPREAD), "--rigs", "2", "--out", str(out)]) == 0
    doc = json.loads((out / "robust.json").read_text())
    assert doc["rigs"] == 2 and len(doc["points"]) == 4 and (out / "robust.png").stat().st_size > 0
    assert doc["summary"]["nominal_held"] is not None
    capsys.readouterr()
    refused(capsys, [*argv, "--rigs", "3"], "--rigs N and one of --spread FILE or --calibration DIR")
    refused(capsys, [*argv, "--spread", str(SPREAD)], "--rigs N")
    refused(capsys, [*argv, "--spread", "no/such.toml", "--rigs", "2"], "no/such.toml")


def _ellipse_maps(rigs: int, nx: int, nt: int, seed: int) -> list[str]:
    """Each rig holds an ellipse of starts, its centre and axes drawn about the map's middle."""
    import numpy as np

    rng = np.random.default_rng(seed)
    xs, ts = np.linspace(-1, 1, nx), np.linspace(-1, 1, nt)
    maps = []
    for _ in range(rigs):
        cx, ct = rng.normal(0, 0.1, 2)
        a, b = 0.7 * (1 + 0.1 * rng.standard_normal(2))
        maps.append(
            "".join("h" if ((x - cx) / a) ** 2 + ((t - ct) / b) ** 2 < 1 else "l" for x in xs for t in ts)
        )
    return maps


@pytest.mark.quick
def test_refining_each_rig_costs_less_than_refining_the_probability_contour_for_the_same_counts() -> None:
    """The design's choice, on maps alone: per rig, a cell is split only for the rigs whose corners disagree;
    on the contour (jointly, or on the held count) every rig runs every split cell's corners. Per rig is
    the cheapest of the three for identical counts; the held count can even miss a strip no corner shows."""
    costs = refinement_costs(_ellipse_maps(12, 33, 33, 0), 33, 33, 8)
    assert all(way["counts_equal"] for way in (costs["per_rig"], costs["joint"], costs["held_count"]))
    assert (
        costs["per_rig"]["runs"]
        < min(costs["joint"]["runs"], costs["held_count"]["runs"])
        < costs["brute_force"]
    )
    # Two rigs on a 9 × 3 grid, one holding columns 0–4, the other 6–8: every corner of the one coarse cell
    # counts one rig, column 5 none.
    left = "".join("h" if i <= 4 else "l" for i in range(9) for _ in range(3))
    right = "".join("h" if i >= 6 else "l" for i in range(9) for _ in range(3))
    crossing = refinement_costs([left, right], 9, 3, 8)
    assert crossing["per_rig"]["counts_equal"] and crossing["joint"]["counts_equal"]
    assert not crossing["held_count"]["counts_equal"]


@pytest.mark.quick
def test_the_robust_folder_holds_the_numbers_it_was_given(tmp_path: Path) -> None:
    """``write_robust`` (the render side) writes the result's JSON as computed and a map the size of the
    figure; a folder already there is not overwritten."""
    from twin.app.robust import RobustResult
    from twin.app.robust_render import write_robust

    settings = SweepSettings("appendix-sf", x0=Grid(-0.1, 0.1, 2), theta0=Grid(-0.2, 0.2, 2), duration_s=1.0)
    points = [
        {"x0_m": x, "theta0_rad": th, "held": h, "lost": 3 - h, "rigs": 3, "rate": h / 3, "robust": h == 3}
        for (x, th), h in zip(settings.starts().tolist(), (3, 2, 0, 3), strict=True)
    ]
    summary = {"held_by_every_rig": 2, "starts": 4, "robust": 2}
    result = RobustResult(settings, 3, 0.95, 0.95, "test", [], ["HHLH"] * 3, points, True, summary=summary)
    out = write_robust(result, tmp_path / "robust")
    written = json.loads((out / "robust.json").read_text())
    assert [p["held"] for p in written["points"]] == [3, 2, 0, 3] and written["rigs"] == 3
    assert written["summary"] == summary
    assert (out / "robust.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(Exception, match="robust"):
        write_robust(result, out)
