"""What a learned controller sees, does and is paid: the one home of the observation, action and reward that
the Gymnasium environment (``twin.app.envs``), its vector form (``twin.rigs.vector``) and the runtime wrapper of a
trained policy (``controllers.policy.PolicyController``) share, so that a policy meets on the rig exactly
the inputs it was trained on.

Observation (``ObservationSpec``): what the I/O card gives, the last ``stack`` blocks newest first — each
block's ball and angle ADC volts (``kind="volts"``: ``DaqSample.ball_v``, ``angle_v``), or the same volts
through the rig software's calibration (``kind="converted"``: x in m by eq 6.3.1, θ in rad by eq 6.2.10,
``twin.converters``) — and, with ``setpoint=True``, the setpoint (m) last. Before ``stack`` blocks exist the
oldest block read fills the rest (the start block, as a controller's filter starts from it).

Action (``ActionSpec``): the DAC command in volts (``kind="dac"``, Box over the DAC's range, 0…5 V, Table
6.4) or the motor volts the software means (``kind="motor"``, ±12 V, converted by appendix A's
``V/9.6 + 2.5``, ``twin.converters.dac_command_v``). An action outside its box is clipped to it (the card
cannot output more). An action is one finite real number, a scalar or an array of shape (1,)
(``check_action``; a vector of environments takes (n,) or (n, 1), ``check_actions``): anything else is refused.

Reward (``reward``, per 20 ms step, from the simulation's true state after the step — never what the
controller measured)::

    r = 1 − 0.5·(e/L)² − 0.2·(θ/θ_stop)² − 0.05·(V/V_rail)² − 0.2·[|V| = V_rail]

with e = x − setpoint, L the track's half length (0.323 m), θ_stop the beam's stops (43.4°), V the motor
volts at the step's end and V_rail the amplifier's rail (12 V). Each term is at most its weight, so
r ∈ [0.05, 1] while the ball is kept: every step alive pays (an episode that loses the ball loses every
later step), most of all near the setpoint with the beam level, little effort and the amplifier off its
rail (where the controller has no authority left).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from twin.converters import ball_position_m, beam_angle_rad, dac_command_v
from twin.parameters import Parameters

__all__ = [
    "ActionSpec",
    "check_action",
    "check_actions",
    "ObservationSpec",
    "REWARD_WEIGHTS",
    "observation",
    "reward",
]

ObservationKind = Literal["volts", "converted"]
ActionKind = Literal["dac", "motor"]

# The reward's weights (error, tilt, effort, rail): each term's largest value, see the module's docstring.
REWARD_WEIGHTS = (0.5, 0.2, 0.05, 0.2)
MAX_STACK = 50  # one second of blocks: a longer memory is a recurrent policy's job, not the observation's


@dataclass(frozen=True)
class ObservationSpec:
    """The observation's layout: ``kind`` volts or converted, the last ``stack`` blocks, the setpoint."""

    kind: ObservationKind = "volts"
    stack: int = 1
    setpoint: bool = False

    def __post_init__(self) -> None:
        if self.kind not in ("volts", "converted"):
            raise ValueError(f"observation kind {self.kind!r}: expected 'volts' or 'converted'")
        if (
            isinstance(self.stack, bool)
            or not isinstance(self.stack, int)
            or not 1 <= self.stack <= MAX_STACK
        ):
            raise ValueError(f"stack = {self.stack!r}: a whole number of blocks, 1…{MAX_STACK}")
        if not isinstance(self.setpoint, bool):
            raise ValueError(f"setpoint = {self.setpoint!r}: true or false")

    @property
    def size(self) -> int:
        return 2 * self.stack + (1 if self.setpoint else 0)

    def bounds(self, params: Parameters) -> tuple[np.ndarray, np.ndarray]:
        """The observation's box: the ADC's range per channel (volts), or what the converters read at its
        ends (converted; the software's curves are monotonic), and the track for the setpoint."""
        daq = params.daq
        if self.kind == "volts":
            lo2 = np.array([daq.adc_min_v, daq.adc_min_v])
            hi2 = np.array([daq.adc_max_v, daq.adc_max_v])
        else:
            sw = params.software
            ends = np.array([daq.adc_min_v, daq.adc_max_v])
            x, th = ball_position_m(ends, sw), beam_angle_rad(ends, sw)
            lo2, hi2 = np.array([x.min(), th.min()]), np.array([x.max(), th.max()])
        lo, hi = np.tile(lo2, self.stack), np.tile(hi2, self.stack)
        if self.setpoint:
            half = params.track.half_length_m
            lo, hi = np.r_[lo, -half], np.r_[hi, half]
        return lo, hi


def observation(
    spec: ObservationSpec,
    ball_v: Sequence[float] | np.ndarray,
    angle_v: Sequence[float] | np.ndarray,
    params: Parameters,
    setpoint_m: float = 0.0,
) -> np.ndarray:
    """The observation from the blocks read so far, newest last in ``ball_v``/``angle_v`` (at least one):
    over a batch when they are (B, K) arrays (one row per run, the same for every row). float64."""
    b = np.asarray(ball_v, dtype=float)
    a = np.asarray(angle_v, dtype=float)
    k = spec.stack
    take = np.minimum(np.arange(k), b.shape[-1] - 1)  # 0 = newest; the oldest repeats when short
    b = b[..., ::-1][..., take]
    a = a[..., ::-1][..., take]
    if spec.kind == "converted":
        sw = params.software
        b, a = ball_position_m(b, sw), beam_angle_rad(a, sw)
    pairs = np.stack([b, a], axis=-1).reshape(*b.shape[:-1], 2 * k)
    if not spec.setpoint:
        return pairs
    sp = np.broadcast_to(np.asarray(setpoint_m, dtype=float), pairs.shape[:-1])[..., None]
    return np.concatenate([pairs, sp], axis=-1)


