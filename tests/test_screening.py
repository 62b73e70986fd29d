"""Screen, then confirm (twin.app.screening): the fast engine decides every start, MuJoCo every start near a class
change and an audit sample. On synthetic maps (no physics) the band follows a boundary MuJoCo moves, an island
only the audit can see is caught by it, and the result is MuJoCo's on every start MuJoCo ran; on the twin, a
screened sweep's records are brute force's wherever MuJoCo decided."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from twin.app.screening import Screening
from twin.app.sweep import Grid, SweepSettings, run_sweep, verdict_class


def _job(table: np.ndarray, calls: list[list[int]]):
    def run(requests: list[tuple[int, int]], within: Any) -> tuple[list[dict[str, Any] | None], bool]:
        calls.append([k for _, k in requests])
        return [{"c": str(table[m].flat[k])} for m, k in requests], True

    return run


def _screen(fast: np.ndarray, mujoco: np.ndarray, **kw: Any) -> tuple[Screening, list[list[int]]]:
    calls: list[list[int]] = []
    maps, nx, nt = fast.shape
    s = Screening(nx, nt, maps, _job(fast, []), _job(mujoco, calls), classify=lambda r: r["c"], **kw)
    s.run()
    return s, calls


def _half_plane(nx: int, nt: int, cut: float) -> np.ndarray:
    i, j = np.meshgrid(np.arange(nx), np.arange(nt), indexing="ij")
    return np.where(i + 0.5 * j < cut, "held", "lost")


@pytest.mark.quick
def test_the_band_follows_a_boundary_that_mujoco_moves() -> None:
    """MuJoCo's boundary sits 4 grid steps from the fast engine's: the band is taken again after each wave
    until every start within one step of MuJoCo's boundary was run on MuJoCo, and the map is MuJoCo's."""
    fast = _half_plane(30, 20, 10.0)[None]
    mujoco = _half_plane(30, 20, 14.0)[None]
    s, _ = _screen(fast, mujoco, audit=0)
    final = np.array([s.classify(s.record(0, k)) for k in range(600)]).reshape(30, 20)
    assert (final == mujoco[0]).all()
    decided = np.zeros(600, dtype=bool)
    decided[list(s.mujoco[0])] = True
    assert decided[s.near_change(final.astype(object)).ravel()].all()  # every start near a change
    assert s.stats.waves >= 4 and len(s.stats.changed) > 0
    assert all(s.record(0, k)["engine"] == ("mujoco" if decided[k] else "fast") for k in range(600))
    assert decided.sum() < 0.5 * 600  # and not the whole map


@pytest.mark.quick
def test_an_island_far_from_every_boundary_is_what_the_audit_is_for() -> None:
    fast = _half_plane(20, 20, 6.0)[None]
    mujoco = fast.copy()
    mujoco[0, 15, 15] = "kept"  # an island inside the lost region: no class change near it on the fast map
    s, _ = _screen(fast, mujoco, audit=0)
    assert not s.stats.audit_mismatches and s.classify(s.record(0, 15 * 20 + 15)) == "lost"  # missed
    s, _ = _screen(fast, mujoco, audit=400)  # every start the fast engine decided alone
    assert s.stats.audit_mismatches == [{"map": 0, "i": 15, "j": 15, "fast": "lost", "mujoco": "kept"}]


@pytest.mark.quick
def test_maps_are_screened_together_and_the_audit_is_seeded() -> None:
    fast = np.stack([_half_plane(12, 12, c) for c in (4.0, 8.0, 30.0)])  # the last: one class, no band
    s1, calls1 = _screen(fast, fast, audit=5, seed=3)
    s2, calls2 = _screen(fast, fast, audit=5, seed=3)
    assert calls1 == calls2 and s1.summary() == s2.summary()
    assert len(s1.mujoco[2]) == 5  # the map without a class change: its audit only
    assert s1.summary()["audit"] == {"checked": 15, "mismatches": []}
    with pytest.raises(ValueError, match="band"):
        Screening(3, 3, 1, _job(fast, []), _job(fast, []), band=0)


@pytest.mark.quick
def test_a_screened_sweep_is_brute_force_on_every_start_mujoco_ran() -> None:
    settings = SweepSettings(
        "appendix-sf", x0=Grid(-0.3, 0.3, 4), theta0=Grid(-0.7, 0.0, 4), duration_s=2.0, engine="screen",
        screen_audit=2,
    )  # fmt: skip
    screened = run_sweep(settings, nthread=2)
    brute = run_sweep(SweepSettings(**{**settings.__dict__, "engine": "mujoco"}), nthread=2)
    engines = [p["engine"] for p in screened.points]
    assert {"fast", "mujoco"} >= set(engines) and "mujoco" in engines
    for p, q in zip(screened.points, brute.points, strict=True):
        if p["engine"] == "mujoco":
            assert p == q
        else:
            assert verdict_class(p) == verdict_class(q)  # this small map: the fast engine agrees too
    assert screened.screening is not None and screened.screening["fast_runs"] == 16
    fast = run_sweep(SweepSettings(**{**settings.__dict__, "engine": "fast"}), nthread=2)
    assert {p["engine"] for p in fast.points} == {"fast"} and fast.screening is None


@pytest.mark.quick
def test_a_screened_robust_map_is_brute_force_on_every_run_mujoco_made() -> None:
    from twin.app.montecarlo import load_spread
    from twin.app.robust import run_robust
    from twin.parameters import Parameters

    base = Parameters()
    spread = load_spread("docs/examples/spread.toml", base)
    settings = SweepSettings(
        "appendix-sf", x0=Grid(-0.3, 0.3, 3), theta0=Grid(-0.7, 0.0, 4), duration_s=2.0, engine="screen",
        screen_audit=1,
    )  # fmt: skip
    screened = run_robust(settings, base, spread, 2, nthread=2)
    brute = run_robust(SweepSettings(**{**settings.__dict__, "engine": "mujoco"}), base, spread, 2, nthread=2)
    assert screened.screening is not None and screened.screening["fast_runs"] == 24
    assert screened.rig_classes == brute.rig_classes  # this small map: the fast engine agrees everywhere
    assert screened.points == brute.points


@pytest.mark.quick
def test_a_run_is_confirmed_when_not_held_or_held_near_a_band() -> None:
    from twin.app.screening import HELD_MARGINS, near_class_change
    from twin.verdict import Criteria

    held = {"failed": False, "ball_lost": False, "held": True, "steady_x_m": 0.002, "steady_theta_rad": 0.0,
            "limit_cycle_x_pp_m": 0.001, "limit_cycle_theta_pp_rad": 0.005}  # fmt: skip
    assert not near_class_change(held)
    assert near_class_change({**held, "held": False}) and near_class_change({**held, "ball_lost": True})
    c = Criteria()
    for metric, (band, margin) in HELD_MARGINS.items():
        inside = getattr(c, band) - margin
        assert near_class_change({**held, metric: -(inside + 1e-6)}), metric
        assert not near_class_change({**held, metric: inside - 1e-6}), metric


@pytest.mark.quick
def test_a_screened_monte_carlo_is_brute_force_on_every_run_mujoco_made() -> None:
    from twin.app.montecarlo import MonteCarloSettings, load_spread, run_montecarlo
    from twin.parameters import Parameters

    base = Parameters()
    spread = load_spread("docs/examples/spread.toml", base)
    settings = MonteCarloSettings("appendix-sf", 6, duration_s=2.0, engine="screen", audit=2)
    screened = run_montecarlo(settings, base, spread)
    brute = run_montecarlo(MonteCarloSettings(**{**settings.__dict__, "engine": "mujoco"}), base, spread)
    assert screened.screening is not None and screened.screening["fast_runs"] == 6
    mujoco = [p for p in screened.runs if p["engine"] == "mujoco"]
    assert len(mujoco) == screened.screening["mujoco_runs"] >= 2
    for p, q in zip(screened.runs, brute.runs, strict=True):
        if p["engine"] == "mujoco":
            assert p == q


@pytest.mark.quick
def test_a_screened_search_counts_only_the_violations_mujoco_confirms() -> None:
    from twin.app.falsify import Axis, FalsifySettings, falsify
    from twin.parameters import Parameters
    from twin.requirements import load_spec

    spec = load_spec("docs/examples/falsify.toml")
    settings = FalsifySettings(
        "appendix-sf", (Axis("x0_m", 0.10, 0.32), Axis("theta0_rad", -0.70, -0.30)), duration_s=2.0,
        noise=False, budget=20, engine="screen",
    )  # fmt: skip
    result = falsify(settings, Parameters(), spec)
    out = result.to_json()
    assert out["found"] and out["counterexample"] is not None
    first = result.runs[result.first_violation or 0]
    assert first["engine"] == "mujoco" and first["fast_objective"] < 0 and first["objective"] < 0
    assert all(r["engine"] == "mujoco" for r in result.runs if r["objective"] < 0)
    assert out["decided_by"]["fast"] + out["decided_by"]["mujoco"] == out["runs_spent"]


@pytest.mark.quick
def test_the_readme_agreement_table_is_the_measured_json_rendered() -> None:
    import json
    from pathlib import Path

    from twin.app.screening import render_agreement

    root = Path(__file__).resolve().parent.parent
    data = json.loads((root / "docs" / "validation" / "screen_agreement.json").read_text())
    readme = (root / "docs" / "validation" / "engines.md").read_text()  # the manual's page of the table
    block = readme.split("<!-- screen-table -->\n", 1)[1].split("<!-- /screen-table -->", 1)[0]
    assert block == render_agreement(data)
    for m in data["maps"]:  # the measured claims the README makes of them
        assert m["screened_equals_brute_force"] == m["starts"] and m["screened_audit_mismatches"] == 0


def test_a_screened_sweep_is_the_same_on_one_worker_and_on_two() -> None:
    settings = SweepSettings(
        "appendix-clp", x0=Grid(-0.3, 0.3, 5), theta0=Grid(-0.7, 0.7, 5), duration_s=3.0, engine="screen",
        screen_audit=3,
    )  # fmt: skip
    one = run_sweep(settings, workers=1).to_json()
    two = run_sweep(settings, workers=2).to_json()
    assert one["points"] == two["points"] and one["screening"] == two["screening"]


@pytest.mark.quick
@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (
            ["sweep", "--controller", "appendix-sf", "--engine", "screen", "--plant", "reference"],
            ["--engine"],
        ),
        (["sweep", "--controller", "appendix-sf", "--engine", "screen", "--refine"], ["--refine"]),
        (["sweep", "--controller", "appendix-sf", "--band", "0"], ["--band"]),
        (
            [
                "montecarlo",
                "--controller",
                "appendix-sf",
                "--spread",
                "docs/examples/spread.toml",
                "--engine",
                "warp",
            ],
            ["--engine"],
        ),  # fmt: skip
    ],
)
def test_engine_options_that_cannot_work_are_refused(capsys, argv: list[str], needles: list[str]) -> None:
    from tests.cli_checks import refused

    refused(capsys, argv, *needles)


@pytest.mark.quick
def test_a_held_verdict_near_its_band_is_marginal_on_either_side() -> None:
    from twin.app.screening import HELD_MARGINS, near_held_band
    from twin.verdict import Criteria

    kept_on_track = {"failed": False, "ball_lost": False, "steady_x_m": 0.002, "steady_theta_rad": 0.0,
                     "limit_cycle_x_pp_m": 0.001, "limit_cycle_theta_pp_rad": 0.005}  # fmt: skip
    band, margin = HELD_MARGINS["steady_x_m"]
    edge = getattr(Criteria(), band)
    assert not near_held_band({**kept_on_track, "held": True})
    assert near_held_band({**kept_on_track, "held": True, "steady_x_m": edge - margin / 2})
    assert near_held_band({**kept_on_track, "held": False, "steady_x_m": -(edge + margin / 2)})
    assert not near_held_band({**kept_on_track, "held": False, "steady_x_m": edge + 2 * margin})
    # two failing metrics: marginal only when both are within their margins
    both = {**kept_on_track, "held": False, "steady_x_m": edge + margin / 2, "limit_cycle_x_pp_m": 0.05}
    assert not near_held_band(both)
    assert not near_held_band({**kept_on_track, "held": False, "ball_lost": True, "steady_x_m": edge})
    # a map's screening confirms by the offsets alone (the limit cycles' flips sit at its class changes)
    from twin.app.screening import near_offset_band

    cycle_band, cycle_margin = HELD_MARGINS["limit_cycle_theta_pp_rad"]
    cycling = getattr(Criteria(), cycle_band) + cycle_margin / 2
    assert near_held_band({**kept_on_track, "held": False, "limit_cycle_theta_pp_rad": cycling})
    assert not near_offset_band({**kept_on_track, "held": False, "limit_cycle_theta_pp_rad": cycling})
    assert near_offset_band({**kept_on_track, "held": True, "steady_x_m": edge - margin / 2})


@pytest.mark.quick
def test_a_marginal_start_far_from_every_boundary_is_mujocos() -> None:
    fast = _half_plane(20, 20, 6.0)[None]
    mujoco = fast.copy()
    mujoco[0, 15, 15] = "kept"  # the island of the audit test, now marginal on the fast engine
    calls: list[list[int]] = []
    s = Screening(
        20, 20, 1, _job(fast, []), _job(mujoco, calls), audit=0, classify=lambda r: r["c"],
        marginal=lambda r: r is not None and r.get("k") == 15 * 20 + 15,
    )  # fmt: skip

    def fast_job(requests, within):
        return [{"c": str(fast[m].flat[k]), "k": k} for m, k in requests], True

    s.fast_job = fast_job
    s.run()
    assert s.classify(s.record(0, 15 * 20 + 15)) == "kept" and s.record(0, 15 * 20 + 15)["engine"] == "mujoco"


@pytest.mark.quick
def test_a_measured_table_replaces_only_its_block(tmp_path) -> None:
    import json

    from twin.outputs import write_measured_table

    readme = tmp_path / "README.md"
    readme.write_text("intro\n<!-- t -->\nold\n<!-- /t -->\nrest\n")
    write_measured_table(tmp_path / "m.json", {"a": 1}, readme, "t", "new\n")
    assert readme.read_text() == "intro\n<!-- t -->\nnew\n<!-- /t -->\nrest\n"
    assert json.loads((tmp_path / "m.json").read_text()) == {"a": 1}
    with pytest.raises(ValueError, match="no <!-- other --> marker"):
        write_measured_table(tmp_path / "m.json", {}, readme, "other", "x\n")
    assert readme.read_text() == "intro\n<!-- t -->\nnew\n<!-- /t -->\nrest\n"  # untouched


def test_validate_screens_its_region_check_and_says_so() -> None:
    from tests.test_validate import QUICK
    from twin.app.validate import validate
    from twin.parameters import Parameters

    screened = validate("appendix-sf", Parameters(), QUICK, engine="screen")
    brute = validate("appendix-sf", Parameters(), QUICK)
    region = {c.name: c for c in screened.checks}["region"]
    assert "screened: MuJoCo decided" in region.measured
    assert region.passed == {c.name: c for c in brute.checks}["region"].passed
    assert screened.region is not None and brute.region is not None
    assert [verdict_class(p) for p in screened.region.points] == [
        verdict_class(p) for p in brute.region.points
    ]


@pytest.mark.quick
def test_a_start_within_a_ball_radius_of_a_track_end_is_mujocos() -> None:
    from twin.app.screening import map_marginal, near_track_end
    from twin.parameters import Parameters

    p = Parameters()
    edge = p.track.half_length_m - p.ball.radius_m
    held = {"failed": False, "ball_lost": False, "held": True, "steady_x_m": 0.0, "steady_theta_rad": 0.0,
            "limit_cycle_x_pp_m": 0.0, "limit_cycle_theta_pp_rad": 0.0}  # fmt: skip
    assert near_track_end({**held, "x0_m": -(edge + 1e-4)}, p) and near_track_end(
        {**held, "x0_m": edge + 1e-4}, p
    )
    assert not near_track_end({**held, "x0_m": edge - 1e-4}, p)
    assert map_marginal(p)({**held, "x0_m": -0.32}) and not map_marginal(p)({**held, "x0_m": -0.304})
