"""What a rig part declares, the registry of parts by role, and a rig as one part per role.

Every part declares (``Part``):

    name, role      which part it is and the place it takes in a rig (``ROLES``)
    groups          its parameter groups: the parameter table's dataclasses (``twin.parameters``), whose fields
                    carry each value's unit, bounds and source; the part points at them, it holds no numbers
    equations       the homes of its equations (functions and classes of the core), pointed at, never copied
    mjcf            its MJCF fragment: the elements of ``models/ballbeam.xml`` it owns and the function that
                    writes its parameters into them (``twin.model``); a part outside MuJoCo owns none
    batch           its batch form: the function the batch rig or the fast engine runs for N runs at once,
                    beside the one-run form it must equal on any inputs

A part that a simulated rig instantiates for each run adds its runtime: a ball or angle sensor its chain
(``BallSensorPart.chain``, ``AngleSensorPart.chain``), an I/O board its DAC (``IoBoardPart.dac_writer``), an
actuator what it makes of the DAC's volts (``ActuatorPart.drive``). ``RigParts`` is a rig: one part per role,
``replace`` swaps one. A new part is one module: its parameter group, its ``Part`` and one ``register`` call.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal, Protocol, TypeVar, get_args

import mujoco
import numpy as np

from twin.interface import CommandRange
from twin.model import build_spec, register_fragment
from twin.parameters import ParameterError, Parameters
from twin.physics import PhysicsBlock

__all__ = [
    "ROLES",
    "ActuatorPart",
    "AngleSensorChain",
    "AngleSensorPart",
    "BallSensorChain",
    "BallSensorPart",
    "BatchForm",
    "IoBoardPart",
    "MjcfFragment",
    "Part",
    "PartError",
    "RigParts",
    "Role",
    "part_named",
    "register",
    "registered",
    "rig_parts",
    "vary",
]

Role = Literal["ball", "track", "beam_drive", "actuator", "ball_sensor", "angle_sensor", "io_board"]
ROLES: tuple[Role, ...] = get_args(Role)

# MJCF element kinds a fragment may own, with the MuJoCo object type to look its names up by.
MJCF_KINDS: Mapping[str, mujoco.mjtObj] = {
    "body": mujoco.mjtObj.mjOBJ_BODY,
    "joint": mujoco.mjtObj.mjOBJ_JOINT,
    "geom": mujoco.mjtObj.mjOBJ_GEOM,
    "site": mujoco.mjtObj.mjOBJ_SITE,
    "actuator": mujoco.mjtObj.mjOBJ_ACTUATOR,
    "sensor": mujoco.mjtObj.mjOBJ_SENSOR,
}


class PartError(ParameterError):
    """A part that breaks its contract (an unknown role, a name registered twice, a part in the wrong role), or
    a rig that names a part the registry does not have."""


@dataclass(frozen=True)
class MjcfFragment:
    """The MJCF elements a part owns, as (kind, name) pairs (kinds: ``MJCF_KINDS``), and ``apply``, which writes
    the part's parameters into them on a model's spec (``twin.model.build_spec`` calls it)."""

    elements: tuple[tuple[str, str], ...] = ()
    apply: Callable[[mujoco.MjSpec, Parameters], None] | None = None

    def missing(self, model: mujoco.MjModel) -> list[str]:
        """The elements the compiled ``model`` lacks (or of an unknown kind), as "kind 'name'"."""
        return [
            f"{kind} {name!r}"
            for kind, name in self.elements
            if kind not in MJCF_KINDS or mujoco.mj_name2id(model, MJCF_KINDS[kind], name) < 0
        ]


@dataclass(frozen=True)
class BatchForm:
    """A part's batch form beside its one-run form: ``single(params, row)`` is one run's outputs (1-D) for its
    input row, ``batch(params, rows)`` every run's (N, outputs) at once, each run with its own parameters;
    ``inputs(rng, n)`` draws n runs' parameters and input rows (seeded: the same draws for the same rng).
    ``tolerance``: the largest |batch − single| the two may differ by (0: bit for bit)."""

    single: Callable[[Parameters, np.ndarray], np.ndarray]
    batch: Callable[[Sequence[Parameters], np.ndarray], np.ndarray]
    inputs: Callable[[np.random.Generator, int], tuple[list[Parameters], np.ndarray]]
    home: str
    tolerance: float = 0.0

    def difference(self, rng: np.random.Generator, n: int) -> float:
        """The largest |batch − single| over n runs drawn from ``rng`` (inf if the shapes differ)."""
        params, rows = self.inputs(rng, n)
        one = np.array([self.single(p, row) for p, row in zip(params, rows, strict=True)])
        many = np.asarray(self.batch(params, rows))
        if one.shape != many.shape:
            return float("inf")
        return float(np.max(np.abs(many - one))) if one.size else 0.0


@dataclass(frozen=True, kw_only=True)
class Part:
    """A rig part's contract (see the module docstring). ``source``: where the part and its numbers come from
    (a thesis section, a data sheet, a measurement)."""

    name: str
    role: Role
    source: str
    groups: Mapping[str, type]
    equations: tuple[Callable[..., Any], ...]
    mjcf: MjcfFragment
    batch: BatchForm


def dac_range(params: Parameters) -> CommandRange:
    """The PCI-1712's output: its DAC's volts, ``daq.dac_min_v`` … ``daq.dac_max_v``."""
    return CommandRange(params.daq.dac_min_v, params.daq.dac_max_v)


def zero_command(params: Parameters) -> float:
    """The DC motor's amplifier at 0 V: its zero command (``amplifier.zero_command_v``, §6.4)."""
    return params.amplifier.zero_command_v


