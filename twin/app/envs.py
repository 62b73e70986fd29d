"""The twin as a Gymnasium environment: ``BallBeam-v0`` (one rig) and its vector form on the batch engine.

``gymnasium.make("twin.app.envs:BallBeam-v0", **options)`` (the module-prefixed id imports this module,
which registers the id; Gymnasium 1.x loads no plugins by itself) or ``gymnasium.make_vec("twin.app.envs:
BallBeam-v0", num_envs=N, vectorization_mode="vector_entry_point", **options)``.

A step is one 20 ms tick of the one loop (``twin.engine.ClosedLoop`` on ``twin.rigs.sim.SimRig``, as ``ballbeam
run``) whose controller is the agent: the action answers the block last observed (``ClosedLoop.answer``), the
next block is read (``ClosedLoop.sense``). ``reset`` holds the rig at the episode's initial state and
reads the start block (k = −1, what ``Controller.start`` reads) and block 0 (the first ``update``'s): the
first action is the command computed from block 0, as on the rig. Observation, action and reward:
``twin.learning`` (their one home, shared with ``controllers.policy.PolicyController``).

Each reset draws, from the environment's generator in this order: the episode's rig (a sample of the spread
or calibration, about the base parameters: never about the last episode's), the initial state (uniform over
``x0_range_m`` × ``theta0_range_rad``, or one of ``starts``), the setpoint (uniform over
``setpoint_range_m``) and the sensor-noise seed. ``reset(options={"x0_m": …, "theta0_rad": …,
"setpoint_m": …, "noise_seed": …})`` sets them for that episode (the draws are still made: the stream does
not shift); the vector env takes one value for all or an array of one per env.

``info`` is simulation only (``info["sim_only"]`` is True): the true state (x, θ, ẋ, θ̇), the simulated time,
the motor volts, the lost ball and the stops; at an episode's end ``info["verdict"]``, the verdict of the
episode as ``ballbeam run`` gives it (``twin.verdict.Verdict.to_json``), judged about the setpoint. Nothing of
it exists on the rig: a policy must not read it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import gymnasium
import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv

from twin.app.options import MAX_RUN_S
from twin.engine import ClosedLoop, block_peak_abs_theta_rad, judge
from twin.interface import Controller, DaqSample
from twin.learning import (
    ActionKind,
    ActionSpec,
    ObservationKind,
    ObservationSpec,
    check_action,
    check_actions,
    episode_ticks,
    observation,
    reward,
)
from twin.parameters import Parameters
from twin.parts.description import rig_of
from twin.physics import check_initial_state, check_on_track
from twin.rigs.backends import DEFAULT_PLANT, backend
from twin.rigs.sim import make_rig
from twin.rigs.vector import VectorBlocks, VectorRig
from twin.verdict import Criteria, Trace

__all__ = ["ENV_ID", "BallBeamEnv", "BallBeamVectorEnv", "EnvConfig"]

ENV_ID = "BallBeam-v0"
# The chapter 7 range (twin.app.sweep's default grid): the whole track and nearly the whole stroke.
CHAPTER7_X0_M = (-0.32, 0.32)
CHAPTER7_THETA0_RAD = (-0.7, 0.7)
_SEED_BOUND = 2**31 - 1
RESET_OPTIONS = "x0_m, theta0_rad, setpoint_m, noise_seed"


@dataclass(frozen=True)
class EnvConfig:
    """The options of an environment, checked once (``ValueError`` naming the option)."""

    params: Parameters
    spread: Any  # twin.app.montecarlo.Distribution | None: each episode's rig is drawn from it
    obs: ObservationSpec
    action: ActionSpec
    duration_s: float
    x0_range_m: tuple[float, float]
    theta0_range_rad: tuple[float, float]
    starts: tuple[tuple[float, float], ...]
    setpoint_range_m: tuple[float, float]
    noise: bool
    ideal_sensors: bool
    plant: str  # a registered backend's name (twin.rigs.backends)
    terminate_at_stops: bool
    criteria: Criteria

    @property
    def ticks(self) -> int:
        return episode_ticks(self.duration_s, self.params.period_s)


def make_config(
    *,
    rig: str | Path | None = None,
    params: Parameters | str | Path | None = None,
    spread: str | Path | None = None,
    calibration: str | Path | None = None,
    observation: str = "volts",
    stack: int = 1,
    setpoint_in_observation: bool = False,
    action: str = "dac",
    duration_s: float = 10.0,
    x0_range_m: Sequence[float] = CHAPTER7_X0_M,
    theta0_range_rad: Sequence[float] = CHAPTER7_THETA0_RAD,
    starts: Sequence[Sequence[float]] | None = None,
    setpoint_range_m: Sequence[float] = (0.0, 0.0),
    noise: bool = True,
    ideal_sensors: bool = False,
    plant: str = DEFAULT_PLANT,
    terminate_at_stops: bool = True,
    criteria: Criteria | None = None,
) -> EnvConfig:
    """The environment's options (see ``BallBeamEnv``) checked into an ``EnvConfig``."""
    from twin.app.montecarlo import load_calibration_spread, load_spread

    _check_types(params, spread, calibration, criteria)
    if rig is not None and not isinstance(rig, (str, Path)):
        raise ValueError(f"rig = {rig!r:.80}: a rig description's path (….toml) or a preset's name")
    if calibration is not None and spread is not None:
        raise ValueError("give a spread or a calibration, not both")
    if rig is not None and isinstance(params, Parameters):
        raise ValueError("a Parameters is a whole rig: give rig or a Parameters as params, not both")
    described = rig_of(str(rig)) if rig is not None else Parameters()
    if isinstance(params, (str, Path)):
        base = Parameters.from_file(params, base=described)
    else:
        base = params or described
    dist = None
    if calibration is not None:
        if params is not None:
            raise ValueError("a calibration brings its parameters: give params or a calibration, not both")
        base, dist = load_calibration_spread(calibration)
    elif spread is not None:
        dist = load_spread(spread, base)
    backend(plant)  # a registered backend (ValueError naming the value and the choices otherwise)
    for name, flag in (
        ("setpoint_in_observation", setpoint_in_observation),
        ("noise", noise),
        ("ideal_sensors", ideal_sensors),
        ("terminate_at_stops", terminate_at_stops),
    ):
        if not isinstance(flag, (bool, np.bool_)):
            raise ValueError(f"{name} = {flag!r}: true or false")
    kind = "volts" if observation == "volts" else "converted" if observation == "converted" else None
    if kind is None:
        raise ValueError(f"observation = {observation!r}: expected 'volts' or 'converted'")
    if action not in ("dac", "motor"):
        raise ValueError(f"action = {action!r}: expected 'dac' or 'motor'")
    episode_ticks(duration_s, base.period_s, MAX_RUN_S)  # a positive duration, at most a run's
    x0r = _range("x0_range_m", x0_range_m)
    th0r = _range("theta0_range_rad", theta0_range_rad)
    spr = _range("setpoint_range_m", setpoint_range_m)
    half, stop = base.track.half_length_m, base.beam.stop_angle_rad
    for name, (lo, hi), bound in (("x0_range_m", x0r, half), ("theta0_range_rad", th0r, stop)):
        if max(abs(lo), abs(hi)) > bound:
            raise ValueError(f"{name} = {(lo, hi)}: beyond the rig (|value| ≤ {bound:.4f})")
    for end in spr:
        check_on_track(base, "setpoint_range_m", end)
    start_list: tuple[tuple[float, float], ...] = ()
    if starts is not None:
        try:
            start_list = tuple((float(a), float(b)) for a, b in starts)
        except (TypeError, ValueError):
            raise ValueError(f"starts = {starts!r}: pairs (x0_m, theta0_rad)") from None
        if not start_list:
            raise ValueError("starts is empty: give at least one (x0_m, theta0_rad)")
        for x0, th0 in start_list:
            check_initial_state(base, x0, th0, 0.0, 0.0)
    return EnvConfig(
        params=base,
        spread=dist,
        obs=ObservationSpec(
            cast(ObservationKind, kind),
            int(stack) if isinstance(stack, np.integer) else stack,
            bool(setpoint_in_observation),
        ),
        action=ActionSpec(cast(ActionKind, action)),
        duration_s=float(duration_s),
        x0_range_m=x0r,
        theta0_range_rad=th0r,
        starts=start_list,
        setpoint_range_m=spr,
        noise=bool(noise),
        ideal_sensors=bool(ideal_sensors),
        plant=plant,
        terminate_at_stops=bool(terminate_at_stops),
        criteria=criteria or Criteria(),
    )


