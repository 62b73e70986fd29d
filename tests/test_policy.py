"""A learned policy as a controller: LinearPolicy's file and bits, PolicyController's contract, and the training
example end to end (its folder, its module through --controller, the same policy from the same seed)."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from controllers.policy import LinearPolicy, PolicyController
from twin.interface import Controller, DaqSample, Setpoint
from twin.learning import ActionSpec, ObservationSpec, observation
from twin.parameters import Parameters
from twin.rigs.sim import run_closed_loop

ROOT = Path(__file__).resolve().parents[1]


def _policy(kind: str = "volts", stack: int = 2, setpoint: bool = False) -> LinearPolicy:
    spec = ObservationSpec(kind, stack, setpoint)  # type: ignore[arg-type]
    rng = np.random.default_rng(0)
    k = spec.size
    return LinearPolicy(
        tuple(rng.normal(0, 0.1, k)),
        2.5,
        tuple(rng.normal(2.5, 0.1, k)),
        tuple(rng.uniform(0.1, 1, k)),
        spec,
        ActionSpec(),
    )


@pytest.mark.quick
def test_a_policy_file_round_trips_and_a_bad_one_is_refused_naming_it(tmp_path: Path) -> None:
    policy = _policy(setpoint=True)
    path = tmp_path / "policy.json"
    path.write_text(json.dumps(policy.to_json()))
    assert LinearPolicy.load(path) == policy
    bad = tmp_path / "bad.json"
    for text, says in (
        ("{", "cannot read a policy"),
        ('{"format": "other"}', "not a linear policy"),
        (json.dumps({**policy.to_json(), "weights": [1.0]}), "weights: 5 finite numbers"),
        (json.dumps({**policy.to_json(), "scale": [0.0] * 5}), "scale: positive numbers"),
        (
            json.dumps({**policy.to_json(), "observation": {"kind": "volts", "stack": 0, "setpoint": True}}),
            "stack = 0",
        ),
    ):
        bad.write_text(text)
        with pytest.raises(ValueError, match=str(bad)) as err:
            LinearPolicy.load(bad)
        assert says in str(err.value)


@pytest.mark.quick
def test_the_policy_gives_the_same_bits_alone_and_over_a_batch() -> None:
    policy = _policy(stack=3)
    obs = np.random.default_rng(1).normal(2.5, 0.5, (50, policy.obs_spec.size))
    batch = policy(obs)
    assert batch.shape == (50, 1)
    assert all(policy(o)[0] == batch[i, 0] for i, o in enumerate(obs))
    # and it is the affine map it says, up to rounding
    x = (obs - np.array(policy.mean)) / np.array(policy.scale)
    assert np.allclose(batch[:, 0], policy.bias + x @ np.array(policy.weights), rtol=0, atol=1e-12)


@pytest.mark.quick
def test_the_controller_sees_the_environments_observation() -> None:
    """start fills the history with the start block; each update shifts the next block in (twin.learning)."""
    seen: list[np.ndarray] = []
    p = Parameters()

    def record(obs: np.ndarray) -> float:
        seen.append(obs)
        return 2.6

    c = PolicyController(record, observation=ObservationSpec("converted", 3, True), setpoint_m=0.05)
    assert isinstance(c, Controller) and isinstance(c, Setpoint) and c.period_s == p.daq.period_s
    blocks = [DaqSample(0.02 * k, 2.0 + 0.1 * k, 1.0 - 0.05 * k) for k in range(4)]
    c.start(blocks[0])
    for k in (1, 2, 3):
        assert c.update(blocks[k]) == 2.6
    ball = [b.ball_v for b in blocks]
    angle = [b.angle_v for b in blocks]
    spec = ObservationSpec("converted", 3, True)
    assert np.array_equal(
        seen[0], observation(spec, ball[:1] * 2 + ball[1:2], angle[:1] * 2 + angle[1:2], p, 0.05)
    )
    assert np.array_equal(seen[2], observation(spec, ball[1:], angle[1:], p, 0.05))
    # u is the motor volts the command means, (2.6 − 2.5)·9.6
    assert c.telemetry.u == pytest.approx(0.96)
    assert not isinstance(PolicyController(record), Setpoint)  # no setpoint in its observation: none declared


@pytest.mark.quick
def test_a_policy_returning_nan_fails_the_run_naming_the_tick() -> None:
    c = PolicyController(lambda obs: np.array([np.nan]))
    with pytest.raises(Exception, match="finite") as err:
        run_closed_loop(c, x0_m=0.0, theta0_rad=0.0, duration_s=0.2)
    assert "tick" in str(err.value) or "finite" in str(err.value)


def _train(out: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    argv = [sys.executable, str(ROOT / "scripts" / "train_policy.py"), "--out", str(out)]
    argv += ["--iterations", "2", "--directions", "2", "--top", "1", "--duration", "0.4", *extra]
    return subprocess.run(argv, capture_output=True, text=True, timeout=600, cwd=ROOT)


def test_the_training_example_writes_a_policy_the_commands_accept(tmp_path: Path) -> None:
    first, second = tmp_path / "a", tmp_path / "b"
    done = _train(first)
    assert done.returncode == 0, done.stderr
    assert _train(second).returncode == 0
    assert (first / "policy.json").read_bytes() == (
        second / "policy.json"
    ).read_bytes()  # same seed, same bits
    record = json.loads((first / "training.json").read_text())
    assert len(record["history"]) == 2 and record["settings"]["seed"] == 0
    spec = importlib.util.spec_from_file_location("learned_policy_test", first / "learned_policy.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    controller = module.make_policy(Parameters().software)
    assert isinstance(controller, PolicyController)
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "twin.app.cli",
            "run",
            "--controller",
            "learned_policy:make_policy",
            "--x0",
            "0.1",
            "--theta0",
            "0",
            "--duration",
            "0.5",
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=first,
        env={"PYTHONPATH": f"{ROOT}:{first}", "PATH": ""},
    )
    assert run.returncode in (0, 1) and "Traceback" not in run.stderr, run.stderr
    assert json.loads(run.stdout)["controller"] == "learned_policy:make_policy"
    # an existing folder is not written over without --overwrite, and --overwrite replaces only its files
    (first / "notes.txt").write_text("mine")
    again = _train(first)
    assert again.returncode == 2 and "Traceback" not in again.stderr
    assert _train(first, "--overwrite", "--seed", "1").returncode == 0
    assert (first / "notes.txt").read_text() == "mine"
    assert (first / "policy.json").read_bytes() != (second / "policy.json").read_bytes()


def test_the_training_example_trains_on_a_spread_and_refuses_a_bad_one(tmp_path: Path) -> None:
    done = _train(tmp_path / "dr", "--spread", str(ROOT / "docs" / "examples" / "spread.toml"))
    assert done.returncode == 0, done.stderr
    record = json.loads((tmp_path / "dr" / "training.json").read_text())
    assert record["settings"]["spread"].endswith("spread.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[motor]\nresistance_ohm = { sd = -1 }\n")
    refused = _train(tmp_path / "x", "--spread", str(bad))
    assert refused.returncode == 2 and "Traceback" not in refused.stderr and str(bad) in refused.stderr
    assert not (tmp_path / "x").exists()
