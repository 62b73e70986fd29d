"""Whatever a command writes, the command that reads it back accepts, with the same result: falsify.json and
certify.json → ``run --replay`` (on the engine that made the run, at any budget), export-fmu → the unit's own
rig, ``params --json`` → ``--params``, a run's log → ``judge``, ``calibrate`` and ``compare``, calibrate's
params.toml → ``run --params`` and its folder → ``--calibration``. (sweep.json, montecarlo.json, robust.json and
validation.json are reports: no command reads them back.)"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import pytest

from twin.app.certify import CertifySettings, certify
from twin.app.cli import main
from twin.app.falsify import Axis, FalsifySettings, falsify
from twin.app.falsify_render import write_falsify
from twin.app.montecarlo import load_spread
from twin.app.replay import REPLAY_HEAD_BYTES, load_replay
from twin.parameters import MAX_FILE_BYTES, Parameters
from twin.requirements import ROBUSTNESS_LIMIT, Spec, parse_requirements

ROOT = Path(__file__).parents[1]
SPEC = ROOT / "docs" / "examples" / "falsify.toml"
ON_TRACK = Spec(
    parse_requirements({"requirements": {"on_track": "always (abs(x_m) <= 0.323 and lost < 0.5)"}}, "t"),
    {},
    "t",
)


def _replayed(capsys: pytest.CaptureFixture[str], path: Path) -> dict:
    """``run --replay path --json``'s summary (exit 0 or 1: a verdict, not a refusal)."""
    capsys.readouterr()
    rc = main(["run", "--replay", str(path), "--json"])
    out, err = capsys.readouterr()
    assert rc in (0, 1), err
    return json.loads(out)


