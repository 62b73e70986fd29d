"""Learn a controller on the twin: augmented random search over a linear policy of the last blocks' raw volts.

    python scripts/train_policy.py --out learned/            # then: cd learned && ballbeam validate …

The policy is ``controllers.policy.LinearPolicy``: the DAC command as an affine map of the last ``--stack``
blocks' ball and angle ADC volts (``BallBeam-v0``'s "volts" observation, through the full sensor chain with
its noise). It is searched in a basis of each channel's newest level and the differences of consecutive
blocks, each scaled by its running spread (``block_features``): there a rate is one input, as it is to a
state feedback. The search is Mania, Guy and Recht's augmented
random search (ARS V2-t, "Simple random search provides a competitive approach to reinforcement learning",
2018): each iteration draws ``--directions`` perturbations δ of the weights, runs the policy at θ + νδ and
θ − νδ for one episode each (a pair shares its start and noise seed), and steps θ along the ``--top`` best
directions' return differences, scaled by their spread. Every episode of an iteration runs at once on the
vector environment (one batch). numpy only; the same seed gives the same policy, bit for bit.

Episodes start uniformly in the box ``ballbeam validate`` requires to be held (|x0| ≤ 0.2 m, |θ0| ≤ 0.3 rad,
which holds the chapter 4 and all chapter 6 hardware starts). The folder gets ``policy.json``, a module
``learned_policy.py`` whose ``make_policy`` builds the controller (``--controller learned_policy:make_policy``)
and ``training.json`` (settings, the return of every iteration, the wall time); with ``--validate`` the
script then runs ``ballbeam validate`` on the policy into ``OUT/validation`` and prints its verdict.
``--spread FILE`` or ``--calibration DIR`` train on rigs drawn from what you know of yours (each episode its
own draw, as ``ballbeam montecarlo`` draws them), and validate over the same spread.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import argparse  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import subprocess  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402

import numpy as np  # noqa: E402

from controllers.policy import LinearPolicy  # noqa: E402
from twin import fixedorder  # noqa: E402
from twin.app.envs import BallBeamVectorEnv  # noqa: E402
from twin.learning import ActionSpec, ObservationSpec  # noqa: E402
from twin.outputs import JobFiles, atomic_directory, check_output_folder  # noqa: E402

OUTPUTS = JobFiles("train_policy", ("policy.json", "learned_policy.py", "training.json"))
REQUIRED_X0_M = (-0.2, 0.2)  # twin.app.validate.ValidationCriteria's required box
REQUIRED_THETA0_RAD = (-0.3, 0.3)

MODULE = '''"""The policy learned by scripts/train_policy.py: ``--controller learned_policy:make_policy``."""

from pathlib import Path

from controllers.policy import LinearPolicy


def make_policy(software=None):
    return LinearPolicy.load(Path(__file__).with_name("policy.json")).controller(software)
'''


@dataclass(frozen=True)
class Settings:
    iterations: int
    directions: int
    top: int
    step: float
    explore: float
    stack: int
    duration_s: float
    seed: int
    spread: str | None = None  # domain randomization: each episode's rig drawn from this spread file
    calibration: str | None = None  # … or from this calibration's values and uncertainties


class RunningNorm:
    """The observations' running mean and covariance (Welford, merged batch by batch; the sums over the batch
    axis add row after row, in numpy's order on any machine)."""

    def __init__(self, k: int) -> None:
        self.n = 0
        self.mean = np.zeros(k)
        self.m2 = np.zeros((k, k))

    def add(self, x: np.ndarray) -> None:
        m = len(x)
        if not m:
            return
        mean_b = x.mean(axis=0)
        xc = x - mean_b
        m2_b = (xc[:, :, None] * xc[:, None, :]).sum(axis=0)
        delta = mean_b - self.mean
        total = self.n + m
        self.mean = self.mean + delta * m / total
        self.m2 = self.m2 + m2_b + np.multiply.outer(delta, delta) * (self.n * m / total)
        self.n = total

    def scaling(self, features: np.ndarray) -> np.ndarray:
        """diag(1/σ)·F for the feature map F (features = F·obs): each feature's spread by the running
        covariance (σ_i² = (F·C·Fᵀ)_ii, in Python floats), floored at 1 mV. The identity scaling before any
        data."""
        if self.n < 2:
            return features.copy()
        c = (self.m2 / (self.n - 1)).tolist()
        rows = features.tolist()
        out = []
        for f in rows:
            cf = [fixedorder.dot(row, f) for row in c]  # C·f (C symmetric)
            sd = max(fixedorder.dot(f, cf), 1e-6) ** 0.5
            out.append([v / sd for v in f])
        return np.array(out)


