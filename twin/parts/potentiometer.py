"""A rotary potentiometer on the beam's pivot as the angle sensor (``potentiometer``), group ``potentiometer``.

The pot's body is fixed to the frame, its shaft turns with the beam; its track is a voltage divider across
the board's reference (on an Arduino the 5 V that is also the ADC's reference: the reading is ratiometric).
The wiper's volts (``pot_wiper_v``):

    u = 1/2 + (θ − θ_zero)/travel                      the wiper's place along the track (0 … 1)
    V = V_ref·(u + L·sin 2πu), u and V within 0 … 1    L: the linearity error

θ_zero is the beam angle at which the wiper is at mid-track (the level beam, as mounted), travel the
electrical travel (Bourns 3382: 330° nominal). The linearity error's shape is an assumption: the data sheet
gives only its bound (Bourns 3382: ±2 %), taken here as one full sine over the track, zero at both ends and at
mid-track (the level beam), ±L·V_ref at a quarter and three quarters of the travel.

The board reads the wiper at each block's end through its ADC (``twin.parts.part_named("io_board",
params.parts.io_board).adc``: the PCI-1712's volts, an Arduino's ``analogRead`` counts), the wiper's contact
noise added: a Gaussian of ``noise_rms_v`` per reading, clipped to the rails (a wiper cannot leave its track's
ends). A chain (``AngleSensorChain``) is built from the parameters alone, so its noise is seeded by the
parameter ``potentiometer.noise_seed`` (``np.random.default_rng(noise_seed)``): the same parameters give
bit-identical readings; runs meant to differ set different seeds. A block that starts before the last one
ended (the rig was reset: the chain protocol has no reset) starts the noise again from its seed, as the rig's
ball chain does on ``reset``. ``level_v`` (what a microcontroller's pin
sees every physics step) is the noiseless wiper.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from twin import model as mdl
from twin.parameters import Parameters, check_group, param, register_group
from twin.parts.contract import (
    AngleSensorPart,
    BatchForm,
    MjcfFragment,
    board_adc,
    board_batch_adc,
    board_volts_of,
    register,
)
from twin.physics import PhysicsBlock

__all__ = [
    "HOUSING",
    "POTENTIOMETER",
    "Potentiometer",
    "PotentiometerBatch",
    "PotentiometerChain",
    "pot_wiper_v",
]

HOUSING = "potentiometer_housing"
# Bourns 3382: an 11 mm square body, 5.5 mm deep (drawing); mounted on the pivot's axis on the side facing away
# from the motor, clear of the beam bar's 22 mm half-width.
_BODY_HALF_M = (0.0055, 0.00275, 0.0055)
_AXIS_OFFSET_M = -0.03
# A block that begins more than this before the last one ended starts a new run (consecutive blocks share a
# knot, up to the clock's rounding: ~1e-17 s).
RESET_TOLERANCE_S = 1e-6


@dataclass(frozen=True)
class Potentiometer:
    """A rotary potentiometer on the pivot: its supply, electrical travel, mounting zero, linearity error and
    wiper noise (with the noise's seed)."""

    supply_v: float = param(
        5.0,
        "V",
        "assumed: the track across the board's 5 V reference (an Arduino's AVcc: a ratiometric reading)",
        gt=0.0,
        le=10.0,
        why="a pot on a board's reference: at most 10 V, the PCI-1712's input range",
    )
    electrical_travel_rad: float = param(
        math.radians(330.0),
        "rad",
        "Bourns 3382 data sheet, Electrical Characteristics: adjustment angle 330° nominal",
        ge=math.radians(90.0),
        le=2.0 * math.pi,
        why="the beam's ±43.4° must fit on the track (≥ 90°); a single-turn track is at most 360°",
    )
    zero_angle_rad: float = param(
        0.0,
        "rad",
        "assumed: mounted so that the level beam puts the wiper at mid-track (calibrated on the rig)",
        ge=-math.radians(45.0),
        le=math.radians(45.0),
        why="a mounting error larger than the beam's stops (43.4°) would be seen at once",
    )
    linearity_error: float = param(
        0.02,
        "fraction of V_ref",
        "Bourns 3382 data sheet, Electrical Characteristics: linearity ±2 % (the shape, one sine over the track, "
        "assumed)",
        ge=0.0,
        le=0.15,
        why="generic carbon pots are specified to ±10 … 15 %; beyond 1/2π the wiper's volts would not rise",
    )
    noise_rms_v: float = param(
        0.001,
        "V",
        "assumed: 1 mV RMS of wiper contact noise per reading (0.02 % of 5 V, a fifth of an Arduino's 4.9 mV LSB), "
        "fit from a log",
        ge=0.0,
        le=0.5,
        why="10 % of a 5 V track is a broken wiper, not noise",
    )
    noise_seed: int = param(
        0,
        "seed",
        "the chain's seed (np.random.default_rng): an angle chain is built from the parameters alone",
        ge=0,
        le=2**31 - 1,
        integer=True,
        why="a numpy seed, a non-negative 31-bit integer",
    )

    def __post_init__(self) -> None:
        check_group(self, "potentiometer")


register_group("potentiometer", Potentiometer)


def pot_wiper_v(theta_rad: float | np.ndarray, pot: Potentiometer) -> float | np.ndarray:
    """The wiper's volts at beam angle(s) θ: V_ref·(u + L·sin 2πu) with u = 1/2 + (θ − θ_zero)/travel, u and the
    result clipped to the track's ends (module docstring). One float in, one float out; arrays elementwise, the
    same bits."""
    volts = _wiper_v(
        np.asarray(theta_rad, dtype=float),
        pot.zero_angle_rad,
        pot.electrical_travel_rad,
        pot.linearity_error,
        pot.supply_v,
    )
    return float(volts) if np.ndim(theta_rad) == 0 else volts


def _wiper_v(
    theta_rad: np.ndarray,
    zero_rad: float | np.ndarray,
    travel_rad: float | np.ndarray,
    linearity: float | np.ndarray,
    supply_v: float | np.ndarray,
) -> np.ndarray:
    """``pot_wiper_v`` with each constant a number or an array (one per run: the batch form's)."""
    u = np.clip(0.5 + (theta_rad - zero_rad) / travel_rad, 0.0, 1.0)
    return supply_v * np.clip(u + linearity * np.sin(2.0 * np.pi * u), 0.0, 1.0)


def _noisy_pin_v(level_v: float | np.ndarray, noise: float | np.ndarray, pot: Potentiometer) -> np.ndarray:
    """The pin's volts for a reading: the wiper plus its noise (``noise`` standard normal draws), on the track."""
    return np.clip(np.asarray(level_v) + pot.noise_rms_v * np.asarray(noise), 0.0, pot.supply_v)


class PotentiometerChain:
    """One run's potentiometer read by the rig's board (``AngleSensorChain``): the wiper at each block's end,
    its noise seeded by ``potentiometer.noise_seed``, through the board's ADC."""

    def __init__(self, params: Parameters) -> None:
        self.pot = params.of(Potentiometer)
        self.adc = board_adc(params)
        self.rng = np.random.default_rng(self.pot.noise_seed)
        self.last_reading_v: float | None = None
        self._end_s: float | None = None  # the last block's end

    def _new_run(self, block: PhysicsBlock) -> None:
        """A block that starts before the last one ended: the rig was reset (``SimRig.reset``; the protocol has
        no reset); the noise starts again from its seed, as the rig's ball chain's does."""
        if self._end_s is not None and float(block.time_s[0]) < self._end_s - RESET_TOLERANCE_S:
            self.rng = np.random.default_rng(self.pot.noise_seed)
        self._end_s = float(block.time_s[-1])

    def level_v(self, theta_rad: float) -> float:
        """The wiper's volts at one angle (noiseless)."""
        return float(pot_wiper_v(float(theta_rad), self.pot))

    def read_block_v(self, block: PhysicsBlock) -> float:
        """The board's reading of the wiper at the block's end, one noise draw a reading."""
        self._new_run(block)
        pin = _noisy_pin_v(self.level_v(float(block.theta_rad[-1])), self.rng.standard_normal(), self.pot)
        self.last_reading_v = self.adc(float(pin))
        return self.last_reading_v


class PotentiometerBatch:
    """N runs' potentiometers read in step (``twin.parts.contract.AngleSensorBatch``): each run a fresh
    ``PotentiometerChain`` bit for bit: the wiper on arrays (``_wiper_v``, each run's pot), one noise draw a
    reading from each run's generator (its ``noise_seed``), each run's board's ADC (``board_batch_adc``)."""

    def __init__(self, params: Sequence[Parameters]) -> None:
        pots = [p.of(Potentiometer) for p in params]

        def column(name: str) -> np.ndarray:
            return np.array([getattr(pot, name) for pot in pots], dtype=float)

        self.zero_rad, self.travel_rad = column("zero_angle_rad"), column("electrical_travel_rad")
        self.linearity, self.supply_v = column("linearity_error"), column("supply_v")
        self.noise_rms_v = column("noise_rms_v")
        self.seeds = [pot.noise_seed for pot in pots]
        self.rngs = [np.random.default_rng(seed) for seed in self.seeds]
        self.adc = board_batch_adc(params)
        self._end_s: float | None = None  # the last block's end (the runs are in step)

    def read(self, runs: np.ndarray, times_s: np.ndarray, theta_rad: np.ndarray) -> np.ndarray:
        """``PotentiometerChain.read_block_v`` for runs ``runs``: the wiper at the block's end, its noise, the ADC."""
        if self._end_s is not None and float(times_s[0]) < self._end_s - RESET_TOLERANCE_S:  # as ``_new_run``
            self.rngs = [np.random.default_rng(seed) for seed in self.seeds]
        self._end_s = float(times_s[-1])
        supply = self.supply_v[runs]
        level = _wiper_v(
            np.asarray(theta_rad)[:, -1],
            self.zero_rad[runs],
            self.travel_rad[runs],
            self.linearity[runs],
            supply,
        )
        draws = np.array([self.rngs[i].standard_normal() for i in runs.tolist()])
        pin = np.clip(level + self.noise_rms_v[runs] * draws, 0.0, supply)  # ``_noisy_pin_v``'s operations
        return np.asarray(self.adc(runs, pin), dtype=float)


# --- the MJCF fragment: the pot's body at the pivot, drawn only --------------------------------------------
def apply_housing(spec: mujoco.MjSpec, params: Parameters) -> None:
    """Add the pot's body on the pivot's axis (a visual box: no contact, geom group 2, no mass)."""
    pivot = np.asarray(spec.body(mdl.BEAM_BODY).pos, dtype=float)
    spec.worldbody.add_geom(
        name=HOUSING,
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=list(_BODY_HALF_M),
        pos=(pivot + np.array([0.0, _AXIS_OFFSET_M, 0.0])).tolist(),
        contype=0,
        conaffinity=0,
        group=2,
        mass=0.0,
        rgba=[0.15, 0.25, 0.55, 1.0],
    )


# --- the batch form: N runs' readings at once ---------------------------------------------------------------
def _inputs(rng: np.random.Generator, n: int) -> tuple[list[Parameters], np.ndarray]:
    boards = rng.choice(["pci1712", "arduino_uno"], n).tolist()
    params = [
        Parameters().with_overrides(
            {
                "parts.io_board": board,
                "potentiometer.zero_angle_rad": float(zero),
                "potentiometer.linearity_error": float(lin),
                "potentiometer.noise_rms_v": float(sigma),
                "potentiometer.noise_seed": int(seed),
            }
        )
        for board, zero, lin, sigma, seed in zip(
            boards,
            rng.uniform(-0.05, 0.05, n).tolist(),
            rng.uniform(0.0, 0.1, n).tolist(),
            rng.uniform(0.0, 0.01, n).tolist(),
            rng.integers(0, 2**31 - 1, n).tolist(),
            strict=True,
        )
    ]
    # angles past the track's ends for some (a 330° track ends at ±165°)
    return params, rng.uniform(-3.2, 3.2, (n, 1))


def _single(params: Parameters, row: np.ndarray) -> np.ndarray:
    """One run's chain reading a block that ends at the row's angle, and its level there."""
    chain = PotentiometerChain(params)
    theta = float(row[0])
    block = PhysicsBlock(np.array([0.0, 0.02]), np.zeros(2), np.array([theta, theta]), np.ones(2, dtype=bool))
    return np.array([chain.read_block_v(block), chain.level_v(theta)])


def _batch(params: Sequence[Parameters], rows: np.ndarray) -> np.ndarray:
    """Every run's wiper and pin volts at once in numpy (each its own pot, its seed's first draw), then each
    run's board's ADC (the board part's per-reading converter)."""
    pots = [p.of(Potentiometer) for p in params]
    theta = rows[:, 0]
    zero = np.array([p.zero_angle_rad for p in pots])
    travel = np.array([p.electrical_travel_rad for p in pots])
    lin = np.array([p.linearity_error for p in pots])
    supply = np.array([p.supply_v for p in pots])
    sigma = np.array([p.noise_rms_v for p in pots])
    level = _wiper_v(theta, zero, travel, lin, supply)
    draws = np.array([np.random.default_rng(p.noise_seed).standard_normal() for p in pots])
    pin = np.clip(level + sigma * draws, 0.0, supply)
    adcs = [board_adc(p) for p in params]
    readings = np.array([adc(v) for adc, v in zip(adcs, pin.tolist(), strict=True)])
    return np.column_stack([readings, level])


def pot_angle_of(params: Parameters) -> Callable[[float], float]:
    """The software's conversion: the board's reading → volts → θ = θ_zero + (V/V_ref − ½)·travel (the wiper's
    nominal line, its linearity error unknown to a sketch)."""
    pot = params.of(Potentiometer)
    volts_of = board_volts_of(params)
    return lambda reading: (
        pot.zero_angle_rad + (volts_of(reading) / pot.supply_v - 0.5) * pot.electrical_travel_rad
    )


POTENTIOMETER = register(
    AngleSensorPart(
        name="potentiometer",
        source="Bourns 3382 rotary position sensor data sheet (330° adjustment angle, ±2 % linearity); the "
        "linearity's shape and the wiper noise assumed (fit from a log); read by the board's ADC",
        groups={"potentiometer": Potentiometer},
        equations=(pot_wiper_v, PotentiometerChain),
        mjcf=MjcfFragment((), apply_housing),
        batch=BatchForm(_single, _batch, _inputs, "twin.parts.potentiometer.pot_wiper_v"),
        chain=PotentiometerChain,
        batch_read=PotentiometerBatch,
        angle_of=pot_angle_of,
    )
)
