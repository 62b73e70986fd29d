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
actuator what it makes of the DAC's volts (``ActuatorPart.drive``). Its batch runtime is the same for the N runs
of the batch engine (``twin.rigs.batch.BatchRig``) at once, each run bit for bit its one-run runtime:
``BallSensorPart.batch_chain``, ``AngleSensorPart.batch_read``, ``IoBoardPart.batch_dac``/``batch_adc``,
``ActuatorPart.batch_drive`` (optional: a part without one runs one run at a time, and the batch engine refuses
it naming the part). ``RigParts`` is a rig: one part per role, ``replace`` swaps one. A new part is one module:
its parameter group, its ``Part`` and one ``register`` call.
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
    "AngleSensorBatch",
    "AngleSensorChain",
    "AngleSensorPart",
    "BallSensorBatch",
    "BallSensorChain",
    "BallSensorPart",
    "BatchForm",
    "BatchWrite",
    "IoBoardPart",
    "MjcfFragment",
    "Part",
    "PartError",
    "RigParts",
    "Role",
    "StepLaw",
    "board_batch_adc",
    "board_reading_unit",
    "fixed_unit",
    "missing_batch_runtime",
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


class BallSensorBatch(Protocol):
    """What the batch engine asks of a ball sensor's chains over N runs in step (``twin.sensors.BallChainBatch``,
    ``twin.parts.ranging.SampledBatch``): run i's readings are its ``BallSensorChain``'s bit for bit, each run
    started as ``SimRig.reset`` starts the chain (its seed, the ball at rest at its start)."""

    def advance(
        self, runs: np.ndarray, times_s: np.ndarray, x_m: np.ndarray, on_track: np.ndarray
    ) -> np.ndarray:
        """The runs ``runs`` (indices into the batch) over the shared ``times_s`` (K,), their positions and
        on-track flags one row each (len(runs), K): the board's readings (len(runs),) at the block's end."""
        ...


class AngleSensorBatch(Protocol):
    """What the batch engine asks of an angle sensor over N runs in step: run i's readings are its
    ``AngleSensorChain.read_block_v``'s bit for bit (a fresh chain per run, as ``SimRig`` builds one)."""

    def read(self, runs: np.ndarray, times_s: np.ndarray, theta_rad: np.ndarray) -> np.ndarray:
        """The board's readings (len(runs),) of the runs ``runs`` (indices into the batch) for a block: the
        shared ``times_s`` (K,), the beam's angle one row per run (len(runs), K)."""
        ...


# A batch's per-tick conversion: (runs, values) → values, runs the indices into the batch whose values these are
# (each run's own constants and state: a servo's dead band).
BatchWrite = Callable[[np.ndarray, np.ndarray], np.ndarray]
# An actuator's law stepped with the physics (``ActuatorPart.step_law``): (the control its ``drive`` made of the
# board's output, the drive joint's angle rad, its speed rad/s) → the torque (N·m) on that joint over the next
# physics step; it holds its own state (a stepper's ramp), which the call advances by one step.
StepLaw = Callable[[float, float, float], float]
# A ball sensor's chains of N runs: (each run's parameters, seeds, the ball's starts x0_m, the chains' start t0_s).
BallBatchFactory = Callable[[Sequence[Parameters], np.ndarray, np.ndarray, float], BallSensorBatch]


def board_reading_unit(params: Parameters) -> str:
    """The unit of an analog sensor's reading (a sensor read through the board's ADC, the default
    ``reading_unit``): the ADC's of the board ``params.parts.io_board`` names (``IoBoardPart.adc_unit``)."""
    board = part_named("io_board", params.parts.io_board)
    return board.adc_unit if isinstance(board, IoBoardPart) else "V"


def _own_unit(unit: str, params: Parameters) -> str:
    return unit


def fixed_unit(unit: str) -> Callable[[Parameters], str]:
    """A ``reading_unit`` that is the sensor's own, whatever the board (a digital sensor's: "mm" over I²C); a
    partial, not a closure, so that a part still pickles."""
    return functools.partial(_own_unit, unit)