def block_features(spec: ObservationSpec) -> np.ndarray:
    """F: per channel the newest block's level and the differences of consecutive blocks (newest first), a
    change of basis of the stacked observation in which a rate is one input: the search then finds the
    finite-difference state feedback that holds the ball (README, "Validate your own controller") as a
    point of its space, not as a narrow valley of two nearly opposite weights."""
    k = spec.size
    f = np.zeros((k, k))
    for c in (0, 1):  # ball, angle (observation(): pairs newest first)
        f[c, c] = 1.0
        for j in range(spec.stack - 1):
            row = 2 + 2 * j + c
            f[row, 2 * j + c], f[row, 2 * (j + 1) + c] = 1.0, -1.0
    return f


def _sd(values: np.ndarray) -> float:
    mean = fixedorder.total(values.tolist()) / len(values)
    return float(np.sqrt(fixedorder.total(((values - mean) ** 2).tolist()) / len(values)))


def effective(weights: np.ndarray, scaling: np.ndarray) -> np.ndarray:
    """Weights on the scaled features as weights on (obs − mean): w·(M·x) = (Mᵀ·w)·x, each row."""
    columns = scaling.T.tolist()  # row i of Mᵀ
    return np.array([[fixedorder.dot(col, list(w)) for col in columns] for w in weights.tolist()])


def episode_returns(
    env: BallBeamVectorEnv,
    weights: np.ndarray,
    bias: np.ndarray,
    mean: np.ndarray,
    seeds: list[int],
    norm: RunningNorm | None,
) -> np.ndarray:
    """One episode of each policy bias[i] + weights[i]·(obs − mean), env i with seed ``seeds[i]``: the returns,
    the observations seen added to ``norm``."""
    obs, _ = env.reset(seed=seeds)
    n = len(weights)
    returns = np.zeros(n)
    going = np.ones(n, dtype=bool)
    while going.any():
        action = bias + fixedorder.dots(obs - mean, weights)
        if norm is not None:
            norm.add(obs[going])
        obs, reward, terminated, truncated, _ = env.step(action[:, None])
        returns += np.where(going, reward, 0.0)
        going &= ~(terminated | truncated)
    return returns