@pytest.mark.parametrize("engine", ["screen", "fast", "mujoco"])
def test_a_falsify_json_replays_on_its_engine_with_the_robustness_it_states(
    engine: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "fz"
    argv = ["falsify", "--controller", "appendix-sf", "--spec", str(SPEC), "--x0", "0.0:0.12"]
    argv += [
        "--theta0",
        "-0.2:0.2",
        "--budget",
        "6",
        "--duration",
        "2",
        "--engine",
        engine,
        "--out",
        str(out),
    ]
    assert main(argv) in (0, 1)
    least = json.loads((out / "falsify.json").read_text())["least_robust"]
    assert least["plant"] == ("reference" if engine == "fast" else "twin")
    summary = _replayed(capsys, out / "falsify.json")
    assert summary["replayed"]["same"] and summary["requirements"] == least["robustness"]
    assert summary["plant"] == least["plant"] and summary["ideal_sensors"] is False


def test_a_certify_json_replays_its_counterexample(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    spec = tmp_path / "tight.toml"
    spec.write_text('[requirements]\nnear_centre = "always (abs(x_m) <= 0.05)"\n')
    out = tmp_path / "cert"
    argv = ["certify", "--controller", "appendix-sf", "--spec", str(spec)]
    argv += ["--spread", str(ROOT / "docs" / "examples" / "spread.toml"), "--duration", "1", "--batch", "2"]
    assert main([*argv, "--out", str(out)]) == 1
    cx = json.loads((out / "certify.json").read_text())["counterexample"]
    summary = _replayed(capsys, out / "certify.json")
    assert summary["replayed"]["same"] and summary["requirements"] == cx["robustness"]


def test_a_falsify_or_certify_file_of_any_size_they_allow_is_read_back(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A 5 000-run search's falsify.json is past 1 MiB, a 100 000-run one past ``REPLAY_HEAD_BYTES``; certify's
    runs list grows likewise: the runs to repeat come first and the bulk after them is never parsed."""
    p = Parameters()
    small = falsify(
        FalsifySettings(
            "appendix-sf", (Axis("x0_m", 0.2, 0.3), Axis("theta0_rad", -0.6, -0.3)), duration_s=1.0,
            noise=False, budget=5, engine="mujoco", keep_going=True,
        ),
        p,
        ON_TRACK,
    )  # fmt: skip
    stated = small.to_json()["least_robust"]
    for copies, past in ((1_000, MAX_FILE_BYTES), (8_000, REPLAY_HEAD_BYTES)):
        small.runs = small.runs[:5] * copies  # the writer's file for a search of 5 000 or 40 000 runs
        folder = tmp_path / f"fz{copies}"
        write_falsify(small, folder)
        assert (folder / "falsify.json").stat().st_size > past
        summary = _replayed(capsys, folder / "falsify.json")
        assert summary["replayed"]["same"] and summary["requirements"] == stated["robustness"]
    spec = Spec(parse_requirements({"requirements": {"near": "always (abs(x_m) <= 0.05)"}}, "t"), {}, "t")
    settings = CertifySettings("appendix-sf", (0.1, 0.2), (-0.1, 0.1), 0.7, 0.8, duration_s=1.0, batch=2)
    result = certify(settings, p, spec, load_spread(ROOT / "docs" / "examples" / "spread.toml", p))
    assert result.counterexample is not None
    result.runs = result.runs * (REPLAY_HEAD_BYTES // len(json.dumps(result.to_json()["runs"])) + 1)
    path = tmp_path / "certify.json"
    path.write_text(json.dumps(result.to_json(), indent=1) + "\n")  # as certify --out writes it
    assert path.stat().st_size > REPLAY_HEAD_BYTES
    summary = _replayed(capsys, path)
    assert summary["replayed"]["same"] and summary["requirements"] == result.counterexample["robustness"]


def test_export_fmu_refuses_what_a_run_refuses_and_its_unit_builds_its_rig(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from twin.fmi.unit import RigUnit

    bad = tmp_path / "bad.fmu"
    assert (
        main(["run", "--controller", "lqr", "--x0", "0", "--theta0", "0", "--set", "daq.period_s=0.0137"])
        == 2
    )
    run_says = capsys.readouterr().err
    assert main(["export-fmu", "--out", str(bad), "--set", "daq.period_s=0.0137"]) == 2
    err = capsys.readouterr().err
    assert "daq.period_s = 0.0137" in err and "--set daq.period_s=0.0137" in err and "Traceback" not in err
    assert run_says.strip().split(": ")[-1] in err and not bad.exists()
    good = tmp_path / "good.fmu"
    assert main(["export-fmu", "--out", str(good), "--set", "daq.period_s=0.01"]) == 0
    with zipfile.ZipFile(good) as unit:
        unit.extractall(tmp_path / "unit")
    rig = RigUnit(tmp_path / "unit" / "resources")
    rig.start()  # the importer's initialization: the rig built from the exported values
    assert rig.period_s == 0.01 and rig.step(0.0, 0.01) is None


@pytest.mark.quick
def test_params_json_is_read_back_by_params(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["params", "--set", "motor.resistance_ohm=9.5", "--set", "daq.period_s=0.01", "--json"]) == 0
    written = capsys.readouterr().out
    path = tmp_path / "p.json"
    path.write_text(written)
    assert main(["params", "--params", str(path), "--json"]) == 0
    assert capsys.readouterr().out == written
    assert Parameters.from_file(path) == Parameters().with_overrides(
        {"motor.resistance_ohm": 9.5, "daq.period_s": 0.01}
    )


@pytest.mark.slow
def test_a_runs_log_is_read_by_judge_calibrate_and_compare_and_the_calibration_by_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    start = ["--controller", "appendix-sf", "--x0", "0.1", "--theta0", "-0.1", "--duration", "6"]
    for log in ("run.mat", "run.csv"):
        assert main(["run", *start, "--log", log]) in (0, 1)
        capsys.readouterr()
        assert main(["judge", log, "--json"]) in (0, 1)
        assert json.loads(capsys.readouterr().out)["ticks"] > 250
    assert main(["calibrate", "run.mat", "--fit", "motor.resistance_ohm", "--out", "cal", "--json"]) in (0, 1)
    fitted = json.loads((tmp_path / "cal" / "calibration.json").read_text())["params"]["motor.resistance_ohm"]
    assert Parameters.from_file(tmp_path / "cal" / "params.toml").motor.resistance_ohm == fitted["value"]
    capsys.readouterr()
    assert main(["run", *start, "--params", "cal/params.toml", "--json"]) in (0, 1)
    assert json.loads(capsys.readouterr().out)["controller"] == "appendix-sf"
    assert main(
        ["compare", "run.csv", "--out", "cmp", "--calibration", "cal", "--controller", "appendix-sf"]
    ) in (0, 1)
    assert (tmp_path / "cmp" / "comparison.json").exists()
    assert main(["export-fmu", "--out", "cal.fmu", "--calibration", "cal"]) == 0


FAILING_CONTROLLER = """
from twin.interface import Controller


class Fails(Controller):
    name = "fails"

    def start(self, sample):
        pass

    def update(self, sample):
        raise ValueError("no card")
"""


def _strict(text: str) -> object:
    def refuse(name: str) -> object:
        raise AssertionError(f"{name} is not JSON")

    return json.loads(text, parse_constant=refuse)


def test_a_failed_controllers_search_writes_strict_json(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A controller that fails scores −inf inside the search; falsify.json and --json state it finitely, and the
    file still replays (its reader accepts what its writer wrote)."""
    (tmp_path / "fails_ctrl.py").write_text(FAILING_CONTROLLER)
    monkeypatch.chdir(tmp_path)
    spec = Path(__file__).parents[1] / "docs" / "examples" / "falsify.toml"
    argv = ["falsify", "--controller", "fails_ctrl:Fails", "--spec", str(spec), "--x0", "0.0:0.1"]
    argv += ["--theta0", "0", "--no-noise", "--budget", "4", "--duration", "1", "--engine", "mujoco"]
    assert main([*argv, "--out", "fz", "--json"]) == 1
    out = _strict(capsys.readouterr().out)
    data = _strict((tmp_path / "fz" / "falsify.json").read_text())
    assert isinstance(out, dict) and isinstance(data, dict)
    assert data["counterexample"]["objective"] == -ROBUSTNESS_LIMIT
    assert all(t["objective"] == -ROBUSTNESS_LIMIT for t in data["trace"])
    replay = load_replay(tmp_path / "fz" / "falsify.json")
    assert replay.controller == "fails_ctrl:Fails"
