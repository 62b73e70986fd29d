"""``ballbeam falsify`` (twin.app.falsify) and ``run --replay``: the search finds the ball-losing starts of a box
that crosses appendix-sf's region of attraction, its counterexample repeats bit for bit and loses the ball as
stated; inside the region it finds none and reports the least robust run; the same seed gives the same search,
with workers too; bad inputs are refused naming the option or the file's field."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_checks import refused

from twin.app.cli import main
from twin.app.falsify import Axis, FalsifySettings, falsify, uniform_search
from twin.app.falsify_render import write_falsify
from twin.app.fanout import Runs, run_starts
from twin.app.montecarlo import load_spread
from twin.app.replay import load_replay
from twin.parameters import Parameters
from twin.requirements import load_spec

ROOT = Path(__file__).parents[1]
SPEC = ROOT / "docs" / "examples" / "falsify.toml"


def _settings(x: tuple[float, float], th: tuple[float, float], **kw: object) -> FalsifySettings:
    return FalsifySettings(
        "appendix-sf", (Axis("x0_m", *x), Axis("theta0_rad", *th)), duration_s=4.0, noise=False, **kw
    )  # type: ignore[arg-type]


@pytest.mark.quick
def test_a_box_across_the_boundary_gives_a_counterexample_that_replays_bit_for_bit(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "fz"
    argv = ["falsify", "--controller", "appendix-sf", "--spec", str(SPEC), "--x0", "0.10:0.32"]
    argv += ["--theta0", "-0.70:-0.30", "--no-noise", "--budget", "60", "--duration", "4", "--out", str(out)]
    assert main(argv) == 1  # a counterexample: exit 1
    data = json.loads((out / "falsify.json").read_text())
    cx = data["counterexample"]
    assert data["found"] and cx["objective"] < 0 and cx["ball_lost"]
    assert data["runs_to_first_violation"] <= data["runs_spent"] <= 60
    assert (out / "falsify.png").stat().st_size > 10_000
    replay = load_replay(out / "falsify.json")
    assert (replay.x0_m, replay.theta0_rad, replay.seed, replay.noise) == (
        cx["x0_m"],
        cx["theta0_rad"],
        0,
        False,
    )
    # every violation the search reports is one: the trace's objectives are the runs' least robustness
    assert min(t["objective"] for t in data["trace"]) == cx["objective"]
    capsys.readouterr()
    assert main(["run", "--replay", str(out / "falsify.json"), "--json"]) == 1
    summary = json.loads(capsys.readouterr().out)
    assert summary["ball_lost"] and summary["replayed"]["same"]
    assert summary["requirements"] == cx["robustness"]
    assert (summary["x0_m"], summary["theta0_rad"]) == (cx["x0_m"], cx["theta0_rad"])


@pytest.mark.quick
def test_inside_the_region_none_is_found_and_the_least_robust_run_is_reported(tmp_path: Path) -> None:
    spec = load_spec(SPEC)
    result = falsify(_settings((-0.05, 0.05), (-0.1, 0.1), budget=20), Parameters(), spec)
    out = result.to_json()
    write_falsify(result, tmp_path / "out")
    assert json.loads((tmp_path / "out" / "falsify.json").read_text())["least_robust"] == out["least_robust"]
    assert not out["found"] and out["counterexample"] is None and out["runs_spent"] == 20
    least = out["least_robust"]
    assert least["objective"] == min(t["objective"] for t in out["trace"]) > 0
    # the least robust run's robustness is 0.323 − its largest |x| (the ball is kept): recomputed here
    records, _ = run_starts(
        Runs("appendix-sf", Parameters(), 4.0, False, "twin", False, spec.requirements),
        np.array([[least["x0_m"], least["theta0_rad"]]]),
        np.array([least["seed"]], dtype=np.int64),
    )
    assert records[0] is not None and records[0]["requirements"]["on_track"] == least["objective"]


def test_the_same_seed_gives_the_same_search_with_workers_too() -> None:
    spec = load_spec(SPEC)
    settings = _settings((0.0, 0.16), (-0.7, -0.2), budget=30, seed=5, keep_going=True)
    a = falsify(settings, Parameters(), spec).to_json()
    b = falsify(settings, Parameters(), spec, workers=2).to_json()
    for out in (a, b):
        out.pop("wall_s")
    assert a == b and a["runs_spent"] == 30
    c = falsify(FalsifySettings(**{**settings.__dict__, "seed": 6}), Parameters(), spec).to_json()
    assert [t["x0_m"] for t in c["trace"]][5:] != [t["x0_m"] for t in a["trace"]][5:]


def test_a_spread_is_searched_and_its_rig_replays(tmp_path: Path) -> None:
    """A rig of the spread at a searched point: the run's parameters in the file repeat the run."""
    p = Parameters()
    spread = load_spread(ROOT / "docs" / "examples" / "spread.toml", p)
    settings = FalsifySettings(
        "appendix-sf", (), x0_m=0.12, theta0_rad=-0.5, duration_s=3.0, noise=True, budget=12
    )
    result = falsify(settings, p, load_spec(SPEC), spread)
    assert len(result.runs) == 12
    run = result.runs[3]
    assert set(run["values"]) == set(spread.names)
    for name, value in run["values"].items():
        group, field = name.split(".")
        assert getattr(getattr(Parameters().with_overrides(run["parameters"]), group), field) == value
    uniform = uniform_search(settings, p, load_spec(SPEC), spread, batch=6)
    assert len(uniform.runs) == 12