def _check_types(params: object, spread: object, calibration: object, criteria: object) -> None:
    """The options that name files or carry objects, refused naming the option when of another type."""
    if params is not None and not isinstance(params, (Parameters, str, Path)):
        raise ValueError(f"params = {params!r:.80}: a Parameters, or the path of a parameter file")
    for name, value, what in (
        ("spread", spread, "spread file"),
        ("calibration", calibration, "calibration folder"),
    ):
        if value is not None and not isinstance(value, (str, Path)):
            raise ValueError(f"{name} = {value!r:.80}: the path of a {what}")
    if criteria is not None and not isinstance(criteria, Criteria):
        raise ValueError(f"criteria = {criteria!r:.80}: a twin.verdict.Criteria")


def _range(name: str, value: Sequence[float]) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} = {value!r}: expected (low, high)") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        raise ValueError(f"{name} = {value!r}: finite, low ≤ high")
    return lo, hi


@dataclass(frozen=True)
class Episode:
    """What a reset draws: the rig, the start, the setpoint, the noise seed."""

    params: Parameters
    x0_m: float
    theta0_rad: float
    setpoint_m: float
    noise_seed: int


def draw_episode(cfg: EnvConfig, rng: np.random.Generator, options: Mapping[str, Any] | None) -> Episode:
    """One episode's draws from ``rng`` in the documented order; ``options`` may set the start and setpoint."""
    from twin.app.montecarlo import sample_parameters

    params = cfg.params
    if cfg.spread is not None:
        sets, _ = sample_parameters(cfg.params, cfg.spread, 1, int(rng.integers(_SEED_BOUND)))
        params = sets[0]
    if cfg.starts:
        x0, th0 = cfg.starts[int(rng.integers(len(cfg.starts)))]
    else:
        x0 = float(rng.uniform(*cfg.x0_range_m))
        th0 = float(rng.uniform(*cfg.theta0_range_rad))
    setpoint = float(rng.uniform(*cfg.setpoint_range_m))
    seed = int(rng.integers(_SEED_BOUND))
    if options is not None and not isinstance(options, Mapping):
        raise ValueError(f"options = {options!r:.80}: a dict of {RESET_OPTIONS}")
    opts = dict(options or {})
    unknown = set(opts) - set(RESET_OPTIONS.split(", "))
    if unknown:
        raise ValueError(f"reset options {sorted(map(str, unknown))}: known are {RESET_OPTIONS}")
    if "noise_seed" in opts:
        given = opts["noise_seed"]
        if isinstance(given, (bool, np.bool_)) or not isinstance(given, (int, np.integer)) or given < 0:
            raise ValueError(f"noise_seed = {given!r}: a whole number ≥ 0")
        seed = int(given)
    x0 = _finite("x0_m", opts.get("x0_m", x0))
    th0 = _finite("theta0_rad", opts.get("theta0_rad", th0))
    setpoint = _finite("setpoint_m", opts.get("setpoint_m", setpoint))
    check_initial_state(params, x0, th0, 0.0, 0.0)
    check_on_track(params, "setpoint_m", setpoint)
    return Episode(params, x0, th0, setpoint, seed)


