"""A quadrature encoder on the beam drive's input shaft as the angle sensor (``shaft_encoder``), group
``shaft_encoder``: Quanser's SRV02 reads its load shaft (the arm that lifts the BB01's beam) with a 1024-line
encoder decoded in quadrature, 4096 counts a turn (``config_servo.m``: K_ENC = 2π/(4·1024) rad/count).

The encoder turns with the drive's input shaft, not with the beam: on a lever drive (``end_lever``) that is the
servo's shaft φ, which the beam follows through the linkage's exact closure; on the thesis's pivot the shaft is
the beam's own hinge (φ = θ). Its reading is the counter's value, in counts (the board's unit for it):

    φ(θ)             the drive's shaft angle for the beam at θ: the reference model's shaft map
                     (``twin.reference.drive_law``, registered by the drive with ``register_shaft_map``); in
                     MuJoCo the drive joint (``twin.model.drive_joint``) holds the same angle up to the
                     link's compliance (its soft connect under the beam's weight: 0.9 mrad of the BB01's arm, 0.6
                     of a count; tests/test_part_shaft_encoder.py measures it)
    n = ⌊(φ(θ) − φ(0))·N/2π + ½⌋   ``encoder_counts``: the count, zeroed with the beam level (the lab's
                     software resets the counter with the arm at its home, the beam level), the reset assumed
                     in the middle of a count (so the count is the nearest whole count); N = counts a turn

The board reads the counter at each block's end (no noise: a quadrature count is exact, its error is its
quantization, 2π/4096 = 1.53 mrad of the shaft). The counter's width (a Q8-USB's 24 bits) is not modelled: the
SRV02's ±56° of travel is ±637 counts.

The software's conversion (``angle_of``): the beam angle the lab's software computes from the count, the shaft
angle 2π·n/N through the drive's ratio AT LEVEL, θ = (2π·n/N)/φ′(0): for the BB01 lever (the arm horizontal and the
link vertical at level) φ′(0) = L/r_arm exactly, so this is Quanser's small-angle θ_beam = (r_arm/L)·θ_l (BB01 lab
manual, Rotary Experiment #04 §4.1.1). It is not the exact inverse of the closure: on the quanser-bb01 preset's
linkage the exact beam angle is 0.5 % below the linear one at 10° of arm, 14 % below at +50° and 17 % at +56° (the
arm's stop); a controller that wants the exact angle inverts ``twin.parts.linkage.Linkage.theta_rad`` itself
(tests/test_part_shaft_encoder.py).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from twin.parameters import Parameters, check_group, param, register_group
from twin.parts.contract import AngleSensorPart, BatchForm, MjcfFragment, fixed_unit, register
from twin.physics import PhysicsBlock
from twin.reference import drive_law

__all__ = [
    "SHAFT_ENCODER",
    "ShaftEncoder",
    "ShaftEncoderBatch",
    "ShaftEncoderChain",
    "encoder_counts",
    "shaft_angle_of",
    "shaft_encoder_angle_of",
]


@dataclass(frozen=True)
class ShaftEncoder:
    """The encoder's resolution: counts a turn of the shaft it is on."""

    counts_per_rev: int = param(
        4096,
        "counts/rev",
        "Quanser config_servo.m K_ENC = 2π/(4·1024): the SRV02's 1024-line encoder in quadrature, 4096 counts a "
        "turn of its load shaft",
        ge=4,
        le=2**24,
        integer=True,
        why="a quadrature encoder has at least one line (4 counts); a 24-bit counter holds at most 2^24 a turn",
    )

    def __post_init__(self) -> None:
        check_group(self, "shaft_encoder")


register_group("shaft_encoder", ShaftEncoder)


def encoder_counts(phi_rad: float | np.ndarray, counts_per_rev: float | np.ndarray) -> float | np.ndarray:
    """The counter's value for the shaft turned ``phi_rad`` from where it was reset: ⌊φ·N/2π + ½⌋ (the reset in
    the middle of a count: the nearest whole count), as a float. One float in, one float out; arrays
    elementwise, the same bits."""
    counts = np.floor(
        np.asarray(phi_rad, dtype=float) * np.asarray(counts_per_rev, dtype=float) / (2.0 * np.pi) + 0.5
    )
    return float(counts) if np.ndim(counts) == 0 else counts


def shaft_angle_of(params: Parameters) -> Callable[[float], float]:
    """θ → the drive's shaft angle from its level pose, φ(θ) − φ(0): the drive's shaft map
    (``twin.reference.drive_law``); the beam's own angle on the thesis's pivot (no law: φ = θ)."""
    law = drive_law(params)
    if law is None:
        return float
    shaft = law.shaft
    level = shaft(0.0)[0]
    return lambda theta_rad: shaft(float(theta_rad))[0] - level


