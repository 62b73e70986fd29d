"""BallBeam-v0: Gymnasium's checker on every option, determinism, the vector env equal to the single env bit for
bit (autoreset included), domain randomization that samples the calibration and never compounds, an episode
equal to ``ballbeam run`` of the same policy, and clear refusals."""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from controllers.policy import LinearPolicy
from twin.app.envs import ENV_ID, BallBeamEnv, BallBeamVectorEnv
from twin.learning import REWARD_WEIGHTS, ActionSpec, ObservationSpec, reward
from twin.parameters import Parameters
from twin.rigs.sim import run_closed_loop

OPTIONS: list[dict[str, Any]] = [
    {},
    {"observation": "converted", "stack": 4},
    {"setpoint_in_observation": True, "setpoint_range_m": (-0.1, 0.1)},
    {"action": "motor"},
    {"ideal_sensors": True, "noise": False},
    {"plant": "reference"},
    {"terminate_at_stops": False, "duration_s": 1.0},
    {"starts": [(0.14, -0.2), (-0.13, 0.29)]},
    {"spread": "docs/examples/spread.toml"},
]


@pytest.mark.quick
@pytest.mark.parametrize("options", OPTIONS, ids=lambda o: ",".join(o) or "default")
def test_gymnasiums_checker_passes(options: dict[str, Any]) -> None:
    env = gymnasium.make(f"twin.app.envs:{ENV_ID}", **options)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # its advice to normalize a Box of volts to [-1, 1]
        check_env(env.unwrapped, skip_render_check=True)


def _episode(env: gymnasium.Env, seed: int, actions: np.ndarray) -> list[Any]:
    obs, info = env.reset(seed=seed)
    out = [obs, info["true_state"]]
    for a in actions:
        obs, r, term, trunc, info = env.step(a)
        out += [obs, r, term, trunc, info["true_state"]]
        if term or trunc:
            out.append(info["verdict"])
            break
    return out


def _same(a: list[Any], b: list[Any]) -> bool:
    return len(a) == len(b) and all(
        np.array_equal(x, y) if isinstance(x, np.ndarray) else x == y for x, y in zip(a, b, strict=True)
    )


def test_the_same_seed_gives_the_same_episode_and_another_seed_another() -> None:
    actions = np.random.default_rng(0).uniform(2.3, 2.7, (120, 1))
    env = BallBeamEnv(x0_range_m=(-0.2, 0.2), theta0_range_rad=(-0.3, 0.3), duration_s=2.0)
    first = _episode(env, 7, actions)
    assert _same(first, _episode(env, 7, actions))  # the same env, reseeded
    assert _same(
        first,
        _episode(
            BallBeamEnv(x0_range_m=(-0.2, 0.2), theta0_range_rad=(-0.3, 0.3), duration_s=2.0), 7, actions
        ),
    )
    other = _episode(env, 8, actions)
    assert not np.array_equal(first[0], other[0])
    assert not np.array_equal(first[1], other[1])  # another start