@pytest.mark.quick
def test_bad_falsify_and_replay_inputs_are_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    base = ["falsify", "--controller", "appendix-sf", "--spec", str(SPEC)]
    refused(capsys, [*base, "--x0", "0.3:0.1"], "--x0", "A ≤ B")
    refused(capsys, [*base, "--x0", "a:b"], "--x0", "not a number")
    refused(capsys, [*base, "--x0", "0.1:0.5"], "--x0/--theta0")
    refused(capsys, [*base, "--latency", "0:0.05"], "--latency")
    refused(capsys, [*base, "--x0", "0.1", "--theta0", "0.2"], "nothing to search")
    refused(capsys, [*base, "--budget", "0"], "--budget")
    one = falsify(
        _settings((0.0, 0.16), (-0.4, -0.4), budget=12, keep_going=True), Parameters(), load_spec(SPEC)
    )
    assert len(one.runs) == 12 and all(
        len(r["u"]) == 1 for r in one.runs
    )  # one input: CMA-ES past the corners
    bad = tmp_path / "bad.json"
    bad.write_text('{"counterexample": {"controller": "appendix-sf", "x0_m": "0.1"}}')
    refused(capsys, ["run", "--replay", str(bad)], str(bad), "parameters")
    good = {
        "controller": "appendix-sf",
        "x0_m": 0.1,
        "theta0_rad": 0,
        "seed": 0,
        "noise": True,
        "duration_s": 1e9,
    }
    good |= {"parameters": {}, "requirements": {"a": "always (x_m <= 1)"}, "robustness": {}}
    bad.write_text(json.dumps({"counterexample": good}))
    refused(capsys, ["run", "--replay", str(bad)], str(bad), "duration_s = 1000000000.0")
    bad.write_text(json.dumps({"counterexample": {**good, "duration_s": 1, "x0_m": 0.5}}))
    assert (
        main(["run", "--replay", str(bad)]) == 2 and "x_m = 0.5 is off the track" in capsys.readouterr().err
    )
    bad.write_text("not json")
    refused(capsys, ["run", "--replay", str(bad)], str(bad), "JSON")
    bad.write_text("{}")
    refused(capsys, ["run", "--replay", str(bad)], "no run to repeat")
    refused(capsys, ["run", "--replay", str(bad), "--x0", "0.1"], "--replay brings", "--x0")
    refused(capsys, ["view", "--replay", str(bad), "--seed", "3"], "--replay brings", "--seed")


@pytest.mark.quick
def test_the_readmes_falsifier_table_is_the_benchs_json_rendered() -> None:
    import re

    from twin.app.falsify_render import render_table

    bench = json.loads((ROOT / "docs" / "validation" / "falsify_bench.json").read_text())
    block = re.search(
        r"<!-- falsify-table -->\n(.*?)<!-- /falsify-table -->",
        (ROOT / "docs" / "validation" / "engines.md").read_text(),
        re.S,
    )
    assert block is not None and block[1] == render_table(bench)
    # the table's ratio is the medians' (a search without a violation counts budget + 1)
    for key in ("corner", "spread_tail"):
        ratio = bench[f"{key}_uniform_median_runs"] / bench[f"{key}_falsifier_median_runs"]
        assert bench[f"{key}_uniform_over_falsifier"] == ratio


