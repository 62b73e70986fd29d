"""The MuJoCo twin's linearization equals the analytic reference model's (issue acceptance: 1 %)."""

import json
import subprocess
import sys

import numpy as np
import pytest

from twin.linearize import linearize_mujoco
from twin.reference import ReferenceModel


@pytest.mark.parametrize("kind", ["torque", "voltage"])
def test_mujoco_linearization_matches_reference(params, reference: ReferenceModel, kind: str) -> None:
    a, b = linearize_mujoco(params, kind)
    a_ref, b_ref = reference.linearize(kind)
    for got, want, name in ((a, a_ref, "A"), (b, b_ref, "B")):
        big = np.abs(want) > 1e-3
        rel = np.abs(got - want)[big] / np.abs(want)[big]
        assert rel.max() < 0.01, f"{kind} {name}: worst relative error {rel.max():.4f}"
        # Entries the reference has as (near) zero stay small in the twin too.
        assert np.all(np.abs(got[~big]) < 1e-3), f"{kind} {name}"


def test_cli_prints_the_linearization_as_json() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "twin.app.cli", "linearize", "--input", "voltage", "--json"],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    result = json.loads(out.stdout)
    assert result["state"] == ["x", "theta", "xdot", "thetadot"]
    assert result["input"] == "voltage"
    a, b = np.array(result["A"]), np.array(result["B"])
    assert a.shape == (4, 4) and b.shape == (4, 1)
    ref = subprocess.run(
        [
            sys.executable,
            "-m",
            "twin.app.cli",
            "linearize",
            "--input",
            "voltage",
            "--source",
            "reference",
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    np.testing.assert_allclose(a, np.array(json.loads(ref.stdout)["A"]), rtol=0.01, atol=1e-3)


def test_cli_reports_a_bad_parameter_file(tmp_path) -> None:
    bad = tmp_path / "rig.toml"
    bad.write_text("[motor]\nresistance_ohm = 0\n")
    out = subprocess.run(
        [sys.executable, "-m", "twin.app.cli", "linearize", "--params", str(bad)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 2
    assert "motor.resistance_ohm = 0.0" in out.stderr and str(bad) in out.stderr
    assert "Traceback" not in out.stderr