def test_the_vector_env_is_the_single_env_bit_for_bit() -> None:
    """64 envs, random commands, episodes ending by loss, stops and truncation (next-step autoreset): every
    observation, reward, termination, truncation, true state and verdict is the single env's with seed + i."""
    n, steps = 64, 160
    options: dict[str, Any] = {"stack": 3, "x0_range_m": (-0.25, 0.25), "duration_s": 1.2}
    venv = gymnasium.make_vec(
        f"twin.app.envs:{ENV_ID}", num_envs=n, vectorization_mode="vector_entry_point", **options
    )
    singles = [BallBeamEnv(**options) for _ in range(n)]
    obs, infos = venv.reset(seed=100)
    for i, env in enumerate(singles):
        o, info = env.reset(seed=100 + i)
        assert np.array_equal(o, obs[i]) and np.array_equal(info["true_state"], infos["true_state"][i])
    actions = np.random.default_rng(1).uniform(1.8, 3.2, (steps, n, 1))
    pending = np.zeros(n, dtype=bool)
    ends = {"lost": 0, "stops": 0, "truncated": 0}
    for k in range(steps):
        obs, rewards, terms, truncs, infos = venv.step(actions[k])
        for i, env in enumerate(singles):
            if pending[i]:  # autoreset: this step is the next episode's reset
                o, info = env.reset()
                r, term, trunc = 0.0, False, False
            else:
                o, r, term, trunc, info = env.step(actions[k, i])
                if term or trunc:
                    assert infos["_verdict"][i] and infos["verdict"][i] == info["verdict"]
                    ends["truncated" if trunc else "lost" if info["ball_lost"] else "stops"] += 1
            assert np.array_equal(o, obs[i]), (k, i)
            assert (r, term, trunc) == (rewards[i], terms[i], truncs[i]), (k, i)
            assert np.array_equal(info["true_state"], infos["true_state"][i])
            pending[i] = term or trunc
    assert all(count > 0 for count in ends.values()), ends  # every way an episode ends was exercised
    venv.close()


def _calibration(tmp_path: Path) -> Path:
    """A calibration as ``ballbeam calibrate`` writes it: three values, their uncertainties, a correlation."""
    out = tmp_path / "cal"
    out.mkdir()
    Parameters().save(out / "params.toml")
    p = Parameters()
    data = {
        "params": {
            "motor.resistance_ohm": {"value": 9.8, "sd": 0.3},
            "beam.inertia_pivot_kgm2": {"value": p.beam.inertia_pivot_kgm2 * 1.05, "sd": 2e-4},
            "beam.pivot_damping_nm_s_per_rad": {"value": 1e-3, "sd": 1e-4},
        },
        "correlation": {
            "names": ["motor.resistance_ohm", "beam.inertia_pivot_kgm2", "beam.pivot_damping_nm_s_per_rad"],
            "matrix": [[1, 0.7, -0.3], [0.7, 1, 0.0], [-0.3, 0.0, 1]],
        },
    }
    (out / "calibration.json").write_text(json.dumps(data))
    return out


NAMES = ("motor.resistance_ohm", "beam.inertia_pivot_kgm2", "beam.pivot_damping_nm_s_per_rad")


def _values(p: Parameters) -> np.ndarray:
    return np.array([p.motor.resistance_ohm, p.beam.inertia_pivot_kgm2, p.beam.pivot_damping_nm_s_per_rad])


def test_domain_randomization_samples_the_calibration_and_does_not_compound(tmp_path: Path) -> None:
    cal = _calibration(tmp_path)
    data = json.loads((cal / "calibration.json").read_text())
    mean = np.array([data["params"][k]["value"] for k in NAMES])
    sd = np.array([data["params"][k]["sd"] for k in NAMES])
    cov = np.array(data["correlation"]["matrix"]) * np.outer(sd, sd)
    env = BallBeamEnv(calibration=cal, duration_s=0.1)
    base = env.cfg.params
    n = 1000
    env.reset(seed=3)
    draws = [_values(env.episode.params)]  # type: ignore[union-attr]
    for _ in range(n - 1):
        env.reset()
        draws.append(_values(env.episode.params))  # type: ignore[union-attr]
    x = np.array(draws)
    # Each mean within 4 standard errors; each covariance within 4 of its sampling sd,
    # sqrt((σ_i²σ_j² + σ_ij²)/n) for a normal sample.
    assert np.all(np.abs(x.mean(axis=0) - mean) < 4 * sd / np.sqrt(n))
    s = np.cov(x, rowvar=False)
    se = np.sqrt((np.outer(sd**2, sd**2) + cov**2) / n)
    assert np.all(np.abs(s - cov) < 4 * se), (s, cov)
    # Not compounding: the base is untouched, and the spread of the last 500 draws is the first 500's (a
    # random walk's would have grown with the episodes).
    assert env.cfg.params is base and _values(base).tolist() == _values(Parameters()).tolist()
    first, last = x[:500].std(axis=0), x[500:].std(axis=0)
    assert np.all(np.abs(last / first - 1) < 0.2)
    # The rig each episode ran is the one drawn (its model compiled from those parameters).
    assert env.rig.params.motor.resistance_ohm == env.episode.params.motor.resistance_ohm  # type: ignore[union-attr]