def train(s: Settings, progress: bool = True) -> tuple[LinearPolicy, list[dict[str, float]], float]:
    spec = ObservationSpec("volts", s.stack, False)
    action = ActionSpec("dac")
    env = BallBeamVectorEnv(
        2 * s.directions,
        stack=s.stack,
        duration_s=s.duration_s,
        x0_range_m=REQUIRED_X0_M,
        theta0_range_rad=REQUIRED_THETA0_RAD,
        spread=s.spread,
        calibration=s.calibration,
    )
    rng = np.random.default_rng(np.random.SeedSequence([s.seed, 0x415253]))  # "ARS"
    k = spec.size
    theta = np.zeros(k + 1)
    theta[-1] = env.cfg.params.amplifier.zero_command_v  # start at 0 V on the motor
    norm = RunningNorm(k)
    features = block_features(spec)
    history: list[dict[str, float]] = []
    t0 = time.perf_counter()
    for it in range(s.iterations):
        mean, scaling = norm.mean.copy(), norm.scaling(features)
        delta = rng.standard_normal((s.directions, k + 1))
        pairs = [int(v) for v in rng.integers(2**31 - 1, size=s.directions)]
        weights = np.concatenate([theta + s.explore * delta, theta - s.explore * delta])
        seeds = pairs + pairs  # θ + νδ_j and θ − νδ_j see the same start and noise
        returns = episode_returns(env, effective(weights[:, :-1], scaling), weights[:, -1], mean, seeds, norm)
        plus, minus = returns[: s.directions], returns[s.directions :]
        best = np.argsort(-np.maximum(plus, minus), kind="stable")[: s.top]
        spread = _sd(np.concatenate([plus[best], minus[best]]))
        if spread > 0:  # products added in a fixed order: the same policy on any machine
            step = fixedorder.dots(delta[best].T, plus[best] - minus[best])
            theta = theta + s.step / (s.top * spread) * step
        history.append(
            {"iteration": it, "mean_return": float(returns.mean()), "best_return": float(returns.max())}
        )
        if progress:
            print(
                f"iteration {it:4d}: mean return {returns.mean():7.1f}, best {returns.max():7.1f}", flush=True
            )
    wall = time.perf_counter() - t0
    # θ in the scaling its last step was taken in, folded into weights on the raw volts (scale 1).
    policy = LinearPolicy(
        weights=tuple(float(v) for v in effective(theta[None, :-1], scaling)[0]),
        bias=float(theta[-1]),
        mean=tuple(float(v) for v in mean),
        scale=(1.0,) * k,
        obs_spec=spec,
        action_spec=action,
    )
    return policy, history, wall


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="folder for policy.json, learned_policy.py, training.json")
    ap.add_argument(
        "--overwrite", action="store_true", help="replace this script's files in an existing --out"
    )
    ap.add_argument("--iterations", type=int, default=100)
    ap.add_argument(
        "--directions", type=int, default=16, help="perturbations per iteration (2 episodes each)"
    )
    ap.add_argument("--top", type=int, default=8, help="best directions used in a step")
    ap.add_argument("--step", type=float, default=0.02, help="step size α")
    ap.add_argument("--explore", type=float, default=0.05, help="perturbation size ν")
    ap.add_argument("--stack", type=int, default=2, help="blocks in the observation")
    ap.add_argument("--duration", type=float, default=10.0, help="episode length (s)")
    ap.add_argument("--seed", type=int, default=0)
    rigs = ap.add_mutually_exclusive_group()
    rigs.add_argument("--spread", help="train on rigs drawn from this spread file (domain randomization)")
    rigs.add_argument("--calibration", help="train on rigs drawn from this calibration folder")
    ap.add_argument("--validate", action="store_true", help="run ballbeam validate on the policy afterwards")
    args = ap.parse_args(argv)
    if not 1 <= args.top <= args.directions:
        ap.error(f"--top {args.top}: between 1 and --directions ({args.directions})")
    for name in ("iterations", "directions", "stack"):
        if getattr(args, name) < 1:
            ap.error(f"--{name} {getattr(args, name)}: at least 1")
    for name in ("step", "explore", "duration"):
        if not getattr(args, name) > 0:
            ap.error(f"--{name} {getattr(args, name)}: a positive number")
    try:
        check_output_folder("--out", args.out, OUTPUTS, overwrite=args.overwrite)
    except (OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    s = Settings(
        args.iterations,
        args.directions,
        args.top,
        args.step,
        args.explore,
        args.stack,
        args.duration,
        args.seed,
        args.spread,
        args.calibration,
    )
    try:
        policy, history, wall = train(s)
    except ValueError as exc:  # a spread or calibration the environment refuses: named, no traceback
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"trained in {wall:.1f} s on {os.cpu_count()} CPUs")
    with atomic_directory(args.out, OUTPUTS, overwrite=args.overwrite) as tmp:
        (tmp / "policy.json").write_text(json.dumps(policy.to_json(), indent=1) + "\n")
        (tmp / "learned_policy.py").write_text(MODULE)
        record = {
            "settings": s.__dict__,
            "wall_s": round(wall, 1),
            "cpus": os.cpu_count(),
            "history": history,
        }
        (tmp / "training.json").write_text(json.dumps(record, indent=1) + "\n")
    print(f"wrote {args.out}/policy.json, learned_policy.py, training.json")
    if not args.validate:
        return 0
    out = Path(args.out).resolve()
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(out), str(Path(__file__).resolve().parents[1])]))
    cmd = [sys.executable, "-m", "twin.app.cli", "validate", "--controller", "learned_policy:make_policy"]
    if args.spread or args.calibration:  # validated over the rigs it was trained on
        cmd += ["--spread", str(Path(args.spread).resolve())] if args.spread else []
        cmd += ["--calibration", str(Path(args.calibration).resolve())] if args.calibration else []
    cmd += ["--out", str(out / "validation"), "--overwrite"]
    print("$ " + " ".join(cmd[2:]), flush=True)
    return subprocess.run(cmd, env=env, cwd=out, check=False).returncode


if __name__ == "__main__":
    raise SystemExit(main())