class BallSensorChain(Protocol):
    """What a simulated rig asks of a ball sensor's chain for one run (``twin.sensors.BallPositionChain``):
    the analog signal at the board's pin now (``filtered_v``) and the board's last reading (``reading_v``),
    advanced over the physics' blocks."""

    reading_v: float
    filtered_v: float

    @property
    def dropout_count(self) -> int: ...

    def reset(
        self,
        x_m: float,
        t_s: float = 0.0,
        *,
        in_contact: bool = True,
        seed: int | np.random.Generator | None = None,
    ) -> None: ...

    def set_params(self, params: Parameters) -> None: ...

    def advance(
        self, times_s: np.ndarray, x_m: np.ndarray, in_contact: bool | np.ndarray = True
    ) -> float: ...

    def advance_block(self, block: PhysicsBlock) -> float: ...

    def advance_rig_block(
        self,
        times_s: np.ndarray,
        x_m: np.ndarray,
        in_contact: np.ndarray,
        equal_steps: bool,
        x_range_m: tuple[float, float] | None = None,
        all_on_track: bool | None = None,
    ) -> float: ...


class AngleSensorChain(Protocol):
    """What a simulated rig asks of an angle sensor's chain (``twin.sensors.AngleChain``): the board's reading
    of a block and the analog signal at one angle."""

    def read_block_v(self, block: PhysicsBlock) -> float: ...

    def level_v(self, theta_rad: float) -> float: ...


@dataclass(frozen=True, kw_only=True)
class BallSensorPart(Part):
    """A ball sensor: ``chain(params, seed)`` is one run's chain (its noise seeded)."""

    role: Role = "ball_sensor"
    chain: Callable[[Parameters, int], BallSensorChain]


@dataclass(frozen=True, kw_only=True)
class AngleSensorPart(Part):
    """An angle sensor: ``chain(params)`` is one run's chain."""

    role: Role = "angle_sensor"
    chain: Callable[[Parameters], AngleSensorChain]


@dataclass(frozen=True, kw_only=True)
class IoBoardPart(Part):
    """An I/O board: ``dac_writer(params)`` gives what its output puts out for a command (one float: the DAC's
    volts on the PCI-1712, a servo pulse's width in µs on an Arduino); ``adc(params)`` what it reads for an
    analog input's volts at its pin (the ADC's volts on the PCI-1712, ``analogRead``'s counts on an Arduino),
    for the analog sensors' chains; ``output_range(params)`` what its output can be (the guard refuses a
    controller's command outside it; default the DAC's, ``dac_range``)."""

    role: Role = "io_board"
    dac_writer: Callable[[Parameters], Callable[[float], float]]
    adc: Callable[[Parameters], Callable[[float], float]]
    output_range: Callable[[Parameters], CommandRange] = dac_range


@dataclass(frozen=True, kw_only=True)
class ActuatorPart(Part):
    """An actuator: ``drive(params)`` gives the MuJoCo actuator's control (the motor's terminal volts; a
    servo's target angle) for the board's output, a fresh write path per run (it may hold state);
    ``rest_command(params)`` is the board's command that leaves the beam at rest where it is held (the
    amplifier's zero command, 2.5 V, by default: ``zero_command``), what the rig writes before the
    controller's first command."""

    role: Role = "actuator"
    drive: Callable[[Parameters], Callable[[float], float]]
    rest_command: Callable[[Parameters], float] = zero_command


# The part type each role needs (its runtime), for ``RigParts`` and ``register``.
ROLE_TYPES: Mapping[Role, type[Part]] = {
    "ball": Part,
    "track": Part,
    "beam_drive": Part,
    "actuator": ActuatorPart,
    "ball_sensor": BallSensorPart,
    "angle_sensor": AngleSensorPart,
    "io_board": IoBoardPart,
}

_REGISTRY: dict[Role, dict[str, Part]] = {role: {} for role in ROLES}
P = TypeVar("P", bound=Part)