@pytest.mark.quick
def test_the_vector_env_draws_each_envs_rigs_as_the_single_env(tmp_path: Path) -> None:
    cal = _calibration(tmp_path)
    venv = BallBeamVectorEnv(4, calibration=cal, duration_s=0.2)
    venv.reset(seed=11)
    for _ in range(25):  # past two episode ends
        venv.step(np.full((4, 1), 2.5))
    singles = [BallBeamEnv(calibration=cal, duration_s=0.2) for _ in range(4)]
    for i, env in enumerate(singles):
        env.reset(seed=11 + i)
        for _ in range(2):
            env.reset()
        assert env.episode == venv._episodes[i]


@pytest.mark.quick
def test_an_episode_is_ballbeam_run_of_the_same_policy() -> None:
    """A policy stepped through the env and the same policy as a PolicyController in ``run_closed_loop`` write
    the same DAC commands and reach the same verdict (the env's reset/step are the engine's start/tick)."""
    spec = ObservationSpec("converted", 3, False)
    rng = np.random.default_rng(3)
    policy = LinearPolicy(
        tuple(rng.normal(0, 0.05, 6)), 2.5, (0.0,) * 6, (0.1, 0.3) * 3, spec, ActionSpec("dac")
    )
    env = BallBeamEnv(observation="converted", stack=3, duration_s=3.0)
    obs, _ = env.reset(seed=4, options={"x0_m": 0.1, "theta0_rad": -0.1})
    ep = env.episode
    assert ep is not None
    commands, done = [], False
    while not done:
        action = policy(obs)
        commands.append(float(env.cfg.action.command_v(action, ep.params)[0]))
        obs, _, term, trunc, info = env.step(action)
        done = term or trunc
    run = run_closed_loop(policy.controller(), x0_m=0.1, theta0_rad=-0.1, duration_s=3.0, seed=ep.noise_seed)
    assert run.log is not None
    assert run.log.aout[1 : len(commands) + 1].tolist() == commands
    assert run.verdict.to_json() == info["verdict"]


@pytest.mark.quick
def test_the_reward_is_as_documented() -> None:
    p = Parameters()
    w_e, w_th, w_u, w_rail = REWARD_WEIGHTS
    half, stop, rail = p.track.half_length_m, p.beam.stop_angle_rad, p.amplifier.rail_v
    assert reward(0.0, 0.0, 0.0, p) == 1.0
    assert reward(half, 0.0, 0.0, p) == pytest.approx(1 - w_e)
    assert reward(0.1, 0.0, 0.0, p, setpoint_m=0.1) == 1.0
    assert reward(0.0, stop, 0.0, p) == pytest.approx(1 - w_th)
    assert reward(0.0, 0.0, rail / 2, p) == pytest.approx(1 - w_u / 4)
    assert reward(0.0, 0.0, -rail, p) == pytest.approx(1 - w_u - w_rail)
    worst = reward(-half, stop, rail, p, setpoint_m=0.0)  # every term at its largest: still worth staying
    assert worst == pytest.approx(1 - sum(REWARD_WEIGHTS)) and worst > 0