@dataclass(frozen=True)
class ActionSpec:
    """The action: the DAC command (V) or the motor volts the software means."""

    kind: ActionKind = "dac"

    def __post_init__(self) -> None:
        if self.kind not in ("dac", "motor"):
            raise ValueError(f"action kind {self.kind!r}: expected 'dac' or 'motor'")

    def bounds(self, params: Parameters) -> tuple[float, float]:
        if self.kind == "dac":
            return params.daq.dac_min_v, params.daq.dac_max_v
        rail = params.amplifier.rail_v
        return -rail, rail

    def command_v(self, action: float | np.ndarray, params: Parameters) -> np.ndarray:
        """The DAC command(s) for an action (one per run over a batch), clipped to the box and the DAC's
        range; ``ValueError`` for an action that is not finite."""
        a = np.asarray(action, dtype=float).reshape(-1)
        if not np.isfinite(a).all():
            bad = a[~np.isfinite(a)][0]
            raise ValueError(f"action {bad!r}: a {self.kind} command must be a finite number of volts")
        lo, hi = self.bounds(params)
        a = np.clip(a, lo, hi)
        if self.kind == "motor":
            a = np.clip(dac_command_v(a, params.software), params.daq.dac_min_v, params.daq.dac_max_v)
        return a


def _shown(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _real_array(value: object) -> np.ndarray | None:
    """``value`` as a float64 array when it is real numbers (Python or numpy ints and floats, in a scalar, a
    list or an array); None for anything else (bool, str, None, complex, objects)."""
    if isinstance(value, (bool, np.bool_, str, bytes)) or value is None:
        return None
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError):  # ragged lists
        return None
    if arr.dtype.kind not in "iuf":  # b(ool), U/S (text), O(bject), c(omplex)
        return None
    return arr.astype(np.float64)


def check_action(action: object) -> float:
    """One action (the single environment's, a trained policy's): a finite real number, as a scalar or an
    array of shape (1,); ``ValueError`` naming the value and the expected form otherwise (a second value is
    not dropped, ``True`` and ``'2.5'`` are not volts, ``None`` is not NaN)."""
    arr = _real_array(action)
    if arr is None or arr.shape not in ((), (1,)) or not np.isfinite(arr).all():
        raise ValueError(
            f"action {_shown(action)}: expected a finite real number of volts, a scalar or an array of shape (1,)"
        )
    return float(arr.reshape(-1)[0])


def check_actions(actions: object, n: int) -> np.ndarray:
    """The vector environment's actions, one per env: finite real numbers of shape (n,) or (n, 1), as an (n,)
    float64 array; ``ValueError`` naming the value, its shape and the expected form otherwise."""
    arr = _real_array(actions)
    if arr is None or arr.shape not in ((n,), (n, 1)) or not np.isfinite(arr).all():
        shape = "" if arr is None else f" (shape {arr.shape})"
        raise ValueError(
            f"actions {_shown(actions)}{shape}: expected finite real numbers of volts, one per env: "
            f"shape ({n},) or ({n}, 1)"
        )
    return arr.reshape(n)


def reward(
    x_m: float | np.ndarray,
    theta_rad: float | np.ndarray,
    motor_v: float | np.ndarray,
    params: Parameters,
    setpoint_m: float | np.ndarray = 0.0,
) -> np.ndarray:
    """The step's reward (see the module's docstring) from the true state and the motor volts; over a batch
    element by element."""
    w_e, w_th, w_u, w_rail = REWARD_WEIGHTS
    rail = params.amplifier.rail_v
    e = (np.asarray(x_m, dtype=float) - setpoint_m) / params.track.half_length_m
    th = np.asarray(theta_rad, dtype=float) / params.beam.stop_angle_rad
    v = np.asarray(motor_v, dtype=float)
    at_rail = np.abs(v) >= rail * (1.0 - 1e-12)
    return 1.0 - w_e * e * e - w_th * th * th - w_u * (v / rail) ** 2 - w_rail * at_rail


def episode_ticks(duration_s: float, period_s: float, max_s: float = math.inf) -> int:
    """Steps of an episode of ``duration_s`` (truncated after them): whole periods, at least one; a duration
    that is not a number of seconds in (0, ``max_s``] is refused (``ValueError`` naming it)."""
    ok = (
        isinstance(duration_s, (int, float, np.integer, np.floating))
        and not isinstance(duration_s, (bool, np.bool_))
        and math.isfinite(duration_s)
        and 0 < duration_s <= max_s
    )
    if not ok:
        most = "" if math.isinf(max_s) else f", at most {max_s:g} s (an episode's trace keeps every tick)"
        raise ValueError(f"duration_s = {duration_s!r}: a positive number of seconds{most}")
    return max(1, int(round(duration_s / period_s)))