@dataclass(frozen=True, kw_only=True)
class BallSensorPart(Part):
    """A ball sensor: ``chain(params, seed)`` is one run's chain (its noise seeded). ``batch_chain(params, seeds,
    x0_m, t0_s)``: the chains of N runs (one parameter set and seed each, the ball at rest at x0_m[i] at the
    chain's start t0_s) in step, each run its ``chain`` reset there with its seed (``BallSensorBatch``)."""

    role: Role = "ball_sensor"
    chain: Callable[[Parameters, int], BallSensorChain]
    batch_chain: BallBatchFactory | None = None
    # The software's conversion (what a sketch or the rig's software computes): a reading in the board's unit →
    # the ball's x (m, from the track's centre), the inverse of the sensor's nominal curve; NaN for a reading that
    # carries no position (a lost echo). None: the part gives none (a controller that needs it is refused).
    position_of: Callable[[Parameters], Callable[[float], float]] | None = None
    # The unit of its reading as the board reads it (the live view's plots name it): by default an analog
    # sensor's, the board's ADC's (``board_reading_unit``); a digital sensor gives its own (``fixed_unit``).
    reading_unit: Callable[[Parameters], str] = board_reading_unit


@dataclass(frozen=True, kw_only=True)
class AngleSensorPart(Part):
    """An angle sensor: ``chain(params)`` is one run's chain. ``batch_read(params)``: N runs' fresh chains (one
    parameter set each) read in step (``AngleSensorBatch``)."""

    role: Role = "angle_sensor"
    chain: Callable[[Parameters], AngleSensorChain]
    batch_read: Callable[[Sequence[Parameters]], AngleSensorBatch] | None = None
    # The software's conversion: a reading → the beam's angle θ (rad), as ``BallSensorPart.position_of``;
    # ``measures_angle`` False for a rig without an angle sensor (its reading carries nothing).
    angle_of: Callable[[Parameters], Callable[[float], float]] | None = None
    measures_angle: bool = True
    # The unit of its reading, as ``BallSensorPart.reading_unit`` (default: the board's ADC's).
    reading_unit: Callable[[Parameters], str] = board_reading_unit


@dataclass(frozen=True, kw_only=True)
class IoBoardPart(Part):
    """An I/O board: ``dac_writer(params)`` gives what its output puts out for a command (one float: the DAC's
    volts on the PCI-1712, a servo pulse's width in µs on an Arduino); ``adc(params)`` what it reads for an
    analog input's volts at its pin (the ADC's volts on the PCI-1712, ``analogRead``'s counts on an Arduino),
    for the analog sensors' chains; ``output_range(params)`` what its output can be (the guard refuses a
    controller's command outside it; default the DAC's, ``dac_range``). ``batch_dac(params)`` and
    ``batch_adc(params)``: ``dac_writer`` and ``adc`` of N runs (one parameter set each) as one ``BatchWrite``,
    each run's values its own converter's bit for bit."""

    role: Role = "io_board"
    dac_writer: Callable[[Parameters], Callable[[float], float]]
    adc: Callable[[Parameters], Callable[[float], float]]
    # The software's conversion of an analog reading back to the pin's volts (the inverse of ``adc``, at the
    # middle of its step): what an analog sensor's software conversion starts from. None: not given.
    volts_of: Callable[[Parameters], Callable[[float], float]] | None = None
    output_range: Callable[[Parameters], CommandRange] = dac_range
    # The unit of ``adc``'s readings (the live view's plots name it; its output's is ``output_range``'s).
    adc_unit: str = "V"
    batch_dac: Callable[[Sequence[Parameters]], BatchWrite] | None = None
    batch_adc: Callable[[Sequence[Parameters]], BatchWrite] | None = None