def test_an_episode_ends_as_documented() -> None:
    env = BallBeamEnv(duration_s=4.0)
    env.reset(seed=0, options={"x0_m": 0.0, "theta0_rad": 0.0})
    for k in range(200):  # 0 V on the motor, the ball at rest on a level beam: nothing happens but time
        _, r, term, trunc, info = env.step(np.array([2.5]))
        assert not term and trunc == (k == 199)
    assert (
        info["verdict"]["held"]
        and info["verdict"]["duration_s"] == pytest.approx(4.0 + Parameters().start.free_run_s)
        and info["sim_only"]
    )
    env.reset(seed=0, options={"x0_m": 0.3, "theta0_rad": -0.3})  # tilted toward the end it starts at
    for _ in range(200):
        _, _, term, trunc, info = env.step(np.array([2.5]))
        if term or trunc:
            break
    assert term and info["ball_lost"] and info["verdict"]["ball_lost"]
    env.reset(seed=0, options={"x0_m": 0.0, "theta0_rad": 0.0})
    for _ in range(200):  # full positive drive: the beam runs to its stops
        _, _, term, trunc, info = env.step(np.array([5.0]))
        if term:
            break
    assert term and info["at_stops"] and not info["ball_lost"]


@pytest.mark.parametrize(
    "options, message",
    [
        ({"observation": "ohms"}, "observation = 'ohms'"),
        ({"action": "torque"}, "action = 'torque'"),
        ({"stack": 0}, "stack = 0"),
        ({"duration_s": -1.0}, "duration_s = -1.0"),
        ({"x0_range_m": (-0.5, 0.5)}, "x0_range_m"),
        ({"theta0_range_rad": (0.3, -0.3)}, "theta0_range_rad"),
        ({"starts": [(0.4, 0.0)]}, "off the track"),
        ({"plant": "simulink"}, "plant = 'simulink'"),
        ({"spread": "no/such/spread.toml"}, "no/such/spread.toml"),
        ({"noise": "yes"}, "noise = 'yes'"),
    ],
)
def test_bad_options_are_refused_naming_them(options: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        BallBeamEnv(**options)


def test_bad_actions_and_reset_options_are_refused() -> None:
    env = BallBeamEnv()
    with pytest.raises(ValueError, match="initial x_m = 0.5 is off the track"):
        env.reset(seed=0, options={"x0_m": 0.5})
    with pytest.raises(ValueError, match="known are"):
        env.reset(seed=0, options={"x0": 0.1})
    env.reset(seed=0)
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([np.nan]))
    obs, *_ = env.step(np.array([99.0]))  # clipped to the DAC's 5 V, as the card would
    assert env.rig.command_v == 5.0
    assert env.observation_space.contains(obs)
    short = BallBeamEnv(duration_s=0.04)
    short.reset(seed=0)
    assert short.step(np.array([2.5]))[3] is False and short.step(np.array([2.5]))[3] is True
    with pytest.raises(RuntimeError, match="the episode has ended"):
        short.step(np.array([2.5]))


def test_vector_reset_options_set_each_env_as_the_single_envs_do() -> None:
    x0, th0, seeds = np.array([0.1, -0.05, 0.2]), np.array([0.0, 0.1, -0.2]), np.array([5, 6, 7])
    venv = BallBeamVectorEnv(3, duration_s=0.5)
    obs, infos = venv.reset(
        seed=1, options={"x0_m": x0, "theta0_rad": th0, "noise_seed": seeds, "setpoint_m": 0.02}
    )
    for i in range(3):
        env = BallBeamEnv(duration_s=0.5)
        o, info = env.reset(
            seed=1 + i,
            options={"x0_m": x0[i], "theta0_rad": th0[i], "noise_seed": seeds[i], "setpoint_m": 0.02},
        )
        assert np.array_equal(o, obs[i]) and np.array_equal(info["true_state"], infos["true_state"][i])
        assert (
            env.episode is not None and env.episode.noise_seed == seeds[i] and env.episode.setpoint_m == 0.02
        )
    with pytest.raises(ValueError, match="noise_seed = -1"):
        venv.reset(seed=1, options={"noise_seed": -1})
