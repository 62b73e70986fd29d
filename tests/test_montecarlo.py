"""Monte Carlo robustness: spreads are read and sampled as stated (means, deviations, correlations,
bounds), every run is the single run of its sample and seed, and the success interval is exact."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from controllers import registry
from twin.app.cli import main
from twin.app.montecarlo import (
    MonteCarloResult,
    MonteCarloSettings,
    load_calibration_spread,
    load_spread,
    run_montecarlo,
    sample_parameters,
    summarize,
)
from twin.parameters import ParameterError, Parameters
from twin.rigs.sim import run_closed_loop

SPREAD = """
[motor]
resistance_ohm = { rel_sd = 0.05 }
[beam]
pivot_friction_nm = { low = 0.0, high = 0.004 }
"""


@pytest.fixture
def spread_file(tmp_path: Path) -> Path:
    path = tmp_path / "spread.toml"
    path.write_text(SPREAD)
    return path


def test_a_spread_is_sampled_as_stated(spread_file: Path) -> None:
    p = Parameters()
    spread = load_spread(spread_file, p)
    sets, values = sample_parameters(p, spread, 4000, seed=1)
    r, f = values[:, 0], values[:, 1]
    nominal, sd = p.motor.resistance_ohm, 0.05 * p.motor.resistance_ohm
    assert abs(r.mean() - nominal) < 4 * sd / np.sqrt(len(r))
    assert r.std() == pytest.approx(sd, rel=0.05)
    assert f.min() >= 0.0 and f.max() <= 0.004 and f.mean() == pytest.approx(0.002, abs=1e-4)
    assert [s.motor.resistance_ohm for s in sets[:3]] == pytest.approx(r[:3].tolist())
    again, _ = sample_parameters(p, spread, 3, seed=1)
    assert again == sets[:3]  # the seed decides the samples


@pytest.mark.quick
def test_draws_outside_the_bounds_are_drawn_again(tmp_path: Path) -> None:
    """Pivot friction is ≥ 0: a normal about 0 gives only its non-negative half."""
    path = tmp_path / "s.toml"
    path.write_text("[beam]\npivot_friction_nm = { sd = 0.001 }\n")
    _, values = sample_parameters(Parameters(), load_spread(path, Parameters()), 500, seed=0)
    assert values.min() >= 0 and np.mean(values) == pytest.approx(0.001 * np.sqrt(2 / np.pi), rel=0.15)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[motor]\nresistance_ohm = { sd = -1 }\n", "standard deviation"),
        ("[motor]\nresistance_ohm = { mean = 3 }\n", "give { sd"),
        ("[motor]\nno_such = { sd = 1 }\n", "unknown parameter 'motor.no_such'"),
        ("[ball_sensor]\nnoise_enabled = { sd = 1 }\n", "only numeric parameters"),
        ("[motor]\nresistance_ohm = { low = 2, high = 1 }\n", "is above high"),
        ("motor = 3\n", "is not a table"),
        ("[motor\n", "not valid TOML"),
        ("", "expected tables"),
    ],
)
def test_a_bad_spread_is_refused_naming_the_file_and_entry(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ParameterError, match=message) as info:
        load_spread(path, Parameters())
    assert str(path) in str(info.value)


def _calibration_dir(tmp_path: Path) -> Path:
    out = tmp_path / "cal"
    out.mkdir()
    Parameters().save(out / "params.toml")
    data = {
        "params": {
            "motor.resistance_ohm": {"value": 9.4, "sd": 0.2, "ci_low": 9.0, "ci_high": 9.8},
            "beam.inertia_pivot_kgm2": {
                "value": Parameters().beam.inertia_pivot_kgm2,
                "sd": 1e-4,
                "ci_low": 0,
                "ci_high": 1,
            },
            "ball_sensor.dropout_rate_hz": {"value": 5.0, "sd": 1.0, "ci_low": 3, "ci_high": 7},
        },
        "correlation": {
            "names": ["motor.resistance_ohm", "beam.inertia_pivot_kgm2"],
            "matrix": [[1, 0.8], [0.8, 1]],
        },
    }
    (out / "calibration.json").write_text(json.dumps(data))
    return out


def test_a_calibration_is_sampled_with_its_correlations(tmp_path: Path) -> None:
    base, spread = load_calibration_spread(_calibration_dir(tmp_path))
    _, values = sample_parameters(base, spread, 3000, seed=2)
    assert spread.names == ("motor.resistance_ohm", "beam.inertia_pivot_kgm2", "ball_sensor.dropout_rate_hz")
    assert np.corrcoef(values[:, 0], values[:, 1])[0, 1] == pytest.approx(0.8, abs=0.03)
    assert abs(np.corrcoef(values[:, 0], values[:, 2])[0, 1]) < 0.06
    assert values[:, 0].std() == pytest.approx(0.2, rel=0.05)


def test_every_run_is_the_single_run_of_its_sample(spread_file: Path) -> None:
    p = Parameters()
    spread = load_spread(spread_file, p)
    settings = MonteCarloSettings("appendix-clp", n=4, duration_s=2.0, seed=5)
    result = run_montecarlo(settings, p, spread)
    sets, _ = sample_parameters(p, spread, 4, seed=5)
    assert result.complete and result.summary["runs"] == 4
    for run, params in zip(result.runs, sets, strict=True):
        single = run_closed_loop(
            registry.make("appendix-clp", params),
            x0_m=-0.2,
            theta0_rad=0.3,
            duration_s=2.0,
            seed=run["seed"],
            params=params,
        )
        assert {k: run[k] for k in single.verdict.to_json()} == single.verdict.to_json()
        assert run["parameters"]["motor.resistance_ohm"] == params.motor.resistance_ohm


@pytest.mark.quick
def test_the_success_interval_is_exact() -> None:
    """Clopper-Pearson: all n held gives [(α/2)^(1/n), 1]; none held gives [0, 1 − (α/2)^(1/n)]."""
    run = {"held": True, "ball_lost": False, "steady_x_m": 0.001, "settling_time_s": 2.0}
    s = summarize([run] * 20)
    assert s["success_ci"][0] == pytest.approx(0.025 ** (1 / 20), abs=1e-6) and s["success_ci"][1] == 1.0
    lost = {"held": False, "ball_lost": True, "steady_x_m": None, "settling_time_s": None}
    s = summarize([lost] * 20 + [run])
    assert s["worst"][0] == lost and s["lost"] == 20 and s["held"] == 1


@pytest.mark.quick
def test_the_command(tmp_path: Path, spread_file: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "mc"
    args = [
        "montecarlo",
        "--controller",
        "appendix-sf",
        "--n",
        "3",
        "--duration",
        "1",
        "--spread",
        str(spread_file),
    ]
    assert main([*args, "--out", str(out), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["summary"]["runs"] == 3
    assert json.loads((out / "montecarlo.json").read_text()) == printed
    assert (out / "distributions.png").read_bytes()[:4] == b"\x89PNG"
    assert main(["montecarlo", "--controller", "appendix-sf"]) == 2
    assert "--spread FILE or --calibration DIR" in capsys.readouterr().err
    assert main([*args, "--x0", "0.5"]) == 2
    assert "--x0/--theta0" in capsys.readouterr().err


@pytest.mark.quick
def test_the_command_draws_the_distributions_of_its_own_result(
    tmp_path: Path, spread_file: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import struct

    import twin.app.montecarlo_render as montecarlo_render

    drawn: list[tuple[MonteCarloResult, Path]] = []
    real = montecarlo_render.render_distributions

    def spy(result: MonteCarloResult, path: Path) -> None:
        drawn.append((result, path))
        real(result, path)

    monkeypatch.setattr(montecarlo_render, "render_distributions", spy)
    out = tmp_path / "mc"
    argv = ["montecarlo", "--controller", "appendix-sf", "--n", "2", "--duration", "1"]
    assert main([*argv, "--spread", str(spread_file), "--out", str(out), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    ((result, path),) = drawn
    assert path.name == "distributions.png" and result.summary == printed["summary"]
    png = (out / "distributions.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and png[12:16] == b"IHDR"
    assert struct.unpack(">II", png[16:24]) == (1100, 418)  # figsize (10, 3.8) in at 110 dpi