def _finite(name: str, value: Any) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{name} = {value!r}: a number")
    if not math.isfinite(float(value)):
        raise ValueError(f"{name} = {value!r}: a finite number")
    return float(value)


def _spaces(cfg: EnvConfig) -> tuple[spaces.Box, spaces.Box]:
    lo, hi = cfg.obs.bounds(cfg.params)
    a_lo, a_hi = cfg.action.bounds(cfg.params)
    return (
        spaces.Box(lo, hi, dtype=np.float64),
        spaces.Box(np.array([a_lo]), np.array([a_hi]), dtype=np.float64),
    )


class _Trace:
    """An episode's ticks for its verdict (``twin.engine.judge``: as ``ballbeam run`` records them)."""

    def __init__(self, n: int, ticks: int) -> None:
        self.cols = np.zeros((5, n, ticks + 2))  # true time, x, θ, motor volts, peak |θ|
        self.count = np.zeros(n, dtype=np.int64)

    def clear(self, rows: np.ndarray) -> None:
        self.count[rows] = 0

    def add(
        self, rows: np.ndarray, time_s: np.ndarray, state: np.ndarray, motor_v: np.ndarray, peak: np.ndarray
    ) -> None:
        k = self.count[rows]
        for j, values in enumerate((time_s, state[:, 0], state[:, 1], motor_v, peak)):
            self.cols[j, rows, k] = values
        self.count[rows] = k + 1

    def verdict(
        self, i: int, ep: Episode, lost_time_s: float | None, criteria: Criteria
    ) -> dict[str, object]:
        n = int(self.count[i])
        t, x, th, v, peak = (self.cols[j, i, :n] for j in range(5))
        return judge(
            ep.params,
            Trace(t, x, th, v, peak),
            x0_m=ep.x0_m,
            ball_lost_time_s=lost_time_s,
            criteria=criteria,
            x_ref_m=ep.setpoint_m,
        ).to_json()