def test_view_replay_opens_the_counterexample(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``view --replay``: the view gets the file's controller, start, seed, noise and rig, and the live twin's
    first run starts there."""
    import twin.viewer
    from controllers import registry
    from twin.viewer.session import LiveTwin

    spec = load_spec(SPEC)
    p = Parameters().with_overrides({"motor.resistance_ohm": 9.9})
    result = falsify(_settings((0.10, 0.32), (-0.70, -0.30), budget=10), p, spec)
    write_falsify(result, tmp_path / "fz")
    seen: dict[str, object] = {}
    monkeypatch.setattr(twin.viewer, "serve", lambda catalogue, **kwargs: seen.update(kwargs) or {})
    assert main(["view", "--replay", str(tmp_path / "fz" / "falsify.json"), "--duration", "1"]) == 0
    cx = result.to_json()["counterexample"]
    assert seen["initial"] == (cx["x0_m"], cx["theta0_rad"]) and seen["controller"] == "appendix-sf"
    assert seen["seed"] == cx["seed"] and seen["params"].motor.resistance_ohm == 9.9  # type: ignore[attr-defined]
    assert seen["params"].ball_sensor.noise_enabled is False  # type: ignore[attr-defined]
    live = LiveTwin(seen["params"], registry, "appendix-sf", cx["seed"], 1.0, initial=seen["initial"])  # type: ignore[arg-type]
    try:
        assert (live.x0_m, live.theta0_rad) == (cx["x0_m"], cx["theta0_rad"])
    finally:
        live.close()


def test_a_flick_and_a_setpoint_are_inputs_of_a_run_the_batch_and_the_search(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``Scenario``: a kick of 0 is no flick (the same bits); a flick leaves the ticks before it as they were and
    changes the ball's speed after; ``run_batch`` with scenarios gives ``run_closed_loop``'s runs bit for bit; a
    search over a flick finds the kick that loses the ball and ``run --replay`` repeats it; a setpoint reaches
    the requirements' ``setpoint_m``."""
    from controllers import registry
    from twin.engine import Scenario
    from twin.rigs.batch import run_batch
    from twin.rigs.sim import run_closed_loop

    def run(scenario: Scenario | None) -> object:
        return run_closed_loop(
            registry.make("appendix-sf"), x0_m=0.1, theta0_rad=0.0, duration_s=3.0, seed=2, scenario=scenario
        )

    plain, zero, kicked = run(None), run(Scenario(1.0, 0.0)), run(Scenario(1.0, 0.4))
    logs = [vars(r.log) for r in (plain, zero, kicked)]  # type: ignore[attr-defined]
    assert all(np.array_equal(logs[0][k], logs[1][k]) for k in logs[0])
    k = int(np.searchsorted(logs[0]["true_time_s"], 1.0))  # the first tick after the flick
    assert np.array_equal(logs[0]["true_x_m"][:k], logs[2]["true_x_m"][:k])
    assert logs[2]["true_xdot_m_s"][k] - logs[0]["true_xdot_m_s"][k] == pytest.approx(0.4, abs=0.02)
    batch = run_batch(
        registry, "appendix-sf", x0_m=np.array([0.1, 0.1]), theta0_rad=np.zeros(2), seeds=np.array([2, 2]),
        duration_s=3.0, record=True, scenarios=[None, Scenario(1.0, 0.4)],
    )  # fmt: skip
    for got, want in zip(batch, (plain, kicked), strict=True):
        assert all(np.array_equal(vars(got.log)[name], v) for name, v in vars(want.log).items())  # type: ignore[attr-defined]
    out = tmp_path / "fz"
    # kicks within the live view's Flick range (0.02…0.5 m/s either way): clp holds the unkicked ball at 0
    argv = ["falsify", "--controller", "clp", "--spec", str(SPEC), "--x0", "0", "--theta0", "0"]
    argv += ["--flick-time", "0.5:2", "--flick-speed", "-0.5:0.5", "--no-noise", "--duration", "3"]
    assert main([*argv, "--budget", "20", "--out", str(out)]) == 1
    cx = json.loads((out / "falsify.json").read_text())["counterexample"]
    assert cx["ball_lost"] and abs(cx["flick_speed_m_s"]) > 0.2 and 0.5 <= cx["flick_time_s"] <= 2
    capsys.readouterr()
    assert main(["run", "--replay", str(out / "falsify.json"), "--json"]) == 1
    summary = json.loads(capsys.readouterr().out)
    assert summary["replayed"]["same"] and summary["ball_lost"]
    spec = tmp_path / "sp.toml"
    spec.write_text('[requirements]\nat = "always (setpoint_m <= 0.05)"\n')
    base = ["falsify", "--controller", "lqr", "--spec", str(spec), "--x0", "0:0.1", "--theta0", "0"]
    assert main([*base, "--setpoint", "0.05", "--budget", "3", "--duration", "1", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert {t["objective"] for t in data["trace"]} == {0.0} and data["least_robust"]["setpoint_m"] == 0.05
    refused(capsys, [*base, "--setpoint", "0.4"], "--setpoint")
    refused(capsys, [*base, "--flick-time", "1"], "--flick-speed")
    refused(
        capsys,
        ["falsify", "--controller", "appendix-sf", "--spec", str(spec), "--setpoint", "0:0.1"],
        "no ball setpoint",
    )
