"""No angle sensor (``none``), group ``no_angle``: many servo builds never measure the beam's angle (the servo's
own loop holds it). The board's angle input is then unused and tied to ground: it reads 0.0 in every block and
its pin sees 0 V (``DaqSample.angle_v`` = 0.0, as ``twin.interface`` says of an absent sensor). A controller for
such a rig must not use the angle channel. No MJCF: nothing is drawn.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from twin.parameters import Parameters, check_group, param, register_group
from twin.parts.contract import AngleSensorPart, BatchForm, MjcfFragment, register
from twin.physics import PhysicsBlock

__all__ = ["NO_ANGLE", "NoAngle", "NoAngleBatch", "NoAngleChain", "grounded_reading"]


@dataclass(frozen=True)
class NoAngle:
    """The unused angle input: what it reads (zero, a grounded input; the only value the group admits)."""

    grounded_reading: float = param(
        0.0,
        "board unit",
        "an unused input tied to ground: 0 V at the pin, a reading of 0 (twin.interface: an absent angle sensor "
        "reads 0.0)",
        ge=0.0,
        le=0.0,
        why="a grounded input reads zero; a rig with an angle signal names an angle sensor part",
    )

    def __post_init__(self) -> None:
        check_group(self, "no_angle")


register_group("no_angle", NoAngle)


def grounded_reading(theta_rad: float | np.ndarray) -> float | np.ndarray:
    """The reading of a grounded input at any beam angle(s): 0.0 (an array of zeros for an array)."""
    return 0.0 if np.ndim(theta_rad) == 0 else np.zeros(np.shape(theta_rad))


class NoAngleChain:
    """The chain of a rig without an angle sensor (``AngleSensorChain``): every reading and level is 0.0."""

    def __init__(self, params: Parameters) -> None:
        self.last_reading_v: float | None = None

    def level_v(self, theta_rad: float) -> float:
        """The grounded pin: 0 V."""
        return float(grounded_reading(theta_rad))

    def read_block_v(self, block: PhysicsBlock) -> float:
        """The grounded input's reading: 0.0."""
        self.last_reading_v = float(grounded_reading(float(block.theta_rad[-1])))
        return self.last_reading_v


class NoAngleBatch:
    """N runs' grounded inputs (``twin.parts.contract.AngleSensorBatch``): every reading 0.0."""

    def __init__(self, params: Sequence[Parameters]) -> None:
        self.n = len(params)

    def read(self, runs: np.ndarray, times_s: np.ndarray, theta_rad: np.ndarray) -> np.ndarray:
        return np.asarray(grounded_reading(theta_rad[:, -1]), dtype=float)


def _inputs(rng: np.random.Generator, n: int) -> tuple[list[Parameters], np.ndarray]:
    return [Parameters()] * n, rng.uniform(-0.8, 0.8, (n, 1))


def _single(params: Parameters, row: np.ndarray) -> np.ndarray:
    chain = NoAngleChain(params)
    theta = float(row[0])
    block = PhysicsBlock(np.array([0.0, 0.02]), np.zeros(2), np.array([theta, theta]), np.ones(2, dtype=bool))
    return np.array([chain.read_block_v(block), chain.level_v(theta)])


def _batch(params: Sequence[Parameters], rows: np.ndarray) -> np.ndarray:
    zeros = np.asarray(grounded_reading(rows[:, 0]))
    return np.column_stack([zeros, zeros])


NO_ANGLE = register(
    AngleSensorPart(
        name="none",
        source="no angle sensor: servo builds (Arduino and a hobby servo) whose beam angle is never measured; "
        "the unused input grounded, reading 0.0",
        groups={"no_angle": NoAngle},
        equations=(grounded_reading, NoAngleChain),
        mjcf=MjcfFragment(),
        batch=BatchForm(_single, _batch, _inputs, "twin.parts.no_angle.grounded_reading"),
        chain=NoAngleChain,
        batch_read=NoAngleBatch,
        measures_angle=False,
    )
)