def _check_role(part: Part) -> None:
    if part.role not in ROLES:
        raise PartError(f"part {part.name!r}: role {part.role!r} is not one of {list(ROLES)}")
    need = ROLE_TYPES[part.role]
    if not isinstance(part, need):
        raise PartError(
            f"part {part.name!r} ({type(part).__name__}) cannot be a {part.role}: that role needs a {need.__name__}"
        )


def register(part: P) -> P:
    """Add ``part`` to the registry under its role (``PartError`` if its role is unknown, its type is not the
    role's, or the role already has a part of that name); returns it."""
    _check_role(part)
    parts = _REGISTRY[part.role]
    if part.name in parts:
        raise PartError(f"a {part.role} named {part.name!r} is registered already")
    register_fragment(part.role, part.name, part.mjcf.apply)  # a rig's model applies it (twin.model)
    parts[part.name] = part
    return part


def part_named(role: Role, name: str) -> Part:
    """The registered ``role`` part called ``name`` (``PartError`` naming the field ``parts.<role>`` and the
    role's parts if there is none)."""
    if role not in ROLES:
        raise PartError(f"role {role!r} is not one of {list(ROLES)}")
    part = _REGISTRY[role].get(name)
    if part is None:
        raise PartError(
            f"parts.{role} = {name!r}: no {role} of that name (there are: {sorted(_REGISTRY[role])})"
        )
    return part


def rig_parts(params: Parameters) -> RigParts:
    """The rig ``params`` describes: the part its ``parts`` group names for each role (``PartError`` naming the
    first unknown one)."""
    return _rig_parts(tuple(getattr(params.parts, role) for role in ROLES))


@functools.lru_cache(maxsize=64)
def _rig_parts(names: tuple[str, ...]) -> RigParts:
    chosen: dict[str, Any] = {role: part_named(role, name) for role, name in zip(ROLES, names, strict=True)}
    return RigParts(**chosen)


def registered(role: Role | None = None) -> list[Part]:
    """The registered parts of ``role`` (every role's, in ``ROLES`` order, for None), in registration order."""
    if role is not None and role not in ROLES:
        raise PartError(f"role {role!r} is not one of {list(ROLES)}")
    return [part for r in ROLES if role in (None, r) for part in _REGISTRY[r].values()]


@dataclass(frozen=True)
class RigParts:
    """A rig as one part per role. ``replace`` gives the rig with one part swapped (its role's); the simulated
    rig (``twin.rigs.sim.SimRig``) instantiates its sensors and its output stage from these."""

    ball: Part
    track: Part
    beam_drive: Part
    actuator: ActuatorPart
    ball_sensor: BallSensorPart
    angle_sensor: AngleSensorPart
    io_board: IoBoardPart

    def __post_init__(self) -> None:
        for role in ROLES:
            part = getattr(self, role)
            if part.role != role:
                raise PartError(f"part {part.name!r} is a {part.role}, not a {role}")
            _check_role(part)

    def __iter__(self) -> Iterator[Part]:
        return (getattr(self, role) for role in ROLES)

    def replace(self, part: Part) -> RigParts:
        """This rig with ``part`` in its role."""
        _check_role(part)  # the role's type, which ``__post_init__`` checks again
        changes: dict[str, Any] = {part.role: part}
        return dataclasses.replace(self, **changes)

    def motor_volts_of(self, params: Parameters) -> Callable[[float], float]:
        """The motor's terminal volts for a command written to the board: the board's DAC, then the actuator
        (``twin.output_stage.motor_volts_of`` for today's parts, the same operations)."""
        dac, drive = self.io_board.dac_writer(params), self.actuator.drive(params)
        return lambda command_v: drive(dac(command_v))

    def build_spec(self, params: Parameters, *, hold_beam_rad: float | None = None) -> mujoco.MjSpec:
        """The model's spec with each part's fragment patched from ``params`` (``twin.model.build_spec``)."""
        fragments = tuple(part.mjcf.apply for part in self if part.mjcf.apply is not None)
        return build_spec(params, hold_beam_rad=hold_beam_rad, fragments=fragments)


def vary(
    base: Parameters, names: Sequence[str], rng: np.random.Generator, n: int, spread: float = 0.05
) -> list[Parameters]:
    """n parameter sets around ``base``, each of ``names`` (dotted) scaled by its own factor drawn uniformly
    within ±``spread`` (for a batch form's inputs: each run its own part)."""
    factors = rng.uniform(1.0 - spread, 1.0 + spread, size=(n, len(names)))
    out = []
    for row in factors.tolist():
        values = {}
        for name, factor in zip(names, row, strict=True):
            group, _, attr = name.partition(".")
            values[name] = getattr(getattr(base, group), attr) * factor
        out.append(base.with_overrides(values, origin="vary"))
    return out