@dataclass(frozen=True, kw_only=True)
class ActuatorPart(Part):
    """An actuator: ``drive(params)`` gives the MuJoCo actuator's control (the motor's terminal volts; a
    servo's target angle) for the board's output, a fresh write path per run (it may hold state);
    ``rest_command(params)`` is the board's command that leaves the beam at rest where it is held (the
    amplifier's zero command, 2.5 V, by default: ``zero_command``), what the rig writes before the
    controller's first command. ``batch_drive(params)``: N runs' fresh write paths (one parameter set each) as
    one ``BatchWrite``, each run's state its own (a servo's dead band), bit for bit its ``drive``."""

    role: Role = "actuator"
    drive: Callable[[Parameters], Callable[[float], float]]
    rest_command: Callable[[Parameters], float] = zero_command
    batch_drive: Callable[[Sequence[Parameters]], BatchWrite] | None = None
    # The software's conversions between the board's command and the actuator's control (the motor's volts, a
    # servo's target angle): ``command_of`` the command that asks for a control, ``control_of`` the control a
    # command gives, nominally (no dead band, no quantization). None: the part gives none.
    command_of: Callable[[Parameters], Callable[[float], float]] | None = None
    control_of: Callable[[Parameters], Callable[[float], float]] | None = None
    # The unit of its control (what ``drive`` gives: the motor's volts, a servo's target angle), for the view.
    control_unit: str = "V"
    # A torque computed once per physics step from the drive joint's state (``StepLaw``; a fresh one per run),
    # for an actuator MuJoCo has no element for (a stepper's sine law and ramp): the simulated rig steps it
    # (``twin.rigs.sim.SimRig``) with its MuJoCo actuator a plain torque motor; the batch engine refuses it.
    step_law: Callable[[Parameters], StepLaw] | None = None


# The batch runtime field each role's part needs in the batch engine (``missing_batch_runtime``).
BATCH_RUNTIME: Mapping[Role, str] = {
    "actuator": "batch_drive",
    "ball_sensor": "batch_chain",
    "angle_sensor": "batch_read",
    "io_board": "batch_dac",
}


def missing_batch_runtime(parts: RigParts) -> list[str]:
    """The parts of a rig the batch engine cannot run (no batch runtime), each as "parts.<role> = 'name' (no
    <Type>.<field>)"; empty if it can run them all."""
    return [
        f"parts.{role} = {getattr(parts, role).name!r} (no {type(getattr(parts, role)).__name__}.{field})"
        for role, field in BATCH_RUNTIME.items()
        if getattr(getattr(parts, role), field, None) is None
    ]


def board_adc(params: Parameters) -> Callable[[float], float]:
    """The ADC of the board ``params.parts.io_board`` names (``IoBoardPart.adc``): volts at its pin in, its
    reading out (an analog sensor's chain reads through it)."""
    board = part_named("io_board", params.parts.io_board)
    assert isinstance(board, IoBoardPart)  # the registry holds an io_board's part type (ROLE_TYPES)
    return board.adc(params)


def board_volts_of(params: Parameters) -> Callable[[float], float]:
    """The software's conversion of the board's analog reading back to volts (``IoBoardPart.volts_of`` of the
    board ``params.parts.io_board`` names); ``PartError`` naming the board if it gives none."""
    board = part_named("io_board", params.parts.io_board)
    if not isinstance(board, IoBoardPart) or board.volts_of is None:
        raise PartError(
            f"parts.io_board = {params.parts.io_board!r} gives no conversion of its readings to volts"
        )
    return board.volts_of(params)


def board_batch_adc(params: Sequence[Parameters]) -> BatchWrite:
    """The ADC of the board each run's ``parts.io_board`` names, over N runs (``IoBoardPart.batch_adc``), for an
    analog sensor's batch: one board's batch for all when they name one board, else each run through its own
    board's ``adc`` (the same bits). ``PartError`` naming the board if it has no ``batch_adc``."""
    names = {p.parts.io_board for p in params}
    boards = {name: part_named("io_board", name) for name in sorted(names)}
    for name, board in boards.items():
        if not isinstance(board, IoBoardPart) or board.batch_adc is None:
            raise PartError(
                f"parts.io_board = {name!r} has no batch ADC (IoBoardPart.batch_adc): run it one run at a time"
            )
    if len(boards) == 1:
        (board,) = boards.values()
        assert isinstance(board, IoBoardPart) and board.batch_adc is not None
        return board.batch_adc(params)
    adcs = []
    for p in params:
        board = boards[p.parts.io_board]
        assert isinstance(board, IoBoardPart)
        adcs.append(board.adc(p))

    def read(runs: np.ndarray, volts: np.ndarray) -> np.ndarray:
        return np.array([adcs[i](v) for i, v in zip(runs.tolist(), np.asarray(volts).tolist(), strict=True)])

    return read


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
            values[name] = getattr(base.group(group), attr) * factor  # the table's groups and the parts' own
        out.append(base.with_overrides(values, origin="vary"))
    return out