class ShaftEncoderChain:
    """One run's encoder read by the board at each block's end (``AngleSensorChain``): counts."""

    def __init__(self, params: Parameters) -> None:
        self.counts_per_rev = params.of(ShaftEncoder).counts_per_rev
        self.shaft = shaft_angle_of(params)

    def level_v(self, theta_rad: float) -> float:
        """The count at one beam angle (what a board's counter holds at every physics step)."""
        return float(encoder_counts(self.shaft(float(theta_rad)), self.counts_per_rev))

    def read_block_v(self, block: PhysicsBlock) -> float:
        """The count at the block's end."""
        return self.level_v(float(block.theta_rad[-1]))


class ShaftEncoderBatch:
    """N runs' encoders read in step (``twin.parts.contract.AngleSensorBatch``): each run's shaft angle from its
    own drive's map, the counts of all at once (``encoder_counts`` on arrays), each run its chain's bits."""

    def __init__(self, params: Sequence[Parameters]) -> None:
        self.shafts = [shaft_angle_of(p) for p in params]
        self.counts_per_rev = np.array([p.of(ShaftEncoder).counts_per_rev for p in params], dtype=float)

    def read(self, runs: np.ndarray, times_s: np.ndarray, theta_rad: np.ndarray) -> np.ndarray:
        ends = np.asarray(theta_rad, dtype=float)[:, -1]
        phi = np.array([self.shafts[i](t) for i, t in zip(runs.tolist(), ends.tolist(), strict=True)])
        return np.asarray(encoder_counts(phi, self.counts_per_rev[runs]), dtype=float)


def shaft_encoder_angle_of(params: Parameters) -> Callable[[float], float]:
    """The software's conversion: counts → the shaft's angle 2π·n/N → the beam's angle through the drive's ratio
    at level, θ = φ/φ′(0) (module docstring: Quanser's r_arm/L·θ_l on the BB01 lever)."""
    law = drive_law(params)
    ratio = 1.0 if law is None else law.shaft(0.0)[1]  # φ′(0) = dφ/dθ at the level beam
    step = 2.0 * math.pi / params.of(ShaftEncoder).counts_per_rev
    return lambda counts: counts * step / ratio


# --- the batch form: N runs' counts at once, on the pivot and on the lever -----------------------------------
_LEVER = {"parts.beam_drive": "end_lever", "parts.actuator": "hobby_servo", "parts.io_board": "arduino_uno"}


def _inputs(rng: np.random.Generator, n: int) -> tuple[list[Parameters], np.ndarray]:
    resolutions = rng.choice([1024, 2000, 4096], n).tolist()
    params = [
        Parameters().with_overrides(
            {"shaft_encoder.counts_per_rev": int(res), **(_LEVER if i % 2 else {})}, origin="batch form"
        )
        for i, res in enumerate(resolutions)
    ]
    # the beam within the default lever's reach (about ±0.16 rad) and the pivot's
    return params, rng.uniform(-0.15, 0.15, (n, 1))


def _single(params: Parameters, row: np.ndarray) -> np.ndarray:
    """One run's chain reading a block that ends at the row's angle."""
    theta = float(row[0])
    block = PhysicsBlock(np.array([0.0, 0.02]), np.zeros(2), np.array([0.0, theta]), np.ones(2, dtype=bool))
    return np.array([ShaftEncoderChain(params).read_block_v(block)])


def _batch(params: Sequence[Parameters], rows: np.ndarray) -> np.ndarray:
    """Every run's count at once (``ShaftEncoderBatch``)."""
    theta = np.column_stack([np.zeros(len(rows)), rows[:, 0]])
    return ShaftEncoderBatch(params).read(np.arange(len(rows)), np.array([0.0, 0.02]), theta)[:, None]


SHAFT_ENCODER = register(
    AngleSensorPart(
        name="shaft_encoder",
        reading_unit=fixed_unit("counts"),  # the card's counter input, not its ADC
        source="Quanser config_servo.m (K_ENC: the SRV02's 1024-line encoder, 4096 counts/rev in quadrature, on "
        "its load shaft); the count zeroed with the beam level (assumed: the lab resets it at home)",
        groups={"shaft_encoder": ShaftEncoder},
        equations=(encoder_counts, shaft_angle_of, shaft_encoder_angle_of, ShaftEncoderChain),
        mjcf=MjcfFragment(),
        batch=BatchForm(_single, _batch, _inputs, "twin.parts.shaft_encoder.encoder_counts"),
        chain=ShaftEncoderChain,
        batch_read=ShaftEncoderBatch,
        angle_of=shaft_encoder_angle_of,
    )
)
