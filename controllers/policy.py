"""A learned policy as a hardware controller: ``PolicyController`` wraps any callable from observation to
action, so that a policy trained on ``BallBeam-v0`` (``twin.app.envs``) runs through ``ballbeam run``,
``sweep``, ``validate``, the live view and the wire like any other controller.

The observation is built from the blocks the rig gives exactly as the environment builds it, and the action
becomes the DAC command exactly as the environment converts it (``twin.learning``: their one home); so a
policy meets on the rig, tick for tick, the inputs it was trained on. ``start`` is the environment's reset
(the start block fills the history), each ``update`` its step.

``LinearPolicy`` is the policy of the training example (``scripts/train_policy.py``): an affine map of the
normalized observation, saved as JSON. A module of the user's that builds the controller is what
``--controller MODULE:FUNCTION`` takes::

    def make_policy(software):
        return LinearPolicy.load("policy.json").controller(software)
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from twin import fixedorder
from twin.converters import motor_volts_from_command
from twin.interface import Controller, DaqSample
from twin.learning import ActionSpec, ObservationSpec, check_action, observation
from twin.parameters import Parameters, SoftwareCalibration

__all__ = ["LinearPolicy", "PolicyController"]

POLICY_FORMAT = "ballbeam-linear-policy/1"


class PolicyController(Controller):
    """``policy(observation) → action`` as a ``Controller`` (raw blocks in, the DAC command out).

    ``observation``/``action``: the environment's options the policy was trained with; ``params``: the rig
    as the software knows it (its calibration converts volts for a "converted" observation and motor volts
    for a "motor" action; the DAC's range clips the command), ``software`` replacing its calibration (the
    catalogue passes the rig's). The telemetry logs u as the motor volts the command means (appendix A's
    u(k)), uhesap as the action before it was clipped (for a "dac" action, in motor volts too)."""

    def __init__(
        self,
        policy: Callable[[np.ndarray], Any],
        *,
        observation: ObservationSpec | None = None,
        action: ActionSpec | None = None,
        params: Parameters | None = None,
        software: SoftwareCalibration | None = None,
        setpoint_m: float = 0.0,
        name: str = "policy",
    ) -> None:
        super().__init__()
        if not callable(policy):
            raise TypeError(f"policy {policy!r} is not callable")
        self.policy = policy
        self.obs_spec = observation or ObservationSpec()
        self.action_spec = action or ActionSpec()
        p = params or Parameters()
        self.params = p if software is None else replace(p, software=software)
        self.name = name
        self.period_s = self.params.period_s
        if self.obs_spec.setpoint:
            self.setpoint_m = float(setpoint_m)  # the Setpoint capability: the view and experiments move it
        self._ball = np.zeros(self.obs_spec.stack)
        self._angle = np.zeros(self.obs_spec.stack)

    def start(self, sample: DaqSample) -> None:
        self._ball[:] = sample.ball_v
        self._angle[:] = sample.angle_v

    def update(self, sample: DaqSample) -> float:
        self._ball[:-1], self._ball[-1] = self._ball[1:], sample.ball_v
        self._angle[:-1], self._angle[-1] = self._angle[1:], sample.angle_v
        setpoint = getattr(self, "setpoint_m", 0.0)
        obs = observation(self.obs_spec, self._ball, self._angle, self.params, setpoint)
        raw = self.policy(obs)
        command = float(self.action_spec.command_v(check_action(raw), self.params)[0])
        sw = self.params.software
        self.telemetry.u = float(motor_volts_from_command(command, sw))
        first = float(np.asarray(raw, dtype=float).reshape(-1)[0])
        self.telemetry.u_computed = (
            float(motor_volts_from_command(first, sw)) if self.action_spec.kind == "dac" else first
        )
        return command


@dataclass(frozen=True)
class LinearPolicy:
    """action = bias + Σ weights_i·(obs_i − mean_i)/scale_i (products added left to right: the same bits on
    any machine, one observation or a batch of them), with the environment options it was trained with."""

    weights: tuple[float, ...]
    bias: float
    mean: tuple[float, ...]
    scale: tuple[float, ...]
    obs_spec: ObservationSpec
    action_spec: ActionSpec

    def __post_init__(self) -> None:
        k = self.obs_spec.size
        for name in ("weights", "mean", "scale"):
            values = getattr(self, name)
            if len(values) != k or not all(math.isfinite(v) for v in values):
                raise ValueError(f"{name}: {k} finite numbers for this observation, got {list(values)!r}")
        if not all(s > 0 for s in self.scale):
            raise ValueError(f"scale: positive numbers, got {list(self.scale)!r}")
        if not math.isfinite(self.bias):
            raise ValueError(f"bias = {self.bias!r}: a finite number")

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """The action for an observation (k,) → (1,), or for a batch (n, k) → (n, 1)."""
        x = (np.asarray(obs, dtype=float) - np.array(self.mean)) / np.array(self.scale)
        return (self.bias + fixedorder.dots(x, np.array(self.weights)))[..., None]

    def controller(
        self, software: SoftwareCalibration | None = None, params: Parameters | None = None
    ) -> PolicyController:
        return PolicyController(
            self,
            observation=self.obs_spec,
            action=self.action_spec,
            params=params,
            software=software,
            name="linear policy",
        )

    def to_json(self) -> dict[str, Any]:
        return {
            "format": POLICY_FORMAT,
            "observation": {
                "kind": self.obs_spec.kind,
                "stack": self.obs_spec.stack,
                "setpoint": self.obs_spec.setpoint,
            },
            "action": self.action_spec.kind,
            "weights": list(self.weights),
            "bias": self.bias,
            "mean": list(self.mean),
            "scale": list(self.scale),
        }

    @classmethod
    def from_json(cls, data: Any, source: str = "the policy") -> LinearPolicy:
        if not isinstance(data, dict) or data.get("format") != POLICY_FORMAT:
            raise ValueError(f"{source}: not a linear policy (expected format {POLICY_FORMAT!r})")
        try:
            obs = data["observation"]
            spec = ObservationSpec(obs["kind"], obs["stack"], obs["setpoint"])
            return cls(
                weights=tuple(float(v) for v in data["weights"]),
                bias=float(data["bias"]),
                mean=tuple(float(v) for v in data["mean"]),
                scale=tuple(float(v) for v in data["scale"]),
                obs_spec=spec,
                action_spec=ActionSpec(data["action"]),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{source}: {type(exc).__name__}: {exc}") from None

    @classmethod
    def load(cls, path: str | Path) -> LinearPolicy:
        path = Path(path)
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
            raise ValueError(f"{path}: cannot read a policy: {exc}") from None
        return cls.from_json(data, str(path))