def _step_outcome(
    cfg: EnvConfig,
    stop_rad: np.ndarray,
    state: np.ndarray,
    motor_v: np.ndarray,
    peak: np.ndarray,
    lost: np.ndarray,
    setpoint: np.ndarray,
    steps: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Rewards, terminations, truncations and the stops flags of rigs after a step (arrays over them): the
    reward's scales are the base rig's (the same for every episode), the stops each episode's own."""
    r = reward(state[:, 0], state[:, 1], motor_v, cfg.params, setpoint)
    at_stops = peak >= stop_rad - cfg.criteria.stop_tolerance_rad
    terminated = lost | (at_stops & cfg.terminate_at_stops)
    truncated = ~terminated & (steps >= cfg.ticks)
    return r, terminated, truncated, at_stops


class _Agent(Controller):
    """The environment's agent as the loop's controller: it answers each block from outside the loop, between
    ``step`` calls (``ClosedLoop.answer``), never through ``update``."""

    name = "agent"

    def __init__(self, period_s: float) -> None:
        super().__init__()
        self.period_s = period_s

    def start(self, sample: DaqSample) -> None:
        """The start block is the first observation's history: nothing to initialise."""

    def update(self, sample: DaqSample) -> float:
        raise RuntimeError("the agent's commands arrive with step(action), not from update")


class BallBeamEnv(gymnasium.Env[np.ndarray, np.ndarray]):
    """``BallBeam-v0``: the rig as a controller sees it, one 20 ms tick a step.

    Options (keywords of ``gymnasium.make``): ``params`` (``Parameters`` or a parameter file), ``spread`` (a
    spread file) or ``calibration`` (a ``ballbeam calibrate`` directory): each episode's rig drawn as
    ``ballbeam montecarlo`` draws it; ``observation`` "volts" | "converted", ``stack`` (blocks),
    ``setpoint_in_observation``; ``action`` "dac" (Box 0…5 V) | "motor" (Box ±12 V); ``duration_s`` (truncated
    after it, 10 s); ``x0_range_m``, ``theta0_range_rad`` (the chapter 7 range) or ``starts``;
    ``setpoint_range_m`` (0); ``noise``; ``ideal_sensors``; ``plant`` "twin" | "reference";
    ``terminate_at_stops`` (True: an episode also ends when the beam hits its stops); ``criteria`` (the
    verdict's)."""

    metadata: dict[str, Any] = {"render_modes": [], "render_fps": 50}

    def __init__(self, **options: Any) -> None:
        self.cfg = make_config(**options)
        self.observation_space, self.action_space = _spaces(self.cfg)
        self.rig: Any = None
        self._loop: Any = None
        self._episode: Episode | None = None
        self._trace = _Trace(1, self.cfg.ticks)
        self._ball = np.zeros(self.cfg.obs.stack)
        self._angle = np.zeros(self.cfg.obs.stack)
        self._steps = 0
        self._ended = False
        self._rig_params: Parameters | None = None

    @property
    def episode(self) -> Episode | None:
        """This episode's draws (its rig's parameters, start, setpoint, noise seed): simulation only."""
        return self._episode

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        cfg = self.cfg
        ep = self._episode = draw_episode(cfg, self.np_random, options)
        if self.rig is None or ep.params is not self._rig_params:
            self.rig = make_rig(
                ep.params,
                plant=cfg.plant,
                ideal_sensors=cfg.ideal_sensors,
                noise=cfg.noise,
                seed=ep.noise_seed,
            )
            self._rig_params = ep.params
        rig = self.rig
        rig.reset(ep.x0_m, ep.theta0_rad, seed=ep.noise_seed)
        # The one loop, its controller the agent: it reads the start block now, and each step answers a block.
        loop = self._loop = ClosedLoop(rig, _Agent(rig.period_s), record=False, controller_timeout_s=math.inf)
        one = np.zeros(1, dtype=np.int64)
        self._trace.clear(one)
        loop.start()
        first = loop.last_sample
        assert first is not None
        self._record(one)
        self._ball[:] = first.ball_v
        self._angle[:] = first.angle_v
        self._steps, self._ended = 0, False
        return self._after_block(loop.sense(), one), self._info(False)

    def _record(self, one: np.ndarray) -> None:
        rig = self.rig
        self._trace.add(
            one,
            np.array([rig.time_s]),
            rig.true_state()[None, :],
            np.array([rig.motor_volts_v]),
            np.array([block_peak_abs_theta_rad(rig.last_block)]),
        )

    def _after_block(self, sample: Any, one: np.ndarray) -> np.ndarray:
        """The block just read: recorded for the verdict, shifted into the history; the observation."""
        self._record(one)
        self._ball[:-1], self._ball[-1] = self._ball[1:], sample.ball_v
        self._angle[:-1], self._angle[-1] = self._angle[1:], sample.angle_v
        assert self._episode is not None
        return observation(
            self.cfg.obs, self._ball, self._angle, self._episode.params, self._episode.setpoint_m
        )

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self._episode is None:
            raise RuntimeError("call reset before step")
        if self._ended:
            raise RuntimeError("the episode has ended (terminated or truncated): call reset")
        ep, rig = self._episode, self.rig
        command = float(self.cfg.action.command_v(check_action(action), ep.params)[0])
        self._loop.answer(command)
        one = np.zeros(1, dtype=np.int64)
        obs = self._after_block(self._loop.sense(), one)
        self._steps += 1
        state = rig.true_state()[None, :]
        r, term, trunc, stops = _step_outcome(
            self.cfg,
            np.array([ep.params.beam.stop_angle_rad]),
            state,
            np.array([rig.motor_volts_v]),
            np.array([block_peak_abs_theta_rad(rig.last_block)]),
            np.array([rig.ball_lost]),
            np.array([ep.setpoint_m]),
            np.array([self._steps]),
        )
        info = self._info(bool(stops[0]))
        if term[0] or trunc[0]:
            self._ended = True
            info["verdict"] = self._trace.verdict(0, ep, rig.ball_lost_time_s, self.cfg.criteria)
        return obs, float(r[0]), bool(term[0]), bool(trunc[0]), info

    def _info(self, at_stops: bool) -> dict[str, Any]:
        rig = self.rig
        return {
            "sim_only": True,
            "true_state": rig.true_state(),
            "true_time_s": float(rig.time_s),
            "motor_volts_v": float(rig.motor_volts_v),
            "ball_lost": bool(rig.ball_lost),
            "at_stops": at_stops,
        }


class BallBeamVectorEnv(VectorEnv[np.ndarray, np.ndarray, np.ndarray]):
    """``num_envs`` copies of ``BallBeam-v0`` stepped as one batch (``twin.rigs.vector.VectorRig``): sub-env i is
    the single env reset with seed + i (``reset(seed=…)``, as Gymnasium's ``SyncVectorEnv`` seeds) bit for
    bit — observations, rewards, terminations, truncations, infos — with next-step autoreset. The MuJoCo twin
    only (for the reference plant, ``SyncVectorEnv`` over ``BallBeam-v0``)."""

    metadata: dict[str, Any] = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(self, num_envs: int = 1, *, nthread: int | None = None, **options: Any) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs = {num_envs!r}: at least one")
        self.cfg = cfg = make_config(**options)
        if cfg.plant != DEFAULT_PLANT:  # VectorRig steps rows of MuJoCo's batch
            raise ValueError("the vector env runs the MuJoCo twin: for the reference plant use SyncVectorEnv")
        n = self.num_envs = int(num_envs)
        self.single_observation_space, self.single_action_space = _spaces(cfg)
        self.observation_space = spaces.Box(
            np.tile(self.single_observation_space.low, (n, 1)),
            np.tile(self.single_observation_space.high, (n, 1)),
            dtype=np.float64,
        )
        self.action_space = spaces.Box(
            np.tile(self.single_action_space.low, (n, 1)),
            np.tile(self.single_action_space.high, (n, 1)),
            dtype=np.float64,
        )
        self.rigs = VectorRig(n, cfg.params, ideal_sensors=cfg.ideal_sensors, nthread=nthread)
        self._rngs: list[np.random.Generator | None] = [None] * n
        self._episodes: list[Episode | None] = [None] * n
        self._ball = np.zeros((n, cfg.obs.stack))
        self._angle = np.zeros((n, cfg.obs.stack))
        self._trace = _Trace(n, cfg.ticks)
        self._autoreset = np.zeros(n, dtype=bool)
        self._obs = np.zeros((n, cfg.obs.size))
        self._setpoint = np.zeros(n)
        self._stop_rad = np.zeros(n)
        self._state = np.zeros((n, 4))
        self._time, self._motor, self._lost_time = np.zeros(n), np.zeros(n), np.full(n, np.nan)
        self._lost, self._at_stops = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
        self._noisy: dict[Parameters, Parameters] = {}

    def reset(
        self, *, seed: int | Sequence[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        n = self.num_envs
        if seed is None:
            seeds: list[int | None] = [None] * n
        elif isinstance(seed, (int, np.integer)):
            seeds = [int(seed) + i for i in range(n)]
        else:
            seeds = list(seed)
            if len(seeds) != n:
                raise ValueError(f"{len(seeds)} seeds for {n} envs")
        for i, s in enumerate(seeds):
            if s is not None or self._rngs[i] is None:
                self._rngs[i] = seeding.np_random(s)[0]
        if options is not None and not isinstance(options, Mapping):
            raise ValueError(f"options = {options!r:.80}: a dict of {RESET_OPTIONS}")
        opts = dict(options or {})
        for k, v in opts.items():
            if np.ndim(v) and (np.ndim(v) != 1 or len(v) != n):
                raise ValueError(f"options {k!r} = {v!r:.80}: one value for every env, or a sequence of {n}")
        per_env = [{k: (v[i] if np.ndim(v) else v) for k, v in opts.items()} for i in range(n)]
        self._reset_envs(np.arange(n), per_env)
        self._autoreset[:] = False
        self._at_stops[:] = False
        return self._obs.copy(), self._infos(np.zeros(n, dtype=bool))

    def _rig_params(self, ep: Episode) -> Parameters:
        """The episode's parameters with the noise switched as configured (``make_rig``'s ``noise``)."""
        got = self._noisy.get(ep.params)  # by value: an id could be a freed episode's, reused
        if got is None:
            if len(self._noisy) > 4 * self.num_envs:
                self._noisy.clear()
            got = self._noisy[ep.params] = ep.params.with_overrides(
                {"ball_sensor.noise_enabled": self.cfg.noise}
            )
        return got

    def _reset_envs(self, rows: np.ndarray, options: Sequence[Mapping[str, Any] | None]) -> None:
        cfg = self.cfg
        eps = []
        for i, opt in zip(rows.tolist(), options, strict=True):
            rng = self._rngs[i]
            assert rng is not None
            eps.append(draw_episode(cfg, rng, opt))
            self._episodes[i] = eps[-1]
        start, first = self.rigs.reset(
            rows,
            [self._rig_params(e) for e in eps],
            np.array([e.x0_m for e in eps]),
            np.array([e.theta0_rad for e in eps]),
            np.array([e.noise_seed for e in eps]),
        )
        self._trace.clear(rows)
        self._trace.add(rows, start.true_time_s, start.state, start.motor_v, start.peak_theta_rad)
        self._ball[rows] = start.ball_v[:, None]
        self._angle[rows] = start.angle_v[:, None]
        self._setpoint[rows] = [e.setpoint_m for e in eps]
        self._stop_rad[rows] = [e.params.beam.stop_angle_rad for e in eps]
        self._blocks_in(rows, first)

    def _blocks_in(self, rows: np.ndarray, b: VectorBlocks) -> None:
        """The block just read by rigs ``rows``: its trace, the observation, what the infos report."""
        self._trace.add(rows, b.true_time_s, b.state, b.motor_v, b.peak_theta_rad)
        self._ball[rows, :-1] = self._ball[rows, 1:]
        self._ball[rows, -1] = b.ball_v
        self._angle[rows, :-1] = self._angle[rows, 1:]
        self._angle[rows, -1] = b.angle_v
        obs = self.cfg.obs
        if obs.kind == "volts":  # the parameters do not enter
            self._obs[rows] = observation(
                obs, self._ball[rows], self._angle[rows], self.cfg.params, self._setpoint[rows]
            )
        else:  # each rig's own software calibration
            by_software: dict[int, list[int]] = {}
            for j, i in enumerate(rows.tolist()):
                ep = self._episodes[i]
                assert ep is not None
                by_software.setdefault(id(ep.params.software), []).append(j)
            for members in by_software.values():
                at = rows[members]
                ep = self._episodes[int(at[0])]
                assert ep is not None
                self._obs[at] = observation(
                    obs, self._ball[at], self._angle[at], ep.params, self._setpoint[at]
                )
        self._state[rows] = b.state
        self._time[rows] = b.true_time_s
        self._motor[rows] = b.motor_v
        self._lost[rows] = b.ball_lost
        self._lost_time[rows] = b.lost_time_s

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        n, cfg = self.num_envs, self.cfg
        a = check_actions(actions, n)
        resetting = np.flatnonzero(self._autoreset)
        if resetting.size:  # next-step autoreset: these envs' actions are ignored
            self._reset_envs(resetting, [None] * len(resetting))
        going = np.flatnonzero(~self._autoreset)
        rewards = np.zeros(n)
        terminated = np.zeros(n, dtype=bool)
        truncated = np.zeros(n, dtype=bool)
        self._at_stops[resetting] = False
        if going.size:
            if cfg.spread is None:  # every episode's rig is the base's: one conversion for all
                commands = cfg.action.command_v(a[going], cfg.params)
            else:
                commands = np.empty(len(going))
                for j, i in enumerate(going.tolist()):
                    ep = self._episodes[i]
                    assert ep is not None
                    commands[j] = cfg.action.command_v(a[i], ep.params)[0]
            b = self.rigs.step(going, commands)
            self._blocks_in(going, b)
            r, term, trunc, stops = _step_outcome(
                cfg,
                self._stop_rad[going],
                b.state,
                b.motor_v,
                b.peak_theta_rad,
                b.ball_lost,
                self._setpoint[going],
                self._trace.count[going] - 2,
            )
            rewards[going], terminated[going], truncated[going], self._at_stops[going] = r, term, trunc, stops
        ended = terminated | truncated
        infos = self._infos(ended)
        self._autoreset = ended
        return self._obs.copy(), rewards, terminated, truncated, infos

    def _infos(self, ended: np.ndarray) -> dict[str, Any]:
        """Every env's simulation-only info (arrays over the envs); ``verdict`` (with its mask ``_verdict``,
        Gymnasium's convention) for the envs whose episode ended at this step."""
        n = self.num_envs
        infos: dict[str, Any] = {
            "sim_only": np.ones(n, dtype=bool),
            "true_state": self._state.copy(),
            "true_time_s": self._time.copy(),
            "motor_volts_v": self._motor.copy(),
            "ball_lost": self._lost.copy(),
            "at_stops": self._at_stops.copy(),
        }
        if ended.any():
            verdicts = np.full(n, None, dtype=object)
            for i in np.flatnonzero(ended).tolist():
                ep = self._episodes[i]
                assert ep is not None
                lost_t = None if math.isnan(self._lost_time[i]) else float(self._lost_time[i])
                verdicts[i] = self._trace.verdict(i, ep, lost_t, self.cfg.criteria)
            infos["verdict"], infos["_verdict"] = verdicts, ended.copy()
        return infos


def register() -> None:
    """Register ``BallBeam-v0`` with Gymnasium (once; importing this module does it)."""
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(
            id=ENV_ID,
            entry_point="twin.app.envs:BallBeamEnv",
            vector_entry_point="twin.app.envs:BallBeamVectorEnv",
        )


register()
